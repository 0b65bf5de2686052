"""The floor the cameras see (edge/floor.py)."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.floor import (
    MIN_PERSON_PX,
    detectable_range_m,
    floor_points,
    guess_layout,
    in_front,
    point_in_polygon,
    polygon_area,
    seen_by,
    views_at,
    visible_floor,
)
from superbody.edge.site import load_site
from superbody.models.data.wtf import load_wtf
from tests.conftest import WTF_SITE

SQUARE = ((0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0))


def _wall_camera(pos=(0.0, 0.0, 2.5), target=(4.0, 0.0, 0.8)) -> Camera:
    R = look_at_rotation(np.array(pos), np.array(target))
    return Camera(id="a", width=640, height=480, fps=15.0, fx=500.0, fy=500.0, cx=320.0, cy=240.0,
                  position=pos, rotation=tuple(tuple(r) for r in R))


@pytest.mark.parametrize("xy, inside", [
    ((1.0, 1.0), True),     # centre
    ((-0.1, 1.0), False),   # left of the square
    ((2.5, 2.5), False),    # beyond a corner
    ((1.99, 0.01), True),   # just inside a corner
])
def test_point_in_polygon(xy, inside):
    assert point_in_polygon(np.array([xy]), SQUARE)[0] == inside


def test_point_in_polygon_empty():
    assert point_in_polygon(np.zeros((0, 2)), SQUARE).shape == (0,)


def test_a_wall_camera_sees_in_front_not_behind_and_far_without_a_range_cut_off():
    cam = _wall_camera()
    pts = np.array([[4.0, 0.0], [-2.0, 0.0], [4.0, 8.0], [9.0, 0.0], [20.0, 0.0]])
    # in front on its axis; behind it; far off to the side; 9 m away (still seen: poorly, but seen);
    # 20 m away, beyond where a person spans MIN_PERSON_PX rows (17.7 m at fy = 500)
    assert detectable_range_m(cam) == pytest.approx(500 * 1.7 / MIN_PERSON_PX)
    assert seen_by(cam, pts).tolist() == [True, False, False, True, False]
    assert seen_by(cam, pts, max_range_m=5.0).tolist() == [True, False, False, False, False]  # an explicit range still cuts
    assert in_front([cam], pts).tolist() == [True, False, True, True, True]


def test_visible_floor_is_in_front_of_the_camera_and_reaches_as_far_as_it_sees():
    cam = _wall_camera()
    poly = np.array(visible_floor([cam]))
    assert poly[:, 0].min() >= 0.3 - 0.05  # the wall margin
    assert point_in_polygon(np.array([[9.0, 0.0]]), poly)[0]  # no 5 m cut-off
    assert np.hypot(poly[:, 0], poly[:, 1]).max() <= detectable_range_m(cam) + 0.1
    ranged = np.array(visible_floor([cam], max_range_m=5.0))
    assert np.hypot(ranged[:, 0], ranged[:, 1]).max() <= 5.0 + 0.1
    area2 = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert area2 > 0  # counter-clockwise
    assert point_in_polygon(np.array([[4.0, 0.0]]), poly)[0]


def test_visible_floor_needs_a_camera():
    with pytest.raises(ValueError, match="no cameras"):
        visible_floor([])


def test_apartment_floor_is_the_room_not_the_recording(dev_json):
    """The shipped floor holds where dev.json walked and reaches well beyond it, toward camera 3."""
    site = load_site(WTF_SITE)
    truth = np.array([s.truth[:2] for s in load_wtf(dev_json, site)])
    assert point_in_polygon(truth, site.floor).mean() == 1.0
    x0, y0, x1, y1 = site.floor_bounds
    assert y1 > truth[:, 1].max() + 1.0  # the recording stops at y = 0.8 m; camera 3 hangs at y = 2.94 m
    assert y1 < site.camera("3").t[1]
    # The stretch the paper's test recording walks near camera 3 (x 0.1-1.0 m, y 1.5-1.9 m), 5.5 m from
    # camera 1: once cut out of the floor by a 5 m range limit.
    notch = np.mgrid[0.1:1.01:0.1, 1.5:1.91:0.1].reshape(2, -1).T
    assert point_in_polygon(notch, site.floor).all()
    # Every floor point is seen by at least one camera.
    g = np.mgrid[x0:x1:0.1, y0:y1:0.1].reshape(2, -1).T
    g = g[point_in_polygon(g, site.floor)]
    assert (views_at(site.cameras, g) >= 1).mean() > 0.97


# --- layouts: wall, ring, ceiling -----------------------------------------------------------------


def _cam(cid: str, pos, target=None, R=None, w=1280, h=720, f=900.0) -> Camera:
    R = look_at_rotation(np.array(pos, float), np.array(target, float)) if R is None else np.asarray(R, float)
    return Camera(id=cid, width=w, height=h, fps=15.0, fx=f, fy=f, cx=w / 2, cy=h / 2,
                  position=tuple(float(v) for v in pos), rotation=tuple(tuple(float(v) for v in r) for r in R))


def _ring(n=5, radius=4.0, height=2.5) -> list[Camera]:
    """n cameras evenly around a circle, each aimed at the centre at 1 m."""
    a = 2 * np.pi * np.arange(n) / n
    return [_cam(f"r{i}", (radius * np.cos(t), radius * np.sin(t), height), (0.0, 0.0, 1.0)) for i, t in enumerate(a)]


def _down(pos, tilt_deg=0.0, heading_deg=0.0) -> np.ndarray:
    """World-from-camera rotation of a camera looking straight down, then tilted ``tilt_deg`` towards ``heading_deg``."""
    t, h = np.radians(tilt_deg), np.radians(heading_deg)
    z = np.array([np.sin(t) * np.cos(h), np.sin(t) * np.sin(h), -np.cos(t)])  # optical axis
    x = np.array([-np.sin(h), np.cos(h), 0.0])  # image x across the tilt
    return np.stack([x, np.cross(z, x), z], axis=1)


def _ceiling_grid() -> list[Camera]:
    """Four wide-angle cameras (93 deg) 3.5 m up on a 2 m grid, looking straight down."""
    return [_cam(f"c{i}", (x, y, 3.5), R=_down((x, y, 3.5)), f=600.0) for i, (x, y) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)])]


def _ceiling_outward() -> list[Camera]:
    """Four wide-angle cameras back to back at the ceiling's centre, 3.2 m up, each tilted 35 deg outward."""
    return [_cam(f"o{i}", (0.0, 0.0, 3.2), R=_down((0, 0, 3.2), 35.0, 90.0 * i), f=600.0) for i in range(4)]


def _apartment() -> list[Camera]:
    return list(load_site(WTF_SITE).cameras)


# (cameras, the layout guess_layout must see)
LAYOUT_CASES = [
    (_ring(5), "ring"),  # the dome: five cameras around the space, aimed at its middle
    (_ring(3), "ring"),  # three: the smallest ring, 120 deg apart
    (_ring(4, radius=3.0, height=2.2), "ring"),  # a room's four corners
    (_ceiling_grid(), "ceiling"),  # looking straight down
    (_ceiling_outward(), "ceiling"),  # tilted outward, 55 deg below the horizon
    (_apartment(), "wall"),  # the paper's apartment: three walls, a 190 deg gap where the room goes on
    (_ring(5)[:2], "wall"),  # two cameras cannot surround anything
    ([_cam("w0", (0, 0, 2.5), (4, 0, 1)), _cam("w1", (0, 3, 2.5), (4, 3, 1))], "wall"),  # side by side on one wall
]


@pytest.mark.parametrize("cameras, layout", LAYOUT_CASES)
def test_guess_layout(cameras, layout):
    assert guess_layout(cameras) == layout


def test_a_ring_floor_is_the_views_overlap_inside_the_ring():
    cams = _ring(5)
    poly = visible_floor(cams, layout="ring")
    area = polygon_area(poly)
    hull = 0.5 * 5 * 4.0**2 * np.sin(2 * np.pi / 5)  # the ring's pentagon, 38 m^2
    assert 0.5 * hull < area <= hull + 0.5
    # The common view (where all five cameras see a person) is inside; the cameras' far views are not.
    g = np.mgrid[-5:5.01:0.25, -5:5.01:0.25].reshape(2, -1).T
    common = g[views_at(cams, g) == 5]
    assert len(common) > 50 and point_in_polygon(common, poly).mean() > 0.97
    assert not point_in_polygon(np.array([[0.0, 7.0], [-6.0, 0.0]]), poly).any()
    assert (views_at(cams, floor_points(poly, 0.2)) >= 2).mean() > 0.97
    assert polygon_area(poly, signed=True) > 0  # counter-clockwise


@pytest.mark.parametrize("cameras, lo, hi", [
    (_ceiling_grid(), 15.0, 40.0),  # 2 x 2 grid straight down: the views' overlap, a cross, and its corners
    (_ceiling_outward(), 40.0, 120.0),  # back to back: four overlaps apart (the diagonals), joined
])
def test_a_ceiling_floor_is_where_the_cameras_views_overlap(cameras, lo, hi):
    poly = visible_floor(cameras, layout="ceiling")
    assert lo < polygon_area(poly) < hi
    g = np.mgrid[-8:8.01:0.25, -8:8.01:0.25].reshape(2, -1).T
    two = g[views_at(cameras, g) >= 2]
    assert point_in_polygon(two, poly).mean() > 0.97  # every overlap
    assert (views_at(cameras, floor_points(poly, 0.2)) >= 1).mean() > 0.97  # and nothing no camera sees


def test_the_wall_rule_finds_no_room_for_cameras_back_to_back():
    """Cameras at a ceiling's centre looking outward have no common 'in front': the old rule fails."""
    with pytest.raises(ValueError, match="in front of them"):
        visible_floor(_ceiling_outward(), layout="wall")
    assert polygon_area(visible_floor(_ceiling_outward(), layout="auto")) > 40.0


def test_auto_keeps_the_shipped_apartment_floor():
    site = load_site(WTF_SITE)
    assert visible_floor(site.cameras, layout="auto") == site.floor == visible_floor(site.cameras)


@pytest.mark.parametrize("kwargs, message", [
    (dict(layout="dome"), "valid layouts: auto, wall, ring, ceiling"),  # unknown layout names the valid ones
    (dict(layout="ring", cameras=2), "at least 3 cameras"),  # two cameras are no ring
])
def test_visible_floor_layout_errors(kwargs, message):
    cams = _ring(5)[: kwargs.pop("cameras", 5)]
    with pytest.raises(ValueError, match=message):
        visible_floor(cams, **kwargs)


@pytest.mark.parametrize("polygon, area", [
    (SQUARE, 4.0),  # counter-clockwise square
    (SQUARE[::-1], 4.0),  # clockwise: the same area
    (((0, 0), (1, 0), (0, 1)), 0.5),  # a triangle
])
def test_polygon_area(polygon, area):
    assert polygon_area(polygon) == pytest.approx(area)
    clockwise = polygon == SQUARE[::-1]
    assert polygon_area(polygon, signed=True) == pytest.approx(-area if clockwise else area)
