"""benchmarks/filter_tuning.py runs, and each value it lists reaches the host's filter (a smoke
test on one short recording; the figures come from running the benchmark)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from tests.conftest import ROOT

SCRIPT = str(ROOT / "benchmarks" / "filter_tuning.py")


def test_filter_tuning_writes_one_row_per_value(tmp_path):
    out = tmp_path / "tuning.json"
    r = subprocess.run([sys.executable, SCRIPT, "--analytic", "--recordings", "1", "--duration", "4", "--accel", "0.5,3,20",
                        "--json-out", str(out)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert doc["accel_std_mps2"] == [0.5, 3.0, 20.0] and doc["recordings"] == 1 and doc["estimator"] == "analytic"
    table = np.array([doc[k] for k in ("x_mm", "y_mm", "yaw_deg", "jitter_mm")])  # (4, 3)
    assert np.isfinite(table).all() and (table > 0).all()
    # The values reach the filter: a stiffer model (0.5) smooths more than a loose one (20).
    assert doc["jitter_mm"][0] < doc["jitter_mm"][2]
    assert "<- default" in r.stdout and "1/1 replayed" in r.stderr


def test_filter_tuning_refuses_bad_arguments(tmp_path):
    for args, message in ((["--accel", "1,0"], "accel_std_mps2 must be in (0.0, 100.0]"),
                          (["--model", str(tmp_path / "nope.onnx")], "nope.onnx: no such file"),
                          (["--recordings", "0"], "--recordings must be in [1, 100]")):
        r = subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and "Traceback" not in r.stderr and message in r.stderr, r.stderr[-1000:]
