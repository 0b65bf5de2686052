"""Where a person stands on the floor, from one camera's 2D view.

A joint of known height above the floor (edge.body.TYPICAL_HEIGHT_M) and a calibrated camera
give a point: the pixel's ray meets the horizontal plane at that height. The lowest visible
body part is used, because the lower the joint, the further it is (vertically) from a
wall-mounted camera and the less an error in its assumed height moves the point:

    ankles (mean of the visible ones) at 0.12 m -> hips at 0.91 m -> shoulders at 1.43 m
    -> the bottom-centre of the bounding box at 0 m

A level whose ray misses its plane in front of the camera, or meets it farther than
``max_range_m`` away, falls through to the next one. A box is used only if it spans a person's
height at that range (a detector's box around a head alone would put the "feet" metres away).

The uncertainty is a 1-sigma distance in metres, mostly along the viewing direction:

    sigma^2 = body^2 + (r * dz / dh)^2 + (dtheta * (r^2 + dh^2) / dh)^2

with r the horizontal range, dh the camera's height above the plane, dz the spread of the
joint's real height (people differ, knees bend), dtheta the pixel noise as an angle, and body
how far that part sits from the point between the feet. It grows with range and with each
fallback (higher joints sit closer to the camera's height).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import INDEX, LEFT_HIP, LEFT_SHOULDER, RIGHT_HIP, RIGHT_SHOULDER, TYPICAL_HEIGHT_M
from superbody.edge.camera import Camera, intersect_plane, pixel_to_ray
from superbody.edge.messages.observation import PersonView

__all__ = ["MAX_RANGE_M", "LEVELS", "Level", "ground_point", "ground_points"]

MAX_RANGE_M: Final[float] = 30.0


class Level(NamedTuple):
    """One body part the ground point can come from, with its error model."""

    name: str
    joints: tuple[int, ...]  # COCO-17 indices averaged in the image; () for the bbox
    height_m: float  # height of that part above the floor
    height_std_m: float  # how much that height varies between people and poses
    body_std_m: float  # how far that part sits, horizontally, from the point between the feet
    pixel_std: float  # detector noise on that pixel


_LEFT_ANKLE, _RIGHT_ANKLE = INDEX["left_ankle"], INDEX["right_ankle"]

# Tried in this order; the index into LEVELS is what ground_points reports as "level".
LEVELS: Final[tuple[Level, ...]] = (
    Level("ankles", (_LEFT_ANKLE, _RIGHT_ANKLE), TYPICAL_HEIGHT_M[_LEFT_ANKLE], 0.05, 0.10, 4.0),
    Level("hips", (LEFT_HIP, RIGHT_HIP), TYPICAL_HEIGHT_M[LEFT_HIP], 0.08, 0.10, 4.0),
    Level("shoulders", (LEFT_SHOULDER, RIGHT_SHOULDER), TYPICAL_HEIGHT_M[LEFT_SHOULDER], 0.10, 0.12, 4.0),
    # Used only when no ankle, hip or shoulder was seen, so the box's bottom edge is as likely
    # an occluder's edge (a table, a sofa) as the feet: a loose error model.
    Level("bbox", (), 0.0, 0.35, 0.50, 8.0),
)
# Below this height difference the ray grazes the plane and the point means nothing.
_MIN_DH_M: Final[float] = 0.05
# A box whose bottom is this close to the image's bottom edge has its feet cut off.
_EDGE_PX: Final[float] = 2.0
# Heights a box's top edge may reach at the range its bottom edge gives, metres. A box that
# stops at the knees already reads ~1.5 m for a 1.75 m adult seen from 2.5 m up; one that stops
# at the hips or elbows reads ~1.1-1.3 m, and its "floor point" would be metres too far.
_BOX_HEIGHT_M: Final[tuple[float, float]] = (1.4, 2.3)
# The joint levels' indices as one (levels, 2) table, and each level's error model as (L,) arrays.
_JOINTS = np.array([lv.joints for lv in LEVELS if lv.joints])  # (3, 2)
_HEIGHT = np.array([lv.height_m for lv in LEVELS])  # (L,)
_HEIGHT_STD = np.array([lv.height_std_m for lv in LEVELS])
_BODY_STD = np.array([lv.body_std_m for lv in LEVELS])
_PIXEL_STD = np.array([lv.pixel_std for lv in LEVELS])


def ground_points(
    keypoints: NDArray[np.float32],
    bboxes: NDArray[np.float32],
    cam: Camera,
    max_range_m: float = MAX_RANGE_M,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int8]]:
    """Ground points of many views from one camera, in one pass.

    Args:
        keypoints: (N, 17, 3) COCO-17 (u, v, score) per view; NaN rows for missing joints.
        bboxes: (N, 4) (x0, y0, x1, y1) pixels.
        cam: the camera that saw them.
        max_range_m: farthest accepted horizontal distance from the camera.

    Returns:
        ``(xy, sigma, level)``: floor points (N, 2) in metres, their 1-sigma uncertainty (N,)
        in metres, and the index into ``LEVELS`` used (N,), -1 where none worked (those rows
        of ``xy`` and ``sigma`` are NaN).
    """
    kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, 17, 3)  # (N, 17, 3)
    bb = np.asarray(bboxes, dtype=np.float64).reshape(-1, 4)  # (N, 4)
    n, n_levels = len(kp), len(LEVELS)
    dh, sigma_fixed, sigma_range, sigma_pixel = _camera_terms(cam)  # (L,) each
    t = cam.t  # (3,)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Candidate pixel of each level: the mean of its visible joints, or the box's bottom
        # centre; then the box's top centre: (N, L + 1, 2), NaN where there is none.
        pts = kp[:, _JOINTS, :2]  # (N, 3, 2, 2)
        seen = ~np.isnan(pts[..., 0])  # (N, 3, 2)
        uv = np.empty((n, n_levels + 1, 2))
        uv[:, : n_levels - 1] = np.where(seen[..., None], pts, 0.0).sum(axis=2) / seen.sum(axis=2)[..., None]  # NaN if none
        box_ok = (bb[:, 2] > bb[:, 0]) & (bb[:, 3] > bb[:, 1]) & (bb[:, 3] < cam.height - _EDGE_PX)  # False for NaN
        uv[:, n_levels - 1 :, 0] = np.where(box_ok, 0.5 * (bb[:, 0] + bb[:, 2]), np.nan)[:, None]
        uv[:, n_levels - 1, 1] = np.where(box_ok, bb[:, 3], np.nan)  # bottom centre
        uv[:, n_levels, 1] = np.where(box_ok, bb[:, 1], np.nan)  # top centre

        # One batch of rays; where each level's ray meets its plane z = h.
        flat = uv.reshape(-1, 2)  # (N (L + 1), 2)
        usable = ~np.isnan(flat).any(axis=1)
        d: NDArray[np.float64] = np.full((len(flat), 3), np.nan)
        if usable.any():
            d[usable] = pixel_to_ray(flat[usable], cam)[1]
        d = d.reshape(n, n_levels + 1, 3)  # (N, L + 1, 3)
        hit, valid = intersect_plane(t, d[:, :n_levels].reshape(-1, 3), np.tile(_HEIGHT, n))
        points, valid = hit[:, :2].reshape(n, n_levels, 2), valid.reshape(n, n_levels)  # (N, L, 2), (N, L)
        r = np.hypot(points[..., 0] - t[0], points[..., 1] - t[1])  # (N, L) horizontal range
        valid &= (r <= max_range_m) & (dh >= _MIN_DH_M)
        # A box is a person's only if it spans a plausible body: the top edge's ray, at the
        # bottom point's range, must be at a person's height (a head-only box fails this).
        top = d[:, n_levels]  # (N, 3)
        top_height = t[2] + top[:, 2] * r[:, -1] / np.hypot(top[:, 0], top[:, 1])  # (N,)
        clipped = bb[:, 1] <= _EDGE_PX  # head above the image: the height is unknown
        valid[:, -1] &= clipped | ((top_height >= _BOX_HEIGHT_M[0]) & (top_height <= _BOX_HEIGHT_M[1]))

    level = np.where(valid.any(axis=1), np.argmax(valid, axis=1), -1).astype(np.int8)  # (N,) first that worked
    found = level >= 0
    rows = np.arange(n)
    lv = np.maximum(level, 0)
    r_used = r[rows, lv]  # (N,)
    # sigma^2 = body^2 + (r dz / dh)^2 + (dtheta (r^2 + dh^2) / dh)^2
    sigma = np.sqrt(sigma_fixed[lv] + (r_used * sigma_range[lv]) ** 2 + (sigma_pixel[lv] * (r_used * r_used + dh[lv] ** 2)) ** 2)
    xy = np.where(found[:, None], points[rows, lv], np.nan)
    return xy, np.where(found, sigma, np.nan), level


@lru_cache(maxsize=256)
def _camera_terms(cam: Camera) -> tuple[NDArray[np.float64], ...]:
    """Per level (L,): the camera's height above its plane dh, and the error model's terms
    body^2, dz / dh and dtheta / dh (see the module docstring)."""
    dh = np.abs(cam.t[2] - _HEIGHT)  # (L,)
    dtheta = _PIXEL_STD / (0.5 * (cam.fx + cam.fy))  # (L,) pixel noise as an angle
    with np.errstate(divide="ignore"):
        return dh, _BODY_STD**2, _HEIGHT_STD / dh, dtheta / dh


def ground_point(view: PersonView, cam: Camera, max_range_m: float = MAX_RANGE_M) -> tuple[NDArray[np.float64], float] | None:
    """Where the person in ``view`` stands on the floor, seen from ``cam``.

    Args:
        view: one detected person.
        cam: the camera that saw them.
        max_range_m: farthest accepted horizontal distance from the camera.

    Returns:
        ``(xy, sigma)``: the floor point (2,) in metres (REP-103) and its 1-sigma uncertainty
        in metres; ``None`` when no body part gives a point in front of the camera within range.
    """
    xy, sigma, level = ground_points(view.keypoints[None], view.bbox[None], cam, max_range_m)
    if level[0] < 0:
        return None
    return xy[0], float(sigma[0])
