"""benchmarks/live_cv.py refuses what it cannot use with one line naming the flag (its figures are
checked against crossval's own in tests/models/test_pipeline.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import ROOT

SCRIPT = str(ROOT / "benchmarks" / "live_cv.py")


# (arguments after --cv / --folds, text the error must contain)
BAD = [
    (["--set", "filter.acceleration=3"], "KEY one of"),  # unknown key: the valid ones are listed
    (["--set", "freshness_s"], "--set must be KEY=V1,V2"),  # no values
    (["--set", "filter.accel_std_mps2=3,-1"], "FilterConfig.accel_std_mps2 must be in (0.0, 100.0], got -1.0"),
    (["--set", "freshness_s=soon"], "--set freshness_s: could not convert"),
    (["--set", "filter.enabled=maybe"], "--set filter.enabled: must be true or false, got 'maybe'"),
    ([], "not a crossval --temporal predictions file"),  # --cv names no file
]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_arguments_exit_2_naming_the_flag(tmp_path, args, message):
    r = subprocess.run([sys.executable, SCRIPT, "--cv", str(tmp_path / "none.npz"), "--folds", str(tmp_path), *args],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr and message in r.stderr, r.stderr[-1000:]
