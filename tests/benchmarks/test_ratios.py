"""The speed benchmarks write, beside their absolute figures, ratios against a reference timed
in the same run on the same core (smoke tests at the smallest settings; the figures themselves
come from running the benchmarks): host_bench's step cost per observation over json.loads of
the same payloads (and, with --zenoh, end-to-end latency over Zenoh's own round trip),
model_bench's graphs/s over the single fast GAT's."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from tests.conftest import ROOT


def _run(module: str, *args: str, timeout: float) -> subprocess.CompletedProcess:
    # As make bench runs them: a module of the repository's benchmarks package, from its root.
    return subprocess.run([sys.executable, "-m", f"benchmarks.{module}", *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def _positive(v: object) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v) and v > 0


def test_host_bench_ratio_of_step_to_json_loads(tmp_path):
    out = tmp_path / "host.json"
    r = _run("host_bench", "--configs", "2x2,1x1", "--seconds", "1", "--json-out", str(out), timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert set(doc) == {"2x2", "1x1"}
    for row in doc.values():
        for key in ("step_us_per_obs", "json_loads_us_per_obs", "step_us_per_obs_over_json_loads"):
            assert _positive(row[key]), (key, row)
        assert row["step_us_per_obs_over_json_loads"] == pytest.approx(row["step_us_per_obs"] / row["json_loads_us_per_obs"])
    assert "step/json" in r.stdout


@pytest.mark.slow
def test_host_bench_ratio_of_e2e_to_zenoh_round_trip(tmp_path):
    out = tmp_path / "host.json"
    r = _run("host_bench", "--configs", "2x1", "--seconds", "4", "--zenoh", "--json-out", str(out), timeout=180)
    assert r.returncode == 0, r.stderr[-2000:]
    row = json.loads(out.read_text())["2x1"]  # one camera may publish no pose in 4 s
    for key in ("zenoh_rtt_p50_ms", "zenoh_rtt_p99_ms", "e2e_p50_over_zenoh_rtt", "e2e_p99_over_zenoh_rtt", "step_us_per_obs_over_json_loads"):
        assert _positive(row[key]), (key, row)
    assert row["zenoh_rtt_payload_bytes"] > 0 and row["zenoh_rtt_p50_ms"] <= row["zenoh_rtt_p99_ms"]
    assert "e2e p50/rtt" in r.stdout


def test_model_bench_ratio_to_the_single_fast_gat(tmp_path):
    pytest.importorskip("torch")  # the reference is built and exported with the train extra
    out = tmp_path / "model.json"
    r = _run("model_bench", "--seconds", "0.1", "--json-out", str(out), timeout=180)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert set(doc) == {"fp32", "int8", "fast_gat", "graphs_per_s_over_fast_gat"}
    for kind in ("fp32", "int8", "fast_gat"):
        assert set(doc[kind]) == {"1", "64"} and all(_positive(v) for v in doc[kind].values()), doc
    ratios = doc["graphs_per_s_over_fast_gat"]
    assert set(ratios) == {"fp32", "int8"}
    for kind, by_batch in ratios.items():
        assert set(by_batch) == {"1", "64"}
        for b, v in by_batch.items():
            assert _positive(v) and v == pytest.approx(doc[kind][b] / doc["fast_gat"][b])
    assert "x fast GAT" in r.stdout


def test_benchmarks_run_without_sys_path_edits():
    # The package is installed (editable): the benchmarks import superbody.*, and one another as
    # benchmarks.* when run as modules from the repository.
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        assert "sys.path.insert" not in path.read_text(), path.name
