"""The analytic estimator: triangulation and geometry-only torso pose."""

import math

import numpy as np
import pytest

from superbody.edge.angles import wrap_angle
from superbody.edge.simulator import NoiseModel, PersonState, World, render_views, skeleton
from superbody.edge.site import load_site
from superbody.host.analytic import AnalyticEstimator, joints_3d, triangulate
from superbody.models.wtf import load_wtf
from tests.conftest import WTF_SITE


def test_triangulate_exact_rays():
    p = np.array([0.3, -1.2, 1.4])
    origins = np.array([[0.0, 0.0, 2.5], [3.0, 0.0, 2.0], [0.0, -4.0, 2.2]])
    d = p - origins
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(triangulate(origins, d), p, atol=1e-12)


CLEAN = NoiseModel(pixel_noise_px=0.0, joint_rate=(1.0,) * 17, view_quality_std=0.0, view_miss_prob=0.0,
                   truncated_miss_prob=0.0, swap_prob=0.0, spurious_prob=0.0, facing_visibility=None,
                   occluded_keep=1.0)


# (x, y, yaw, cameras used): noiseless views give the pose back
CASES = [
    (-0.5, -1.0, 0.3, ("1", "2", "3")),  # all three cameras triangulate
    (0.2, -1.5, -2.0, ("1", "3")),  # two cameras
    (-0.3, -0.8, 2.8, ("2",)),  # one camera: typical heights
]


@pytest.mark.parametrize("x,y,yaw,cams", CASES)
def test_noiseless_views_give_the_pose(x, y, yaw, cams):
    site = load_site(WTF_SITE)
    world = World(site, 1, seed=0)
    state = PersonState(x, y, yaw, skeleton(x, y, yaw, 0.0, 0.0))
    views = {}
    for c in cams:
        v = render_views([state], [world.people[0].appearance], site.camera(c), np.random.default_rng(0), CLEAN, site, histograms=False)
        if v:
            views[c] = v[0][1]
    assert set(views) == set(cams)
    est = AnalyticEstimator(site).estimate([views])[0]
    tol = 0.02 if len(cams) > 1 else 0.12
    assert math.hypot(est[0] - x, est[1] - y) < tol
    assert abs(wrap_angle(est[2] - yaw)) < math.radians(3 if len(cams) > 1 else 12)


def test_empty_and_jointless_inputs():
    site = load_site(WTF_SITE)
    assert AnalyticEstimator(site).estimate([]).shape == (0, 3)
    assert np.isnan(joints_3d({}, site)).all()


def test_dev_json_baseline(dev_json):
    """The baseline on real data stays where the dataset README's crude reference puts it."""
    site = load_site(WTF_SITE)
    samples = load_wtf(dev_json)
    est = AnalyticEstimator(site).estimate([s.views for s in samples])
    truth = np.array([s.truth for s in samples])
    mae = np.abs(est[:, :2] - truth[:, :2]).mean(0)
    yaw = np.degrees(np.abs(wrap_angle(est[:, 2] - truth[:, 2]))).mean()
    assert mae[0] < 0.16 and mae[1] < 0.18 and yaw < 16
