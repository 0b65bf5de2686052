"""Calibrating uncertainties (models/hybrid_fit.py), spatial folds (models/evaluation/crossval.py) and the
uncertainty head's loss (models/nets.pose_nll)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from superbody.edge.site import load_site  # noqa: E402
from superbody.host.estimation.hybrid import fuse  # noqa: E402
from superbody.models.evaluation.crossval import spatial_folds  # noqa: E402
from superbody.models.hybrid_fit import (  # noqa: E402
    DEBIAS,
    NET_DEBIAS,
    TRUST_GRID,
    fit_analytic,
    fit_calibration,
    fit_net_bias,
    fit_std_scale,
    fit_trust,
    hybrid_poses,
    leave_one_fold_out,
    robust_sigma,
    scaled_std,
    sigma_coverage,
)
from superbody.models.nets import pose_nll  # noqa: E402
from tests.conftest import WTF_SITE  # noqa: E402


def _gaussian_case(n=4000, true_sigma=(0.1, 0.2, 0.3), claimed=(0.05, 0.4, 0.3), seed=0):
    rng = np.random.default_rng(seed)
    truth = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    pred = truth + rng.normal(0, 1, (n, 3)) * true_sigma
    return pred, np.tile(claimed, (n, 1)), truth


def test_robust_sigma_of_a_gaussian():
    e = np.random.default_rng(1).normal(0, 0.25, (20000, 3))
    np.testing.assert_allclose(robust_sigma(e), 0.25, rtol=0.03)


def test_std_scale_makes_claimed_sigmas_honest():
    pred, std, truth = _gaussian_case()
    scale = fit_std_scale(pred, std, truth)
    np.testing.assert_allclose(scale, [2.0, 0.5, 1.0], rtol=0.06)  # over-confident x, timid y, right yaw
    cov = sigma_coverage(pred, std * scale, truth)
    np.testing.assert_allclose(cov["within_1_sigma"], 0.683, atol=0.03)
    np.testing.assert_allclose(cov["within_2_sigma"], 0.954, atol=0.02)


def test_std_scale_needs_data():
    with pytest.raises(ValueError, match="at least 10"):
        fit_std_scale(np.zeros((3, 3)), np.ones((3, 3)), np.zeros((3, 3)))


def test_no_offset_of_one_recording_is_removed_by_default():
    """dev.json's geometry yaw offset and network y offset did not hold on the paper's test recording."""
    assert DEBIAS == NET_DEBIAS == (False, False, False)
    rng = np.random.default_rng(9)
    n = 600
    cams = rng.integers(1, 4, n)
    truth = np.zeros((n, 3))
    biased = truth + [0.0, 0.1, 0.07] + rng.normal(0, 0.02, (n, 3))
    _, cal = fit_calibration(biased, np.full((n, 3), 0.02), biased, np.ones(n, bool), truth, cams)
    assert np.array(cal.net_bias).tolist() == np.array(cal.analytic_bias).tolist() == [[0.0] * 3] * 3


def test_fit_analytic_by_camera_count_and_pair():
    rng = np.random.default_rng(2)
    n = 3000
    cams = rng.integers(1, 4, n)
    pair = rng.uniform(size=n) < 0.8
    sig = np.array([0.3, 0.15, 0.05])[cams - 1]
    truth = np.zeros((n, 3))
    pred = rng.normal(0, 1, (n, 3)) * sig[:, None]
    pred[~pair, 2] = rng.uniform(-np.pi, np.pi, (~pair).sum())  # no pair: yaw is a guess
    cal = fit_analytic(pred, pair, truth, cams)
    np.testing.assert_allclose([r[0] for r in cal.analytic_std], [0.3, 0.15, 0.05], rtol=0.12)
    np.testing.assert_allclose([r[2] for r in cal.analytic_std], [0.3, 0.15, 0.05], rtol=0.12)
    assert cal.analytic_yaw_std_no_pair > 1.5


def test_fit_analytic_measures_and_removes_the_yaw_bias_but_not_the_position_bias():
    rng = np.random.default_rng(3)
    n = 3000
    cams = rng.integers(1, 4, n)
    bias = np.array([[0.2, 0.0, 0.3], [0.2, 0.0, -0.1], [0.2, 0.0, 0.07]])  # x m, y m, yaw rad per count
    truth = np.column_stack([np.zeros((n, 2)), rng.uniform(-np.pi, np.pi, n)])
    pred = truth + bias[cams - 1] + rng.normal(0, 0.05, (n, 3))
    pred[:, 2] = np.angle(np.exp(1j * pred[:, 2]))
    cal = fit_analytic(pred, np.ones(n, bool), truth, cams, debias=(False, False, True))  # the mechanism, for a site that needs it
    b = np.array(cal.analytic_bias)
    np.testing.assert_allclose(b[:, 2], bias[:, 2], atol=0.01)
    np.testing.assert_array_equal(b[:, :2], 0.0)  # position: measured on one part of a floor, wrong on another
    np.testing.assert_allclose([r[2] for r in cal.analytic_std], 0.05, rtol=0.12)  # the sigma of what is left
    fused, _, _ = hybrid_poses(np.zeros((n, 3)), np.full((n, 3), np.inf), pred, np.ones(n, bool), cams, cal, load_site(WTF_SITE))
    err = np.abs(np.angle(np.exp(1j * (fused[:, 2] - truth[:, 2]))))
    assert np.median(err) < 0.05  # the geometry's yaw, less its bias
    plain = fit_analytic(pred, np.ones(n, bool), truth, cams, debias=(False, False, False))
    assert np.array(plain.analytic_bias).tolist() == [[0.0] * 3] * 3 and plain.analytic_std[0][2] > 0.25


def test_the_networks_y_bias_is_measured_per_camera_count_and_removed_before_the_trust_is_fitted():
    """Three cameras: an otherwise accurate network whose y errs by +0.1 m, against a geometry of
    0.05 m. Where its bias is measured (the mechanism; ``NET_DEBIAS`` turns it on for no axis
    since dev.json's offset did not carry over), the network less it earns the y trust that the
    biased one could not."""
    rng = np.random.default_rng(6)
    n = 1500
    cams = rng.integers(1, 4, n)
    truth = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    offset = np.array([[0.05, 0.0, 0.0], [0.0, -0.03, 0.0], [0.2, 0.1, 0.1]])  # x m, y m, yaw rad per count
    net = truth + offset[cams - 1] + rng.normal(0, 0.02, (n, 3))
    geo = truth + rng.normal(0, 0.05, (n, 3))
    y_only = (False, True, False)
    np.testing.assert_allclose(fit_net_bias(net, truth, cams, y_only), [[0, 0, 0], [0, -0.03, 0], [0, 0.1, 0]], atol=0.005)
    pair = np.ones(n, bool)
    _, cal = fit_calibration(net, np.full((n, 3), 0.02), geo, pair, truth, cams, net_debias=y_only)
    np.testing.assert_allclose(np.array(cal.net_bias)[:, 1], [0.0, -0.03, 0.1], atol=0.005)
    assert cal.net_trust[2][1] >= 1  # y: the debiased network is trusted
    scale, _ = fit_calibration(net, np.full((n, 3), 0.02), geo, pair, truth, cams, net_debias=y_only)
    fused, _, _ = hybrid_poses(net, scaled_std(np.full((n, 3), 0.02), scale, cams), geo, pair, cams, cal, load_site(WTF_SITE))
    three = cams == 3
    err = lambda p, axis: np.abs(p[three, axis] - truth[three, axis]).mean()  # noqa: E731
    assert err(fused, 1) < 0.03 < err(geo, 1) and err(fused, 1) < err(net, 1)
    assert err(fused, 0) <= 1.05 * err(geo, 0)  # x keeps its bias, and goes to geometry


def test_trust_is_earned_per_camera_count_and_per_axis():
    """One camera: the network is good, the geometry poor -> high trust. Three cameras: the
    network's x is biased by 0.3 m, its y and yaw good -> x trust 0, y and yaw trust high."""
    rng = np.random.default_rng(4)
    n = 2000
    cams = np.repeat([1, 3], n // 2)
    truth = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    geo = truth + rng.normal(0, 1, (n, 3)) * np.where(cams[:, None] == 1, [0.4, 0.4, 0.6], [0.05, 0.05, 0.5])
    net = truth + rng.normal(0, 0.05, (n, 3)) + np.where(cams[:, None] == 3, [0.3, 0.0, 0.0], 0.0)
    net_std = np.full((n, 3), 0.05)
    cal = fit_trust(net, net_std, geo, np.ones(n, bool), truth, cams, fit_analytic(geo, np.ones(n, bool), truth, cams))
    (p1, q1, y1), (_, _, _), (p3, q3, y3) = cal.net_trust
    assert min(p1, q1, y1) >= 0.5
    assert p3 == 0.0 and q3 >= 0.5 and y3 >= 0.5  # each axis on its own: the biased x goes to geometry, y and yaw do not
    assert cal.net_trust[1] == (1.0, 1.0, 1.0) and set(cal.net_trust[0]) <= set(TRUST_GRID)  # no 2-camera samples: the default


def test_trust_needs_a_gain_beyond_the_noise_on_every_axis():
    """Two cameras, 60 samples; the network's errors are geometry's own (yaw: 95% of it) plus a
    little noise of their own, so fusing wins by chance or by a little. On these samples the
    lowest error of every axis is at some trust above 0, yet every axis stays geometry's
    (trust 0; yaw too since geometry's yaw has no offset of the data removed). Three cameras,
    where the network is five times surer and independent: every axis trusts it."""
    rng = np.random.default_rng(0)
    n = 60
    cams = np.repeat([2, 3], n)
    truth = np.column_stack([rng.uniform(-1, 1, (2 * n, 2)), rng.uniform(-3, 3, 2 * n)])
    geo_err = rng.normal(0, 1, (2 * n, 3)) * [0.08, 0.08, 0.1]
    geo = truth + geo_err
    net_err = np.where(cams[:, None] == 2, geo_err * [1, 1, 0.95] + rng.normal(0, 0.02, (2 * n, 3)),
                       rng.normal(0, 1, (2 * n, 3)) * [0.016, 0.016, 0.02])
    net = truth + net_err
    net_std = np.tile([0.08, 0.08, 0.1], (2 * n, 1))
    pair = np.ones(2 * n, bool)
    geo_cal = fit_analytic(geo, pair, truth, cams, debias=(False, False, False))
    cal = fit_trust(net, net_std, geo, pair, truth, cams, geo_cal)
    two = cams == 2
    g = geo_cal.analytic_sigmas(cams[two], pair[two])
    def mae_of(t: float) -> np.ndarray:
        d = fuse(net[two], net_std[two], geo[two], g, t)[0] - truth[two]
        d[:, 2] = np.angle(np.exp(1j * d[:, 2]))  # yaw error wrapped
        return np.abs(d).mean(0)

    mae = np.array([mae_of(t) for t in TRUST_GRID])  # (T, 3)
    assert (np.argmin(mae, axis=0) > 0).all()  # the plain minimum would trust the network on every axis
    assert cal.net_trust[1] == (0.0, 0.0, 0.0)
    assert min(cal.net_trust[2]) >= 1.0


def test_a_camera_count_without_samples_gets_the_largest_fitted_sigma():
    """Only two- and three-camera samples: the one-camera row is never surer than the data showed."""
    rng = np.random.default_rng(6)
    n = 4000
    cams = np.repeat([2, 3], n // 2)
    truth = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    geo = truth + rng.normal(0, 1, (n, 3)) * np.where(cams[:, None] == 2, [0.08, 0.05, 0.2], [0.02, 0.06, 0.1])
    cal = fit_analytic(geo, np.ones(n, bool), truth, cams, debias=(False, False, False))
    one, two, three = np.array(cal.analytic_std)
    np.testing.assert_allclose(two, [0.08, 0.05, 0.2], rtol=0.1)
    np.testing.assert_allclose(three, [0.02, 0.06, 0.1], rtol=0.1)
    np.testing.assert_array_equal(one, np.maximum(two, three))


def test_on_simulation_the_network_must_win_alone_to_be_trusted():
    """Three cameras: network and geometry of equal quality with independent errors, so fusing
    wins by far beyond the noise and the plain fit trusts the network. Fitted on simulation
    (``must_win_alone``) that axis goes to geometry; one camera, where the network alone is
    better, keeps its trust."""
    rng = np.random.default_rng(5)
    n = 2000
    cams = np.repeat([1, 3], n // 2)
    truth = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    geo = truth + rng.normal(0, 1, (n, 3)) * np.where(cams[:, None] == 1, [0.4, 0.4, 0.6], [0.05, 0.05, 0.1])
    net = truth + rng.normal(0, 1, (n, 3)) * np.where(cams[:, None] == 1, [0.1, 0.1, 0.1], [0.055, 0.055, 0.11])
    net_std = np.where(cams[:, None] == 1, [0.1, 0.1, 0.1], [0.055, 0.055, 0.11])
    pair = np.ones(n, bool)
    geo_cal = fit_analytic(geo, pair, truth, cams, debias=(False, False, False))
    plain = fit_trust(net, net_std, geo, pair, truth, cams, geo_cal)
    sim = fit_trust(net, net_std, geo, pair, truth, cams, geo_cal, must_win_alone=True)
    assert min(plain.net_trust[2]) > 0  # averaging two equal estimates pays on these samples
    assert sim.net_trust[2] == (0.0, 0.0, 0.0)
    assert sim.net_trust[0] == plain.net_trust[0] and min(sim.net_trust[0]) > 0


def test_hybrid_beats_both_when_errors_are_independent():
    """Two unbiased estimates with independent errors: the fused one is better than either."""
    site = load_site(WTF_SITE)
    rng = np.random.default_rng(3)
    n = 3000
    truth = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-2, 0.5, n), rng.uniform(-3, 3, n)])
    cams = rng.integers(1, 4, n)
    pair = np.ones(n, bool)
    net_sig, geo_sig = 0.1, np.array([0.2, 0.1, 0.05])[cams - 1]
    net = truth + rng.normal(0, net_sig, (n, 3))
    geo = truth + rng.normal(0, 1, (n, 3)) * geo_sig[:, None]
    fold = np.arange(n) % 5
    pose, std, source = leave_one_fold_out(net, np.full((n, 3), net_sig), geo, pair, truth, cams, fold, site)
    assert (source == "hybrid").mean() > 0.95
    err = lambda p: np.abs(p[:, 0] - truth[:, 0])  # noqa: E731
    for k in (1, 2, 3):
        m = cams == k
        assert err(pose)[m].mean() <= min(err(net)[m].mean(), err(geo)[m].mean()) * 1.02


def test_a_calibration_fitted_on_worse_predictions_distrusts_them():
    """The reason ``calibrate hybrid`` fits an int8 model its own calibration: fused with the
    calibration fitted on good predictions, worse ones (the same claimed sigma) drag the hybrid
    off; fitted on themselves, they are trusted less and the hybrid stays nearer geometry."""
    site = load_site(WTF_SITE)
    rng = np.random.default_rng(5)
    n = 600
    truth = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-2, 0.5, n), rng.uniform(-3, 3, n)])
    cams, pair = rng.integers(1, 4, n), np.ones(n, bool)
    net, geo = truth + rng.normal(0, 0.1, (n, 3)), truth + rng.normal(0, 0.15, (n, 3))
    std = np.full((n, 3), 0.1)
    other = net + rng.normal(0, 0.3, (n, 3))  # far worse predictions, the same claimed sigma
    scale, cal = fit_calibration(net, std, geo, pair, truth, cams)
    scale_o, cal_o = fit_calibration(other, std, geo, pair, truth, cams)
    lent = hybrid_poses(other, scaled_std(std, scale, cams), geo, pair, cams, cal, site)[0]
    own = hybrid_poses(other, scaled_std(std, scale_o, cams), geo, pair, cams, cal_o, site)[0]
    err = lambda p: np.abs(p[:, 0] - truth[:, 0]).mean()  # noqa: E731
    assert err(lent) > err(own) * 1.1
    assert np.all(scale_o[:, 0] > scale[:, 0] * 2)  # its sigmas scaled up to its real errors


def test_hybrid_falls_back_to_geometry_off_the_floor():
    site = load_site(WTF_SITE)
    net = np.array([[9.0, 9.0, 0.0], [0.0, 0.0, 0.0]])  # the network's first answer is far off the floor
    geo = np.array([[0.1, 0.1, 0.1], [np.nan, np.nan, 0.0]])  # the geometry found nothing for the second
    cal = fit_analytic(np.zeros((30, 3)) + 0.01, np.ones(30, bool), np.zeros((30, 3)), np.full(30, 2))
    pose, std, source = hybrid_poses(net, np.full((2, 3), 0.1), geo, np.array([True, False]), np.array([2, 1]), cal, site)
    assert source.tolist() == ["analytic", "onnx"]
    np.testing.assert_allclose(pose, [[0.1, 0.1, 0.1], [0.0, 0.0, 0.0]])  # the geometry's pose as it is (no bias removed)


def test_spatial_folds_are_regions_with_a_buffer():
    rng = np.random.default_rng(4)
    xy = np.concatenate([rng.normal(c, 0.2, (50, 2)) for c in ([0, 0], [3, 0], [0, 3])])
    folds = spatial_folds(xy, 3, buffer_m=0.3, seed=0)
    held = [set(h.tolist()) for h, _ in folds]
    assert sorted(len(h) for h in held) == [50, 50, 50]  # the three blobs
    assert set().union(*held) == set(range(150))
    for h, ex in folds:
        assert set(h.tolist()) <= set(ex.tolist())  # the region is excluded from training
        d = np.sqrt(((xy[ex][:, None] - xy[h][None]) ** 2).sum(-1)).min(1)
        assert d.max() <= 0.3 + 1e-9


@pytest.mark.parametrize("folds", [1, 151])
def test_spatial_folds_bad_count(folds):
    with pytest.raises(ValueError, match="folds must be in"):
        spatial_folds(np.zeros((150, 2)), folds)


def test_pose_nll_is_lowest_at_the_true_sigma_and_never_moves_the_pose():
    y = torch.tensor([[0.0, 0.0, 0.0, 1.0]])
    d = 0.2
    def nll(log_s: float, yaw_err: float = 0.0) -> tuple[float, torch.Tensor]:
        out = torch.tensor([[d, -d, math.sin(yaw_err), math.cos(yaw_err), log_s, log_s, log_s]], requires_grad=True)
        loss = pose_nll(out, y).sum()
        loss.backward()
        return float(loss.detach()), out.grad
    values = {s: nll(math.log(s))[0] for s in (0.05, 0.1, 0.2, 0.4, 0.8)}
    # the position part is minimal at sigma = |error|: compare around it
    assert values[0.2] < values[0.1] and values[0.2] < values[0.4]
    _, grad = nll(math.log(0.2), 0.5)
    assert torch.all(grad[0, :4] == 0)  # the means are detached
