"""The hard-conditions scenes (benchmarks/scenes.py, issue 28 item 4): the scorer on hand-made
sequences, each kind of scene run briefly in-process through the host's aggregator, and the
benchmark as its own processes (``--jobs 2``) writing its JSON.

The scene tests assert what each scene is built to exercise and what must hold there.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from collections import Counter

import numpy as np
import pytest

from benchmarks import scenes
from benchmarks.scenes import MotScorer, Visibility
from superbody.edge.messages import wire
from tests.conftest import ROOT

S = 1_000_000_000
TWO = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, math.pi / 2]])  # two standing people, (N, 3)


def _score(steps: list[tuple], countable=(True, True), truth=TWO) -> dict:
    """Each step: (ids, poses (M, 3)) against the same truth."""
    sc = MotScorer()
    for ids, poses in steps:
        sc.add(truth, np.array(countable), ids, np.array(poses, dtype=float).reshape(-1, 3))
    return sc.summary()


ON_A, ON_B = (0.05, 0.0, 0.1), (2.0, 0.05, math.pi / 2)  # 50 mm off each, A's yaw 0.1 rad off

# (steps, expected): each a hand-made sequence of published people.
SCORER_CASES = [
    # Tracked perfectly: every countable person-step a hit, nothing else.
    ([([1, 2], [ON_A, ON_B])] * 3,
     dict(hits=6, misses=0, false_positives=0, id_switches=0, recall=1.0, precision=1.0, mota=1.0, tracks=2, extra_tracks=0)),
    # A's track is replaced by a new id (a loss and a new track): one switch, one duplicate track.
    ([([1, 2], [ON_A, ON_B]), ([3, 2], [ON_A, ON_B]), ([3, 2], [ON_A, ON_B])],
     dict(hits=6, id_switches=1, duplicate_tracks=1, ghost_tracks=0, extra_tracks=1, mota=1 - 1 / 6)),
    # The two tracks swap people and swap back: four switches, no extra track.
    ([([1, 2], [ON_A, ON_B]), ([1, 2], [ON_B, ON_A]), ([1, 2], [ON_A, ON_B])],
     dict(hits=6, id_switches=4, extra_tracks=0)),
    # A ghost 3 m from anyone, in one step: a false positive and a ghost track.
    ([([1, 2], [ON_A, ON_B]), ([1, 2, 9], [ON_A, ON_B, (0.0, 3.0, 0.0)])],
     dict(hits=4, false_positives=1, ghost_steps=1, duplicate_steps=0, ghost_tracks=1, precision=0.8, false_positive_share=0.2)),
    # A second track 0.2 m from A, as long as A's: a duplicate every step, one duplicate track.
    ([([1, 2, 5], [ON_A, ON_B, (0.2, 0.0, 0.0)])] * 2,
     dict(hits=4, false_positives=2, duplicate_steps=2, ghost_steps=0, duplicate_tracks=1, ghost_tracks=0, extra_tracks=1)),
    # Off by more than the 0.5 m gate: B missed and a ghost published.
    ([([1, 2], [ON_A, (2.6, 0.0, 0.0)])],
     dict(hits=1, misses=1, false_positives=1, ghost_steps=1, recall=0.5, mota=0.0)),
    # A track mostly alone (a phantom) that once stands beside B: a ghost track, not B's duplicate.
    ([([1, 2, 7], [ON_A, ON_B, (0.0, 3.0, 0.0)])] * 3 + [([1, 2, 7], [ON_A, ON_B, (2.2, 0.0, 0.0)])],
     dict(ghost_steps=3, duplicate_steps=1, ghost_tracks=1, duplicate_tracks=0, extra_tracks=1)),
    # Nobody published: all misses.
    ([([], [])] * 2, dict(hits=0, misses=4, false_positives=0, recall=0.0, mota=0.0, tracks=0)),
]


@pytest.mark.parametrize("steps,expected", SCORER_CASES)
def test_scorer_counts(steps, expected):
    got = _score(steps)
    for key, value in expected.items():
        assert got[key] == pytest.approx(value), (key, got)


def test_people_passing_close_keep_their_tracks_in_the_score():
    # A and B 0.3 m apart; each track drifts 0.2 m towards the other: by distance alone the
    # Hungarian algorithm would swap them (0.1 + 0.1 < 0.2 + 0.2), but the tracks did not swap.
    truth = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]])
    sc = MotScorer()
    for poses in ([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]], [[0.2, 0.0, 0.0], [0.1, 0.0, 0.0]], [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]]):
        sc.add(truth, np.array([True, True]), [1, 2], np.array(poses))
    s = sc.summary()
    assert s["id_switches"] == 0 and s["hits"] == 6 and s["position_mm_p90"] == pytest.approx(200.0)


def test_scorer_errors_wrap_yaw_and_use_each_poses_own_truth():
    sc = MotScorer()
    # B walks along +x at 2 m/s: published at two capture times 0.5 s apart, each exact at its own.
    truth = np.array([[[0.0, 0.0, math.radians(179)], [1.0, 0.0, 0.0]],
                      [[0.0, 0.0, math.radians(179)], [2.0, 0.0, 0.0]]])  # (M, N, 3)
    sc.add(truth, np.array([True, True]), [1, 2], np.array([[0.0, 0.0, math.radians(-179)], [2.0, 0.0, 0.0]]))
    s = sc.summary()
    assert s["hits"] == 2 and s["position_mm_p50"] == pytest.approx(0.0)
    assert s["yaw_deg_p90"] == pytest.approx(1.8)  # 2 and 0 degrees: across +-180, not 358


def test_people_who_do_not_count_are_neither_hits_nor_misses_nor_false_positives():
    # B is tracked but does not count (not seen long enough); A is missed.
    s = _score([([2], [ON_B])], countable=(True, False))
    assert (s["hits"], s["misses"], s["false_positives"], s["countable_person_steps"], s["true_person_steps"]) == (0, 1, 0, 1, 2)
    assert s["ghost_tracks"] == 0 and s["coverage"] == 0.5


def test_a_switch_across_a_gap_still_counts():
    # A hit as track 1, then not countable (out of view) while nobody is published, then hit as track 4.
    sc = MotScorer()
    for countable, ids, poses in (((True, True), [1, 2], [ON_A, ON_B]), ((False, True), [2], [ON_B]), ((True, True), [4, 2], [ON_A, ON_B])):
        sc.add(TWO, np.array(countable), ids, np.array(poses))
    assert sc.summary()["id_switches"] == 1


def test_empty_steps_are_undefined_not_perfect():
    sc = MotScorer()
    sc.add(np.zeros((0, 3)), np.zeros(0, bool), [], np.zeros((0, 3)))
    s = sc.summary()
    assert s["steps"] == 1 and math.isnan(s["recall"]) and math.isnan(s["precision"]) and math.isnan(s["mota"])
    assert not scenes.meets_bar({**s, "extra_tracks": 0})


def test_visibility_needs_a_settled_run_of_fresh_sightings():
    vis = Visibility(2, fresh_s=0.5, gap_s=1.0, settle_s=2.5)
    for t in np.arange(0.0, 3.01, 0.1):  # person 0 seen throughout, person 1 from 1 s on
        vis.saw([0] if t < 1.0 else [0, 1], int(t * S))
    assert vis.countable(int(3.0 * S)).tolist() == [True, False]
    vis.saw([0], int(4.5 * S))  # a 1.5 s gap restarts person 0's run
    assert vis.countable(int(4.5 * S)).tolist() == [False, False]  # and person 1 is stale (last seen at 3 s)


@pytest.fixture(scope="module")
def run():
    """One short run of a scene, with one estimator, cached for the module."""
    cache: dict[tuple, dict] = {}

    def go(key: str, estimator: str, seconds: float = 6.0) -> dict:
        if (key, estimator, seconds) not in cache:
            cache[key, estimator, seconds] = scenes.run_scene(key, seconds, 1, (estimator,))
        return cache[key, estimator, seconds]

    return go


def test_more_cameras_than_the_model_has_view_slots_drop_no_person(run):
    sc = run("b", "rays", 5.0)
    r = sc["estimators"]["rays"]
    assert sc["cameras"] == 6 and r["max_views"] == 4
    # The scene does what it is for: most estimates had more views than the model's slots ...
    assert r["largest_view_set"] == 6 and r["views_over_limit"] > 0.3
    # ... yet every person is published, once, with all their views reported.
    assert r["recall"] >= 0.95 and r["extra_tracks"] == 0 and r["id_switches"] == 0
    assert r["mean_views"] > 4.0


def test_low_cameras_still_place_and_keep_people(run):
    sc = run("c", "analytic", 5.0)
    r = sc["estimators"]["analytic"]
    assert sc["camera_heights_m"] == [1.0] * 4
    # Geometry from level cameras holds. (The site-independent model's does not: it was trained
    # on cameras 1.8-3 m up and misplaces one person by 0.5-1 m; docs/scenes.md.)
    assert r["tracks"] == sc["people"] and r["extra_tracks"] == 0 and r["id_switches"] == 0
    assert r["recall"] >= 0.95 and r["position_mm_p50"] < 80.0


def test_a_crowd_on_two_by_two_metres_keeps_one_track_per_person(run):
    sc = run("d", "rays")
    r = sc["estimators"]["rays"]
    assert sc["people"] >= 4
    assert r["tracks"] == sc["people"] and r["extra_tracks"] == 0 and r["id_switches"] == 0
    assert r["recall"] >= 0.95


@pytest.mark.parametrize("key", ["e", "h"])  # the same flat signature on every view; no colour at all
def test_identical_or_missing_colours_leave_geometry_and_time(run, key):
    sc = run(key, "rays")
    r = sc["estimators"]["rays"]
    assert sc["colour"] == {"e": "same", "h": "none"}[key]
    assert r["id_switches"] == 0 and r["extra_tracks"] == 0 and r["recall"] >= 0.95


@pytest.mark.parametrize("key", ["f", "i"])  # random partial false positives; a static phantom in one camera
def test_false_positives_cost_the_real_people_nothing(run, key):
    sc = run(key, "rays")
    r = sc["estimators"]["rays"]
    assert sc["spurious_prob"] > 0.1 or sc["phantom_views"] > 40
    assert r["recall"] >= 0.95 and r["id_switches"] == 0 and r["duplicate_tracks"] == 0


@pytest.mark.parametrize("key", ["f", "i"])
def test_false_positives_start_no_ghost_track(run, key):
    # host.tracking.evidence: the cameras that clearly see where a false positive stands do not
    # corroborate it, so it is never confirmed.
    assert run(key, "rays")["estimators"]["rays"]["ghost_tracks"] == 0


def test_people_cut_off_at_the_image_edges(run):
    sc = run("g", "rays")
    r = sc["estimators"]["rays"]
    assert sc["estimators"]["rays"]["coverage"] < 0.5  # the scene does cut people off: most person-steps go unseen
    assert r["recall"] >= 0.8 and r["precision"] >= 0.9 and r["ghost_tracks"] == 0


def test_the_filter_weighs_geometry_by_what_it_is_worth_in_the_four_person_room():
    """Issue 28's real four-person recording: with geometry alone the filter made position worse
    than per-frame output (median 40-44 mm against 26-31). The analytic estimator reported no
    sigmas, so the filter took every pose as 0.1 m and 10 deg uncertain, several times geometry's
    error with two or more cameras, and lagged behind people who turn and shuffle. Scene k (5
    cameras at 1.0 and 2.2 m, 4 people, a calibration 0.5 deg and 2 cm off), 10 s: those old
    defaults left the filtered p90 errors 1.4 and 2.2 times the per-frame ones. Geometry's sigmas
    fitted on simulation of the room keep them within 1.3 times; the filter's defaults now (0.03 m,
    4 deg) still lag in yaw (1.5 times) but both are at least a fifth below the old defaults."""
    import math

    from superbody.host.aggregator import HostConfig
    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.filtering.pose_filter import FilterConfig
    from superbody.models.sim_calibration import geometry_calibration

    sc = scenes.SCENES["k"]()
    rec = scenes.simulate(sc, 10.0, 1)
    geometry = AnalyticEstimator(sc.site)
    p90 = {}
    for name, est, cfg in (("old defaults", geometry, HostConfig(filter=FilterConfig(meas_std_xy_m=0.1, meas_std_yaw_rad=math.radians(10)))),
                           ("defaults", geometry, HostConfig()),
                           ("sigmas", AnalyticEstimator(sc.site, geometry_calibration(sc.site, samples=600)), HostConfig()),
                           ("per frame", geometry, HostConfig(filter=FilterConfig(enabled=False)))):
        r = scenes.replay(sc, rec, est, "analytic", cfg)
        # Every setting keeps every person: one who sets off walking at 1.4 m/s at 4.8 s was lost
        # once with the old defaults' and the per-frame poses while the tracker's position filter
        # took each ground point as unsure in every direction (docs/scenes.md, "Each view sure
        # across its line of sight").
        assert r["recall"] >= 0.95 and r["id_switches"] == 0, name
        p90[name] = np.array([r["position_mm_p90"], r["yaw_deg_p90"]])
    assert (p90["old defaults"] > 1.3 * p90["per frame"]).all()  # the defect, as the scene shows it
    assert (p90["sigmas"] < 1.3 * p90["per frame"]).all()
    for name in ("defaults", "sigmas"):
        assert (p90[name] < 0.8 * p90["old defaults"]).all(), (name, p90)


def _finite_numbers(doc: object) -> bool:
    if isinstance(doc, dict):
        return all(_finite_numbers(v) for v in doc.values())
    if isinstance(doc, list):
        return all(_finite_numbers(v) for v in doc)
    return not isinstance(doc, float) or math.isfinite(doc)


def test_benchmark_runs_as_processes_and_writes_its_json(tmp_path):
    out = tmp_path / "scenes.json"
    r = subprocess.run([sys.executable, "-m", "benchmarks.scenes", "--scenes", "a,g", "--seconds", "6", "--jobs", "2",
                        "--no-progress", "--json-out", str(out)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert doc["config"]["seconds"] == 6 and list(doc["scenes"]) == ["a", "g"]
    assert set(doc["scenes"]["a"]["estimators"]) == {"analytic", "geo-sim", "rays", "site"}  # the apartment ships its own model
    assert set(doc["scenes"]["g"]["estimators"]) == {"analytic", "geo-sim", "rays"}
    for sc in doc["scenes"].values():
        for est in sc["estimators"].values():
            for key in ("recall", "precision", "mota", "id_switches", "extra_tracks", "ghost_tracks", "duplicate_tracks",
                        "false_positive_share", "position_mm_p50", "position_mm_p90", "yaw_deg_p50", "yaw_deg_p90", "coverage"):
                assert isinstance(est[key], (int, float)) and math.isfinite(est[key]), (key, est)
    assert _finite_numbers(doc)
    assert all(est["recall"] > 0.5 for est in doc["scenes"]["a"]["estimators"].values())
    assert "a apartment" in r.stdout and "MOTA" in r.stdout


def test_the_four_person_room_with_a_detectors_false_positives(run):
    """Scene l, the nearest to issue 28's held-out recording: the random partial detections and
    the phantom are there, and geometry still publishes the four people, one track each."""
    sc = run("l", "analytic", 10.0)
    r = sc["estimators"]["analytic"]
    assert sc["spurious_prob"] > 0.1 and sc["phantom_views"] > 40 and sc["colour"] == "none"
    assert r["recall"] >= 0.95 and r["id_switches"] == 0 and r["extra_tracks"] == 0 and r["false_positive_share"] <= 0.05


def test_the_doorway_hides_people_and_the_host_still_finds_them(run):
    """Scene m: people walk out through a doorway into a hallway no camera sees (a third of the
    person-steps there count for nothing: cover 0.63 at this seed), and stand in it seen in part by
    one or two cameras. Measured at seed 1, 12 s, geo-sim: recall 0.942, 1 extra track."""
    sc = run("m", "geo-sim", 12.0)
    r = sc["estimators"]["geo-sim"]
    assert sc["site"] == "room5-door" and r["coverage"] < 0.8
    assert r["recall"] >= 0.9 and r["tracks"] >= sc["people"] and r["id_switches"] == 0


# --- over many seeds (benchmarks/scene_seeds.py) ---------------------------------------------

def test_seeds_parse_ranges_and_lists_and_refuse_nonsense():
    import argparse

    from benchmarks.scene_seeds import parse_seeds

    assert parse_seeds("11-14") == [11, 12, 13, 14]
    assert parse_seeds("3, 1-2,3") == [1, 2, 3]
    for bad in ("", "4-2", "-1", "a", "1-", "0-5000"):
        with pytest.raises(argparse.ArgumentTypeError, match="--seeds"):
            parse_seeds(bad)


def test_seeds_summary_counts_the_seeds_that_met_the_bar():
    from benchmarks.scene_seeds import _tail, summarise

    def run(seed, met, sw, extra, yaw90, pos50=20.0):
        r = {"meets_bar": met, "id_switches": sw, "extra_tracks": extra, "yaw_deg_p90": yaw90, "recall": 1.0,
             "false_positive_share": 0.0, "position_mm_p50": pos50, "yaw_deg_p50": 2.0}
        return "k", seed, {"calibration_mm": 31.4, "estimators": {"analytic": r}}

    got = summarise([run(1, True, 0, 0, 6.5), run(2, False, 3, 1, 31.0), run(3, True, 0, 0, 7.0), run(4, False, 0, 0, 5.0, pos50=37.2)])
    assert got == {("k", "analytic"): {"seeds": 4, "met": 2, "missed": [2, 4], "id_switches": 3, "extra_tracks": 1,
                                       "why": {2: ["switches 3", "extra tracks 1"], 4: ["position 37 mm, calibration alone 31 mm"]},
                                       "yaw_p90": {1: 6.5, 2: 31.0, 3: 7.0, 4: 5.0}}}
    assert _tail(got["k", "analytic"]["yaw_p90"]) == "yaw p90 median 6.8 deg, worst 31.0 (seed 2)"
    assert _tail({4: math.nan}) == "yaw p90 unknown"


def test_the_bar_names_what_a_run_missed():
    s = {"recall": 0.94, "id_switches": 0, "extra_tracks": 2, "false_positive_share": 0.01, "position_mm_p50": 35.0, "yaw_deg_p50": 7.2}
    assert scenes.bar_misses(s) == ["recall 0.940", "extra tracks 2", "yaw 7.2 deg"]
    assert not scenes.meets_bar(s)
    assert scenes.meets_bar({**s, "recall": 0.95, "extra_tracks": 0, "yaw_deg_p50": 7.0})


def test_the_calibrations_own_position_error_is_what_its_cameras_shift_puts_in(monkeypatch):
    import dataclasses

    k = scenes.SCENES["k"]()
    assert scenes.calibration_floor_mm(dataclasses.replace(k, calibration_error=(0.0, 0.0)), 1) == 0.0
    # Every camera 3 cm off along x: a shift no image shows, so every person is placed 3 cm off.
    def shifted(site, degrees, metres, seed):
        return dataclasses.replace(site, cameras=tuple(dataclasses.replace(c, position=(c.position[0] + 0.03, *c.position[1:]))
                                                       for c in site.cameras))

    monkeypatch.setattr(scenes, "miscalibrated", shifted)
    assert scenes.calibration_floor_mm(k, 1) == pytest.approx(30.0, abs=0.1)
    monkeypatch.undo()
    # Cameras off each their own way: the draw of the seed, smaller than their shifts where they cancel out.
    one, two = (scenes.calibration_floor_mm(dataclasses.replace(k, calibration_error=(0.0, m)), 14) for m in (0.02, 0.04))
    assert 5.0 < one < 40.0 and two == pytest.approx(2 * one, rel=0.1)


def test_seeds_benchmark_runs_as_its_own_process():
    out = subprocess.run([sys.executable, "-m", "benchmarks.scene_seeds", "--scenes", "d", "--seeds", "1-2", "--seconds", "4",
                          "--estimators", "analytic", "--jobs", "2"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if line.startswith("d ")]
    assert [r.split()[1] for r in rows if "analytic" in r.split()[2:3]] == ["1", "2"]
    assert "d analytic: bar met at" in out.stdout and "of 2 seeds" in out.stdout
    bad = subprocess.run([sys.executable, "-m", "benchmarks.scene_seeds", "--seeds", "9-1"], cwd=ROOT, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--seeds" in bad.stderr


# --- camera timing: late and out-of-step deliveries ------------------------------------------

def test_visibility_answers_for_any_instant_in_any_order():
    vis = Visibility(1, fresh_s=0.5, gap_s=1.0, settle_s=2.5)
    for t in [*np.arange(0.0, 3.01, 0.1), *np.arange(5.0, 9.01, 0.1)]:  # two runs of sightings, 2 s apart
        vis.saw([0], int(round(t * 10)) * S // 10)
    # Asked after every sighting is in: only the sightings up to each instant count.
    for t, expected in ((2.4, False), (2.6, True), (3.4, True), (3.6, False), (7.4, False), (7.6, True), (1.0, False)):
        assert vis.countable(int(t * S)).tolist() == [expected], t
    with pytest.raises(ValueError, match="before the one at"):
        vis.saw([0], 1 * S)


def test_a_matched_person_counts_at_the_published_persons_own_time():
    # A is published (exactly) as they were when they did not count yet: neither hit nor miss.
    # B is published as they were when they counted, though they no longer count now: a hit.
    sc = MotScorer()
    sc.add(np.stack([TWO, TWO]), np.array([True, False]), [1, 2], np.array([ON_A, ON_B]),
           countable_at=np.array([[False, False], [True, True]]))
    s = sc.summary()
    assert (s["hits"], s["misses"], s["false_positives"], s["countable_person_steps"]) == (1, 0, 0, 1)
    assert s["coverage"] == 0.5  # what the cameras show at the scoring instant, whatever is published


@pytest.fixture(scope="module")
def k5():
    """Scene k (5 cameras, 4 people), 5 simulated seconds at 15 fps."""
    sc = scenes.SCENES["k"]()
    return sc, scenes.simulate(sc, 5.0, 1)


def test_the_truth_is_known_at_any_instant(k5):
    sc, rec = k5
    stamp = rec.frames[7][0]
    assert np.array_equal(rec.truth_at(stamp), rec.truth[stamp])
    world = scenes.World(scenes.miscalibrated(sc.site, *sc.calibration_error, 1), sc.people, seed=1, period_s=60.0,
                         epoch_s=scenes.T0_NS / 1e9)
    between = stamp + 12_345_678  # no frame was captured then
    assert between not in rec.truth
    expected = np.array([[p.x, p.y, p.yaw] for p in world.states(between * 1e-9)])
    np.testing.assert_allclose(rec.truth_at(between), expected)
    assert rec.truth_at(between).shape == (sc.people, 3)


def _per_camera(rec, order):
    """camera id -> [(capture stamp, delivery ns)] in delivery order."""
    out: dict[str, list[tuple[int, int]]] = {}
    for now, j in order:
        out.setdefault(rec.frames[j][1], []).append((rec.frames[j][0], now))
    return out


def test_late_variants_deliver_every_frame_that_late_in_delivery_order(k5):
    sc, rec = k5
    for name, late_ns in (("prompt", 0), ("late0.3", 300_000_000), ("late0.8", 800_000_000)):
        order = scenes.deliveries(rec, sc.site, scenes.TIMINGS[name], 1)
        assert sorted(j for _, j in order) == list(range(len(rec.frames)))  # every frame, once
        assert [now for now, _ in order] == sorted(now for now, _ in order)
        assert all(now == rec.frames[j][0] + late_ns for now, j in order), name
    assert [j for _, j in scenes.deliveries(rec, sc.site, scenes.TIMINGS["prompt"], 1)] == list(range(len(rec.frames)))


def test_mixed_cameras_are_each_their_own_delay_late_and_in_order(k5):
    sc, rec = k5
    order = scenes.deliveries(rec, sc.site, scenes.TIMINGS["mixed"], 1)
    assert [now for now, _ in order] == sorted(now for now, _ in order)
    per = _per_camera(rec, order)
    for delay, cam in zip((0.1, 0.4, 0.8, 1.2, 0.3), sc.site.camera_ids):
        stamps, nows = map(np.array, zip(*per[cam]))
        assert list(stamps) == sorted(stamps)  # a camera's own frames never overtake each other
        late = (nows - stamps) / S
        assert late.min() >= 0 and abs(np.median(late) - delay) < 0.03, (cam, np.median(late))
        assert 0.02 < late.std() < 0.08, (cam, late.std())  # 50 ms jitter (a little less where order holds frames back)
    # Out of step: frames reach the host in another order than they were captured.
    assert [j for _, j in order] != sorted(j for _, j in order)


def test_mixedfps_cameras_capture_at_their_own_rates():
    sc = scenes.SCENES["k"]()
    tm = scenes.TIMINGS["mixedfps"]
    rates = tm.camera_fps(len(sc.site.cameras))
    assert rates == (25.0, 10.0, 5.0, 25.0, 10.0)
    rec = scenes.simulate(sc, 2.0, 1, fps=rates)
    counts = Counter(cam for _, cam, _, _ in rec.frames)
    assert [counts[c] for c in sc.site.camera_ids] == [50, 20, 10, 50, 20]
    assert [f[0] for f in rec.frames] == sorted(f[0] for f in rec.frames)
    per = _per_camera(rec, scenes.deliveries(rec, sc.site, tm, 1))
    for cam, rate in zip(sc.site.camera_ids, rates):
        stamps = np.array([s for s, _ in per[cam]])
        np.testing.assert_allclose(np.diff(stamps), 1e9 / rate, atol=1)
    assert len(rec.score_at) == 30  # scored on the 15 fps grid whatever the rates


class _LaggingHost:
    """A fake ``Aggregator``: records what it is fed and publishes every true person exactly as they
    were ``lag_s`` before the step (a host fusing in event time), or nobody (``publish=False``)."""

    instances: list[_LaggingHost] = []

    def __init__(self, rec, lag_s: float, publish: bool = True):
        self.rec, self.lag_ns, self.publish = rec, int(lag_s * S), publish
        self.ingested: list[tuple[int, int]] = []  # (capture stamp, now)
        self.steps: list[int] = []
        self.rejected: Counter = Counter()
        self.tracker = type("T", (), {"stats": Counter()})()
        _LaggingHost.instances.append(self)

    def ingest(self, payload: bytes, key: str, now_ns: int) -> bool:
        self.ingested.append((wire.decode(payload).stamp_ns, now_ns))
        return True

    def step(self, now_ns: int):
        from superbody.host.messages import pose as pose_msg

        self.steps.append(now_ns)
        at = now_ns - self.lag_ns
        people = tuple(pose_msg.PersonPose(id=k + 1, x=x, y=y, yaw=yaw, vx=0.0, vy=0.0, yaw_rate=0.0, cov=np.eye(3) * 1e-4,
                                           confidence=1.0, cameras=("c0",), stamp_ns=at, views=1, estimator="analytic")
                       for k, (x, y, yaw) in enumerate(self.rec.truth_at(at))) if self.publish else ()
        return pose_msg.PoseArray("room5", len(self.steps), now_ns, people, 0, ("c0",), "analytic")


def test_a_late_replay_feeds_the_host_in_delivery_order_and_scores_each_person_at_its_stamp(k5, monkeypatch):
    sc, rec = k5
    tm = scenes.TIMINGS["mixed"]
    _LaggingHost.instances.clear()
    monkeypatch.setattr(scenes, "Aggregator", lambda site, est, name, config: _LaggingHost(rec, 1.0))
    r = scenes.replay(sc, rec, None, "fake", timing=tm, seed=1)
    host = _LaggingHost.instances[0]
    order = scenes.deliveries(rec, sc.site, tm, 1)
    assert host.ingested == [(rec.frames[j][0], now) for now, j in order]  # capture stamps kept, now = delivery
    assert host.steps == sorted(set(now for now, _ in order))  # a step after each delivery time
    # Published 1 s in the past, exactly: every hit is exact and nobody who counts is missed.
    assert r["timing"] == "mixed" and r["hits"] > 0 and r["misses"] == 0 and r["false_positives"] == 0
    assert r["position_mm_p90"] == pytest.approx(0.0, abs=1e-6) and r["empty_in_view"] == 0.0
    # A host that publishes nobody: every array while someone counts is empty, every countable person missed.
    monkeypatch.setattr(scenes, "Aggregator", lambda site, est, name, config: _LaggingHost(rec, 0.0, publish=False))
    r = scenes.replay(sc, rec, None, "fake", timing=scenes.TIMINGS["late0.8"], seed=1)
    assert r["empty_in_view"] == 1.0 and r["arrays_in_view"] > 0 and r["recall"] == 0.0 and r["misses"] > 0


def test_run_scene_scores_each_timing_under_its_own_key():
    sc = scenes.run_scene("k", 3.0, 1, ("analytic",), timings=("prompt", "late0.8"))
    assert list(sc["estimators"]) == ["analytic", "analytic@late0.8"]
    for key, timing in (("analytic", "prompt"), ("analytic@late0.8", "late0.8")):
        r = sc["estimators"][key]
        assert r["timing"] == timing and r["frames_delivered"] == sc["frames"] and r["arrays"] > 0
        assert 0.0 <= r["empty_in_view"] <= 1.0 or math.isnan(r["empty_in_view"])
    with pytest.raises(ValueError, match="unknown timing 'late9'; timings: prompt, late0.3, late0.8, mixed, mixedfps"):
        scenes.run_scene("k", 3.0, 1, ("analytic",), timings=("late9",))


def test_tracker_settings_reach_the_host_the_scenes_replay_through():
    base = scenes.run_scene("d", 4.0, 1, ("analytic",))["estimators"]["analytic"]
    never = scenes.run_scene("d", 4.0, 1, ("analytic",), tracker={"confirm_after_s": 600.0})["estimators"]["analytic"]
    assert base["tracker"]["confirmed"] > 0 and base["recall"] > 0.5
    assert never["tracker"]["confirmed"] == 0 and never["tracker"]["new_candidates"] > 0
    with pytest.raises(ValueError, match=r"TrackerConfig.gate_m must be a number in \(0.0, 100.0\], got -1"):
        scenes.run_scene("d", 4.0, 1, ("analytic",), tracker={"gate_m": -1.0})


@pytest.mark.parametrize(("text", "expected"), [("gate_m=0.8", ("gate_m", 0.8)), (" min_joints = 4 ", ("min_joints", 4)),
                                                ("use_geometry=False", ("use_geometry", False))])
def test_tracker_settings_parse_as_their_fields_type(text, expected):
    assert scenes.tracker_setting(text) == expected


@pytest.mark.parametrize(("text", "message"), [("gate_m", "FIELD=VALUE with FIELD one of confirm_after_s"),
                                               ("gates=1", "FIELD=VALUE"), ("min_joints=3.5", "min_joints must be an integer, got '3.5'"),
                                               ("use_geometry=1", "use_geometry must be true or false")])
def test_tracker_settings_refuse_unknown_fields_and_wrong_types(text, message):
    with pytest.raises(argparse.ArgumentTypeError, match=message):
        scenes.tracker_setting(text)
