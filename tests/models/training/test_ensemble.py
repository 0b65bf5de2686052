"""Ensembles: the members' estimates combined, as arrays and inside one exported ONNX graph."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from superbody.models.training.ensemble import combine
from tests.conftest import ROOT, WTF_SITE

DEG = math.pi / 180


def test_identical_members_give_the_member():
    pose = np.array([[1.0, -2.0, 170 * DEG], [0.5, 0.5, -90 * DEG]])
    std = np.array([[0.1, 0.2, 0.3], [0.05, 0.05, 0.5]])
    got, got_std = combine(np.stack([pose, pose, pose]), np.stack([std, std, std]))
    np.testing.assert_allclose(got, pose, atol=1e-12)
    np.testing.assert_allclose(got_std, std, atol=1e-12)


def test_positions_average_yaw_is_the_circular_mean_and_spread_widens_sigma():
    # Two members 20 deg apart across +-pi: the mean heading is pi, not 0.
    pose = np.array([[[0.0, 1.0, 170 * DEG]], [[0.2, 1.4, -170 * DEG]]])
    std = np.full((2, 1, 3), 0.1)
    got, got_std = combine(pose, std)
    assert got[0, :2] == pytest.approx([0.1, 1.2])
    assert abs(math.remainder(got[0, 2] - math.pi, 2 * math.pi)) < 1e-12
    # Mixture sigma: sqrt(0.1^2 + 0.1^2) in x; 0.2 m apart in y; in yaw the chord to the mean
    # heading, 2 sin(5 deg), about the 10 degrees (0.175 rad) each member is off.
    assert got_std[0, 0] == pytest.approx(math.hypot(0.1, 0.1))
    assert got_std[0, 1] == pytest.approx(math.hypot(0.1, 0.2))
    assert got_std[0, 2] == pytest.approx(math.hypot(0.1, 2 * math.sin(5 * DEG)))


def test_a_person_one_member_could_not_estimate_is_nan_and_bad_shapes_are_refused():
    pose = np.zeros((2, 2, 3))
    pose[1, 0, 0] = np.nan
    got, got_std = combine(pose, np.ones((2, 2, 3)))
    assert np.isnan(got[0]).all() and np.isnan(got_std[0]).all() and np.isfinite(got[1]).all()
    with pytest.raises(ValueError, match=r"shape \(K >= 1, B, 3\)"):
        combine(np.zeros((2, 3)), np.zeros((2, 3)))


torch = pytest.importorskip("torch")


def test_exported_ensemble_equals_combining_its_members_exported_alone(tmp_path):
    from superbody.edge.site import load_site
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.host.estimation.graph import GraphSpec, floor_centre
    from superbody.models.data.simdata import SimDataConfig, generate
    from superbody.models.nets import build_model
    from superbody.models.training.export import META_ENSEMBLE, export_onnx, load_onnx_model, read_metadata

    site = load_site(WTF_SITE)
    spec = GraphSpec.for_site(site, geometry=True)
    views = [s.views for s in generate(site, SimDataConfig(samples=96, seed=3), progress=False)]
    paths, members = [], []
    for k in range(3):
        torch.manual_seed(k)
        members.append(build_model("gat", spec, origin=tuple(floor_centre(site))).eval())
        paths.append(export_onnx(members[-1], spec, {}, tmp_path / f"m{k}.onnx"))
    ens = export_onnx(members, spec, {}, tmp_path / "ens.onnx")
    assert read_metadata(ens)[META_ENSEMBLE] == "3"
    alone = [OnnxEstimator(p, site).estimate_with_std(views) for p in paths]
    want, want_std = combine(np.stack([a[0] for a in alone]), np.stack([a[1] for a in alone]))
    got, got_std = OnnxEstimator(ens, site).estimate_with_std(views)
    assert np.abs(np.stack([a[0] for a in alone]) - want).max() > 0.01  # the members do differ
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-4)
    assert np.abs(np.remainder(got[:, 2] - want[:, 2] + math.pi, 2 * math.pi) - math.pi).max() < 1e-4
    np.testing.assert_allclose(got_std, want_std, rtol=1e-4, atol=1e-6)
    with pytest.raises(ValueError, match="an ensemble of 3 networks"):
        load_onnx_model(ens)


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "superbody.edge.cli", *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_ensemble_command_exports_fp32_and_int8_from_checkpoints(tmp_path):
    tiny = ["--site", str(WTF_SITE), "--arch", "gat", "--sim-samples", "300", "--epochs", "1", "--hparams",
            '{"hidden": 16, "heads": 2, "layers": 2}', "--out", str(tmp_path), "--no-int8", "--no-progress"]
    for k in (1, 2):
        r = _cli("train", *tiny, "--sim-seed", str(k), "--name", f"m{k}")
        assert r.returncode == 0, r.stderr[-2000:]
    r = _cli("ensemble", "--member", str(tmp_path / "m1.pt"), "--member", str(tmp_path / "m2.pt"), "--out", str(tmp_path), "--name", "ens")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "an ensemble of 2 gat networks" in r.stdout
    from superbody.edge.site import load_site
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.models.data.simdata import SimDataConfig, generate

    site = load_site(WTF_SITE)
    views = [s.views for s in generate(site, SimDataConfig(samples=64, seed=9), progress=False)]
    fp32, _ = OnnxEstimator(tmp_path / "ens.fp32.onnx", site).estimate_with_std(views)
    int8, _ = OnnxEstimator(tmp_path / "ens.int8.onnx", site).estimate_with_std(views)
    assert np.isfinite(fp32).all() and np.abs(int8[:, :2] - fp32[:, :2]).mean() < 0.1
    # One member, a missing file, a file that is not a checkpoint: one-line errors, exit 2.
    for args, message in (
        (["--member", str(tmp_path / "m1.pt")], "at least twice"),
        (["--member", str(tmp_path / "m1.pt"), "--member", str(tmp_path / "nope.pt")], "not a superbody train checkpoint"),
        (["--member", str(tmp_path / "m1.pt"), "--member", str(tmp_path / "ens.fp32.onnx")], "not a superbody train checkpoint"),
    ):
        r = _cli("ensemble", *args, "--out", str(tmp_path), timeout=120)
        assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, r.stderr[-1000:]


def test_calibrate_hybrid_combines_an_ensembles_cross_validations(dev_json, tmp_path):
    # Two members' held-out predictions (synthetic: the truth plus noise, on dev.json's samples):
    # calibrated as one ensemble, the network's figures are those of combine(); folds that differ
    # are refused.
    from superbody.edge.site import load_site
    from superbody.models.data.wtf import TRUTH_OFFSET_M, load_wtf, truth_to_torso

    samples = load_wtf(dev_json, site=load_site(WTF_SITE))
    truth = np.array([s.truth for s in samples])
    torso = truth_to_torso(truth, TRUTH_OFFSET_M)
    fold = np.arange(len(samples)) % 5 + 1
    rng = np.random.default_rng(0)
    paths = []
    for k in range(2):
        pred = torso + rng.normal(0, [0.1, 0.1, 0.2], torso.shape)
        paths.append(tmp_path / f"cv{k}.npz")
        np.savez(paths[-1], predictions=pred, std=np.full_like(pred, 0.1), analytic=torso, truth=truth, fold=fold,
                 views=np.array([len(s.views) for s in samples]), truth_offset_m=TRUTH_OFFSET_M, split="space")
    one = _cli("calibrate", "hybrid", "--cv", str(paths[0]), "--dataset", str(dev_json), "--json-out", str(tmp_path / "one.json"))
    both = _cli("calibrate", "hybrid", "--cv", str(paths[0]), "--cv", str(paths[1]), "--dataset", str(dev_json),
                "--json-out", str(tmp_path / "both.json"))
    assert one.returncode == 0 and both.returncode == 0, (one.stderr[-1000:], both.stderr[-1000:])
    import json

    mae = [json.loads((tmp_path / f"{n}.json").read_text())["reports"]["network (CV)"]["position_mae_mm"]["x"] for n in ("one", "both")]
    assert mae[1] < 0.85 * mae[0]  # two independent noises averaged: about 1/sqrt(2) of one
    with np.load(paths[1]) as z:
        np.savez(tmp_path / "other.npz", **{k: (z[k][::-1] if k == "fold" else z[k]) for k in z.files})
    r = _cli("calibrate", "hybrid", "--cv", str(paths[0]), "--cv", str(tmp_path / "other.npz"), "--dataset", str(dev_json))
    assert r.returncode == 2 and "same split" in r.stderr, r.stderr[-1000:]
