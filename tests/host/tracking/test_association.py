"""Duplicate skeletons within one frame (host/tracking/association.py)."""

from __future__ import annotations

import numpy as np

from superbody.edge.sim import skeleton
from superbody.edge.site import load_site
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.measure import duplicate_views
from tests.conftest import WTF_SITE

SPREAD, SHARED = TrackerConfig().duplicate_spread, TrackerConfig().duplicate_min_joints


def _people_in_one_view(offsets: list[float]) -> np.ndarray:
    """(K, 17, 2) skeletons of people standing 3 m in front of the site's camera 1, each moved
    sideways by its offset (metres), facing the camera, as that camera sees them."""
    from superbody.edge.camera import project

    cam = load_site(WTF_SITE).camera("1")
    fwd = cam.R[:, 2][:2] / np.linalg.norm(cam.R[:, 2][:2])  # the optical axis on the floor
    side = np.array([-fwd[1], fwd[0]])
    yaw = float(np.arctan2(-fwd[1], -fwd[0]))
    out = []
    for s in offsets:
        x, y = np.asarray(cam.t[:2]) + 3.0 * fwd + s * side
        uv, _ = project(np.asarray(skeleton(x, y, yaw, 0.0, 0.0), dtype=np.float64), cam)
        out.append(np.asarray(uv, dtype=np.float64)[:, :2])
    return np.array(out)


def test_copies_a_few_pixels_apart_are_one_detection():
    base = _people_in_one_view([0.0])[0]
    copies = np.array([base + [6.0 * k, 0.0] for k in range(64)])  # the flood: 64 copies, 6 px apart
    dup = duplicate_views(copies, np.full(64, 17), SPREAD, SHARED)
    assert dup.sum() == 63 and not dup[0]  # a chain of copies is one detection, however long
    assert not duplicate_views(copies, np.full(64, 17), 0.0, SHARED).any()  # spread 0: only exact copies are one
    assert duplicate_views(copies[[0, 0, 1]], np.full(3, 17), 0.0, SHARED).tolist() == [False, True, False]


def test_people_standing_side_by_side_are_all_kept():
    xs = [-0.7, -0.25, 0.2, 0.65]  # four people 45 cm apart (shoulder to shoulder), one camera
    kp = _people_in_one_view(xs)
    assert not duplicate_views(kp, np.full(len(xs), 17), SPREAD, SHARED).any()


def test_the_skeleton_with_more_joints_is_kept_and_few_shared_joints_prove_nothing():
    kp = _people_in_one_view([0.0, 0.0])
    kp[0, :8] = np.nan  # the first is a partial view of the same person
    dup = duplicate_views(kp, np.array([9, 17]), SPREAD, SHARED)
    assert list(dup) == [True, False]
    assert not duplicate_views(kp, np.array([9, 17]), SPREAD, 10).any()  # they share 9 joints: not enough for 10
    kp[1, 4:] = np.nan  # now they share only 0 joints: not enough to call them one
    assert not duplicate_views(kp, np.array([9, 4]), SPREAD, SHARED).any()


def test_colours_point_to_a_track_only_when_clearly_nearer_than_every_other():
    from superbody.host.tracking.association import clearly_best

    d = np.array([
        [0.10, 0.50, 0.60],  # clearly the first
        [0.10, 0.15, 0.60],  # the first two alike: neither
        [0.20, 0.20, 0.20],  # identical clothing: nobody
        [np.nan, np.nan, np.nan],  # no colour: nobody
        [np.nan, 0.30, 0.45],  # the second, by 0.15
    ])
    assert clearly_best(d, 0.1).tolist() == [
        [True, False, False], [False, False, False], [False, False, False], [False, False, False], [False, True, False]]
    assert clearly_best(d[:, :1], 0.1).ravel().tolist() == [True, True, True, False, False]  # a lone track
    assert clearly_best(np.zeros((0, 2)), 0.1).shape == (0, 2)
