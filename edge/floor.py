"""The floor a site's cameras see: where people can be, as the cameras see it.

A site's floor polygon is the room, never the path of one recording: models are trained and
checked over all of it, the simulator walks people over it, and a MoveNet node sizes its input for
the people it will see there (``edge.detectors.movenet.short_side_for``). For a site recovered from
cameras alone (``superbody calibrate from-dataset``, ``superbody site import``, or any site without
a hand-drawn floor) it is derived here:

1. a floor point counts as *seen* by a camera when a person standing there has part of their
   torso in the image: the point above it at hip or at shoulder height (0.9 m, 1.4 m) projects
   inside the image (less a small border), in front of the camera (a detector finds a person
   from the head and shoulders, or the hips and legs). There is no range cut-off: a person 6 m
   from every camera is still in the room, only poorly seen, and how well the views see a
   place is the estimator's business, not the floor's. The only limit is the detector's: a
   standing person must span at least ``MIN_PERSON_PX`` image rows (``detectable_range_m``:
   about 22 m for a 640 x 480 camera with a 60 degree field of view);
2. the room, by the cameras' layout (``LAYOUTS``; ``guess_layout`` tells them apart):

   - ``wall``: every camera hangs on a wall and looks into the room, so the room lies in front
     of each camera, beyond ``wall_margin_m`` along its horizontal viewing direction (a
     half-plane per camera); a point seen by one camera counts;
   - ``ring``: cameras stand around a space and look inward (a capture dome, a stage): the room
     is inside the ring (the convex hull of the cameras' foot points) where at least two cameras
     see a person, the views' overlap;
   - ``ceiling``: cameras look down from above: no wall to stand in front of, the room is where
     at least two cameras see a person (one, for a single camera); overlaps apart (cameras back
     to back) are joined by their convex hull, where one camera sees;

3. the floor is the largest region of points seen (as the layout asks) and inside the room,
   its holes filled, traced on a ``cell_m`` grid and simplified to a polygon (counter-clockwise).

Where none of these fits, draw the floor by hand: ``superbody site floor-plot`` draws the
cameras and what they see on a grid to read the corners off.

``views_at`` counts how many cameras see each of a set of floor points, for coverage maps
and for sampling training positions by camera count.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.edge.camera import Camera, project
from superbody.edge.site import Obstacle, obstacles_hide

__all__ = [
    "TORSO_HEIGHTS_M", "MIN_PERSON_PX", "PERSON_HEIGHT_M", "LAYOUTS", "detectable_range_m", "visible", "seen_by", "views_at", "in_front",
    "inside_ring", "guess_layout", "visible_floor", "point_in_polygon", "floor_points", "polygon_area",
]

TORSO_HEIGHTS_M = (0.9, 1.4)  # hips and shoulders of a standing adult (edge.body's typical heights)
PERSON_HEIGHT_M = 1.7  # a standing adult, head to feet
MIN_PERSON_PX = 48  # image rows a pose detector needs for a whole person (its smallest useful scale)
LAYOUTS = ("wall", "ring", "ceiling")  # how the cameras stand: the room each layout implies (module docstring)
# guess_layout: a camera looking down more steeply than this is a ceiling camera; cameras stand in a
# ring when, seen from the point their optical axes meet, no gap between them is wider than
# RING_MAX_GAP_DEG (three walls of a room leave a gap of 180 degrees or more) and each looks within
# RING_AIM_DEG of that point.
CEILING_PITCH_DEG = 50.0
RING_MAX_GAP_DEG = 150.0
RING_AIM_DEG = 45.0


def detectable_range_m(cam: Camera, min_person_px: float = MIN_PERSON_PX) -> float:
    """The farthest distance at which a standing person spans ``min_person_px`` rows of the camera."""
    return float(cam.fy * PERSON_HEIGHT_M / min_person_px)


def visible(cam: Camera, xy: NDArray, heights: Sequence[float], border: float, max_range_m: float | None = None,
            obstacles: Sequence[Obstacle] = ()) -> NDArray[np.bool_]:
    """Which floor points (N, 2) a camera sees a standing person at: the one place visibility is computed.

    Seen: at one of ``heights`` (metres above the point) the person projects inside the image
    less ``border`` (a fraction of its width and height) on each side, in front of the camera,
    within ``max_range_m`` of the camera's foot point (None: the detector's limit,
    ``detectable_range_m``), and no obstacle stands between the camera and that point.
    ``seen_by`` (part of a torso, for coverage and sizing) and the tracker's
    ``host.tracking.evidence.clearly_sees`` (the torso's centre well inside the image) are two uses.

    Returns:
        (N,) bool.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    reach = detectable_range_m(cam) if max_range_m is None else max_range_m
    near = np.hypot(xy[:, 0] - cam.t[0], xy[:, 1] - cam.t[1]) <= reach
    bu, bv = border * cam.width, border * cam.height
    seen = np.zeros(len(xy), bool)
    for h in heights:
        points = np.column_stack([xy, np.full(len(xy), h)])
        uv, z = project(points, cam)
        inside = (z > 0.1) & (uv[:, 0] >= bu) & (uv[:, 0] <= cam.width - bu) & (uv[:, 1] >= bv) & (uv[:, 1] <= cam.height - bv)
        seen |= inside & ~obstacles_hide(cam.t, points, obstacles) if obstacles else inside
    return near & seen


def seen_by(cam: Camera, xy: NDArray, max_range_m: float | None = None, border: float = 0.02) -> NDArray[np.bool_]:
    """Which floor points (N, 2) a camera sees part of a standing person's torso at (hips or
    shoulders), ``border`` of the image left out, within ``max_range_m`` (``visible``)."""
    return visible(cam, xy, TORSO_HEIGHTS_M, border, max_range_m)


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


def inside_ring(cameras: Sequence[Camera], xy: NDArray) -> NDArray[np.bool_]:
    """(N,) floor points inside the convex hull of the cameras' foot points (the space a ring of
    cameras stands around); all False with fewer than three cameras not on one line."""
    import cv2

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    feet = np.array([c.t[:2] for c in cameras], dtype=np.float32).reshape(-1, 2)
    if len(feet) < 3:
        return np.zeros(len(xy), bool)
    hull = cv2.convexHull(feet)[:, 0, :].astype(np.float64)  # (H, 2)
    if len(hull) < 3 or polygon_area(hull) < 1e-6:
        return np.zeros(len(xy), bool)
    return point_in_polygon(xy, hull.tolist())


def _look_target(cameras: Sequence[Camera]) -> NDArray[np.float64] | None:
    """(2,) the floor point nearest (least squares) to every camera's optical axis seen from
    above, or None when the axes are (nearly) parallel or vertical."""
    A = np.zeros((2, 2))
    b = np.zeros(2)
    for cam in cameras:
        d = cam.R[:2, 2]
        n = np.linalg.norm(d)
        if n < 0.2:
            continue
        d = d / n
        P = np.eye(2) - np.outer(d, d)  # distance to the line through the camera along d
        A += P
        b += P @ cam.t[:2]
    if np.linalg.cond(A) > 1e6:
        return None
    return np.asarray(np.linalg.solve(A, b), dtype=np.float64)


def guess_layout(cameras: Sequence[Camera]) -> str:
    """Which of ``LAYOUTS`` the cameras stand in.

    ``ceiling`` when every camera looks down more steeply than ``CEILING_PITCH_DEG``; ``ring`` when
    three or more cameras surround the point their optical axes meet (no angular gap between them
    wider than ``RING_MAX_GAP_DEG``, each aimed within ``RING_AIM_DEG`` of it); else ``wall``.
    """
    if not cameras:
        raise ValueError("guess_layout: no cameras")
    # R[2, 2] is the optical axis' world z: -sin(pitch below the horizon).
    if all(-cam.R[2, 2] >= np.sin(np.radians(CEILING_PITCH_DEG)) for cam in cameras):
        return "ceiling"
    target = _look_target(cameras)
    if len(cameras) < 3 or target is None:
        return "wall"
    to_cam = np.array([c.t[:2] for c in cameras]) - target  # (C, 2)
    bearings = np.sort(np.degrees(np.arctan2(to_cam[:, 1], to_cam[:, 0])))
    gaps = np.diff(np.append(bearings, bearings[0] + 360.0))
    for cam, v in zip(cameras, to_cam):
        d = cam.R[:2, 2]
        if np.linalg.norm(d) < 0.2 or np.linalg.norm(v) < 1e-6:
            continue
        aim = np.degrees(np.arccos(np.clip(-(v @ d) / (np.linalg.norm(v) * np.linalg.norm(d)), -1.0, 1.0)))
        if aim > RING_AIM_DEG:
            return "wall"
    return "ring" if gaps.max() <= RING_MAX_GAP_DEG else "wall"


def _room(cameras: Sequence[Camera], xy: NDArray, layout: str, max_range_m: float | None, wall_margin_m: float) -> NDArray[np.int64]:
    """(N,) how many cameras see each floor point (N, 2), 0 outside the room the layout implies
    (module docstring, steps 1-2)."""
    views = views_at(cameras, xy, max_range_m)
    if layout == "wall":
        return views * in_front(cameras, xy, wall_margin_m)
    if layout == "ring":
        return views * inside_ring(cameras, xy)
    return views


def visible_floor(
    cameras: Sequence[Camera],
    max_range_m: float | None = None,
    wall_margin_m: float = 0.3,
    cell_m: float = 0.05,
    simplify_m: float = 0.05,
    layout: str = "wall",
    min_views: int | None = None,
) -> tuple[tuple[float, float], ...]:
    """The floor polygon the cameras see (see the module docstring).

    Args:
        cameras: the site's cameras (at least one).
        max_range_m: a camera's useful floor range (None, the default: the detector's limit, no
            cut-off of the room).
        wall_margin_m: how far in front of a camera's wall a person can stand (``wall``).
        cell_m: grid resolution.
        simplify_m: largest distance of the polygon from the traced region's outline.
        layout: one of ``LAYOUTS``, or ``"auto"`` (``guess_layout``).
        min_views: cameras that must see a floor point (default: 1 for ``wall``; 2 for ``ring``
            and ``ceiling``, or every camera when there are fewer).

    Returns:
        Vertices (x, y) in metres, counter-clockwise, rounded to 1 cm.

    Raises:
        ValueError: an unknown layout (naming the valid ones), a ring of fewer than three
            cameras, or no floor seen as the layout asks.
    """
    import cv2

    if not cameras:
        raise ValueError("visible_floor: no cameras")
    if layout == "auto":
        layout = guess_layout(cameras)
    if layout not in LAYOUTS:
        raise ValueError(f"visible_floor: unknown layout {layout!r}; valid layouts: auto, {', '.join(LAYOUTS)}")
    if layout == "ring" and len(cameras) < 3:
        raise ValueError(f"visible_floor: a ring layout needs at least 3 cameras around the space, got {len(cameras)}")
    if min_views is None:
        min_views = 1 if layout == "wall" else min(2, len(cameras))
    centres = np.array([c.t[:2] for c in cameras])
    reach = max(detectable_range_m(c) for c in cameras) if max_range_m is None else max_range_m
    lo = centres.min(0) - reach
    hi = centres.max(0) + reach
    nx, ny = (np.ceil((hi - lo) / cell_m)).astype(int) + 1
    # Only the window where a coarse pass finds any of the room is traced finely: the same grid
    # (so the same polygon), a fraction of the points for long-range (HD) cameras.
    rows, cols = _window(lambda xy: _room(cameras, xy, layout, max_range_m, wall_margin_m) >= min_views, lo, nx, ny, cell_m)
    gx, gy = np.meshgrid(lo[0] + cell_m * cols, lo[1] + cell_m * rows)  # (ny', nx')
    views = np.zeros((ny, nx), np.int64)
    views[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1] = _room(cameras, np.column_stack([gx.ravel(), gy.ravel()]), layout, max_range_m,
                                                              wall_margin_m).reshape(gx.shape)
    mask = (views >= min_views).astype(np.uint8)
    if layout == "ceiling" and mask.any():
        # Overlaps apart (cameras back to back, each pair overlapping on one side) make one floor:
        # their convex hull, where at least one camera sees.
        hull = cv2.convexHull(np.argwhere(mask)[:, ::-1].astype(np.int32))
        joined = np.zeros_like(mask)
        cv2.fillConvexPoly(joined, hull, 1)
        mask = joined & (views >= 1).astype(np.uint8)
    if not mask.any():
        why = {"wall": "in front of them", "ring": "inside their ring seen by two of them", "ceiling": f"seen by {min_views} of them"}[layout]
        raise ValueError(f"visible_floor: the cameras see no floor {why} (check their poses, or the layout: {layout})")
    # The largest connected region, its holes filled: a person can cross a small blind spot.
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outline = max(contours, key=cv2.contourArea)
    poly = cv2.approxPolyDP(outline, simplify_m / cell_m, True)[:, 0, :].astype(np.float64)  # (V, 2) grid (col, row)
    pts = lo + poly * cell_m
    if polygon_area(pts, signed=True) < 0:
        pts = pts[::-1]
    return tuple((round(float(x), 2), round(float(y), 2)) for x, y in pts)


def _window(room, lo: NDArray, nx: int, ny: int, cell_m: float, step: int = 10, pad: int = 2) -> tuple[NDArray, NDArray]:
    """(rows, cols) index ranges of the ``nx`` x ``ny`` grid around what ``room`` keeps on a grid
    ``step`` times coarser, ``pad`` coarse cells wider; the whole grid when it keeps nothing."""
    r, c = np.arange(0, ny, step), np.arange(0, nx, step)
    gx, gy = np.meshgrid(lo[0] + cell_m * c, lo[1] + cell_m * r)
    keep = room(np.column_stack([gx.ravel(), gy.ravel()])).reshape(gx.shape)
    if not keep.any():
        return np.arange(ny), np.arange(nx)
    kr, kc = np.flatnonzero(keep.any(1)), np.flatnonzero(keep.any(0))
    r0, r1 = max(0, r[kr[0]] - pad * step), min(ny - 1, r[kr[-1]] + pad * step)
    c0, c1 = max(0, c[kc[0]] - pad * step), min(nx - 1, c[kc[-1]] + pad * step)
    return np.arange(r0, r1 + 1), np.arange(c0, c1 + 1)


def polygon_area(polygon: Sequence[Sequence[float]] | NDArray, signed: bool = False) -> float:
    """The polygon's (V, 2) area in square metres (shoelace); signed: positive counter-clockwise."""
    p = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    a = 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
    return a if signed else abs(a)


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
