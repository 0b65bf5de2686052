"""The offline pipeline end to end, through the command line: simulate -> train -> export ->
quantise -> evaluate on the real dev.json; and a tiny blocked cross-validation."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import onnx
import pytest

from tests.conftest import DEV_JSON, ROOT, WTF_SITE


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "superbody.edge.cli", *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("models")
    r = _cli("train", "--site", str(WTF_SITE), "--arch", "gat", "--sim-samples", "800", "--epochs", "2", "--hparams",
             '{"hidden": 16, "heads": 2, "layers": 2}', "--out", str(out), "--name", "tiny", "--no-progress")
    assert r.returncode == 0, r.stderr[-2000:]
    return out


def test_train_writes_checkpoint_fp32_int8_and_report(tiny):
    for name in ("tiny.pt", "tiny.fp32.onnx", "tiny.int8.onnx", "tiny.train.json"):
        assert (tiny / name).stat().st_size > 0
    meta = {p.key: p.value for p in onnx.load(str(tiny / "tiny.int8.onnx")).metadata_props}
    config = json.loads(meta["train.config"])
    assert config["arch"] == "gat" and config["sim_samples"] == 800 and config["site"] == str(WTF_SITE)
    report = json.loads((tiny / "tiny.train.json").read_text())
    assert len(report["history"]) == 2


def test_eval_on_dev_json(tiny, dev_json, tmp_path):
    out = tmp_path / "eval.json"
    r = _cli("eval", "--dataset", str(dev_json), "--model", str(tiny / "tiny.int8.onnx"), "--json-out", str(out),
             "--predictions-out", str(tmp_path / "pred.csv"))
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert doc["samples"] == 225 and set(doc["by_cameras"]) == {"1", "2", "3"}
    assert doc["position_mae_mm"]["x"] > 0 and doc["baseline"]["samples"] == 225
    assert len((tmp_path / "pred.csv").read_text().splitlines()) == 226


@pytest.mark.parametrize("split", ["time", "space"])
def test_crossval_predicts_every_sample_from_a_model_that_never_saw_it(split, dev_json, tmp_path):
    out, npz = tmp_path / "cv.json", tmp_path / "cv.npz"
    r = _cli("crossval", "--site", str(WTF_SITE), "--real", str(dev_json), "--folds", "3", "--arch", "mlp", "--split", split,
             "--sim-samples", "300", "--epochs", "1", "--real-repeat", "2", "--real-subset-repeat", "1",
             "--json-out", str(out), "--predictions-out", str(npz))
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    held = [f["held_out"] for f in doc["folds"]]
    assert sum(held) == 225 and doc["split"] == split
    if split == "time":
        assert held == [75, 75, 75]
    else:  # floor regions: each fold also keeps its 0.3 m surroundings out of training
        assert all(f["excluded"] >= f["held_out"] for f in doc["folds"])
    assert doc["model"]["samples"] == 225 and doc["model"]["failed"] == 0
    assert doc["analytic"]["samples"] == 225
    z = np.load(npz)
    assert sorted(set(z["fold"].tolist())) == [1, 2, 3]
    assert np.isfinite(z["predictions"]).all() and (z["std"] > 0).all()


def test_calibrate_hybrid_writes_the_model_that_the_host_then_runs_as_hybrid(tiny, dev_json, tmp_path):
    npz = tmp_path / "cv.npz"
    r = _cli("crossval", "--site", str(WTF_SITE), "--real", str(dev_json), "--folds", "3", "--arch", "gat", "--split", "space",
             "--hparams", '{"hidden": 16, "heads": 2, "layers": 2}', "--sim-samples", "300", "--epochs", "1", "--real-repeat", "2",
             "--int8", "--temporal", "--predictions-out", str(npz), "--json-out", str(tmp_path / "cv.json"),
             "--models-out", str(tmp_path / "folds"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "model int8" in r.stdout  # each fold's model quantised as train ships it, scored on its held-out samples
    # --temporal: each fold's model, calibrated as a hybrid on the other folds, run live through the aggregator
    cv = json.loads((tmp_path / "cv.json").read_text())
    for name in ("hybrid", "model temporal", "hybrid temporal", "analytic temporal"):
        assert cv[name]["samples"] == 225 and cv[name]["failed"] == 0, (name, cv[name])
    # geometry has nothing fitted: through the host's filter its yaw on dev.json improves (13.8 -> 10.2 deg per eval --temporal)
    assert cv["analytic temporal"]["yaw_mae_deg"] < cv["analytic"]["yaw_mae_deg"] - 2, (cv["analytic temporal"], cv["analytic"])
    z = np.load(npz)
    for key in ("hybrid", "temporal_network", "temporal_hybrid", "temporal_analytic"):
        assert z[key].shape == (225, 3) and np.isfinite(z[key]).all(), key
    assert not np.allclose(z["temporal_hybrid"], z["hybrid"])  # what the host published, not the per-frame fusion
    # --models-out kept the fold models: benchmarks/live_cv.py replays them, and at the host's
    # defaults reproduces crossval's live figures exactly; another filter setting changes them.
    assert sorted(f.name for f in (tmp_path / "folds").iterdir()) == ["fold1.fp32.onnx", "fold2.fp32.onnx", "fold3.fp32.onnx"]
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "live_cv.py"), "--cv", str(npz), "--folds", str(tmp_path / "folds"),
                        "--dataset", str(dev_json), "--set", "filter.accel_std_mps2=0.5", "--json-out", str(tmp_path / "live.json")],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    live = json.loads((tmp_path / "live.json").read_text())
    assert live["settings"] == [{}, {"filter.accel_std_mps2": 0.5}]
    assert live["reports"]["live defaults"] == cv["hybrid temporal"]
    assert live["reports"]["live filter.accel_std_mps2=0.5"]["position_mae_mm"] != cv["hybrid temporal"]["position_mae_mm"]
    # the degraded-view cross-validation runs on those fold models: every sample plain, and once per degradation
    r = _cli("crossval-degraded", "--cv", str(npz), "--models", str(tmp_path / "folds"), "--dataset", str(dev_json),
             "--json-out", str(tmp_path / "degraded.json"))
    assert r.returncode == 0, r.stderr[-2000:]
    deg = json.loads((tmp_path / "degraded.json").read_text())
    assert deg["plain"]["all"]["samples"] == 225 and deg["plain"]["all"]["hybrid"]["failed"] == 0
    multi = int((z["views"] >= 2).sum())
    assert 3 * 225 <= deg["degraded"]["all"]["samples"] <= 3 * 225 + multi  # a cut may leave nothing of a one-view sample
    assert deg["degraded"]["kind drop_camera"]["samples"] == multi
    assert deg["degraded"]["one view"]["samples"] > deg["plain"]["one view"]["samples"]
    within = deg["degraded"]["all"]["hybrid_within_1_sigma"]
    assert all(0 < w < 1 for w in within) and "| one far view |" in r.stdout
    assert np.isfinite(z["predictions_int8"]).all() and (z["std_int8"] > 0).all()
    drift = z["predictions_int8"] - z["predictions"]
    drift[:, 2] = np.angle(np.exp(1j * drift[:, 2]))  # yaw wrapped
    assert 0 < np.abs(drift).max() < 0.5  # int8 drifts from fp32, a little
    model, model32 = tmp_path / "m.int8.onnx", tmp_path / "m.fp32.onnx"
    shutil.copy(tiny / "tiny.int8.onnx", model)
    shutil.copy(tiny / "tiny.fp32.onnx", model32)
    r = _cli("calibrate", "hybrid", "--cv", str(npz), "--dataset", str(dev_json), "--model", str(model32), "--model", str(model),
             "--json-out", str(tmp_path / "h.json"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "trust in the network" in r.stdout and "hybrid (CV)" in r.stdout
    doc = json.loads((tmp_path / "h.json").read_text())
    assert len(doc["std_scale"]) == 3 and sum(doc["sources"].values()) == 225
    assert "hybrid int8 (CV)" in doc["reports"] and set(doc["int8_vs_fp32_percent"]) == {"x MAE", "y MAE", "yaw MAE"}
    # each model carries the calibration fitted on its own kind's held-out predictions
    for path, fitted in ((model32, doc), (model, doc["int8"])):
        meta = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
        assert json.loads(meta["hybrid.calibration"]) == fitted["calibration"], path
        np.testing.assert_allclose(json.loads(meta["pose.std_scale"]), fitted["std_scale"], atol=1e-5)
    assert doc["int8"]["std_scale"] != doc["std_scale"]  # the int8 predictions' errors are their own
    r = _cli("eval", "--dataset", str(dev_json), "--model", str(model))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "m.int8.onnx (network)" in r.stdout  # the hybrid is scored beside its network alone
    r = _cli("calibrate", "hybrid", "--cv", str(tmp_path / "h.json"), "--dataset", str(dev_json))
    assert r.returncode == 2 and "not a crossval predictions file" in r.stderr


# (arguments, text the one-line error must contain)
def test_view_subsets_are_every_proper_subset_of_a_real_frame_with_its_truth(dev_json):
    from superbody.models.data.wtf import load_wtf
    from superbody.models.training.train import view_subsets

    samples = load_wtf(dev_json)
    by_count = {k: [s for s in samples if len(s.views) == k] for k in (1, 2, 3)}
    assert all(by_count.values())
    assert view_subsets(by_count[1]) == []  # nothing smaller than one view
    subs = view_subsets(by_count[3][:1])
    assert sorted(len(s.views) for s in subs) == [1, 1, 1, 2, 2, 2]
    assert len({tuple(sorted(s.views)) for s in subs}) == 6  # all distinct
    for s in subs:
        np.testing.assert_array_equal(s.truth, by_count[3][0].truth)
        assert all(s.views[c] is by_count[3][0].views[c] for c in s.views)
    assert len(view_subsets(samples)) == 6 * len(by_count[3]) + 2 * len(by_count[2])


BAD = [
    (["train", "--site", str(WTF_SITE), "--real-subset-repeat", "-1"], "real_subset_repeat must be an integer in [0, 1000]"),
    (["train", "--site", "nope.toml"], "cannot read site file"),
    (["train", "--site", str(WTF_SITE), "--arch", "transformer"], "invalid choice"),
    (["train", "--site", str(WTF_SITE), "--sim-samples", "0"], "nothing to train on"),
    (["train", "--site", str(WTF_SITE), "--random-sites", "3"], "random_sites needs variant 'rays'"),
    (["crossval", "--site", str(WTF_SITE)], "needs the real data"),
    (["crossval", "--site", str(WTF_SITE), "--real", str(DEV_JSON), "--models-out", "folds"], "--models-out needs --temporal"),
]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_arguments(args, message):
    r = _cli(*args, timeout=60)
    assert r.returncode == 2 and message in r.stderr, r.stderr[-1000:]


def test_random_search_picks_a_configuration_and_trains_it(tmp_path):
    r = _cli("train", "--site", str(WTF_SITE), "--arch", "mlp", "--search", "2", "--sim-samples", "300", "--epochs", "1",
             "--out", str(tmp_path), "--name", "searched", "--no-int8", "--no-progress")
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stderr.count("search 1/2") == 1 and "search: best" in r.stderr
    config = json.loads((tmp_path / "searched.train.json").read_text())["config"]
    assert set(config["hparams"]) == {"hidden", "slot_dim"}
    assert not (tmp_path / "searched.int8.onnx").exists()


def test_a_site_with_no_labelled_data_gets_a_hybrid_calibrated_on_simulation(tiny, tmp_path):
    """The no-ground-truth journey: train --calibrate-sim (here on the tiny model's site) writes a
    hybrid calibration fitted on simulated people of the site, and the host then runs the model
    as a hybrid. calibrate hybrid-sim does the same to an existing model."""
    from superbody.edge.site import load_site
    from superbody.host.estimation import build_estimator
    from superbody.host.estimation.hybrid import META_HYBRID, HybridEstimator

    model = tmp_path / "m.fp32.onnx"
    shutil.copy(tiny / "tiny.fp32.onnx", model)
    assert META_HYBRID not in {p.key for p in onnx.load(str(model)).metadata_props}
    r = _cli("calibrate", "hybrid-sim", "--site", str(WTF_SITE), "--model", str(model), "--samples", "600",
             "--json-out", str(tmp_path / "sim.json"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "hybrid calibrated on simulation of site wtf-apartment: 600 samples" in r.stdout
    doc = json.loads((tmp_path / "sim.json").read_text())[str(model)]
    for name in ("hybrid (held-out regions)", "network", "analytic"):
        assert doc["reports"][name]["samples"] == 600 and doc["reports"][name]["failed"] == 0
    meta = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    assert json.loads(meta[META_HYBRID])["source"].startswith("simulation of site wtf-apartment")
    est, name = build_estimator(load_site(WTF_SITE), "auto", model)
    assert isinstance(est, HybridEstimator) and name == "hybrid:m.fp32.onnx"
    # the same straight from training
    r = _cli("train", "--site", str(WTF_SITE), "--arch", "gat", "--sim-samples", "400", "--epochs", "1", "--hparams",
             '{"hidden": 16, "heads": 2, "layers": 2}', "--out", str(tmp_path), "--name", "fresh", "--no-progress", "--calibrate-sim")
    assert r.returncode == 0, r.stderr[-2000:]
    for kind in ("fp32", "int8"):
        meta = {p.key: p.value for p in onnx.load(str(tmp_path / f"fresh.{kind}.onnx")).metadata_props}
        assert META_HYBRID in meta, kind
    # every stage's time: what --max-minutes limits, and what comes after it
    assert "(--max-minutes 15 limits building the data and training)" in r.stdout
    for stage in ("building the training data:", "training: 1 epoch (--epochs):", "ONNX export and int8 quantisation:",
                  "hybrid calibration on simulation (--calibrate-sim):"):
        assert stage in r.stdout, stage
    r = _cli("calibrate", "hybrid-sim", "--site", str(WTF_SITE), "--model", str(model), "--samples", "10")
    assert r.returncode == 2 and "--samples" in r.stderr and "[500, 100000]" in r.stderr
