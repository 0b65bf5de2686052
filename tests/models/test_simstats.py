"""The simulator's detector statistics stay close to the real dev.json."""

import pytest

from superbody.models.simstats import simulate, statistics
from superbody.models.wtf import load_wtf
from tests.conftest import WTF_SITE


@pytest.fixture(scope="module")
def both(dev_json):
    real = statistics([{c: v.keypoints for c, v in s.views.items()} for s in load_wtf(dev_json)])
    sim = statistics(simulate(str(WTF_SITE), seconds=120, seed=3, rate_hz=8.0, progress=False))
    return real, sim


def test_joints_per_view_and_scores_match(both):
    real, sim = both
    assert sim["joints_per_view_mean"] == pytest.approx(real["joints_per_view_mean"], rel=0.15)
    for q in ("0.25", "0.5", "0.75"):
        assert sim["score_quantiles"][q] == pytest.approx(real["score_quantiles"][q], abs=0.05)
    assert min(s for s in (sim["score_quantiles"]["0.05"],)) >= 0.5


def test_views_per_person_and_joint_rates_match(both):
    real, sim = both
    for k in ("1", "2", "3"):
        assert sim["views_per_person"][k] == pytest.approx(real["views_per_person"][k], abs=0.2)
    worst = max(abs(sim["joint_rate"][j] - real["joint_rate"][j]) for j in real["joint_rate"])
    assert worst < 0.2
