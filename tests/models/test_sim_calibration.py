"""The hybrid's calibration on simulation (models/sim_calibration.py) and its report
(models/hybrid_fit.format_trust): every camera count of the site is listed."""

from __future__ import annotations

import re

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from superbody.edge.site import load_site  # noqa: E402
from superbody.host.estimation.hybrid import HybridCalibration  # noqa: E402
from superbody.models.hybrid_fit import MIN_TRUST_SAMPLES, format_trust, trust_samples  # noqa: E402
from tests.conftest import LAB_SITE  # noqa: E402

# The lab example's four corner cameras and a fifth over the door, in the middle of the south wall.
FIFTH_CAMERA = """
[[cameras]]
id = "door"
width = 1280
height = 720
fps = 15.0
fx = 900.0
fy = 900.0
cx = 640.0
cy = 360.0
position = [3.0, 0.1, 2.5]
look_at = [3.0, 2.5, 0.8]
"""


@pytest.fixture(scope="module")
def five_cameras(tmp_path_factory):
    """A 5-camera site and a tiny network trained for it (geometry features, fp32 ONNX)."""
    from superbody.models.training.train import TrainConfig, save, train

    out = tmp_path_factory.mktemp("five")
    site = out / "lab5.toml"
    site.write_text(LAB_SITE.read_text().replace('name = "lab-example"', 'name = "lab5"') + FIFTH_CAMERA)
    assert len(load_site(site).cameras) == 5
    cfg = TrainConfig(site=str(site), geometry=True, sim_samples=400, epochs=1, hparams={"hidden": 16, "heads": 2, "layers": 2})
    paths = save(train(cfg, progress=False), cfg, out, "lab5", quantize=False)
    return load_site(site), paths["fp32"]


def test_the_report_lists_every_camera_count_of_a_five_camera_site(five_cameras):
    # Before: the trust for 1, 2 and 3 cameras only, and the scores only for counts with samples
    # among 1-3: a 5-camera site's 4 and 5 were not in the report.
    from superbody.models.sim_calibration import calibrate_on_simulation, format_fits

    site, model = five_cameras
    fits = calibrate_on_simulation(site, [model], samples=600, progress=False, write=False)
    fit = fits[str(model)]
    assert sorted(fit["samples_by_cameras"]) == [1, 2, 3, 4, 5]
    assert sum(fit["samples_by_cameras"].values()) <= 600
    for report in fit["reports"].values():
        assert list(report["by_cameras"]) == ["1", "2", "3", "4", "5"]
    text = format_fits(fits)
    for k in range(1, 6):
        (line,) = [line for line in text.splitlines() if line.strip().startswith(f"{k} camera")]
        row = fit["calibration"].net_trust[min(k, 3) - 1]
        assert line.split(": ", 1)[1].startswith(", ".join(f"{v:g}" for v in row)), line
        if k >= 3:
            assert "one trust for 3-5 cameras" in line or "too few samples" in line, line
    # the scores: every count, those without samples said so
    for line in [line for line in text.splitlines() if " mm, yaw " in line]:
        assert all(re.search(rf"\b{k} cam (\d+ / \d+ mm|no samples)", line) for k in range(1, 6)), line


# (samples per camera count, the lines expected: count -> what its line says)
TRUST_CASES = [
    # five cameras, few people seen by one: that row is the default, said so; 3-5 share the 3+ row
    ({1: 4, 2: 300, 3: 500, 4: 400, 5: 100},
     {1: "1, 1, 1 by default: too few samples to fit (4; the fit needs 10)", 2: "0, 0, 0.5 (300 samples)",
      3: "0, 0, 0 (500 samples; one trust for 3-5 cameras, fitted on their 1000)", 5: "0, 0, 0 (100 samples; one trust"}),
    # nobody seen by five cameras: the count is still listed
    ({1: 50, 2: 300, 3: 500, 4: 3, 5: 0},
     {1: "0.1, 0, 0 (50 samples)", 4: "(3 samples; one trust for 3-5 cameras, fitted on their 503)",
      5: "0, 0, 0 (no samples; one trust for 3-5 cameras, fitted on their 503)"}),
    # three cameras: the 3 row is its own, no pooling said
    ({1: 50, 2: 300, 3: 5}, {3: "3 cameras: 1, 1, 1 by default: too few samples to fit (5; the fit needs 10)"}),
    # one camera
    ({1: 0}, {1: "1 camera: 1, 1, 1 by default: too few samples to fit (0; the fit needs 10)"}),
]


@pytest.mark.parametrize("samples,expected", TRUST_CASES)
def test_format_trust_lists_each_camera_count(samples, expected):
    fitted = ((0.1, 0.0, 0.0), (0.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    rows = tuple(r if sum(v for j, v in samples.items() if min(j, 3) == k) >= MIN_TRUST_SAMPLES else (1.0, 1.0, 1.0)
                 for k, r in enumerate(fitted, 1))  # what fit_trust leaves where a row has too few samples
    cal = HybridCalibration(analytic_std=((0.1, 0.1, 0.1),) * 3, net_trust=rows)
    lines = format_trust(cal, samples)
    assert lines[0].startswith("trust in the network (x, y, yaw) by cameras")
    assert [int(line.split()[0]) for line in lines[1:]] == list(range(1, len(samples) + 1))
    for k, text in expected.items():
        assert text in lines[k], (k, lines[k])


def test_trust_samples_counts_the_samples_both_estimates_have():
    net = np.zeros((6, 3))
    analytic = np.zeros((6, 3))
    analytic[0] = np.nan  # geometry found nothing: not a sample the trust is fitted on
    assert trust_samples(net, analytic, np.array([1, 1, 2, 4, 4, 4]), 5) == {1: 1, 2: 1, 3: 0, 4: 3, 5: 0}
