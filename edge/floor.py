"""The floor a site's cameras see: where people can be, as the cameras see it.

A site's floor polygon is the room, never the path of one recording: models are trained and
checked over all of it. For a site recovered from cameras alone (``superbody calibrate
from-dataset``, or any site without a hand-drawn floor) it is derived here:

1. a floor point counts as *seen* by a camera when a person standing there has part of their
   torso in the image: the point above it at hip or at shoulder height (0.9 m, 1.4 m) projects
   inside the image (less a small border), in front of the camera (a detector finds a person
   from the head and shoulders, or the hips and legs). There is no range cut-off: a person 6 m
   from every camera is still in the room, only poorly seen, and how well the views see a
   place is the estimator's business, not the floor's. The only limit is the detector's: a
   standing person must span at least ``MIN_PERSON_PX`` image rows (``detectable_range_m``:
   about 22 m for a 640 x 480 camera with a 60 degree field of view);
2. the room the cameras stand in: every camera hangs on a wall and looks into the room, so the
   room lies in front of each camera, beyond ``wall_margin_m`` along its horizontal viewing
   direction (a half-plane per camera);
3. the floor is the largest region of points seen by at least one camera and inside the room,
   traced on a ``cell_m`` grid and simplified to a polygon (counter-clockwise).

``views_at`` counts how many cameras see each of a set of floor points, for coverage maps
and for sampling training positions by camera count.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.edge.camera import Camera, project

__all__ = [
    "TORSO_HEIGHTS_M", "MIN_PERSON_PX", "PERSON_HEIGHT_M", "detectable_range_m", "seen_by", "views_at", "in_front", "visible_floor",
    "point_in_polygon", "floor_points",
]

TORSO_HEIGHTS_M = (0.9, 1.4)  # hips and shoulders of a standing adult (edge.body's typical heights)
PERSON_HEIGHT_M = 1.7  # a standing adult, head to feet
MIN_PERSON_PX = 48  # image rows a pose detector needs for a whole person (its smallest useful scale)


def detectable_range_m(cam: Camera, min_person_px: float = MIN_PERSON_PX) -> float:
    """The farthest distance at which a standing person spans ``min_person_px`` rows of the camera."""
    return float(cam.fy * PERSON_HEIGHT_M / min_person_px)


def seen_by(cam: Camera, xy: NDArray, max_range_m: float | None = None, border: float = 0.02) -> NDArray[np.bool_]:
    """Which floor points a camera sees part of a standing person's torso at (hips or shoulders).

    Args:
        cam: the camera.
        xy: (N, 2) floor points, metres.
        max_range_m: farthest floor distance from the camera's foot point that counts (None: the
            detector's limit, ``detectable_range_m``).
        border: image border left out, as a fraction of the width and height.

    Returns:
        (N,) bool.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    reach = detectable_range_m(cam) if max_range_m is None else max_range_m
    near = np.hypot(xy[:, 0] - cam.t[0], xy[:, 1] - cam.t[1]) <= reach
    bu, bv = border * cam.width, border * cam.height
    seen = np.zeros(len(xy), bool)
    for h in TORSO_HEIGHTS_M:
        uv, z = project(np.column_stack([xy, np.full(len(xy), h)]), cam)
        seen |= (z > 0.1) & (uv[:, 0] >= bu) & (uv[:, 0] <= cam.width - bu) & (uv[:, 1] >= bv) & (uv[:, 1] <= cam.height - bv)
    return near & seen


def views_at(cameras: Sequence[Camera], xy: NDArray, max_range_m: float | None = None) -> NDArray[np.int64]:
    """(N,) how many of the cameras see a person standing at each floor point (N, 2)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.sum([seen_by(c, xy, max_range_m) for c in cameras], axis=0).astype(np.int64) if cameras else np.zeros(len(xy), np.int64)


def in_front(cameras: Sequence[Camera], xy: NDArray, wall_margin_m: float = 0.3) -> NDArray[np.bool_]:
    """(N,) floor points in front of every camera's wall (the room the cameras stand in).

    A camera looking straight down has no horizontal direction and clips nothing.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    ok = np.ones(len(xy), bool)
    for cam in cameras:
        d = cam.R[:2, 2]  # the optical axis (camera z) on the floor
        n = np.linalg.norm(d)
        if n < 0.2:
            continue
        ok &= (xy - cam.t[:2]) @ (d / n) >= wall_margin_m
    return ok


def visible_floor(
    cameras: Sequence[Camera],
    max_range_m: float | None = None,
    wall_margin_m: float = 0.3,
    cell_m: float = 0.05,
    simplify_m: float = 0.05,
) -> tuple[tuple[float, float], ...]:
    """The floor polygon the cameras see (see the module docstring).

    Args:
        cameras: the site's cameras (at least one).
        max_range_m: a camera's useful floor range (None, the default: the detector's limit, no
            cut-off of the room).
        wall_margin_m: how far in front of a camera's wall a person can stand.
        cell_m: grid resolution.
        simplify_m: largest distance of the polygon from the traced region's outline.

    Returns:
        Vertices (x, y) in metres, counter-clockwise, rounded to 1 cm.

    Raises:
        ValueError: no camera sees any of the floor in front of the cameras.
    """
    import cv2

    if not cameras:
        raise ValueError("visible_floor: no cameras")
    centres = np.array([c.t[:2] for c in cameras])
    reach = max(detectable_range_m(c) for c in cameras) if max_range_m is None else max_range_m
    lo = centres.min(0) - reach
    hi = centres.max(0) + reach
    nx, ny = (np.ceil((hi - lo) / cell_m)).astype(int) + 1
    gx, gy = np.meshgrid(lo[0] + cell_m * np.arange(nx), lo[1] + cell_m * np.arange(ny))  # (ny, nx)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    ok = (views_at(cameras, xy, max_range_m) > 0) & in_front(cameras, xy, wall_margin_m)
    mask = ok.reshape(ny, nx).astype(np.uint8)
    if not mask.any():
        raise ValueError("visible_floor: the cameras see no floor in front of them (check their poses)")
    # The largest connected region, its holes filled: a person can cross a small blind spot.
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outline = max(contours, key=cv2.contourArea)
    poly = cv2.approxPolyDP(outline, simplify_m / cell_m, True)[:, 0, :].astype(np.float64)  # (V, 2) grid (col, row)
    pts = lo + poly * cell_m
    area2 = np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1])
    if area2 < 0:
        pts = pts[::-1]
    return tuple((round(float(x), 2), round(float(y), 2)) for x, y in pts)


def point_in_polygon(xy: NDArray, polygon: Sequence[Sequence[float]]) -> NDArray[np.bool_]:
    """(N,) whether each point (N, 2) is inside the polygon (even-odd rule)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    p = np.asarray(polygon, dtype=np.float64)
    x, y = xy[:, :1], xy[:, 1:]
    x0, y0 = p[:, 0], p[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    crosses = (y0 > y) != (y1 > y)  # (N, V)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (np.sum(crosses & (x < xc), axis=1) % 2) == 1


def floor_points(polygon: Sequence[Sequence[float]], cell_m: float) -> NDArray[np.float64]:
    """(N, 2) the centres of a ``cell_m`` grid's cells that lie inside the polygon."""
    poly = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(*(np.arange(a + cell_m / 2, b, cell_m) for a, b in zip(lo, hi)))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    return xy[point_in_polygon(xy, polygon)]
