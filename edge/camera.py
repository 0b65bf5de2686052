"""The camera model: OpenCV intrinsics and distortion, and the camera's pose in the world.

Frames: the world is REP-103 (metres, z up, floor at z = 0); the camera frame is OpenCV's
(x right, y down, z forward). ``rotation`` maps camera-frame vectors into the world frame and
``position`` is the optical centre in the world, so ``p_world = R @ p_cam + t``.

The geometry is pure functions on arrays; ``Camera`` only holds the parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Camera",
    "look_at_rotation",
    "world_to_camera",
    "normalised_to_rays",
    "project",
    "distort",
    "undistort",
    "pixel_to_ray",
    "intersect_plane",
]


@dataclass(frozen=True)
class Camera:
    """One camera of a site.

    Attributes:
        id: camera id, unique in its site (letters, digits, ``_`` and ``-``).
        width: image width in pixels.
        height: image height in pixels.
        fps: frames per second the camera node publishes.
        fx, fy, cx, cy: pinhole intrinsics in pixels.
        dist: OpenCV distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), or empty.
        position: optical centre in the world frame, metres, shape (3,).
        rotation: world-from-camera rotation, row-major 3x3.
    """

    id: str
    width: int
    height: int
    fps: float
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = ()
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    @cached_property
    def K(self) -> NDArray[np.float64]:
        """Intrinsic matrix, shape (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @cached_property
    def R(self) -> NDArray[np.float64]:
        """World-from-camera rotation, shape (3, 3)."""
        return np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)

    @cached_property
    def t(self) -> NDArray[np.float64]:
        """Optical centre in the world, shape (3,)."""
        return np.asarray(self.position, dtype=np.float64).reshape(3)

    @cached_property
    def D(self) -> NDArray[np.float64]:
        """Distortion coefficients padded to 8 (k1, k2, p1, p2, k3, k4, k5, k6)."""
        d = np.zeros(8)
        d[: len(self.dist)] = self.dist
        return d

    @cached_property
    def projection_matrix(self) -> NDArray[np.float64]:
        """3x4 matrix P = K [R^T | -R^T t] mapping homogeneous world points to pixels (no distortion)."""
        Rcw = self.R.T
        return self.K @ np.hstack([Rcw, (-Rcw @ self.t)[:, None]])


def look_at_rotation(position: NDArray, target: NDArray, up: NDArray | None = None) -> NDArray[np.float64]:
    """World-from-camera rotation for a camera at ``position`` looking at ``target``.

    The image's "up" (-y in the camera frame) points as close to ``up`` (default world +z) as
    the viewing direction allows.

    Returns:
        Rotation matrix, shape (3, 3), columns the camera's x, y, z axes in the world.
    """
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - np.asarray(position, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at_rotation: viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def world_to_camera(points: NDArray, cam: Camera) -> NDArray[np.float64]:
    """World points (N, 3) to the camera frame (N, 3)."""
    # p_cam = R^T (p_world - t), written row-wise.
    return (np.asarray(points, dtype=np.float64) - cam.t) @ cam.R


def distort(xn: NDArray, dist: NDArray) -> NDArray[np.float64]:
    """Apply OpenCV's distortion to normalised image coordinates.

    Args:
        xn: normalised coordinates (x/z, y/z), shape (N, 2).
        dist: 8 coefficients (k1, k2, p1, p2, k3, k4, k5, k6).

    Returns:
        Distorted normalised coordinates, shape (N, 2).
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = dist
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    # radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=1)


def project(points: NDArray, cam: Camera) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project world points to pixels, with the camera's distortion.

    Args:
        points: world points, shape (N, 3).
        cam: the camera.

    Returns:
        ``(uv, depth)``: pixels, shape (N, 2), and depth along the optical axis, shape (N,).
        Points with depth <= 0 are behind the camera and their pixels are meaningless.
    """
    pc = world_to_camera(np.atleast_2d(points), cam)  # (N, 3)
    z = pc[:, 2]
    safe = np.where(np.abs(z) < 1e-12, 1e-12, z)
    xn = pc[:, :2] / safe[:, None]  # (N, 2)
    if np.any(cam.D):
        xn = distort(xn, cam.D)
    uv = xn * [cam.fx, cam.fy] + [cam.cx, cam.cy]
    return uv, z


def undistort(uv: NDArray, cam: Camera) -> NDArray[np.float64]:
    """Pixels (N, 2) to undistorted normalised image coordinates (N, 2).

    OpenCV's iterative solver gives a first guess; Newton steps on the forward model then take
    it to machine precision, so ``project`` inverts it to well under 1e-6 px.
    """
    uv = np.atleast_2d(np.asarray(uv, dtype=np.float64))
    xd = (uv - np.array([cam.cx, cam.cy])) / np.array([cam.fx, cam.fy])  # (N, 2) distorted, normalised
    if not np.any(cam.D) or len(uv) == 0:
        return xd
    guess = cv2.undistortPoints(
        uv.reshape(-1, 1, 2), cam.K, cam.D,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12),
    ).reshape(-1, 2)
    xn = guess.astype(np.float64)
    eps = 1e-7
    for _ in range(8):
        f = distort(xn, cam.D) - xd  # (N, 2) residual
        jx = (distort(xn + [eps, 0.0], cam.D) - distort(xn - [eps, 0.0], cam.D)) / (2 * eps)
        jy = (distort(xn + [0.0, eps], cam.D) - distort(xn - [0.0, eps], cam.D)) / (2 * eps)
        J = np.stack([jx, jy], axis=2)  # (N, 2, 2): J[n, i, j] = d f_i / d x_j
        xn = xn - np.linalg.solve(J, f[:, :, None])[:, :, 0]
        if np.max(np.abs(f)) < 1e-15:
            break
    return xn


def pixel_to_ray(uv: NDArray, cam: Camera) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Turn pixels into world rays.

    Args:
        uv: pixels, shape (N, 2).
        cam: the camera.

    Returns:
        ``(origin, directions)``: the optical centre, shape (3,), and unit ray directions in
        the world frame, shape (N, 3).
    """
    return cam.t.copy(), normalised_to_rays(undistort(uv, cam), cam.R)


def normalised_to_rays(xn: NDArray, R: NDArray) -> NDArray[np.float64]:
    """Undistorted normalised image coordinates to unit world ray directions.

    Args:
        xn: (..., 2) normalised coordinates (``undistort``).
        R: camera-to-world rotations: (3, 3) for one camera, (..., 3, 3) with one axis fewer
            than ``xn`` for one camera per row of points (e.g. per view, xn (V, K, 2), R (V, 3, 3)),
            or (..., 3, 3) with as many for one per point.

    Returns:
        (..., 3) unit directions: R [x, y, 1], normalised.
    """
    xn = np.asarray(xn, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    d_cam = np.concatenate([xn, np.ones((*xn.shape[:-1], 1))], axis=-1)  # (..., 3)
    # Rotated into the world, d = R d_cam: one matrix product per camera where a camera's points
    # form rows (d^T = d_cam^T R^T), else one per point.
    if R.ndim <= d_cam.ndim:
        d = d_cam @ np.swapaxes(R, -1, -2)
    else:
        d = np.matmul(R, d_cam[..., None])[..., 0]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def intersect_plane(origin: NDArray, directions: NDArray, height: float | NDArray = 0.0) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Intersect rays with the horizontal plane z = ``height``.

    Args:
        origin: ray origin, shape (3,) or (N, 3).
        directions: ray directions, shape (N, 3).
        height: plane height in metres, scalar or shape (N,).

    Returns:
        ``(points, valid)``: intersection points, shape (N, 3), and whether each ray meets the
        plane in front of its origin, shape (N,). Invalid rows are NaN.
    """
    directions = np.atleast_2d(directions)
    origin = np.asarray(origin, dtype=np.float64)  # (3,) or (N, 3): broadcasts against directions
    dz = directions[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        # origin_z + s * dz = height
        s = (np.asarray(height, dtype=np.float64) - origin[..., 2]) / dz
    valid = np.isfinite(s) & (s > 0)
    points = origin + np.where(valid, s, np.nan)[:, None] * directions
    return points, valid
