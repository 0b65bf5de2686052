"""Pure conversions behind the OAK source: device outputs as arrays -> superbody types.

Nothing here imports depthai: ``edge/sources/oak.py`` reads depthai's messages into plain arrays and
these functions turn them into ``PersonView``s, UNIX capture stamps and ``Camera`` intrinsics.

Conventions of the device side (depthai v3, checked on 3.12 with the real host nodes):

- detection boxes and keypoints are normalised to the NN frame, (0, 0) top-left, (1, 1)
  bottom-right; a keypoint's confidence is the sigmoid of the network's visibility logit;
- spatial keypoints are millimetres in the NN frame's camera frame, OpenCV axes (x right,
  y down, z forward); z = 0 means "no depth there" (no stereo match, or outside the range);
- timestamps are ``datetime.timedelta`` on the host's monotonic clock (``dai.Clock.now()``
  equals ``time.monotonic()``), already synchronised from the device's clock;
- intrinsics are a 3x3 matrix for the frame as delivered and 14 distortion coefficients in
  OpenCV's order (k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tx, ty).
"""

from __future__ import annotations

import dataclasses
import datetime
import math

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.camera import Camera
from superbody.edge.messages.observation import PersonView, empty_histogram
from superbody.edge.site import Site

__all__ = [
    "detection_arrays",
    "people_from_arrays",
    "timedelta_ns",
    "monotonic_to_unix_ns",
    "site_distortion",
    "camera_with_intrinsics",
    "intrinsics_disagreement",
    "site_with_camera",
]

# Distortion coefficients the site file can hold (OpenCV's rational model without the thin
# prism and tilt terms).
_SITE_DIST = 8


def people_from_arrays(
    boxes: NDArray,
    keypoints: NDArray,
    points3d_mm: NDArray | None,
    width: int,
    height: int,
    min_keypoint_score: float,
) -> tuple[PersonView, ...]:
    """Detections of one frame as ``PersonView``s in that frame's pixels.

    Args:
        boxes: (N, 4) boxes (xmin, ymin, xmax, ymax), normalised to the frame.
        keypoints: (N, 17, 3) COCO-17 keypoints (x, y normalised, confidence in [0, 1]);
            NaN rows for keypoints the detector did not give.
        points3d_mm: (N, 17, 3) spatial keypoints in millimetres, OpenCV camera frame, z = 0
            where there is no depth; or None without depth.
        width: frame width in pixels.
        height: frame height in pixels.
        min_keypoint_score: joints below this confidence are sent as missing.

    Returns:
        One ``PersonView`` per detection with at least one joint at or above
        ``min_keypoint_score``. Missing joints are NaN rows in ``keypoints`` and in
        ``points3d`` (a joint without its 2D keypoint has no trustworthy depth either: the
        depth at that pixel belongs to whatever hides the joint). Histograms are left empty:
        the camera node computes them from the frame's image.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
    if len(boxes) != len(kp):
        raise ValueError(f"people_from_arrays: {len(boxes)} boxes but {len(kp)} keypoint sets")
    scale = np.array([width, height], dtype=np.float64)
    people = []
    for n in range(len(kp)):
        score = kp[n, :, 2]
        visible = np.isfinite(kp[n]).all(axis=1) & (score >= min_keypoint_score) & (score > 0)  # (17,)
        if not visible.any():
            continue
        out_kp = np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
        out_kp[visible, :2] = kp[n, visible, :2] * scale
        out_kp[visible, 2] = np.minimum(score[visible], 1.0)
        box = np.clip(boxes[n], 0.0, 1.0) * np.tile(scale, 2)  # (4,) pixels
        box[2:] = np.maximum(box[2:], box[:2])
        p3 = None
        if points3d_mm is not None:
            xyz = np.asarray(points3d_mm, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)[n]
            has_depth = visible & np.isfinite(xyz).all(axis=1) & (xyz[:, 2] > 0)  # z = 0: no depth
            p3 = np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
            p3[has_depth] = xyz[has_depth] / 1000.0  # mm -> m
        people.append(PersonView(keypoints=out_kp, bbox=box.astype(np.float32), histogram=empty_histogram(), points3d=p3))
    return tuple(people)


def timedelta_ns(td: datetime.timedelta) -> int:
    """A ``timedelta`` as integer nanoseconds (exact: timedelta holds whole microseconds)."""
    return ((td.days * 86_400 + td.seconds) * 1_000_000 + td.microseconds) * 1_000


def monotonic_to_unix_ns(stamp_ns: int, monotonic_now_ns: int, unix_now_ns: int) -> int:
    """A monotonic-clock instant as UNIX nanoseconds.

    Args:
        stamp_ns: the instant on the monotonic clock (``time.monotonic_ns()``'s clock).
        monotonic_now_ns: ``time.monotonic_ns()`` read now.
        unix_now_ns: ``time.time_ns()`` read now (next to ``monotonic_now_ns``).
    """
    # The instant was (monotonic_now - stamp) ago on both clocks.
    return unix_now_ns - (monotonic_now_ns - stamp_ns)


def site_distortion(coefficients: NDArray | list[float], tol: float = 1e-9) -> tuple[float, ...]:
    """Device distortion coefficients in the form a site file holds (0, 4, 5 or 8 of them).

    Args:
        coefficients: OpenCV-ordered coefficients, any length (depthai gives 14).
        tol: magnitude below which a coefficient counts as zero.

    Returns:
        The shortest of (), k1..p2, k1..k3, k1..k6 that drops only zeros.

    Raises:
        ValueError: a thin-prism or tilt coefficient (index 8 and up) is not zero; the site's
            camera model cannot hold it.
    """
    d = np.asarray(coefficients, dtype=np.float64).ravel()
    if not np.isfinite(d).all():
        raise ValueError(f"distortion coefficients must be finite, got {d.tolist()}")
    extra = np.flatnonzero(np.abs(d[_SITE_DIST:]) > tol)
    if extra.size:
        k = int(extra[0]) + _SITE_DIST
        raise ValueError(
            f"distortion coefficient {k} (s1..s4, tx, ty are 8..13) is {d[k]:g}; a site camera holds only "
            f"k1, k2, p1, p2, k3, k4, k5, k6"
        )
    d = np.pad(d[:_SITE_DIST], (0, max(0, _SITE_DIST - len(d))))
    nonzero = np.flatnonzero(np.abs(d) > tol)
    if nonzero.size == 0:
        return ()
    last = int(nonzero[-1])
    n = 4 if last < 4 else 5 if last < 5 else 8
    return tuple(float(v) for v in d[:n])


def camera_with_intrinsics(cam: Camera, K: NDArray, dist: NDArray | list[float], width: int, height: int) -> Camera:
    """``cam`` with the intrinsics, distortion and image size of a device frame.

    Args:
        cam: the site's camera (its id, fps and pose are kept).
        K: (3, 3) intrinsic matrix of the frame.
        dist: OpenCV-ordered distortion coefficients (see ``site_distortion``).
        width: frame width in pixels.
        height: frame height in pixels.

    Raises:
        ValueError: K is not a zero-skew pinhole matrix with positive focal lengths and the
            principal point inside the frame, or the distortion does not fit a site file.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ValueError(f"intrinsic matrix must be a finite 3x3 matrix, got {K.tolist()}")
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if not (fx > 0 and fy > 0) or not (0 <= cx <= width and 0 <= cy <= height):
        raise ValueError(
            f"intrinsics fx={fx:g}, fy={fy:g} must be > 0 and cx={cx:g}, cy={cy:g} inside the "
            f"{width}x{height} frame"
        )
    if abs(K[0, 1]) > 1e-6 * fx or np.abs(K[2] - [0, 0, 1]).max() > 1e-9 or abs(K[1, 0]) > 1e-9:
        raise ValueError(f"intrinsic matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
    return dataclasses.replace(cam, width=int(width), height=int(height), fx=fx, fy=fy, cx=cx, cy=cy, dist=site_distortion(dist))


def intrinsics_disagreement(cam: Camera, K: NDArray, width: int, height: int, rel_tol: float = 0.01) -> str | None:
    """What differs between the site's intrinsics and a device frame's, or None when they agree.

    Focal lengths agree within ``rel_tol`` of the device's; the principal point within
    ``rel_tol`` of the image width (x) and height (y).
    """
    K = np.asarray(K, dtype=np.float64)
    device = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
    limit = {"fx": rel_tol * K[0, 0], "fy": rel_tol * K[1, 1], "cx": rel_tol * width, "cy": rel_tol * height}
    diffs = [
        f"{name} {getattr(cam, name):.2f} (device {value:.2f})"
        for name, value in device.items()
        if not math.isclose(getattr(cam, name), value, abs_tol=limit[name]) or not math.isfinite(value)
    ]
    if (cam.width, cam.height) != (width, height):
        diffs.insert(0, f"size {cam.width}x{cam.height} (device {width}x{height})")
    return ", ".join(diffs) or None


def site_with_camera(site: Site, cam: Camera) -> Site:
    """``site`` with the camera of ``cam.id`` replaced by ``cam``; ``KeyError`` if there is none."""
    site.camera(cam.id)  # KeyError naming the valid ids
    return dataclasses.replace(site, cameras=tuple(cam if c.id == cam.id else c for c in site.cameras))


def detection_arrays(detections, spatial: bool) -> tuple[NDArray, NDArray, NDArray | None]:
    """A depthai detections message as arrays.

    Returns:
        ``(boxes, keypoints, points3d_mm)``: (N, 4) normalised boxes; (N, 17, 3) normalised
        keypoints with confidences (NaN for a detection without 17 keypoints); and (N, 17, 3)
        spatial keypoints in mm (OpenCV camera frame, z = 0 without depth) or None.
    """
    dets = list(detections.detections)
    boxes = np.array([[d.xmin, d.ymin, d.xmax, d.ymax] for d in dets], dtype=np.float64).reshape(-1, 4)
    kps = np.full((len(dets), NUM_KEYPOINTS, 3), np.nan)
    xyz = np.zeros((len(dets), NUM_KEYPOINTS, 3)) if spatial else None
    for n, d in enumerate(dets):
        points = d.getKeypoints()
        if len(points) != NUM_KEYPOINTS:
            continue
        kps[n] = [(p.imageCoordinates.x, p.imageCoordinates.y, p.confidence) for p in points]
        if xyz is not None:
            xyz[n] = [(p.spatialCoordinates.x, p.spatialCoordinates.y, p.spatialCoordinates.z) for p in points]
    return boxes, kps, xyz
