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
    if not instant.cameras:
        return np.zeros((0, 3)), np.zeros((0, NUM_KEYPOINTS, 3)), seen
    cams = [cameras[c] for c in instant.cameras]
    f = np.array([[c.fx, c.fy] for c in cams])  # (V, 2)
    cxy = np.array([[c.cx, c.cy] for c in cams])  # (V, 2)
    xn = (np.where(seen[..., None], kp[..., :2], 0.0) - cxy[:, None, :]) / f[:, None, :]  # (V, 17, 2) pinhole
    for i, cam in enumerate(cams):
        if np.any(cam.D) and seen[i].any():
            xn[i, seen[i]] = undistort(kp[i, seen[i], :2], cam)
    dirs = normalised_to_rays(xn, np.stack([c.R for c in cams])) * seen[..., None]  # (V, 17, 3)
    origins = np.stack([c.t for c in cams]) - instant.offsets_m
    return origins, dirs, seen


def leave_one_out(origins: NDArray, dirs: NDArray, seen: NDArray, rows: NDArray | None = None) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Each view's joints triangulated from the other views alone.

    Args:
        origins: (V, 3) ray origins.
        dirs: (V, 17, 3) unit ray directions.
        seen: (V, 17) which rays exist.
        rows: (V,) bool, the views to triangulate for (default all; the others get none).

    Returns:
        ``(points, ok)``: (V, 17, 3) the point of joint j from every view but v, and (V, 17)
        where it exists (v saw j; at least ``MIN_OTHER_VIEWS`` others did, their rays meet at
        ``MIN_RAY_ANGLE_DEG`` or more, and the point is in front of them). NaN where not ok.
    """
    V = len(origins)
    sel = np.arange(V) if rows is None else np.flatnonzero(rows)  # (S,)
    # sum_k (I - d_k d_k^T) p = sum_k (I - d_k d_k^T) o_k over the other views k
    proj = (np.eye(3) - dirs[..., :, None] * dirs[..., None, :]) * seen[..., None, None]  # (V, 17, 3, 3)
    rhs = (proj @ origins[:, None, :, None])[..., 0]  # (V, 17, 3)
    A = proj.sum(0)[None] - proj[sel]  # (S, 17, 3, 3) all views but v
    b = rhs.sum(0)[None] - rhs[sel]  # (S, 17, 3)
    others = seen.sum(0)[None] - seen[sel]  # (S, 17)
    ok = seen[sel] & (others >= MIN_OTHER_VIEWS)
    A = np.where(ok[..., None, None], A, np.eye(3))
    ok &= np.linalg.eigvalsh(A)[..., 0] >= _MIN_EIG
    pts = np.linalg.solve(np.where(ok[..., None, None], A, np.eye(3)), np.where(ok[..., None], b, 0.0)[..., None])[..., 0]
    # In front of every other view that saw the joint (a point behind a camera is no meeting).
    depth = np.einsum("kjc,sjkc->sjk", dirs, pts[:, :, None, :] - origins[None, None, :, :])  # (S, 17, K) along view k's ray
    other = seen.T[None, :, :] & (sel[:, None] != np.arange(V)[None, :])[:, None, :]  # (S, 17, K): k is another view that saw j
    ok &= ~(other & (depth < _MIN_DEPTH_M)).any(axis=2)
    points = np.full((V, NUM_KEYPOINTS, 3), np.nan)
    ok_all = np.zeros((V, NUM_KEYPOINTS), dtype=bool)
    points[sel] = np.where(ok[..., None], pts, np.nan)
    ok_all[sel] = ok
    return points, ok_all


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
    if not ok.any():
        return deg, px
    cams = [cameras[c] for c in instant.cameras]
    R = np.stack([c.R for c in cams])  # (V, 3, 3)
    t = np.stack([c.t for c in cams])  # (V, 3)
    # The joint where it was when each view was captured, in that camera's frame: R^T (X + offset - t).
    rel = np.where(ok[..., None], points, 0.0) + (instant.offsets_m - t)[:, None, :]  # (V, 17, 3) world
    pc = np.einsum("vji,vkj->vki", R, rel)  # (V, 17, 3)
    ok = ok & (pc[..., 2] > _MIN_DEPTH_M)
    # The angle between the rays as atan2(|a x b|, a . b): exact for small angles, where arccos is not.
    a, b = rel, dirs
    cross = np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)  # (V, 17, 3)
    angle = np.degrees(np.arctan2(np.sqrt((cross**2).sum(-1)), (a * b).sum(-1)))  # (V, 17)
    xn = pc[..., :2] / np.where(ok, pc[..., 2], 1.0)[..., None]  # (V, 17, 2)
    for i, cam in enumerate(cams):
        if np.any(cam.D) and ok[i].any():
            xn[i, ok[i]] = distort(xn[i, ok[i]], cam.D)
    uv = xn * np.array([[c.fx, c.fy] for c in cams])[:, None, :] + np.array([[c.cx, c.cy] for c in cams])[:, None, :]
    err = np.sqrt(((uv - instant.keypoints[..., :2]) ** 2).sum(-1))  # (V, 17)
    deg[ok], px[ok] = angle[ok], err[ok]
    return deg, px


def instant_residuals(instant: Instant, cameras: Mapping[str, Camera], rows: NDArray | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Leave-one-out residuals of the views of an instant (``rows``, (V,) bool: only those; default
    all): ``(degrees, pixels)``, (V, 17) each, NaN where unmeasured."""
    if len(instant.cameras) <= MIN_OTHER_VIEWS or (rows is not None and not np.any(rows)):
        nan = np.full((len(instant.cameras), NUM_KEYPOINTS), np.nan)
        return nan, nan.copy()
    origins, dirs, seen = rays(instant, cameras)
    points, ok = leave_one_out(origins, dirs, seen, rows)
    return residuals(instant, cameras, points, ok, dirs)
