"""The floor the cameras see (edge/floor.py)."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.floor import (
    MIN_PERSON_PX,
    detectable_range_m,
    in_front,
    point_in_polygon,
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
