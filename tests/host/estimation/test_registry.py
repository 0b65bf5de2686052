"""The estimator registry (host/estimation/__init__.py): by name, and a site that has no model."""

from __future__ import annotations

import dataclasses
import logging
import subprocess
import sys

import pytest

from superbody.edge.site import dump_site, load_site
from superbody.host.estimation import build_estimator
from superbody.host.estimation.analytic import AnalyticEstimator
from tests.conftest import ROOT, WTF_SITE, free_port


@pytest.fixture
def new_site():
    """The apartment's cameras under another name: a site nothing was trained for."""
    return dataclasses.replace(load_site(WTF_SITE), name="new-room")


def test_a_site_without_a_model_runs_geometry_and_says_how_to_train_one(new_site, caplog):
    with caplog.at_level(logging.WARNING, logger="superbody.host"):
        est, name = build_estimator(new_site, "auto")
    assert isinstance(est, AnalyticEstimator) and name == "analytic"
    (record,) = [r for r in caplog.records if "has no model" in r.getMessage()]
    assert "superbody train --site" in record.getMessage() and "'new-room'" in record.getMessage()


@pytest.mark.parametrize("kind", ["onnx", "hybrid"])
def test_asking_for_the_network_without_a_model_is_an_error_naming_the_command(new_site, kind):
    with pytest.raises(ValueError, match=f"--estimator {kind}: site 'new-room' has no model.*superbody train --site"):
        build_estimator(new_site, kind)


def test_the_host_command_starts_on_a_site_without_a_model(new_site, tmp_path):
    """Through the command line: the host runs on the new site (1 s, loopback) and says why it runs geometry."""
    path = tmp_path / "new-room.toml"
    path.write_text(dump_site(new_site))
    r = subprocess.run([sys.executable, "-m", "superbody.edge.cli", "host", "run", "--site", str(path), "--duration", "1",
                        "--connect", f"tcp/127.0.0.1:{free_port()}"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "has no model" in r.stderr and "running geometry alone" in r.stderr
