"""The simulator's detector statistics stay close to the real dev.json."""

import dataclasses

import numpy as np
import pytest

from superbody.edge import body
from superbody.edge.sim import NoiseModel
from superbody.edge.site import load_site
from superbody.models.data.simstats import facing_rates, lr_disagreement, path_floor, simulate, statistics
from superbody.models.data.wtf import load_wtf
from tests.conftest import WTF_SITE


@pytest.fixture(scope="module")
def runs(dev_json):
    loaded = load_wtf(dev_json)
    real = [{c: v.keypoints for c, v in s.views.items()} for s in loaded]
    truths: list = []
    # On the stretch of floor the recording walked: what a detector reports depends on where the person stands.
    floor = path_floor(np.array([s.truth[:2] for s in loaded]))
    sim = simulate(str(WTF_SITE), seconds=120, seed=3, rate_hz=8.0, progress=False, truths=truths, floor=floor)
    return (real, [s.truth for s in loaded]), (sim, truths)


@pytest.fixture(scope="module")
def both(runs):
    (real, _), (sim, _) = runs
    return statistics(real), statistics(sim)


def test_which_joints_show_depends_on_where_the_person_faces_as_in_the_real_file(runs):
    """From behind the nose and eyes vanish but the ears stay; side-on the far eye, ear, elbow
    and wrist are hidden: the cues a single camera has for front and back."""
    site = load_site(WTF_SITE)
    (real, rt), (sim, st) = runs
    r, _ = facing_rates(real, rt, site)
    s, counts = facing_rates(sim, st, site)
    assert counts.min() > 50
    k = body.KEYPOINTS.index
    cue_rows = [k("nose"), k("left_eye"), k("right_eye"), k("left_ear"), k("right_ear"), k("left_elbow"), k("right_elbow"), k("left_wrist"), k("right_wrist")]
    assert np.abs(s[cue_rows] - r[cue_rows]).max() < 0.35
    back, front = [0, -1], [3, 4]  # bins centred on +-157.5 and +-22.5 degrees
    assert s[k("nose"), back].max() < 0.15 < 0.5 < s[k("nose"), front].min()
    assert s[k("left_ear"), back].min() > 0.3
    right_side = 6  # 112.5 degrees: the camera sees the person's right side
    assert s[k("left_eye"), right_side] < 0.1 < 0.4 < s[k("right_eye"), right_side]
    assert s[k("left_elbow"), right_side] < 0.35 < 0.7 < s[k("right_elbow"), right_side]


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


def test_left_right_swaps_are_measured_without_labels_and_as_rare_as_in_the_real_file(runs, dev_json):
    """Two views of one instant disagree about the person's left and right about as often in the
    simulator as in dev.json; a detector that swaps more is seen to (NoiseModel.swap_prob)."""
    site = load_site(WTF_SITE)
    (real, _), (sim, _) = runs
    bad_real, pairs_real = lr_disagreement(real, site)
    bad_sim, pairs_sim = lr_disagreement(sim, site)
    assert pairs_real > 200 and pairs_sim > 200
    assert bad_real / pairs_real < 0.03 and bad_sim / pairs_sim < 0.04
    floor = path_floor(np.array([s.truth[:2] for s in load_wtf(dev_json)]))
    swappy = simulate(str(WTF_SITE), seconds=120, seed=3, rate_hz=8.0, progress=False, floor=floor,
                      noise=dataclasses.replace(NoiseModel(), swap_prob=0.1))
    bad, pairs = lr_disagreement(swappy, site)
    assert bad / pairs > 0.08
