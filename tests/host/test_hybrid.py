"""The hybrid estimator: inverse-variance fusion and the support gate (host/hybrid.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from superbody.edge.site import load_site
from superbody.host.hybrid import HybridCalibration, _near_floor, fuse
from tests.conftest import WTF_SITE

CAL = HybridCalibration(analytic_std=((0.2, 0.2, 0.5), (0.1, 0.1, 0.3), (0.05, 0.05, 0.1)), analytic_yaw_std_no_pair=2.0)


@pytest.mark.parametrize("net, net_std, geo, geo_std, expected", [
    # equal sigmas: the midpoint
    ((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (1.0, 2.0, 0.2), (0.1, 0.1, 0.1), (0.5, 1.0, 0.1)),
    # geometry 3x surer (9x the weight): x = (0 * 1 + 1 * 9) / 10
    ((0.0, 0.0, 0.0), (0.3, 0.3, 0.3), (1.0, 1.0, 0.0), (0.1, 0.1, 0.1), (0.9, 0.9, 0.0)),
    # yaw across the +-pi seam: the mean of 179 and -179 degrees is 180, not 0
    ((0.0, 0.0, math.radians(179)), (1, 1, 0.1), (0.0, 0.0, math.radians(-179)), (1, 1, 0.1), (0.0, 0.0, math.pi)),
    # a hopeless geometric yaw barely moves the network's
    ((0.0, 0.0, 1.0), (0.1, 0.1, 0.1), (0.0, 0.0, -2.0), (0.1, 0.1, 100.0), (0.0, 0.0, 1.0)),
])
def test_fuse(net, net_std, geo, geo_std, expected):
    pose, std = fuse(*(np.array([v], float) for v in (net, net_std, geo, geo_std)))
    np.testing.assert_allclose(pose[0], expected, atol=2e-3)
    assert np.all(std[0] <= np.minimum(net_std, geo_std) + 1e-12)  # fusing never makes it less sure


def test_fuse_empty():
    pose, std = fuse(np.zeros((0, 3)), np.ones((0, 3)), np.zeros((0, 3)), np.ones((0, 3)))
    assert pose.shape == std.shape == (0, 3)


def test_analytic_sigmas_by_camera_count_and_pair():
    s = CAL.analytic_sigmas(np.array([1, 2, 3, 5, 1]), np.array([True, True, True, True, False]))
    np.testing.assert_allclose(s[:, 0], [0.2, 0.1, 0.05, 0.05, 0.2])  # 5 cameras count as 3+
    np.testing.assert_allclose(s[:, 2], [0.5, 0.3, 0.1, 0.1, 2.0])  # no shoulder/hip pair: the wide yaw sigma


@pytest.mark.parametrize("bad", [
    dict(analytic_std=((0.1, 0.1, 0.1),)),                                     # one row, not three
    dict(analytic_std=((0.1, 0.1, 0.1), (0.1, -0.1, 0.1), (0.1, 0.1, 0.1))),   # a negative sigma
    dict(analytic_std=CAL.analytic_std, floor_margin_m=-1.0),                  # negative margin
])
def test_calibration_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        HybridCalibration(**bad)


def test_calibration_json_round_trip():
    assert HybridCalibration.from_json(CAL.to_json()) == CAL


def test_support_gate_knows_the_floor():
    site = load_site(WTF_SITE)
    pts = np.array([[0.0, 0.0], [10.0, 10.0], [site.floor_bounds[2] + 0.3, 0.0]])
    # inside; far away; just beyond the floor's edge (within the 0.5 m margin)
    assert _near_floor(pts, site, 0.5).tolist() == [True, False, True]
    assert _near_floor(pts, site, 0.0).tolist() == [True, False, False]
