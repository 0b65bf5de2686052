"""The estimator registry (host/estimation/__init__.py): by name, and a site that has no model."""

from __future__ import annotations

import dataclasses
import logging
import subprocess
import sys

import numpy as np
import pytest

from superbody.edge.site import dump_site, load_site
from superbody.host.estimation import build_estimator, default_model
from superbody.host.estimation.analytic import NO_CUE, PAIR, AnalyticEstimator
from superbody.host.tracking.ground import ground_points
from superbody.models.data.simdata import SimDataConfig, generate
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


def test_the_no_model_message_names_the_training_command_and_its_page(new_site, tmp_path):
    """The command to run, with the site's own file, whose flags the real ``superbody train``
    takes, and the install guide's section on training (docs/deploy.md says nothing about it)."""
    import shlex

    from superbody.edge.cli import build_parser
    from superbody.host.estimation import no_model_message

    path = tmp_path / "new room.toml"  # a space: the command must still be one the shell runs as is
    path.write_text(dump_site(new_site))
    message = no_model_message(load_site(path))
    assert "docs/install.md#train-a-model-for-the-site" in message and "deploy.md" not in message
    command = message.split("run: ", 1)[1].split(" (", 1)[0]
    argv = shlex.split(command)
    assert argv[:2] == ["superbody", "train"]
    args = build_parser().parse_args(argv[1:])
    assert args.site == str(path) and args.geometry and args.calibrate_sim and args.name == "new-room"
    assert f"--model {args.out}/new-room.fp32.onnx" in message
    # a site that was not read from a file: a placeholder for it
    assert "superbody train --site <site file> --geometry --calibrate-sim" in no_model_message(dataclasses.replace(new_site, source=""))


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


def test_geometry_reports_the_sigmas_of_the_sites_calibration():
    """``--estimator analytic`` on the apartment: geometry's sigmas per camera count come from the
    shipped model's hybrid calibration, so the filter weighs each pose by them (issue 28: without
    sigmas it took every pose as 0.1 m uncertain and made the four-person room worse)."""
    site = load_site(WTF_SITE)
    est, name = build_estimator(site, "analytic")
    assert name == "analytic" and est.sigmas is not None
    sets = [s.views for s in generate(site, SimDataConfig(samples=60, seed=1))]
    got = est.estimate_detailed(sets)
    _, cue = est.estimate_with_cues(sets)
    cams = np.array([len(v) for v in sets])
    want = est.sigmas.analytic_sigmas(cams, cue == PAIR)
    want[cue == NO_CUE, 2] = np.inf  # a yaw from nothing says nothing, calibrated or not
    for i in np.flatnonzero(cams == 1):  # one view: no surer than its ground point
        ((cam, view),) = sets[i].items()
        ground_std = ground_points(view.keypoints[None], site.camera(cam))[1][0]
        want[i, :2] = np.fmax(want[i, :2], ground_std)
    assert (got.std[cams == 1, :2] > est.sigmas.analytic_sigmas(cams, cue == PAIR)[cams == 1, :2]).any()
    np.testing.assert_array_equal(got.std, want)
    assert np.isfinite(got.std[cue != NO_CUE]).all() and got.source == ("analytic",) * len(sets)
    assert len(set(cams.tolist())) > 1 and len({tuple(r) for r in got.std.tolist()}) > 1  # one row per camera count


def test_geometry_without_a_model_reports_no_sigmas(new_site):
    est, _ = build_estimator(new_site, "analytic")
    assert est.sigmas is None


def test_a_model_for_another_site_gives_geometry_no_sigmas_and_a_warning(new_site, caplog):
    """The model is only read for its calibration: one that cannot serve the site is no reason to refuse geometry."""
    other = dataclasses.replace(new_site, cameras=new_site.cameras[:2])
    with caplog.at_level(logging.WARNING, logger="superbody.host"):
        est, _ = build_estimator(other, "analytic", default_model(load_site(WTF_SITE)))
    assert est.sigmas is None
    assert any("without sigmas" in r.getMessage() for r in caplog.records)
