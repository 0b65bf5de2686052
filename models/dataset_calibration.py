"""Camera calibration from 2D-3D pairs, and the WheresTheFellow site built from the dataset.

Each dataset joint has a world position (back-projected from depth) and its pixel, so each
camera's projection matrix follows from the pairs alone (Hartley & Zisserman, "Multiple View
Geometry", 2nd ed., sec. 7.1 and 6.2.4):

1. normalised DLT: ``u ~ P X`` solved for the 3x4 ``P`` by SVD, after translating and scaling
   points and pixels to unit spread (Hartley normalisation) so the system is well conditioned;
2. decomposition ``P = K [R | -R C]`` by RQ, with a positive diagonal in ``K``;
3. skew set to zero (the site file has none) and ``fx, fy, cx, cy, R, C`` refined by nonlinear
   least squares on the reprojection error;
4. the result as an ``edge.camera.Camera`` (world-from-camera rotation, optical centre), whose
   ``edge.camera.project`` gives the reported errors.

The maths is pure functions on arrays; ``calibrate_dataset`` puts them together for the site.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, cast

import cv2
import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import NDArray

from superbody.edge.body import INDEX
from superbody.edge.camera import Camera, project
from superbody.edge.floor import visible_floor
from superbody.edge.site import Site
from superbody.models.data.wtf import CAMERA_IDS, IMAGE_HEIGHT, IMAGE_WIDTH, RawSample

__all__ = [
    "MIN_POINTS",
    "CameraFit",
    "normalised_dlt",
    "decompose_projection",
    "refine_camera",
    "fit_camera",
    "reprojection_errors",
    "dataset_pairs",
    "floor_rectangle",
    "calibrate_dataset",
]

# A projection matrix has 11 degrees of freedom and each pair gives 2 equations.
MIN_POINTS: Final[int] = 6
_ANKLES: Final[tuple[int, int]] = (INDEX["left_ankle"], INDEX["right_ankle"])


@dataclass(frozen=True)
class CameraFit:
    """A calibrated camera and how well it fits its pairs.

    Attributes:
        camera: the camera (zero skew, no distortion).
        skew_px: the skew ``K[0, 1]`` of the DLT decomposition before it was set to zero.
        median_px: median reprojection error of the pairs through ``edge.camera.project``.
        max_px: largest reprojection error, pixels.
        n_points: number of 2D-3D pairs.
    """

    camera: Camera
    skew_px: float
    median_px: float
    max_px: float
    n_points: int


def _normaliser(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Similarity moving points (N, d) to zero mean and mean distance sqrt(d); shape (d+1, d+1)."""
    d = x.shape[1]
    mean = x.mean(axis=0)
    spread = np.linalg.norm(x - mean, axis=1).mean()
    s = math.sqrt(d) / spread
    T = np.eye(d + 1)
    T[:d, :d] *= s
    T[:d, d] = -s * mean
    return T


def normalised_dlt(points: NDArray, pixels: NDArray) -> NDArray[np.float64]:
    """The 3x4 projection matrix mapping world points to pixels, by the normalised DLT.

    Args:
        points: world points, shape (N, 3), N >= 6, not all in one plane.
        pixels: their pixels, shape (N, 2).

    Returns:
        ``P``, shape (3, 4), scaled so that ``P[2, :3]`` is a unit vector and the points lie in
        front of the camera (positive third coordinate).

    Raises:
        ValueError: too few points, or points (nearly) coplanar or collinear.
    """
    X = np.asarray(points, dtype=np.float64)
    uv = np.asarray(pixels, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or uv.shape != (len(X), 2):
        raise ValueError(f"normalised_dlt: need points (N, 3) and pixels (N, 2), got {X.shape} and {uv.shape}")
    if len(X) < MIN_POINTS:
        raise ValueError(f"normalised_dlt: need at least {MIN_POINTS} 2D-3D pairs, got {len(X)}")
    sv = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    if sv[2] < 1e-6 * sv[0]:
        raise ValueError("normalised_dlt: the 3D points are (nearly) coplanar; the DLT needs points spread in 3D")
    T = _normaliser(uv)  # (3, 3)
    U = _normaliser(X)  # (4, 4)
    Xn = np.hstack([X, np.ones((len(X), 1))]) @ U.T  # (N, 4)
    un = np.hstack([uv, np.ones((len(uv), 1))]) @ T.T  # (N, 3)
    # Each pair gives two rows of A p = 0 (from u ~ P X):  X^T p1 - u X^T p3 = 0,  X^T p2 - v X^T p3 = 0.
    zeros = np.zeros_like(Xn)
    A = np.empty((2 * len(X), 12))
    A[0::2] = np.hstack([Xn, zeros, -un[:, :1] * Xn])
    A[1::2] = np.hstack([zeros, Xn, -un[:, 1:2] * Xn])
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    Pn = vt[-1].reshape(3, 4)
    P = np.linalg.solve(T, Pn) @ U  # undo the normalisation: P = T^-1 Pn U
    P /= np.linalg.norm(P[2, :3])
    if np.median(np.hstack([X, np.ones((len(X), 1))]) @ P[2]) < 0:
        P = -P
    return P


def decompose_projection(P: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Split ``P = K [R | -R C]``.

    Args:
        P: projection matrix, shape (3, 4), any positive scale, signed so that points in front
            of the camera have a positive third coordinate (as ``normalised_dlt`` returns it);
            ``-P`` would give the mirrored camera.

    Returns:
        ``(K, R, C)``: intrinsics (3, 3) upper triangular with positive diagonal and
        ``K[2, 2] = 1``; camera-from-world rotation (3, 3), whose determinant is -1 when the
        world frame is mirrored relative to the image (left-handed); optical centre (3,).
    """
    P = np.asarray(P, dtype=np.float64)
    M = P[:, :3]
    K, R = scipy.linalg.rq(M)
    D = np.diag(np.sign(np.diag(K)))  # D D = I: move the signs from K into R
    K, R = K @ D, D @ R
    C = -np.linalg.solve(M, P[:, 3])  # P [C; 1] = 0
    return K / K[2, 2], R, C


def _residuals(params: NDArray, R0: NDArray, X: NDArray, uv: NDArray) -> NDArray:
    """Reprojection residuals (2N,) for params (fx, fy, cx, cy, w(3), C(3)), zero skew.

    The rotation is ``Rodrigues(w) @ R0``: a small correction to the start, far from the
    parametrisation's singularity at 180 degrees whatever the camera's orientation.
    """
    fx, fy, cx, cy = params[:4]
    dR, _ = cv2.Rodrigues(params[4:7])
    R = dR @ R0  # camera-from-world
    pc = (X - params[7:10]) @ R.T  # (N, 3)
    proj = pc[:, :2] / pc[:, 2:3] * [fx, fy] + [cx, cy]
    return (proj - uv).ravel()


def refine_camera(
    K: NDArray, R: NDArray, C: NDArray, points: NDArray, pixels: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Minimise the reprojection error over fx, fy, cx, cy, R, C with zero skew (Levenberg-Marquardt).

    Args:
        K: starting intrinsics (3, 3); its skew is ignored.
        R: starting camera-from-world rotation (3, 3), proper.
        C: starting optical centre (3,).
        points: world points (N, 3).
        pixels: pixels (N, 2).

    Returns:
        ``(K, R, C)`` refined, ``K`` with zero skew.
    """
    R0 = np.asarray(R, dtype=np.float64)
    x0 = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], np.zeros(3), np.asarray(C, dtype=np.float64)])
    args = (R0, np.asarray(points, dtype=np.float64), np.asarray(pixels, dtype=np.float64))
    sol = scipy.optimize.least_squares(_residuals, x0, args=args, method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15)
    # Keep the start if the solver made things worse (it can, by rounding, on an exact fit).
    p = sol.x if sol.cost <= 0.5 * float(np.sum(_residuals(x0, *args) ** 2)) else x0
    K_out = np.array([[p[0], 0.0, p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]])
    dR, _ = cv2.Rodrigues(p[4:7])
    return K_out, dR @ R0, p[7:10].copy()


def reprojection_errors(camera: Camera, points: NDArray, pixels: NDArray) -> NDArray[np.float64]:
    """Pixel distance between ``edge.camera.project`` of ``points`` (N, 3) and ``pixels`` (N, 2); shape (N,)."""
    uv, _ = project(np.asarray(points, dtype=np.float64), camera)
    return np.linalg.norm(uv - np.asarray(pixels, dtype=np.float64), axis=1)


def fit_camera(
    camera_id: str,
    points: NDArray,
    pixels: NDArray,
    *,
    width: int = IMAGE_WIDTH,
    height: int = IMAGE_HEIGHT,
    fps: float = 15.0,
    refine: bool = True,
) -> CameraFit:
    """Calibrate one camera from its 2D-3D pairs.

    Args:
        camera_id: id of the camera in the site.
        points: world points in REP-103 metres, shape (N, 3).
        pixels: their pixels, shape (N, 2).
        width, height: image size in pixels.
        fps: the rate the camera node publishes at.
        refine: refine the zero-skew camera by nonlinear least squares after the DLT.

    Raises:
        ValueError: too few or degenerate pairs, or the world frame is left-handed (the pairs
            fit only a mirrored camera).
    """
    try:
        P = normalised_dlt(points, pixels)
    except ValueError as e:
        raise ValueError(f"camera {camera_id}: {e}") from None
    K, R, C = decompose_projection(P)
    if np.linalg.det(R) < 0:
        raise ValueError(
            f"camera {camera_id}: the pairs fit only a mirrored camera (det R = -1): the world frame "
            "is left-handed; convert it to a right-handed frame first"
        )
    skew = float(K[0, 1])
    if refine:
        K, R, C = refine_camera(K, R, C, points, pixels)
    camera = Camera(
        id=camera_id, width=width, height=height, fps=float(fps),
        fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]), dist=(),
        position=cast("tuple[float, float, float]", tuple(float(v) for v in C)),
        rotation=cast("tuple[tuple[float, float, float], ...]", tuple(tuple(float(v) for v in row) for row in R.T)),  # world-from-camera
    )
    err = reprojection_errors(camera, points, pixels)
    return CameraFit(camera, skew, float(np.median(err)), float(err.max()), len(err))


def dataset_pairs(raw: Sequence[RawSample]) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Every detected joint's world position and pixel, per camera.

    Returns:
        camera id -> ``(points (N, 3) metres REP-103, pixels (N, 2))``, in ``CAMERA_IDS`` order.
    """
    acc: dict[str, tuple[list, list]] = {}
    for s in raw:
        for v in s.views:
            m = v.visible
            pts, pix = acc.setdefault(v.camera, ([], []))
            pts.append(v.joints[m])
            pix.append(v.keypoints[m, :2])
    return {c: (np.concatenate(acc[c][0]), np.concatenate(acc[c][1])) for c in CAMERA_IDS if c in acc}


def floor_rectangle(xy: NDArray, margin: float = 0.5, step: float = 0.1) -> tuple[tuple[float, float], ...]:
    """Bounding rectangle of floor points (N, 2), grown by ``margin`` and rounded outward to ``step``.

    Returns:
        The four corners, counter-clockwise from (x_min, y_min).
    """
    xy = np.asarray(xy, dtype=np.float64)
    # The small epsilon keeps values already on the grid (after float noise) from moving a step.
    lo = np.floor((xy.min(axis=0) - margin) / step + 1e-9) * step
    hi = np.ceil((xy.max(axis=0) + margin) / step - 1e-9) * step
    (x0, y0), (x1, y1) = np.round(lo, 6), np.round(hi, 6)
    return ((float(x0), float(y0)), (float(x1), float(y0)), (float(x1), float(y1)), (float(x0), float(y1)))


def calibrate_dataset(
    raw: Sequence[RawSample], *, name: str = "wtf-apartment", fps: float = 15.0, refine: bool = True,
    floor_range_m: float | None = None,
) -> tuple[Site, dict[str, CameraFit]]:
    """The site of a WheresTheFellow recording: one camera per dataset camera, and the floor.

    The floor is the part of the room the recovered cameras see (``edge.floor.visible_floor``:
    a standing person's hips or shoulders in some camera's image, in front of every camera's
    wall; no range cut-off unless ``floor_range_m`` is given), not where this recording walked; there are no obstacles
    (the data does not show them).

    Args:
        raw: the samples from ``models.data.wtf.load_wtf_raw``.
        name: site name.
        fps: publishing rate written for every camera.
        refine: refine each camera after the DLT.
        floor_range_m: a camera's useful floor range for the floor polygon (None: no cut-off, the
            detector's limit ``edge.floor.detectable_range_m``).

    Returns:
        ``(site, fits)``: the site and each camera's fit, by camera id.

    Raises:
        ValueError: a camera has too few or degenerate pairs.
    """
    fits = {}
    for cid, (points, pixels) in dataset_pairs(raw).items():
        fits[cid] = fit_camera(cid, points, pixels, fps=fps, refine=refine)
    cameras = tuple(f.camera for f in fits.values())
    # The room the cameras see, never the path this recording happened to walk.
    site = Site(name=name, cameras=cameras, floor=visible_floor(cameras, max_range_m=floor_range_m))
    return site, fits
