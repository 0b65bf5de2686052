"""How well one camera's calibration fits what the others see: each camera's joints against the
same joints triangulated from the *other* cameras (leave one out), in pixels and as an angle.

An ``Instant`` is one person's near-simultaneous views from several cameras (the host's set S,
or a group of views the tracker gave to one person). For camera ``v`` and joint ``j``:

1. the point ``X`` closest (least squares) to the rays of joint ``j`` from every *other* camera
   that saw it; at least ``MIN_OTHER_VIEWS`` of them, meeting at ``MIN_RAY_ANGLE_DEG`` or more,
   and in front of all of them;
2. the residual of ``v``: the angle between ``v``'s ray to its detected joint and its ray to
   ``X`` (degrees: the same for any resolution), and the pixel distance between the detected
   joint and ``X`` projected through ``v`` (lens distortion included).

Leaving ``v`` out keeps a moved camera from pulling the point towards its own wrong ray. Views
captured at different instants are brought to the instant's time by the person's floor velocity
(``Instant.offsets_m``): a person walking at 1.4 m/s moves 5 cm in a 15-fps frame period.

Why at least two other views and no typical-height fallback: one other view puts a joint on its
ray at the joint's typical height (edge.body.TYPICAL_HEIGHT_M), unsure by the 10-cm spread of
heights over the ray's slope: 0.3 m along the ray for a camera 2 m up seeing a hip 3 m away,
6 deg seen from the other side, three times the 2 deg a knocked camera shows. A camera whose
people only one other camera sees gets no samples and is reported as unknown, not as fine.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.camera import Camera, distort, normalised_to_rays, undistort
from superbody.edge.messages.observation import PersonView

__all__ = ["Instant", "instant_from_views", "rays", "leave_one_out", "residuals", "instant_residuals", "MIN_OTHER_VIEWS",
           "MIN_RAY_ANGLE_DEG"]

MIN_OTHER_VIEWS: Final[int] = 2
# Two rays meeting at less than this place their point badly along them (the analytic
# estimator's 0.05 cross product is 2.9 deg): 5 deg keeps the point's depth error under 12
# times its sideways error.
MIN_RAY_ANGLE_DEG: Final[float] = 5.0
# The smallest eigenvalue of sum_k (I - d_k d_k^T) for two rays at the angle above is 1 - cos.
_MIN_EIG: Final[float] = 1.0 - math.cos(math.radians(MIN_RAY_ANGLE_DEG))
_MIN_DEPTH_M: Final[float] = 0.1
_NS: Final[float] = 1e9


@dataclass(frozen=True, eq=False)
class Instant:
    """One person's views from several cameras, brought to one time.

    Attributes:
        stamp_ns: the instant's time, UNIX ns.
        cameras: (V,) camera ids, each once.
        keypoints: (V, 17, 3) float64 (u, v, score) per view; NaN rows for missing joints.
        offsets_m: (V, 3) float64 how far the person moved from ``stamp_ns`` to each view's
            capture time (floor velocity times the time difference; zeros when unknown).
        person: the tracker's id of the person (-1: unknown).
    """

    stamp_ns: int
    cameras: tuple[str, ...]
    keypoints: NDArray[np.float64]
    offsets_m: NDArray[np.float64]
    person: int = -1


def instant_from_views(views: Mapping[str, PersonView], stamp_ns: int, stamps: Mapping[str, int] | None = None,
                       velocity: Sequence[float] | NDArray | None = None, person: int = -1) -> Instant:
    """An ``Instant`` from a set S (camera id -> view).

    Args:
        views: the person's latest view per camera.
        stamp_ns: the instant's time (e.g. the newest view's capture time).
        stamps: each view's capture time (camera id -> UNIX ns); None: all at ``stamp_ns``.
        velocity: the person's floor velocity (vx, vy) in m/s (e.g. ``PersonPose.vx, vy``); None: still.
        person: the person's track id.
    """
    cams = tuple(views)
    kp = np.stack([np.asarray(views[c].keypoints, dtype=np.float64) for c in cams]) if cams else np.zeros((0, NUM_KEYPOINTS, 3))
    offsets = np.zeros((len(cams), 3))
    if stamps is not None and velocity is not None:
        dt = np.array([(int(stamps[c]) - int(stamp_ns)) / _NS for c in cams])  # (V,) seconds
        offsets[:, :2] = dt[:, None] * np.asarray(velocity, dtype=np.float64).reshape(1, 2)
    return Instant(int(stamp_ns), cams, kp, offsets, int(person))


def rays(instant: Instant, cameras: Mapping[str, Camera]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The instant's joint rays in the world, each view's brought to the instant's time.

    Returns:
        ``(origins, directions, seen)``: (V, 3) optical centres minus the view's offset (a ray
        from there meets the joint where it was at the instant's time), (V, 17, 3) unit
        directions (zeros where unseen) and (V, 17) which joints each view saw.
    """
    kp = instant.keypoints
    seen = ~np.isnan(kp[:, :, 0])  # (V, 17)
    dirs = np.zeros(kp.shape[:2] + (3,))
    for i, cid in enumerate(instant.cameras):
        cam = cameras[cid]
        if seen[i].any():
            dirs[i, seen[i]] = normalised_to_rays(undistort(kp[i, seen[i], :2], cam), cam.R)
    origins = np.stack([cameras[c].t for c in instant.cameras]) - instant.offsets_m if instant.cameras else np.zeros((0, 3))
    return origins, dirs, seen


def leave_one_out(origins: NDArray, dirs: NDArray, seen: NDArray) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Each view's joints triangulated from the other views alone.

    Args:
        origins: (V, 3) ray origins.
        dirs: (V, 17, 3) unit ray directions.
        seen: (V, 17) which rays exist.

    Returns:
        ``(points, ok)``: (V, 17, 3) the point of joint j from every view but v, and (V, 17)
        where it exists (v saw j; at least ``MIN_OTHER_VIEWS`` others did, their rays meet at
        ``MIN_RAY_ANGLE_DEG`` or more, and the point is in front of them). NaN where not ok.
    """
    # sum_k (I - d_k d_k^T) p = sum_k (I - d_k d_k^T) o_k over the other views k
    proj = (np.eye(3) - dirs[..., :, None] * dirs[..., None, :]) * seen[..., None, None]  # (V, 17, 3, 3)
    rhs = proj @ origins[:, None, :, None]  # (V, 17, 3, 1)
    A = proj.sum(0)[None] - proj  # (V, 17, 3, 3) all views but v
    b = (rhs.sum(0)[None] - rhs)[..., 0]  # (V, 17, 3)
    others = seen.sum(0)[None] - seen  # (V, 17)
    ok = seen & (others >= MIN_OTHER_VIEWS)
    A = np.where(ok[..., None, None], A, np.eye(3))
    ok &= np.linalg.eigvalsh(A)[..., 0] >= _MIN_EIG
    points = np.linalg.solve(np.where(ok[..., None, None], A, np.eye(3)), np.where(ok[..., None], b, 0.0)[..., None])[..., 0]
    # In front of every other view that saw the joint (a point behind a camera is no meeting).
    depth = np.einsum("kjc,vjkc->vjk", dirs, points[:, :, None, :] - origins[None, None, :, :])  # (V, 17, K) along view k's ray
    other = seen.T[None, :, :] & ~np.eye(len(origins), dtype=bool)[:, None, :]  # (V, 17, K): k is another view that saw j
    ok &= ~(other & (depth < _MIN_DEPTH_M)).any(axis=2)
    points[~ok] = np.nan
    return points, ok


def residuals(instant: Instant, cameras: Mapping[str, Camera], points: NDArray, ok: NDArray,
              dirs: NDArray | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each view's residual against points triangulated for it (``leave_one_out``).

    Args:
        instant: the views.
        cameras: camera id -> camera (the calibration under test).
        points: (V, 17, 3) the point each view's joint is compared with, at the instant's time.
        ok: (V, 17) where ``points`` exist.
        dirs: (V, 17, 3) the views' rays (``rays``), to save computing them again.

    Returns:
        ``(degrees, pixels)``: (V, 17) each, NaN where not ok or the point is behind the view's camera.
    """
    if dirs is None:
        dirs = rays(instant, cameras)[1]
    deg = np.full(ok.shape, np.nan)
    px = np.full(ok.shape, np.nan)
    for i, cid in enumerate(instant.cameras):
        m = ok[i]
        if not m.any():
            continue
        cam = cameras[cid]
        # The joint where it was when this view was captured, in the camera's frame.
        pc = (points[i, m] + instant.offsets_m[i] - cam.t) @ cam.R  # (M, 3)
        front = pc[:, 2] > _MIN_DEPTH_M
        to_point = pc @ cam.R.T  # (M, 3) world direction, not normalised
        # The angle as atan2(|a x b|, a . b): exact for small angles, where arccos is not.
        sin = np.linalg.norm(np.cross(to_point, dirs[i, m]), axis=1)
        cos = np.einsum("mc,mc->m", to_point, dirs[i, m])
        xn = pc[:, :2] / np.where(front, pc[:, 2], 1.0)[:, None]
        if np.any(cam.D):
            xn = distort(xn, cam.D)
        uv = xn * [cam.fx, cam.fy] + [cam.cx, cam.cy]
        idx = np.flatnonzero(m)[front]
        deg[i, idx] = np.degrees(np.arctan2(sin[front], cos[front]))
        px[i, idx] = np.linalg.norm(uv[front] - instant.keypoints[i, idx, :2], axis=1)
    return deg, px


def instant_residuals(instant: Instant, cameras: Mapping[str, Camera]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Leave-one-out residuals of every view of an instant: ``(degrees, pixels)``, (V, 17) each, NaN where unmeasured."""
    if len(instant.cameras) <= MIN_OTHER_VIEWS:
        nan = np.full((len(instant.cameras), NUM_KEYPOINTS), np.nan)
        return nan, nan.copy()
    origins, dirs, seen = rays(instant, cameras)
    points, ok = leave_one_out(origins, dirs, seen)
    return residuals(instant, cameras, points, ok, dirs)
