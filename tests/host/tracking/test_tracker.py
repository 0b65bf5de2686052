"""The tracker on synthetic observation sequences, with an injected clock.

Views are made here by projecting a simple 3D skeleton through synthetic cameras; colours are
synthetic hue-saturation patches, shifted a little per camera the way lighting does.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable

import cv2
import numpy as np
import pytest

from superbody.edge.body import NUM_KEYPOINTS, TYPICAL_HEIGHT_M
from superbody.edge.camera import Camera, look_at_rotation, project
from superbody.edge.colour import bhattacharyya, hs_histogram
from superbody.edge.messages.observation import Observation, PersonView, empty_histogram
from superbody.edge.site import Site
from superbody.host.tracking.association import assign, median_colour_distance
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.tracker import Tracker

S = 1_000_000_000  # ns per second
T0 = 1_700_000_000 * S  # a realistic UNIX time


# --- synthetic views -------------------------------------------------------------------------

def make_camera(cid: str, position: tuple[float, float, float], target=(0.0, 0.0, 1.0)) -> Camera:
    R = look_at_rotation(np.array(position), np.array(target))
    return Camera(
        id=cid, width=640, height=480, fps=10.0, fx=400.0, fy=400.0, cx=320.0, cy=240.0,
        position=position, rotation=tuple(tuple(float(v) for v in row) for row in R),
    )


CAMS = (
    make_camera("c1", (4.5, 4.5, 2.6)),
    make_camera("c2", (-4.5, 4.5, 2.6)),
    make_camera("c3", (0.0, -4.5, 2.6)),
)
SITE = Site(name="lab", cameras=CAMS, floor=((-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)))
C1, C2, C3 = CAMS
# Lighting differs between cameras: a small hue shift each.
HUE_SHIFT = {"c1": -2.0, "c2": 0.0, "c3": 2.0}


def skeleton(x: float, y: float, yaw: float = 0.0) -> np.ndarray:
    """(17, 3) world joints of a person standing at (x, y) facing ``yaw``: the typical joint
    heights, left joints offset to the person's left, right ones to the right."""
    lateral = np.array([0.0, 0.03, -0.03, 0.07, -0.07, 0.2, -0.2, 0.25, -0.25, 0.25, -0.25, 0.12, -0.12, 0.1, -0.1, 0.1, -0.1])
    forward = np.array([math.cos(yaw), math.sin(yaw)])
    left = np.array([-forward[1], forward[0]])
    xy = np.array([x, y]) + lateral[:, None] * left
    xy[:3] += 0.1 * forward  # the face is in front
    return np.column_stack([xy, TYPICAL_HEIGHT_M])


def colour(hue: float, shift: float = 0.0, seed: int = 0) -> np.ndarray:
    """HS histogram (16, 8) of a noisy patch of clothing of this hue (OpenCV's 0-180)."""
    rng = np.random.default_rng(seed)
    h = np.clip(rng.normal(hue + shift, 4.0, (24, 12)), 0, 179)
    s = np.clip(rng.normal(170.0, 25.0, (24, 12)), 0, 255)
    hsv = np.stack([h, s, np.full_like(h, 200.0)], axis=-1).astype(np.uint8)
    return hs_histogram(cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR))


def person_view(cam: Camera, x: float, y: float, yaw: float, hist: np.ndarray, keep: int = NUM_KEYPOINTS) -> PersonView | None:
    """The person seen by ``cam``; joints outside the image are missing, and only the first
    ``keep`` joints are kept. None when no joint is in the image."""
    uv, depth = project(skeleton(x, y, yaw), cam)
    inside = (depth > 0) & (uv >= 0).all(axis=1) & (uv[:, 0] < cam.width) & (uv[:, 1] < cam.height)
    inside[keep:] = False
    if not inside.any():
        return None
    kp = np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
    kp[inside, :2], kp[inside, 2] = uv[inside], 0.9
    bbox = np.array([*uv[inside].min(axis=0), *uv[inside].max(axis=0)], dtype=np.float32)
    return PersonView(kp, bbox, hist.astype(np.float32))


Person = tuple[float, float, float, float]  # x, y, yaw, hue


def frame(cam: Camera, t_ns: int, people: dict[str, Person], seed: int = 0) -> tuple[Observation, list[str]]:
    """One camera frame of these people (name -> (x, y, yaw, hue)) and the name behind each view."""
    views, names = [], []
    for k, (name, (x, y, yaw, hue)) in enumerate(people.items()):
        v = person_view(cam, x, y, yaw, colour(hue, HUE_SHIFT.get(cam.id, 0.0), seed * 101 + k))
        if v is not None:
            views.append(v)
            names.append(name)
    return Observation(SITE.name, cam.id, t_ns // 1_000_000, t_ns, cam.width, cam.height, tuple(views)), names


def run(tracker: Tracker, frames: Iterable[tuple[Observation, list[str]]]) -> dict[str, set[int]]:
    """Feed frames; return the track ids each true person's views went to."""
    went: dict[str, set[int]] = defaultdict(set)
    for obs, names in frames:
        for m in tracker.update(obs):
            if m.track_id is not None:
                went[names[m.view_index]].add(m.track_id)
    return dict(went)


def schedule(duration_s: float, cams: tuple[Camera, ...] = CAMS, fps: float = 10.0) -> list[tuple[Camera, int]]:
    """Frames of all cameras, interleaved: each camera at ``fps``, offset from the others."""
    period = round(S / fps)
    out = [(cam, T0 + k * period + j * period // len(cams)) for j, cam in enumerate(cams) for k in range(round(duration_s * fps))]
    return sorted(out, key=lambda ct: ct[1])


def walking(start: tuple[float, float], velocity: tuple[float, float], hue: float):
    """(t_ns -> Person) of someone walking at constant velocity, facing where they go."""
    yaw = math.atan2(velocity[1], velocity[0]) if any(velocity) else 0.0

    def at(t_ns: int) -> Person:
        t = (t_ns - T0) / S
        return (start[0] + velocity[0] * t, start[1] + velocity[1] * t, yaw, hue)

    return at


def one_person(t_ns: int, cam: Camera = C1, x: float = 0.0, seed: int = 0) -> Observation:
    return frame(cam, t_ns, {"a": (x, 0.0, 0.0, 20.0)}, seed)[0]


# --- configuration and bookkeeping ---------------------------------------------------------------

@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("confirm_after_s", -0.1),     # negative time
        ("remove_after_s", 0.0),       # must be positive
        ("d_max", 1.5),                # distances live in [0, 1]
        ("d_max", 0.0),                # nothing could match
        ("history_q", 0),              # at least one histogram
        ("history_q", 2.5),            # not an integer
        ("gate_m", math.inf),          # not finite
        ("use_geometry", "yes"),       # not a bool
        ("min_joints", 18),            # more than COCO-17 has
        ("confirm_max_gap_s", 0.0),    # must be positive
    ],
)
def test_config_is_validated(field, value):
    with pytest.raises(ValueError, match=field):
        TrackerConfig(**{field: value})


def test_empty_inputs():
    tr = Tracker(SITE)
    assert tr.update(Observation(SITE.name, "c1", 0, T0, 640, 480, ())) == []
    assert tr.prune(T0) == [] and tr.people(T0) == [] and tr.view_sets(T0) == {} and tr.tracks == []
    assert tr.stats["observations"] == 1 and tr.stats["views"] == 0


def test_each_tracker_issues_its_own_ids():
    a, b = Tracker(SITE, id_prefix="lab-"), Tracker(SITE)
    for tr in (a, b):
        tr.update(one_person(T0))
    assert a.tracks[0].id == b.tracks[0].id == 1
    assert a.tracks[0].label == "lab-1" and b.tracks[0].label == "1"


@pytest.mark.parametrize(
    ("obs", "counter"),
    [
        (Observation("elsewhere", "c1", 0, T0, 640, 480, ()), "wrong_site"),  # another site's camera
        (Observation("lab", "c9", 0, T0, 640, 480, ()), "unknown_camera"),    # not in the site file
    ],
)
def test_foreign_observations_are_counted_and_dropped(obs, counter):
    tr = Tracker(SITE)
    assert tr.update(obs) == [] and tr.stats[counter] == 1


@pytest.mark.parametrize(
    ("keep", "status", "counter"),
    [
        (2, "ignored", "too_few_joints"),       # nose and one eye: fewer than min_joints = 3
        (3, "ignored", "unplaced_new"),         # nose and eyes: enough to match someone, but nowhere on the floor
        (6, "created", None),                   # and the left shoulder: placed, a new candidate
        (17, "created", None),                  # everything
    ],
)
def test_views_with_too_few_joints_are_ignored(keep, status, counter):
    tr = Tracker(SITE)
    v = person_view(C1, 0.0, 0.0, 0.0, colour(20.0), keep=keep)
    (m,) = tr.update(Observation(SITE.name, "c1", 0, T0, 640, 480, (v,)))
    assert m.status == status
    for name in ("too_few_joints", "unplaced_new"):
        assert tr.stats[name] == (name == counter)


def test_a_poor_view_still_matches_an_existing_track():
    tr = Tracker(SITE)
    tr.update(one_person(T0))
    head = person_view(C2, 0.0, 0.0, 0.0, colour(20.0, seed=5), keep=3)  # nose and eyes only
    (m,) = tr.update(Observation(SITE.name, "c2", 0, T0 + S // 10, 640, 480, (head,)))
    assert m.status == "matched" and m.track_id == tr.tracks[0].id


@pytest.mark.parametrize(
    ("with_a", "newcomer_status"),
    [
        # Camera 2 sees only a view in other colours where A stands: A under other light (or a
        # partial view's odd colours), not a newcomer; no duplicate of A is started.
        (False, "ignored"),
        # Camera 2 sees A and, beside A, someone in other colours: that is a newcomer.
        (True, "created"),
    ],
)
def test_a_view_where_an_unseen_track_stands_does_not_start_a_duplicate(with_a, newcomer_status):
    tr = Tracker(SITE)
    for k in range(5):
        tr.update(one_person(T0 + k * S // 10, seed=k))
    people = {"a": (0.0, 0.0, 0.0, 20.0)} if with_a else {}
    people["b"] = (0.6, 0.0, 0.0, 110.0)
    obs, names = frame(C2, T0 + S // 2, people, seed=99)
    status = {names[m.view_index]: m.status for m in tr.update(obs)}
    assert status["b"] == newcomer_status
    assert tr.stats["suppressed"] == (not with_a)


def _unplaced(view: PersonView) -> PersonView:
    """The view without its ankles, hips, shoulders and knees, its box around what is left: no
    level gives a ground point (a box around a head and arms spans no person's height)."""
    kp = view.keypoints.copy()
    kp[5:7] = kp[11:] = np.nan
    uv = kp[~np.isnan(kp[:, 0]), :2]
    return PersonView(kp, np.array([*uv.min(axis=0), *uv.max(axis=0)], dtype=np.float32), view.histogram)


@pytest.mark.parametrize("use_geometry", [True, False])
def test_a_view_that_cannot_be_placed_on_the_floor_starts_nobody(use_geometry):
    # The demo's flake (3 people, seed 7): a camera saw a known person in its own light, with a
    # box that put them metres away (1-sigma 1.2 m); the view started a candidate, later
    # views of that camera kept it alive on colour alone, and it was confirmed: a duplicate
    # whose poses alternated with the real track's.
    tr = Tracker(SITE, TrackerConfig(use_geometry=use_geometry))
    for k in range(5):
        tr.update(one_person(T0 + k * S // 10, seed=k))
    v = _unplaced(person_view(C2, 0.0, 0.0, 0.0, colour(110.0)))
    assert v.num_visible >= 6  # more joints than the head: placed, it would start someone
    (m,) = tr.update(Observation(SITE.name, "c2", 0, T0 + S // 2, 640, 480, (v,)))
    assert tr.stats["no_ground_point"] == 1
    # With geometry a newcomer must be placed; the paper's tracker has no floor to place them on.
    assert m.status == ("ignored" if use_geometry else "created")
    assert tr.stats["unplaced_new"] == use_geometry


def test_view_without_colour_or_ground_is_ignored():
    kp = np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
    kp[:5] = (320.0, 0.0, 0.9)  # a head at the top row: its floor point is far beyond range
    v = PersonView(kp, np.zeros(4, np.float32), empty_histogram())
    tr = Tracker(SITE)
    (m,) = tr.update(Observation(SITE.name, "c1", 0, T0, 640, 480, (v,)))
    assert m.status == "ignored" and tr.stats["no_signature"] == 1 and tr.tracks == []


# --- confirmation and removal ---------------------------------------------------------------------

@pytest.mark.parametrize("fps", [10.0, 15.0, 30.0])  # frame periods that do and do not divide 2 s
def test_confirms_after_exactly_two_seconds_of_matches(fps):
    tr = Tracker(SITE)
    for k in range(round(3 * fps)):
        t = T0 + round(k * S / fps)
        tr.update(one_person(t, seed=k))
        (track,) = tr.tracks
        if t - T0 < 2 * S:
            assert track.state == "candidate" and tr.people(t) == []
        else:
            assert track.state == "confirmed"
    assert track.confirmed_ns == T0 + round(math.ceil(2 * fps - 1e-9) * S / fps)
    assert tr.stats["confirmed"] == 1 and tr.stats["new_candidates"] == 1


@pytest.mark.parametrize(
    "stamps_ms",
    [
        list(range(0, 60)),                          # 60 frames captured 1 ms apart: a burst
        [0, 0, 0, 10, 10, 10, 20, 20, 20],           # three cameras, one burst of the same instants
    ],
)
def test_a_burst_does_not_confirm(stamps_ms):
    tr = Tracker(SITE)
    for k, ms in enumerate(stamps_ms):
        assert tr.update(one_person(T0 + ms * 1_000_000, cam=CAMS[k % 3], seed=k))
    (track,) = tr.tracks
    assert track.state == "candidate"


def test_a_gap_restarts_the_confirmation_clock():
    tr = Tracker(SITE, TrackerConfig(confirm_max_gap_s=1.0))
    restart = 17 * S // 10
    stamps = [k * S // 10 for k in range(6)] + [restart + k * S // 10 for k in range(25)]  # 0-0.5 s, 1.2 s gap, 1.7-4.1 s
    for k, t in enumerate(stamps):
        tr.update(one_person(T0 + t, seed=k))
    (track,) = tr.tracks
    assert track.confirmed_ns == T0 + restart + 2 * S


@pytest.mark.parametrize(
    ("confirmed", "unseen_s", "removed"),
    [
        (True, 1.9, False),    # a person unseen for a while is kept
        (True, 2.0, True),     # ... and removed at 2 s
        (False, 1.9, False),   # a candidate likewise
        (False, 2.0, True),    # ... dropped at 2 s
        (True, 0.0, False),    # just seen
    ],
)
def test_removal_after_two_seconds_unseen(confirmed, unseen_s, removed):
    tr = Tracker(SITE)
    n = 21 if confirmed else 5
    for k in range(n):
        tr.update(one_person(T0 + k * S // 10, seed=k))
    last = T0 + (n - 1) * S // 10
    now = last + round(unseen_s * S)
    gone = tr.prune(now)
    assert bool(gone) == removed and len(tr.tracks) == (not removed)
    assert tr.stats["removed"] == (removed and confirmed)
    assert tr.stats["dropped_candidates"] == (removed and not confirmed)
    if confirmed and not removed:
        assert len(tr.people(now)) == 1


def test_a_removed_person_comes_back_as_a_new_candidate():
    tr = Tracker(SITE)
    for k in range(21):
        tr.update(one_person(T0 + k * S // 10, seed=k))
    tr.prune(T0 + 5 * S)
    (m,) = tr.update(one_person(T0 + 5 * S))
    assert m.status == "created" and m.track_id == 2


# --- several people, several cameras ------------------------------------------------------------

def test_distinct_colours_crossing_three_cameras_no_swaps():
    a = walking((-2.0, -0.3), (1.0, 0.0), hue=20.0)   # orange, walking +x
    b = walking((2.0, 0.3), (-1.0, 0.0), hue=110.0)   # blue, walking -x; they pass at t = 2 s
    tr = Tracker(SITE)
    went = run(tr, (frame(cam, t, {"a": a(t), "b": b(t)}, seed=k) for k, (cam, t) in enumerate(schedule(4.0))))
    assert len(went["a"]) == len(went["b"]) == 1 and went["a"] != went["b"]
    assert len(tr.tracks) == 2 and len(tr.people(T0 + 4 * S)) == 2
    assert tr.stats["matched"] > 0 and tr.stats["new_candidates"] == 2


@pytest.mark.parametrize(
    ("use_geometry", "identities_kept"),
    [
        (True, True),    # the gate keeps each person's views on their own track
        (False, False),  # colour alone (the paper's tracker) lets camera 2 hand A's views to B
    ],
)
def test_similar_colours_walking_apart_need_the_gate(use_geometry, identities_kept):
    # A in hue 100 and B in hue 106: similar (distance ~0.5 < d_max). Camera 2's lighting shifts
    # hue by +6, so there A looks just like B; and camera 2 sees only A (B is behind a pillar).
    a = walking((-1.0, 0.0), (-0.5, 0.0), hue=100.0)
    b = walking((1.0, 0.0), (0.5, 0.0), hue=106.0)
    shift = {"c1": 0.0, "c2": 6.0, "c3": 0.0}
    assert 0.3 < median_colour_distance(colour(100.0).reshape(1, -1), colour(106.0, seed=1).reshape(1, 1, -1), np.array([1]))[0, 0] < 0.65
    tr = Tracker(SITE, TrackerConfig(use_geometry=use_geometry))
    went: dict[str, set[int]] = defaultdict(set)
    for k, (cam, t) in enumerate(schedule(4.0)):
        people = {"a": a(t)} if cam is C2 else {"a": a(t), "b": b(t)}
        views = [person_view(cam, *p[:3], colour(p[3], shift[cam.id], k * 7 + j)) for j, p in enumerate(people.values())]
        obs = Observation(SITE.name, cam.id, k, t, 640, 480, tuple(views))
        for m in tr.update(obs):
            went[list(people)[m.view_index]].add(m.track_id)
    kept = len(went["a"]) == len(went["b"]) == 1 and went["a"] != went["b"]
    assert kept == identities_kept


def test_position_estimate_follows_a_walker():
    p = walking((-2.0, -1.0), (1.0, 0.5), hue=60.0)
    tr = Tracker(SITE)
    run(tr, (frame(cam, t, {"p": p(t)}, seed=k) for k, (cam, t) in enumerate(schedule(3.0))))
    (track,) = tr.tracks
    x, y, _, _ = p(track.position_stamp_ns)
    assert np.linalg.norm(track.position - (x, y)) < 0.1
    assert np.allclose(track.velocity, (1.0, 0.5), atol=0.2)
    ahead, std = track.predict_position(track.position_stamp_ns + S // 2)
    assert np.linalg.norm(ahead - p(track.position_stamp_ns + S // 2)[:2]) < 0.2 and std > track.position_std


# --- colour ------------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "counts",
    [
        [0],           # a track with no histogram yet: unknown
        [1],           # one histogram: the distance to it
        [2, 3],        # even and odd counts: the two middle values averaged, or the middle one
        [10, 4, 7],    # a full history beside partial ones
    ],
)
def test_median_colour_distance_is_the_median_over_each_history(counts):
    rng = np.random.default_rng(len(counts))
    views = rng.random((3, 128))
    views[2] = 0.0  # an empty histogram: unknown against everyone
    history = rng.random((len(counts), 10, 128))
    got = median_colour_distance(views, history, np.array(counts))
    assert got.shape == (3, len(counts))
    for i in range(3):
        for j, c in enumerate(counts):
            want = np.median([bhattacharyya(views[i], history[j, q]) for q in range(c)]) if c and i < 2 else np.nan
            assert got[i, j] == pytest.approx(want, nan_ok=True)


def test_median_colour_distance_empty():
    assert median_colour_distance(np.zeros((0, 128)), np.zeros((2, 10, 128)), np.array([1, 1])).shape == (0, 2)
    assert median_colour_distance(np.zeros((2, 128)), np.zeros((0, 10, 128)), np.array([], int)).shape == (2, 0)


def test_track_keeps_its_last_q_histograms_and_reports_the_median():
    tr = Tracker(SITE, TrackerConfig(history_q=4))
    for k in range(7):
        (m,) = tr.update(one_person(T0 + k * S // 10, seed=k))
    (track,) = tr.tracks
    hist = track.histograms
    assert hist.shape == (4, 16, 8)
    assert np.array_equal(hist[-1], one_person(T0, seed=6).people[0].histogram)  # newest last
    # The reported distance is the median over the history as it was before this view.
    before = np.stack([one_person(T0, seed=k).people[0].histogram for k in range(2, 6)])
    want = median_colour_distance(hist[-1].reshape(1, -1), before.reshape(1, 4, -1), np.array([4]))[0, 0]
    assert m.colour_distance == pytest.approx(want)


# --- joint assignment -------------------------------------------------------------------------------

def _greedy(cost: np.ndarray, feasible: np.ndarray) -> int:
    """Matches a greedy, row-by-row cheapest-first assignment makes (for comparison)."""
    taken, n = set(), 0
    for r in range(len(cost)):
        options = [c for c in np.argsort(cost[r]) if feasible[r, c] and c not in taken]
        if options:
            taken.add(options[0])
            n += 1
    return n


@pytest.mark.parametrize(
    ("cost", "feasible", "pairs"),
    [
        # Greedy gives row 0 its cheapest column 0 and leaves row 1 with nothing; jointly both match.
        ([[0.1, 0.2], [0.25, 9.0]], [[True, True], [True, False]], {(0, 1), (1, 0)}),
        # Plain minimum cost when everything is feasible.
        ([[0.1, 0.9], [0.8, 0.2]], [[True, True], [True, True]], {(0, 0), (1, 1)}),
        # More rows than columns: the cheapest row wins, the other stays unmatched.
        ([[0.5], [0.1], [0.3]], [[True], [True], [True]], {(1, 0)}),
        # Nothing feasible: nothing matched.
        ([[0.1, 0.2]], [[False, False]], set()),
        # Empty: no views.
        (np.zeros((0, 3)), np.zeros((0, 3), bool), set()),
        # Empty: no tracks.
        (np.zeros((2, 0)), np.zeros((2, 0), bool), set()),
    ],
)
def test_assign(cost, feasible, pairs):
    rows, cols = assign(np.array(cost, float), np.array(feasible, bool))
    assert set(zip(rows.tolist(), cols.tolist())) == pairs
    assert len(pairs) >= _greedy(np.array(cost, float), np.array(feasible, bool))


def test_joint_assignment_beats_greedy_in_the_tracker():
    same = 40.0  # everyone in the same colour: only geometry tells them apart
    tr = Tracker(SITE)
    run(tr, (frame(cam, t, {"p": (0.0, 0.0, 0.0, same), "q": (0.0, 0.6, 0.0, same)}, seed=k)
             for k, (cam, t) in enumerate(schedule(1.0))))
    t1, t2 = tr.tracks
    assert np.allclose(t1.position, (0.0, 0.0), atol=0.1) and np.allclose(t2.position, (0.0, 0.6), atol=0.1)
    # Next frame, from c3 (at y = -4.5, looking along y: its ground points are unsure in y): view A
    # at y = 0.2 is nearest track 1; view B at y = -0.3 can only be track 1 (0.9 m from track 2,
    # beyond one body's 3 sigmas). Greedy nearest-first gives A to track 1 and strands B.
    t = T0 + S
    obs, _ = frame(C3, t, {"A": (0.0, 0.2, 0.0, same), "B": (0.0, -0.3, 0.0, same)}, seed=999)
    matches = tr.update(obs)
    assert [m.status for m in matches] == ["matched", "matched"]
    assert [m.track_id for m in matches] == [t2.id, t1.id]


# --- set S -----------------------------------------------------------------------------------------

def test_view_sets_hold_each_persons_fresh_views():
    tr = Tracker(SITE)
    for k in range(21):  # confirmed by c1 over 2 s
        tr.update(one_person(T0 + k * S // 10, cam=C1, seed=k))
    last_c1 = T0 + 2 * S
    tr.update(one_person(last_c1 - 3 * S // 10, cam=C2))  # c2 saw them 0.3 s before c1's last
    tr.update(one_person(T0, cam=C3))  # c3 long ago
    tr.update(one_person(last_c1, cam=C1, x=3.0))  # someone else: a candidate
    (pid,) = [p.id for p in tr.people(last_c1)]
    assert set(tr.view_sets(last_c1)[pid]) == {"c1", "c2"}  # c3's view is stale
    assert set(tr.view_sets(last_c1 + 3 * S // 10)[pid]) == {"c1"}  # c2's is 0.6 s old now
    assert set(tr.view_sets(last_c1 + 3 * S // 10, freshness_s=1.0)[pid]) == {"c1", "c2"}
    assert tr.view_sets(last_c1 + S) == {}  # nobody fresh: left out
    assert tr.view_sets(last_c1)[pid]["c1"] is tr.tracks[0].views["c1"].view
    with pytest.raises(ValueError, match="freshness_s"):
        tr.view_sets(last_c1, freshness_s=0.0)


def test_ten_people_in_one_camera_stay_ten_tracks():
    """Speed is measured by benchmarks/host_bench.py; here only that ten people stay ten tracks."""
    people = {f"p{i}": (-2.0 + i % 5, -1.0 + 2.0 * (i // 5), 0.0, 17.0 * i) for i in range(10)}
    frames = [frame(C3, T0 + k * S // 10, people, seed=k)[0] for k in range(30)]
    tr = Tracker(SITE)
    for obs in frames:
        tr.update(obs)
    assert len(tr.tracks) == 10


# --- re-identification of people who were out of every camera's view ------------------------------

def _confirm_then_lose(tr: Tracker, people: dict[str, Person], seconds: float = 3.0) -> int:
    """Track ``people`` (all in C1) for ``seconds``, then let ``remove_after_s`` pass unseen."""
    for k in range(round(seconds * 10)):
        tr.update(frame(C1, T0 + k * S // 10, people, seed=k)[0])
    end = T0 + round(seconds * S)
    assert len(tr.people(end)) == len(people)
    tr.prune(end + 3 * S)
    assert tr.people(end + 3 * S) == []
    return end + 3 * S


@pytest.mark.parametrize(
    ("back_x", "back_hue", "after_s", "same_id"),
    [
        (0.0, 20.0, 5.0, True),     # the same person back where they left: their id again
        (2.0, 20.0, 5.0, True),     # ... 2 m away after 5 s: walkable
        (0.0, 110.0, 5.0, False),   # someone in other clothes: a new id
        (0.0, 20.0, 40.0, False),   # back after the 30 s window: forgotten, a new id
    ],
)
def test_a_person_back_after_leaving_every_view_gets_their_id_back(back_x, back_hue, after_s, same_id):
    tr = Tracker(SITE)
    t = _confirm_then_lose(tr, {"a": (0.0, 0.0, 0.0, 20.0)}) + round(after_s * S)
    for k in range(25):  # 2.5 s: long enough to confirm
        tr.update(frame(C1, t + k * S // 10, {"a": (back_x, 0.0, 0.0, back_hue)}, seed=100 + k)[0])
    (person,) = tr.people(t + 25 * S // 10)
    assert (person.id == 1) == same_id and tr.stats["reidentified"] == int(same_id)


def test_reidentification_needs_a_clear_winner():
    # Two people in the same clothes leave together: who comes back is ambiguous, so a new id.
    tr = Tracker(SITE)
    t = _confirm_then_lose(tr, {"a": (-1.0, 0.0, 0.0, 20.0), "b": (1.0, 0.0, 0.0, 20.0)})
    for k in range(25):
        tr.update(frame(C1, t + k * S // 10, {"a": (-1.0, 0.0, 0.0, 20.0)}, seed=100 + k)[0])
    assert [p.id for p in tr.people(t + 25 * S // 10)] == [3] and tr.stats["reidentified"] == 0


@pytest.mark.parametrize(("hue_b", "same_id"), [(20.0, True), (110.0, False)])
def test_a_candidate_that_took_a_persons_views_is_that_person(hue_b, same_id):
    # A second skeleton of someone, 0.8 m to their side, starts a candidate; 0.5 s later their own
    # views stop (their track can no longer take them) and only that skeleton's go on. The
    # candidate is confirmed 2 s after it began, before the person's track is removed (2 s after
    # their last view): it is that person, and keeps their id. In other clothes (someone who came
    # in as the person left), it is someone else.
    tr = Tracker(SITE)
    frames = schedule(6.0)
    lost_at = T0 + 3 * S  # the person's own views stop here
    ids_after: set[int] = set()
    for cam, t in frames:
        people = {}
        if t < lost_at:
            people["a"] = (0.0, 0.0, 0.0, 20.0)
        if t >= lost_at - S // 2:
            people["b"] = (0.8, 0.0, 0.0, hue_b)
        tr.update(frame(cam, t, people, seed=t // (S // 10))[0])
        tr.prune(t)
        if t >= lost_at + 5 * S // 2:
            ids_after |= {p.id for p in tr.people(t)}
    assert tr.stats["confirmed"] == 2  # the person, then the candidate
    assert (ids_after == {1}) == same_id and tr.stats["reidentified"] == int(same_id), (ids_after, tr.stats)


# --- a cap on tracks --------------------------------------------------------------------------------

def test_a_flood_of_copies_is_one_detection_and_people_already_tracked_keep_their_ids():
    # A flood: 70 copies of one view per frame besides a real person, 5 frames/s for 10 s.
    tr = Tracker(SITE)
    real = {"a": (-2.0, 0.0, 0.0, 110.0)}
    for k in range(25):
        tr.update(frame(C1, T0 + k * S // 10, real, seed=k)[0])
    (person,) = tr.people(T0 + 25 * S // 10)
    fake = frame(C1, T0, {"f": (2.0, 1.0, 0.0, 20.0)})[0].people[0]
    for k in range(50):
        t = T0 + 25 * S // 10 + k * S // 5
        obs = frame(C1, t, real, seed=k)[0]
        obs = Observation(obs.site, obs.camera, obs.seq, t, obs.width, obs.height, obs.people + (fake,) * 70)
        ms = tr.update(obs)
        assert ms[0].track_id == person.id  # the real person keeps their id
        assert [m.status for m in ms[2:]] == ["ignored"] * 69  # the copies of the one kept
    assert tr.stats["duplicate_views"] == 50 * 69 and len(tr.tracks) == 2 and len(tr.people(t)) == 2


def test_tracks_are_capped_and_people_already_tracked_keep_their_ids():
    # More distinct people than the cap, every frame: the cap holds, the tracked person stays.
    tr = Tracker(SITE, TrackerConfig(max_tracks=3))
    real = {"a": (-2.0, 0.0, 0.0, 110.0)}
    for k in range(25):
        tr.update(frame(C1, T0 + k * S // 10, real, seed=k)[0])
    (person,) = tr.people(T0 + 25 * S // 10)
    crowd = {**real, **{f"f{j}": (-1.0 + 0.9 * j, 1.5, 0.0, 20.0 + 30 * j) for j in range(5)}}
    for k in range(20):
        t = T0 + 25 * S // 10 + k * S // 5
        ms = tr.update(frame(C1, t, crowd, seed=k)[0])
        assert person.id in [m.track_id for m in ms]  # the real person keeps their id
        assert len(tr.tracks) <= 3
    assert tr.stats["track_cap"] > 0


def test_a_full_tracker_makes_room_by_evicting_the_stalest_candidate():
    tr = Tracker(SITE, TrackerConfig(max_tracks=2))
    tr.update(frame(C1, T0, {"a": (-2.0, 0.0, 0.0, 20.0), "b": (2.0, 0.0, 0.0, 110.0)})[0])
    ms = tr.update(frame(C1, T0 + S // 10, {"c": (0.0, 2.0, 0.0, 60.0)})[0])
    assert [m.status for m in ms] == ["created"] and len(tr.tracks) == 2 and tr.stats["evicted_candidates"] == 1


def test_position_filter_is_two_textbook_axes_for_a_point_alike_in_every_direction():
    # The tracker's (x, y, vx, vy) filter against host.filtering.kalman's textbook steps run on each
    # axis's (position, velocity) alone, on random states whose axes share a covariance.
    from superbody.host.filtering.kalman import continuous_accel_noise, predict, update
    from superbody.host.tracking.motion import predict_positions, update_positions

    rng = np.random.default_rng(4)
    B = 7
    x = rng.normal(size=(B, 2, 2))
    A = rng.normal(size=(B, 2, 2))
    P2 = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(2)  # (B, 2, 2) symmetric positive definite
    dt = rng.uniform(0.0, 1.5, B)
    z, R = rng.normal(size=(B, 2)), rng.uniform(0.01, 1.0, B)
    xg, Pg = predict_positions(x, np.kron(P2, np.eye(2)), dt, 2.0)
    xg, Pg = update_positions(xg, Pg, z, R[:, None, None] * np.eye(2))
    F = np.tile(np.eye(2), (B, 1, 1))
    F[:, 0, 1] = dt
    for a in range(2):  # each axis: (position, velocity), its column of x
        xa, Pa = predict(x[:, :, a, None], P2, F, continuous_accel_noise(dt, 4.0))
        xa, Pa = update(xa, Pa, z[:, a, None, None], np.array([[1.0, 0.0]]), R[:, None, None])
        assert np.allclose(xg[:, :, a], xa[:, :, 0], atol=1e-12)
        assert np.allclose(Pg[:, a::2, a::2], Pa, atol=1e-12)
    assert np.allclose(Pg[:, 0::2, 1::2], 0.0)  # and the axes stay apart


def test_a_point_sure_across_its_line_of_sight_pins_the_track_down_across_it():
    from superbody.host.tracking.motion import update_positions

    x, P = np.zeros((1, 2, 2)), np.diag([0.3**2, 0.3**2, 1.0, 1.0])[None]
    R = np.diag([0.3**2, 0.05**2])[None]  # a camera on the x axis: unsure in x (its range), sure in y
    x, P = update_positions(x, P, np.array([[0.2, 0.2]]), R)
    assert np.isclose(x[0, 0, 0], 0.1) and x[0, 0, 1] > 0.19  # x halfway (two equal sigmas); y nearly all the way
    assert np.isclose(P[0, 0, 0], 0.3**2 / 2) and P[0, 1, 1] < 0.05**2
