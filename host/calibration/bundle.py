"""Bundle adjustment over people's joints: the poses (and optionally focal lengths) of some
cameras refined so that every camera's joints meet.

The unknowns are each free camera's pose change (a rotation vector in its own frame and a shift
of its optical centre, ``R = R0 Exp(w)``, ``t = t0 + dt``), optionally its focal length (one
scale on fx and fy), and one 3D point per joint of each ``Instant`` that two or more cameras saw.
Each detected joint gives two residuals: the reprojection error over the focal length (an
angle, radians: cameras of any resolution weigh alike) times the square root of its detection
score. ``scipy.optimize.least_squares`` (trust region, LSMR steps) minimises them under a
robust loss (soft L1, ``F_SCALE_DEG``: left/right swaps and a wrong person's view cost linearly,
not quadratically). The Jacobian is sparse and built here: each detection's two rows hold its
point's three columns, exact, and its camera's, by forward differences over that camera's own
detections when it is free.

Gauge: the world frame, its scale and the floor come from the cameras that are held fixed. One
fixed camera pins the rotation and translation but not the scale (every point and free camera
scaled about it reprojects the same), so at least two are needed (``MIN_FIXED``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Final, cast

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from superbody.edge.camera import Camera, distort
from superbody.host.calibration.blas import single_threaded_blas
from superbody.host.calibration.residuals import _MIN_DEPTH_M, _MIN_EIG, Instant, rays

__all__ = ["Refinement", "CameraChange", "refine_cameras", "pose_change", "Problem", "build_problem", "F_SCALE_DEG", "MIN_FIXED"]

MIN_FIXED: Final[int] = 2
# The robust loss turns linear beyond this residual: above a real detector's inlier spread
# (0.5-1 deg per axis across views on WheresTheFellow), well below a left/right swap (10+ deg).
F_SCALE_DEG: Final[float] = 1.0
# Joints whose first triangulation misses a view by more than this are left out: a swapped or
# wrongly associated view, which only slows the solver down.
_MAX_START_DEG: Final[float] = 15.0


@dataclass(frozen=True)
class Problem:
    """The observations of a bundle adjustment.

    Attributes:
        camera: (N,) index of each observation's camera in ``cameras``.
        point: (N,) index of its point.
        uv: (N, 2) the detected joint, pixels.
        weight: (N,) its detection score.
        offset: (N, 3) the person's motion from the instant's time to the view's capture.
        points: (P, 3) the points' starting positions (triangulated from every view).
        joint: (P,) each point's COCO-17 joint.
        instant: (P,) each point's instant (index into the instants given).
    """

    camera: NDArray[np.intp]
    point: NDArray[np.intp]
    uv: NDArray[np.float64]
    weight: NDArray[np.float64]
    offset: NDArray[np.float64]
    points: NDArray[np.float64]
    joint: NDArray[np.intp]
    instant: NDArray[np.intp]


def build_problem(instants: Sequence[Instant], cameras: Sequence[Camera]) -> Problem:
    """Every joint seen by two or more cameras of an instant becomes a point, started where the
    rays meet (least squares) and kept if it lies in front of them and within ``_MAX_START_DEG``
    of each; every view of it an observation."""
    index = {c.id: i for i, c in enumerate(cameras)}
    by_id = {c.id: c for c in cameras}
    cam_i: list[int] = []
    pt_i: list[int] = []
    joint: list[int] = []
    inst: list[int] = []
    uv: list[NDArray] = []
    w: list[NDArray] = []
    off: list[NDArray] = []
    pts: list[NDArray] = []
    n_points = 0
    for k, ins in enumerate(instants):
        if len(ins.cameras) < 2:
            continue
        origins, dirs, seen = rays(ins, by_id)
        proj = (np.eye(3) - dirs[..., :, None] * dirs[..., None, :]) * seen[..., None, None]  # (V, 17, 3, 3)
        A = proj.sum(0)  # (17, 3, 3)
        b = (proj @ origins[:, None, :, None]).sum(0)[..., 0]  # (17, 3)
        ok = seen.sum(0) >= 2
        A = np.where(ok[:, None, None], A, np.eye(3))
        ok &= np.linalg.eigvalsh(A)[:, 0] >= _MIN_EIG
        X = np.linalg.solve(A, np.where(ok[:, None], b, 0.0)[..., None])[..., 0]  # (17, 3)
        to = X[None] - origins[:, None, :]  # (V, 17, 3)
        dist = np.linalg.norm(to, axis=2)
        cos = np.einsum("vjc,vjc->vj", to, dirs) / np.maximum(dist, 1e-12)
        good = ~seen | ((cos > math.cos(math.radians(_MAX_START_DEG))) & (dist * cos > _MIN_DEPTH_M))
        ok &= good.all(axis=0)
        for j in np.flatnonzero(ok):
            views = np.flatnonzero(seen[:, j])
            cam_i.extend(index[ins.cameras[v]] for v in views)
            pt_i.extend([n_points] * len(views))
            uv.append(ins.keypoints[views, j, :2])
            w.append(ins.keypoints[views, j, 2])
            off.append(ins.offsets_m[views])
            pts.append(X[j])
            joint.append(int(j))
            inst.append(k)
            n_points += 1
    if not n_points:
        z = np.zeros(0, np.intp)
        return Problem(z, z, np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), z, z)
    return Problem(np.array(cam_i, np.intp), np.array(pt_i, np.intp), np.concatenate(uv), np.concatenate(w), np.concatenate(off),
                   np.array(pts), np.array(joint, np.intp), np.array(inst, np.intp))


@dataclass(frozen=True)
class CameraChange:
    """How far the refinement moved one camera: rotation (deg), optical centre (m), focal length (relative)."""

    rotation_deg: float
    position_m: float
    focal_scale: float = 1.0


def pose_change(before: Camera, after: Camera) -> CameraChange:
    """The rotation angle and the optical centre's shift between two poses of a camera."""
    c = (np.trace(after.R @ before.R.T) - 1.0) / 2.0
    return CameraChange(math.degrees(math.acos(min(1.0, max(-1.0, float(c))))), float(np.linalg.norm(after.t - before.t)),
                        after.fx / before.fx)


@dataclass(frozen=True)
class Refinement:
    """A bundle adjustment's result.

    Attributes:
        cameras: every camera, the free ones refined (same order as given).
        free: the ids of the refined cameras.
        changes: camera id -> its ``CameraChange`` (the fixed ones' are zero).
        points: observed joints' 3D points solved for.
        observations: detected joints used.
        cost_before, cost_after: the robust cost (``least_squares``' ``cost``) at the start and end.
        nfev: residual evaluations.
        seconds: time taken.
        status: ``least_squares``' message.
        cost_by_camera_before, cost_by_camera_after: each camera's share of the two costs.
    """

    cameras: tuple[Camera, ...]
    free: tuple[str, ...]
    changes: dict[str, CameraChange] = field(default_factory=dict)
    points: int = 0
    observations: int = 0
    cost_before: float = math.nan
    cost_after: float = math.nan
    nfev: int = 0
    seconds: float = 0.0
    status: str = ""
    cost_by_camera_before: dict[str, float] = field(default_factory=dict)
    cost_by_camera_after: dict[str, float] = field(default_factory=dict)


def _rotations(rotvecs: NDArray) -> NDArray[np.float64]:
    """(K, 3) rotation vectors to (K, 3, 3) matrices."""
    return Rotation.from_rotvec(rotvecs.reshape(-1, 3)).as_matrix().reshape(-1, 3, 3)


def refine_cameras(cameras: Sequence[Camera], instants: Sequence[Instant] | Problem, free: Sequence[str], *, focal: bool = False,
                   f_scale_deg: float = F_SCALE_DEG, max_nfev: int = 200, progress: Callable[[int], None] | None = None) -> Refinement:
    """Refine the ``free`` cameras' poses (and focal lengths with ``focal``) holding the others.

    Args:
        cameras: every camera of the site, as the site file has them.
        instants: people's views (``Instant``) or a ``Problem`` already built from them.
        free: ids of the cameras to refine; all others are held fixed.
        focal: also refine each free camera's focal length (fx and fy by one scale).
        f_scale_deg: the robust loss's scale (``F_SCALE_DEG``).
        max_nfev: at most this many residual evaluations (each Jacobian counts as one).
        progress: called with each new evaluation count (a progress bar).

    Raises:
        ValueError: an unknown camera id, fewer than ``MIN_FIXED`` fixed cameras, or no joint
            that two cameras saw.
    """
    t_start = time.monotonic()
    ids = [c.id for c in cameras]
    unknown = [c for c in free if c not in ids]
    if unknown:
        raise ValueError(f"refine_cameras: camera(s) {', '.join(unknown)} not in the site; cameras: {', '.join(ids)}")
    if len(ids) - len(set(free)) < MIN_FIXED:
        raise ValueError(f"refine_cameras: at least {MIN_FIXED} cameras must be held fixed (they carry the world frame and its scale); "
                         f"{len(ids) - len(set(free))} of {len(ids)} are")
    prob = instants if isinstance(instants, Problem) else build_problem(instants, cameras)
    if not len(prob.points):
        raise ValueError("refine_cameras: no joint was seen by two cameras at once")
    free_idx = np.array([ids.index(c) for c in dict.fromkeys(free)], np.intp)
    k, n_par = len(free_idx), 7 if focal else 6
    P, N = len(prob.points), len(prob.camera)
    R0 = np.stack([c.R for c in cameras])  # (C, 3, 3)
    t0 = np.stack([c.t for c in cameras])  # (C, 3)
    f0 = np.array([[c.fx, c.fy] for c in cameras])  # (C, 2)
    cxy = np.array([[c.cx, c.cy] for c in cameras])  # (C, 2)
    distorted = [i for i, c in enumerate(cameras) if np.any(c.D)]
    slot = np.full(len(cameras), -1)
    slot[free_idx] = np.arange(k)
    sw = np.sqrt(prob.weight)[:, None]  # (N, 1)

    def unpack(x: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        cp = x[: n_par * k].reshape(k, n_par)
        R, t, f = R0.copy(), t0.copy(), f0.copy()
        if k:
            R[free_idx] = R0[free_idx] @ _rotations(cp[:, :3])
            t[free_idx] = t0[free_idx] + cp[:, 3:6]
            if focal:
                f[free_idx] = f0[free_idx] * np.exp(cp[:, 6:7])
        return R, t, f, x[n_par * k:].reshape(P, 3)

    calls = [0]

    def project(x: NDArray, rows: NDArray | slice) -> tuple[NDArray, NDArray, NDArray]:
        """Residuals (M, 2) of the observations ``rows``, their camera-frame points (M, 3) and normalised coordinates (M, 2)."""
        R, t, f, X = unpack(x)
        ci = prob.camera[rows]
        pc = np.einsum("nji,nj->ni", R[ci], X[prob.point[rows]] + prob.offset[rows] - t[ci])  # (M, 3) R^T (X - t)
        xn = pc[:, :2] / np.where(pc[:, 2:] > 1e-6, pc[:, 2:], 1e-6)  # (M, 2)
        xd = xn.copy()
        for i in distorted:
            m = ci == i
            xd[m] = distort(xn[m], cameras[i].D)
        r = (xd * f[ci] + cxy[ci] - prob.uv[rows]) / f0[ci] * sw[rows]  # (M, 2) radians, score-weighted
        return r, pc, xn

    def fun(x: NDArray) -> NDArray:
        calls[0] += 1
        if progress is not None:
            progress(calls[0])
        return project(x, slice(None))[0].ravel()

    every = np.arange(N)
    own = [np.flatnonzero(prob.camera == i) for i in free_idx]  # each free camera's observations
    # The Jacobian's pattern: each observation's two rows, its point's 3 columns, then its camera's if free.
    pt_rows = np.repeat(np.arange(2 * N), 3)
    pt_cols = (n_par * k + 3 * np.repeat(prob.point, 2))[:, None] + np.arange(3)  # (2N, 3)
    cam_rows = [np.repeat(np.stack([2 * o, 2 * o + 1], 1).ravel(), n_par) for o in own]
    cam_cols = [np.tile(n_par * s + np.arange(n_par), 2 * len(o)) for s, o in enumerate(own)]
    rows_all = np.concatenate([pt_rows, *cam_rows])
    cols_all = np.concatenate([pt_cols.ravel(), *cam_cols])

    def jac(x: NDArray) -> csr_matrix:
        R, t, f, X = unpack(x)
        r, pc, xn = project(x, every)
        ci = prob.camera
        z = np.where(pc[:, 2] > 1e-6, pc[:, 2], 1e-6)
        # d xn / d pc = [[1/z, 0, -x/z], [0, 1/z, -y/z]]
        J = np.zeros((N, 2, 3))
        J[:, 0, 0] = J[:, 1, 1] = 1.0 / z
        J[:, :, 2] = -xn / z[:, None]
        for i in distorted:  # the distortion's own 2x2 Jacobian, by central differences
            m = np.flatnonzero(ci == i)
            D, h = cameras[i].D, 1e-7
            dx = (distort(xn[m] + [h, 0.0], D) - distort(xn[m] - [h, 0.0], D)) / (2 * h)
            dy = (distort(xn[m] + [0.0, h], D) - distort(xn[m] - [0.0, h], D)) / (2 * h)
            J[m] = np.stack([dx, dy], axis=2) @ J[m]
        # d r / d X = diag(f / f0 * sqrt(w)) (d xd / d pc) R^T
        dX = (f[ci] / f0[ci] * sw)[:, :, None] * np.einsum("nak,njk->naj", J, R[ci])  # (N, 2, 3)
        blocks = [dX.ravel()]
        for s, o in enumerate(own):  # a free camera's columns: forward differences over its own observations
            cols = np.empty((len(o), 2, n_par))
            for q in range(n_par):
                xq = x.copy()
                xq[n_par * s + q] += 1e-6
                cols[:, :, q] = (project(xq, o)[0] - r[o]) / 1e-6
            blocks.append(cols.ravel())
        return csr_matrix((np.concatenate(blocks), (rows_all, cols_all)), shape=(2 * N, n_par * k + 3 * P))

    x0 = np.concatenate([np.zeros(n_par * k), prob.points.ravel()])
    fs = math.radians(f_scale_deg)
    with single_threaded_blas():
        # ftol 1e-6: on noisy joints the default 1e-8 takes 4 times the evaluations for the
        # same cameras (to 0.001 deg, 0.01 cm on a simulated 5-camera room).
        sol = least_squares(fun, x0, jac=jac, loss="soft_l1", f_scale=fs, x_scale="jac", method="trf", tr_solver="lsmr",
                            ftol=1e-6, max_nfev=max_nfev)
    R, t, f, _ = unpack(sol.x)
    out = []
    for i, c in enumerate(cameras):
        if slot[i] < 0:
            out.append(c)
            continue
        rot = _orthonormal(R[i])
        out.append(replace(c, rotation=cast("tuple[tuple[float, float, float], ...]", tuple(tuple(float(v) for v in row) for row in rot)),
                           position=cast("tuple[float, float, float]", tuple(float(v) for v in t[i])),
                           fx=float(f[i, 0]), fy=float(f[i, 1])))
    def by_camera(r: NDArray) -> dict[str, float]:
        rho = fs**2 * (np.sqrt(1.0 + (r.reshape(-1, 2) / fs) ** 2) - 1.0).sum(1)  # (N,) soft_l1, as least_squares counts it
        return {c: float(rho[prob.camera == i].sum()) for i, c in enumerate(ids)}

    before, after = by_camera(fun(x0)), by_camera(sol.fun)
    changes = {c.id: pose_change(c, o) for c, o in zip(cameras, out)}
    return Refinement(tuple(out), tuple(ids[i] for i in free_idx), changes, P, N, sum(before.values()), float(sol.cost), int(sol.nfev),
                      time.monotonic() - t_start, str(sol.message), before, after)


def _orthonormal(R: NDArray) -> NDArray[np.float64]:
    """The rotation nearest ``R`` (SVD), so the site file's check of it passes after rounding."""
    u, _, vt = np.linalg.svd(R)
    return u @ vt
