"""benchmarks/codec_bench.py runs and writes the figures issue 9 asks for (a smoke test: one
round of two calls; the speed itself is measured by running the benchmark)."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT


def test_codec_bench_writes_medians(tmp_path):
    out = tmp_path / "codec.json"
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "codec_bench.py"), "--rounds", "1", "--calls", "2",
                        "--json-out", str(out)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"observation_10", "pose_array_10"}
    assert set(doc["observation_10"]) == {"decode_us", "json_loads_us"}
    assert set(doc["pose_array_10"]) == {"encode_us", "decode_us", "json_dumps_us"}
    assert all(v > 0 for d in doc.values() for v in d.values())
    assert "Observation decode" in r.stdout and "ratio" in r.stdout


def test_codec_bench_refuses_a_bad_count():
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "codec_bench.py"), "--rounds", "0"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("codec_bench: error:") and "Traceback" not in r.stderr
