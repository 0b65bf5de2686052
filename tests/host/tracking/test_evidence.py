"""Evidence before a candidate is confirmed (host/tracking/evidence.py): negative evidence from the
cameras that clearly see where it stands, and room for one body per person."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.messages.observation import Observation
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import EDGE_MARGIN, MERGE_AFTER_S, clearly_sees, coincident, too_close
from superbody.host.tracking.track import Track
from superbody.host.tracking.tracker import Tracker
from tests.host.tracking.test_tracker import C1, CAMS, SITE, T0, S, frame, schedule


def test_a_camera_clearly_sees_its_middle_not_its_edges_nor_behind_it():
    cam = C1  # at (4.5, 4.5, 2.6), aimed at the origin
    toward = -np.array([4.5, 4.5]) / np.hypot(4.5, 4.5)
    side = np.array([-toward[1], toward[0]])
    pts = np.array([[0.0, 0.0], [6.0, 6.0], 4.75 * side, 3.0 * side, 5.5 * side])
    # the middle of its view; behind it; off to the side: torso centre at u = 29 px (inside the
    # image, within its edge margin of 64 px), at u = 136 px (clearly), beyond the image (u < 0)
    assert clearly_sees(cam, pts).tolist() == [True, False, False, True, False]
    assert clearly_sees(cam, np.zeros((0, 2))).shape == (0,)
    assert 0 < EDGE_MARGIN < 0.5


def test_an_obstacle_between_camera_and_person_hides_them():
    from superbody.edge.site import Obstacle

    shelf = Obstacle("shelf", (2.0, 2.0, 0.0), (2.6, 2.6, 2.0))  # on the line from c1 (4.5, 4.5) to the origin
    pts = np.array([[0.0, 0.0], [1.0, -1.0]])
    assert clearly_sees(C1, pts).tolist() == [True, True]
    assert clearly_sees(C1, pts, (shelf,)).tolist() == [False, True]
    low = Obstacle("table", (2.0, 2.0, 0.0), (2.6, 2.6, 0.5))  # below the line of sight to the torso
    assert clearly_sees(C1, pts, (low,)).tolist() == [True, True]


def test_too_close():
    others = np.array([[0.0, 0.0], [2.0, 0.0]])
    got = too_close(np.array([[0.1, 0.1], [0.5, 0.0], [1.8, 0.1]]), others, 0.3)
    assert got.tolist() == [True, False, True]
    assert too_close(np.array([[0.0, 0.0]]), np.zeros((0, 2)), 0.3).tolist() == [False]


def test_two_tracks_one_camera_frame_matched_both_are_two_people_however_close():
    from superbody.host.tracking.track import StampedView

    old, young = _placed(1, (0.0, 0.0), 1 * S), _placed(2, (0.2, 0.0), 2 * S)
    view = object()  # the views themselves do not matter here, only which frame they came from
    old.views["c1"], young.views["c1"] = StampedView(5 * S, view), StampedView(5 * S, view)  # type: ignore[arg-type]
    assert coincident([old, young], 10 * S, 0.3) == [] and coincident([old, young], 11 * S, 0.3) == []
    young.views["c1"] = StampedView(5 * S + 66_000_000, view)  # another frame: nothing says two bodies
    assert coincident([old, young], 12 * S, 0.3) == [] and coincident([old, young], 13 * S, 0.3) == [young]


def _placed(tid: int, xy: tuple[float, float], confirmed_ns: int) -> Track:
    tr = Track(tid, str(tid), "confirmed", 0, confirmed_ns, 4, confirmed_ns=confirmed_ns)
    tr._kf_t, tr._kf_x = confirmed_ns, np.array([xy, [0.0, 0.0]])
    return tr


def test_the_younger_of_two_coincident_tracks_goes_after_a_while_and_only_then():
    old, young, apart = _placed(7, (0.0, 0.0), 1 * S), _placed(3, (0.1, 0.0), 2 * S), _placed(9, (1.0, 0.0), 3 * S)
    people = [young, apart, old]  # any order: age is the confirmation time
    assert coincident(people, 10 * S, 0.3) == []  # close from now on
    assert coincident(people, 10 * S + int(MERGE_AFTER_S * S) - 1, 0.3) == []
    assert coincident(people, 10 * S + int(MERGE_AFTER_S * S), 0.3) == [young]
    young._kf_x[0] = (0.5, 0.0)  # walked apart: the clock restarts
    assert coincident(people, 20 * S, 0.3) == [] and young._close_since_ns is None


# --- through the tracker ------------------------------------------------------------------------

def _phantom_frames(duration_s: float, cams, seen_by_others: bool) -> list[Observation]:
    """c1 reports a static person at the origin in 4 frames of 5; the other cameras report empty
    frames (they look at the same spot and see nothing) or are not there at all."""
    out = []
    for k, (cam, t) in enumerate(schedule(duration_s, cams)):
        obs, _ = frame(cam, t, {"coat": (0.0, 0.0, 0.0, 100.0)} if cam.id == "c1" and k % 5 else {}, seed=k)
        out.append(obs)
    return out


@pytest.mark.parametrize("others_look, confirmed", [(True, False), (False, True)])
def test_a_person_only_one_of_three_cameras_reports_is_not_confirmed(others_look, confirmed):
    tr = Tracker(SITE)
    cams = CAMS if others_look else CAMS[:1]
    for obs in _phantom_frames(5.0, cams, others_look):
        tr.update(obs)
    assert len(tr.tracks) == 1
    assert (tr.tracks[0].state == "confirmed") == confirmed
    # the rule off: confirmed whatever the other cameras say
    off = Tracker(SITE, TrackerConfig(confirm_min_support=0.0))
    for obs in _phantom_frames(5.0, cams, others_look):
        off.update(obs)
    assert off.tracks[0].state == "confirmed"


def test_a_person_all_cameras_see_is_confirmed_as_before():
    tr = Tracker(SITE)
    for k, (cam, t) in enumerate(schedule(3.0)):
        tr.update(frame(cam, t, {"a": (0.3, -0.2, 0.0, 20.0)}, seed=k)[0])
    assert [p.state for p in tr.tracks] == ["confirmed"]
    assert tr.tracks[0]._support == tr.tracks[0]._chances or tr.tracks[0]._support / tr.tracks[0]._chances > 0.9


def _with_legs_twice(obs: Observation) -> Observation:
    """Each view also reported as a second skeleton of its legs alone, in other colours: the
    detector split one person in two (joints not shared with the first, so not one detection)."""
    extra = []
    for v in obs.people:
        kp = np.full((NUM_KEYPOINTS, 3), np.nan, np.float32)
        kp[11:] = v.keypoints[11:]
        kp[11:, :2] += 4.0
        if np.isnan(kp[:, 0]).all():
            continue
        lo, hi = np.nanmin(kp[:, :2], axis=0), np.nanmax(kp[:, :2], axis=0)
        v.keypoints[11:] = np.nan
        hist = np.roll(v.histogram, 40)
        extra.append(type(v)(kp, np.array([*lo, *hi], np.float32), hist))
    return Observation(obs.site, obs.camera, obs.seq, obs.stamp_ns, obs.width, obs.height, obs.people + tuple(extra))


@pytest.mark.parametrize("min_sep, tracks", [(0.3, 1), (0.0, 2)])
def test_a_second_skeleton_of_one_person_never_becomes_a_second_person(min_sep, tracks):
    tr = Tracker(SITE, TrackerConfig(min_separation_m=min_sep))
    for k, (cam, t) in enumerate(schedule(5.0, CAMS[:1])):
        tr.update(_with_legs_twice(frame(cam, t, {"a": (0.2, 0.1, 0.0, 20.0)}, seed=k)[0]))
        tr.prune(t)
    assert len(tr.people(T0 + 5 * S)) == tracks


def test_two_people_side_by_side_are_both_kept():
    tr = Tracker(SITE)
    people = {"a": (0.0, 0.0, 0.0, 20.0), "b": (0.0, 0.45, 0.0, 110.0)}  # shoulder to shoulder, 0.45 m apart
    for k, (cam, t) in enumerate(schedule(4.0)):
        tr.update(frame(cam, t, people, seed=k)[0])
        tr.prune(t)
    assert len(tr.people(T0 + 4 * S)) == 2 and tr.stats["merged"] == 0
