"""A ChArUco board drawn on the floor as a given camera sees it (perspective, distortion,
anti-aliasing, blur, lighting, sensor noise): the tests and the accuracy script check the
calibration against cameras whose pose is known exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.calibration.board import _INK, _PAPER, BoardError, BoardSpec, board_to_world, make_board
from superbody.edge.camera import Camera

__all__ = ["board_texture", "placement_in_front", "render_board"]


def board_texture(spec: BoardSpec, px_per_m: float, margin_m: float = 0.0) -> tuple[NDArray[np.uint8], float]:
    """The board as printed, with a white paper margin.

    Args:
        spec: the board.
        px_per_m: resolution, pixels per metre.
        margin_m: white margin around the chessboard, metres.

    Returns:
        ``(image, scale)``: the image, shape (H, W), uint8, and its exact pixels per metre
        (sizes are rounded to whole pixels). Texture pixel (i, j) is centred on the board point
        ``((j + 0.5) / scale - margin_m, (i + 0.5) / scale - margin_m)``.
    """
    w_m, h_m = spec.size_m
    w = max(1, round(w_m * px_per_m))
    scale = w / w_m
    h = max(1, round(h_m * scale))
    img = make_board(spec).generateImage((w, h), marginSize=0)
    m = round(margin_m * scale)
    if m:
        img = cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_CONSTANT, value=255)
    return cast("NDArray[np.uint8]", img), scale  # cv2 stubs: any MatLike; the board image is uint8


def placement_in_front(cam: Camera, spec: BoardSpec, distance_m: float, yaw_offset: float = 0.0) -> tuple[tuple[float, float], float]:
    """Where to lay the board so that its centre lies ``distance_m`` in front of the camera.

    The centre is on the floor, at ``distance_m`` horizontally from the point below the camera
    along the camera's heading; the board's x axis runs across the line of sight (left to right
    as the camera sees it), turned by ``yaw_offset`` radians.

    Returns:
        ``(origin_xy, yaw)`` for ``board_to_world``.
    """
    forward = cam.R[:, 2].copy()
    forward[2] = 0.0
    if np.linalg.norm(forward) < 1e-9:
        raise BoardError(f"camera {cam.id!r} looks straight down: it has no heading")
    forward /= np.linalg.norm(forward)
    centre = cam.t[:2] + distance_m * forward[:2]
    # The camera's right on the floor is forward turned clockwise.
    yaw = math.atan2(-forward[0], forward[1]) + yaw_offset
    R, _ = board_to_world((0.0, 0.0), yaw)
    w_m, h_m = spec.size_m
    half = R @ np.array([w_m / 2, h_m / 2, 0.0])
    return (float(centre[0] - half[0]), float(centre[1] - half[1])), yaw


def _floor_shade(xy: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    """A grey floor with a faint plank pattern and low-frequency variation, per world point (N, 2)."""
    shade = np.full(len(xy), 118.0)
    for _ in range(4):
        k = rng.uniform(0.5, 3.0, 2) * rng.choice([-1.0, 1.0], 2)
        shade += 6.0 * np.sin(xy @ k + rng.uniform(0, 2 * math.pi))
    shade -= 14.0 * (np.mod(xy[:, 0] / 0.2, 1.0) < 0.03)  # plank seams every 20 cm
    return shade


def _normalised_grid(cam: Camera, u: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Undistorted normalised coordinates of a grid of pixels, shapes (H, W) each.

    With distortion, OpenCV's iterative undistortion runs on the whole pixels around the grid
    and sub-pixel positions are interpolated bilinearly: the mapping is smooth, so this is
    exact to far below a thousandth of a pixel and several times faster.
    """
    if not np.any(cam.D):
        xn = (u - cam.cx) / cam.fx
        yn = (v - cam.cy) / cam.fy
        return np.broadcast_to(xn[None, :], (len(v), len(u))), np.broadcast_to(yn[:, None], (len(v), len(u)))
    u0, v0 = math.floor(u.min()), math.floor(v.min())
    cu = np.arange(u0, math.floor(u.max()) + 2, dtype=np.float64)
    cv = np.arange(v0, math.floor(v.max()) + 2, dtype=np.float64)
    grid = np.stack(np.meshgrid(cu, cv), axis=2).reshape(-1, 1, 2)
    coarse = cv2.undistortPoints(
        grid, cam.K, cam.D, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12),
    ).reshape(len(cv), len(cu), 2).astype(np.float64)
    i, j = np.floor(u - u0).astype(int), np.floor(v - v0).astype(int)
    wx, wy = (u - u0 - i)[None, :, None], (v - v0 - j)[:, None, None]
    rows0, rows1 = coarse[j], coarse[j + 1]  # (H, Wc, 2)
    top = (1 - wx) * rows0[:, i] + wx * rows0[:, i + 1]
    bottom = (1 - wx) * rows1[:, i] + wx * rows1[:, i + 1]
    out = (1 - wy) * top + wy * bottom  # (H, W, 2)
    return out[..., 0], out[..., 1]


def _floor_points(cam: Camera, u: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Where the rays through a grid of pixels meet the floor.

    Args:
        cam: the camera.
        u: pixel columns, shape (W,); v: pixel rows, shape (H,).

    Returns:
        ``(xy, hits)``: floor points, shape (H, W, 2) (the camera's foot where the ray misses),
        and whether the ray meets the floor in front of the camera, shape (H, W).
    """
    xn, yn = _normalised_grid(cam, u, v)  # (H, W) each
    R = cam.R
    # World direction of the ray (xn, yn, 1) in the camera frame, one component at a time.
    dx = R[0, 0] * xn + R[0, 1] * yn + R[0, 2]
    dy = R[1, 0] * xn + R[1, 1] * yn + R[1, 2]
    dz = R[2, 0] * xn + R[2, 1] * yn + R[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -cam.t[2] / dz  # camera z + s * dz = 0
    hits = np.isfinite(s) & (s > 0)
    s = np.where(hits, s, 0.0)
    xy = np.stack([cam.t[0] + s * dx, cam.t[1] + s * dy], axis=2)  # (H, W, 2)
    return xy, hits


def render_board(
    spec: BoardSpec,
    cam: Camera,
    origin_xy: Sequence[float],
    yaw: float,
    *,
    margin_m: float = 0.03,
    supersample: int = 4,
    blur_px: float = 0.7,
    noise: float = 2.5,
    seed: int = 0,
) -> NDArray[np.uint8]:
    """Draw the board lying on the floor as the camera sees it.

    Every pixel's ray goes through the camera model (its distortion included) to the floor: a
    grey plank floor, or above the horizon a wall. Pixels near the board average
    ``supersample``^2 rays on the board's printed texture (anti-aliasing). Then an uneven light,
    a Gaussian lens blur of ``blur_px`` and sensor noise of standard deviation ``noise`` grey
    levels.

    Args:
        spec: the board.
        cam: the camera, pose and intrinsics.
        origin_xy: the board's origin on the floor, metres.
        yaw: the direction of its x axis, radians.
        margin_m: white paper margin around the chessboard, metres.
        supersample: rays per pixel along each axis on the board.
        blur_px: standard deviation of the blur, output pixels (0: none).
        noise: standard deviation of the noise, grey levels (0: none).
        seed: seed of the floor pattern, the light and the noise.

    Returns:
        Grey image, shape (cam.height, cam.width), uint8.
    """
    rng = np.random.default_rng(seed)
    W, H = cam.width, cam.height
    R_wb, t_wb = board_to_world(origin_xy, yaw)
    w_m, h_m = spec.size_m
    floor, hits = _floor_points(cam, np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    img = np.where(hits, _floor_shade(floor.reshape(-1, 2), rng).reshape(H, W), 170.0)  # above the horizon: a wall
    # Board x, y of each floor point: p_board = R^T (p_world - t) with z = 0.
    bxy = (floor - t_wb[:2]) @ R_wb[:2, :2]  # (H, W, 2)
    pad = margin_m + 0.5 * spec.square_m
    near = hits & np.all((bxy > -pad) & (bxy < np.array([w_m, h_m]) + pad), axis=2)
    rows, cols = np.nonzero(cv2.dilate(near.astype(np.uint8), np.ones((5, 5), np.uint8)))
    if len(rows):
        r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
        s = int(supersample)
        # Sub-pixel k of pixel j sits at j - 0.5 + (k + 0.5) / s, so that INTER_AREA's s x s
        # mean lands on the pixel's centre.
        u = c0 - 0.5 + (np.arange((c1 - c0) * s) + 0.5) / s
        v = r0 - 0.5 + (np.arange((r1 - r0) * s) + 0.5) / s
        fine, fine_hits = _floor_points(cam, u, v)
        fxy = (fine - t_wb[:2]) @ R_wb[:2, :2]  # (h, w, 2) board x, y
        texture, scale = board_texture(spec, px_per_m=max(400.0, 1500.0 * 0.16 / spec.square_m), margin_m=margin_m)
        map_x = np.where(fine_hits, (fxy[..., 0] + margin_m) * scale - 0.5, -10.0).astype(np.float32)
        map_y = np.where(fine_hits, (fxy[..., 1] + margin_m) * scale - 0.5, -10.0).astype(np.float32)
        paper = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        cover = cv2.remap(np.full_like(texture, 255), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        alpha = cover.astype(np.float32) / 255.0  # (h, w) board coverage
        board_grey = alpha * (_INK + (_PAPER - _INK) * paper.astype(np.float32) / 255.0)
        # The mean of (1 - a) f + a b over a pixel whose floor shade f is one value.
        size = (c1 - c0, r1 - r0)
        a_mean = cv2.resize(alpha, size, interpolation=cv2.INTER_AREA)
        ab_mean = cv2.resize(board_grey, size, interpolation=cv2.INTER_AREA)
        img[r0:r1, c0:c1] = (1.0 - a_mean) * img[r0:r1, c0:c1] + ab_mean
    # Uneven light: a gentle linear gradient across the image.
    gx, gy = rng.uniform(-0.12, 0.12, 2)
    img = img * (1.0 + gx * (np.arange(W) / W - 0.5))[None, :] * (1.0 + gy * (np.arange(H) / H - 0.5))[:, None]
    img = img.astype(np.float32)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise > 0:
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
