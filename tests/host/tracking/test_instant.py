"""One instant's frames, all cameras' views, associated with the tracks at once (``Tracker.update_instant``)."""

from __future__ import annotations

import numpy as np

from superbody.host.tracking.motion import posterior, update_positions
from superbody.host.tracking.tracker import Tracker
from tests.host.tracking.test_tracker import C1, C2, C3, CAMS, SITE, T0, S, frame, run, schedule

_HUE = 20.0  # one colour for everybody: only where they stand tells them apart


def _standing(tracker: Tracker, people: dict[str, tuple[float, float, float, float]], seconds: float) -> dict[str, set[int]]:
    """Everybody standing still for ``seconds`` from T0, seen by all three cameras; the ids each went to."""
    return run(tracker, [frame(cam, t, people, seed=k) for k, (cam, t) in enumerate(schedule(seconds))])


def test_a_newcomer_seen_by_every_camera_in_one_instant_starts_one_candidate():
    tr = Tracker(SITE)
    frames = [frame(cam, T0 + j * S // 100, {"a": (0.5, 0.5, 0.0, _HUE)}, seed=j)[0] for j, cam in enumerate(CAMS)]
    went = {m.track_id for ms in tr.update_instant(frames) for m in ms}
    assert len(went) == 1 and None not in went
    assert [m.status for ms in tr.update_instant([]) for m in ms] == []  # an empty instant changes nothing
    assert len(tr.tracks) == 1 and tr.tracks[0].hits == 3


def test_the_other_cameras_of_the_instant_decide_a_view_the_predictions_cannot():
    """Two people in one colour, A at (0, 0) and B at (1, 0); unseen for 1.5 s, A steps to
    (0.7, 0). Camera c1 sees only A, and first: against the tracks' predictions A's view is
    nearer B's (0.3 m against 0.7 m). c2 and c3 see both, A at 0.7 and B at 1.0 still: where
    they place each track, c1's view is A's."""
    tr = Tracker(SITE)
    went = _standing(tr, {"a": (0.0, 0.0, 0.0, _HUE), "b": (1.0, 0.0, 0.0, _HUE)}, 3.0)
    assert all(len(ids) == 1 for ids in went.values()) and went["a"] != went["b"]
    (a,), (b,) = went["a"], went["b"]
    t = T0 + round(4.5 * S)
    now = {"a": (0.7, 0.0, 0.0, _HUE), "b": (1.0, 0.0, 0.0, _HUE)}
    f1, names1 = frame(C1, t, {"a": now["a"]}, seed=7)
    rest = [frame(cam, t + (j + 1) * S // 30, now, seed=8 + j) for j, cam in enumerate((C2, C3))]
    matches = tr.update_instant([f1] + [f for f, _ in rest])
    assert names1 == ["a"] and [m.track_id for m in matches[0]] == [a]
    for ms, (_, names) in zip(matches[1:], rest, strict=True):
        assert {names[m.view_index]: m.track_id for m in ms} == {"a": a, "b": b}


def test_a_posterior_in_information_form_is_the_kalman_filter_point_after_point():
    rng = np.random.default_rng(3)
    xy, cov = rng.normal(size=(3, 2)), np.array([np.diag([0.2, 0.5]), np.eye(2), [[0.3, 0.1], [0.1, 0.2]]])
    z = rng.normal(size=(3, 2, 2))
    R = np.array([[[[0.04, 0.01], [0.01, 0.09]], 0.5 * np.eye(2)]] * 3)
    z[1, 1] = np.nan  # the second track has one point, the first and third two
    got_xy, got_cov = posterior(xy, cov, z, R)
    for m in range(3):
        x, P = np.array([xy[m], [0.0, 0.0]])[None], np.zeros((1, 4, 4))
        P[0, :2, :2], P[0, 2:, 2:] = cov[m], np.eye(2)
        for g in range(2):
            if np.isfinite(z[m, g]).all():
                x, P = update_positions(x, P, z[m, g][None], R[m, g][None])
        assert np.allclose(got_xy[m], x[0, 0]) and np.allclose(got_cov[m], P[0, :2, :2])
    nowhere = np.full((1, 2), np.nan)
    assert np.isnan(posterior(nowhere, np.full((1, 2, 2), np.nan), z[:1], R[:1])[0]).all()  # no position: none after
