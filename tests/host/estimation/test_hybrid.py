"""The hybrid estimator: inverse-variance fusion and the support gate (host/estimation/hybrid.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from superbody.edge.site import load_site
from superbody.host.estimation.hybrid import HybridCalibration, _near_floor, combine, fuse
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


def test_trust_moves_the_weights_not_the_claimed_accuracy():
    net, geo = np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 1.0, 0.5]])
    s = np.full((1, 3), 0.1)
    pose, std = fuse(net, s, geo, s, trust=np.array([[10.0, 0.0, 1.0]]))
    np.testing.assert_allclose(pose[0, :2], [1 / 11, 1.0])  # x: weights 10 : 1; y: geometry alone
    # x: sd of (10 a + b) / 11 for independent a, b of sd 0.1 = 0.1 sqrt(101) / 11, above 1 / sqrt(1100)
    np.testing.assert_allclose(std[0], [0.1 * math.sqrt(101) / 11, 0.1, 0.1 / math.sqrt(2)])
    pose, std = fuse(net, s, geo, s * 2, trust=0.0)  # no trust: the geometry, as sure as it is
    np.testing.assert_allclose(pose, geo)
    np.testing.assert_allclose(std, s * 2)


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
    dict(analytic_std=CAL.analytic_std, analytic_bias=((0, 0, 0),) * 2),         # two bias rows
    dict(analytic_std=CAL.analytic_std, analytic_bias=((0, 0, 20), (0, 0, 0), (0, 0, 0))),  # 20 rad
    dict(analytic_std=CAL.analytic_std, net_bias=((0, 0, 0),) * 4),              # four network bias rows
    dict(analytic_std=CAL.analytic_std, net_bias=((0, 11, 0), (0, 0, 0), (0, 0, 0))),  # 11 m
])
def test_calibration_rejects_bad_values(bad):
    with pytest.raises(ValueError, match="net_bias must be" if "net_bias" in bad else None):
        HybridCalibration(**bad)


def test_calibration_json_round_trip():
    assert HybridCalibration.from_json(CAL.to_json()) == CAL
    biased = HybridCalibration(analytic_std=CAL.analytic_std, analytic_bias=((0.1, 0, 0.05), (0, 0, 0.07), (0, -0.02, 3.1)))
    assert HybridCalibration.from_json(biased.to_json()) == biased
    net = HybridCalibration(analytic_std=CAL.analytic_std, net_bias=((0, 0.01, 0), (0, 0.03, 0), (0, 0.1, 0)))
    assert HybridCalibration.from_json(net.to_json()) == net
    # A calibration written before the network's bias existed reads as no bias.
    old = json.loads(CAL.to_json())
    del old["net_bias"]
    assert HybridCalibration.from_json(json.dumps(old)).net_bias == ((0.0, 0.0, 0.0),) * 3


def test_the_network_pose_less_its_bias_is_what_is_fused():
    """Three cameras: the network's y less its 0.1 m bias; one camera: no bias. The support gate and
    the "onnx" fallback (no geometry) see the debiased pose too."""
    cal = HybridCalibration(analytic_std=CAL.analytic_std, net_bias=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)))
    net = np.array([[0.5, 0.6, 0.2]] * 3)
    net_std = np.full((3, 3), 1e-6)  # the network alone decides where geometry exists
    geo = np.array([[0.5, 0.5, 0.2], [0.5, 0.5, 0.2], [np.nan, np.nan, np.nan]])
    pose, _, source = combine(net, net_std, geo, np.ones(3, bool), np.array([1, 3, 3]), cal, load_site(WTF_SITE))
    np.testing.assert_allclose(pose[:, :2], [[0.5, 0.6], [0.5, 0.5], [0.5, 0.5]], atol=1e-6)
    assert list(source) == ["hybrid", "hybrid", "onnx"]
    np.testing.assert_array_equal(net[1], [0.5, 0.6, 0.2])  # the input is not modified


def test_debias_subtracts_the_bias_of_each_camera_count_and_wraps_yaw():
    cal = HybridCalibration(analytic_std=CAL.analytic_std, analytic_bias=((0.1, 0.0, 0.1), (0.0, 0.0, 0.0), (0.0, 0.2, -0.2)))
    geo = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.5], [1.0, 1.0, math.pi - 0.1], [np.nan, np.nan, np.nan]])
    out = cal.debias(geo, np.array([1, 2, 4, 1]))
    np.testing.assert_allclose(out[:3], [[0.9, 1.0, -0.1], [1.0, 1.0, 0.5], [1.0, 0.8, -math.pi + 0.1]], atol=1e-12)
    assert np.isnan(out[3]).all()  # no geometry stays no geometry
    np.testing.assert_array_equal(geo[1], [1.0, 1.0, 0.5])  # the input is not modified


def test_support_gate_knows_the_floor():
    site = load_site(WTF_SITE)
    west = min(site.floor, key=lambda v: v[0])  # the floor's westmost corner
    pts = np.array([[0.0, 0.0], [10.0, 10.0], [west[0] - 0.3, west[1]]])
    # inside; far away; just beyond the floor's edge (within the 0.5 m margin)
    assert _near_floor(pts, site, 0.5).tolist() == [True, False, True]
    assert _near_floor(pts, site, 0.0).tolist() == [True, False, False]


def test_a_model_without_calibration_is_told_the_command_that_exists():
    # The error once named `superbody calibrate-hybrid`, which is no command.
    import shlex

    from superbody.edge.cli import build_parser
    from superbody.edge.resources import model_path
    from superbody.host.estimation.estimator import ModelMismatchError, OnnxEstimator
    from superbody.host.estimation.hybrid import META_HYBRID, HybridEstimator

    site = load_site(WTF_SITE)
    net = OnnxEstimator(model_path("wtf-apartment.fp32.onnx"), site)
    del net.metadata[META_HYBRID]
    with pytest.raises(ModelMismatchError, match="run superbody calibrate hybrid") as e:
        HybridEstimator(net, site)
    command = shlex.split(str(e.value).split("run superbody ", 1)[1].split(" on it")[0])
    with pytest.raises(SystemExit) as done:
        build_parser().parse_args([*command, "--help"])
    assert done.value.code == 0
