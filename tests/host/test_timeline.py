"""The cameras' timelines (host.timeline): admission once per frame, delays and rates measured, the
watermark, release in capture order, the rate limit and the problems the status reports."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.messages.observation import Observation
from superbody.edge.site import Site
from superbody.host.timeline import DISORDER_MIN, RateLimit, Timeline

S = 1_000_000_000  # ns per second
MS = 1_000_000
T0 = 1_700_000_000 * S


def _cam(cid: str, fps: float = 10.0) -> Camera:
    pos = np.array([0.0, -4.0, 2.5])
    return Camera(cid, 640, 480, fps, 500.0, 500.0, 320.0, 240.0, np.zeros(5), look_at_rotation(pos, np.array([0.0, 0.0, 1.0])), pos)


SITE = Site(name="lab", cameras=(_cam("c1"), _cam("c2"), _cam("c3", fps=5.0)), floor=((-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)))


def frame(cam: str, t_ns: int, seq: int = 0) -> Observation:
    return Observation("lab", cam, seq, t_ns, 640, 480, ())


def timeline(max_delay_s: float = 1.5, start_ns: int | None = T0) -> Timeline:
    return Timeline(SITE, max_delay_s=max_delay_s, remove_after_s=2.0, restart_gap_s=1.0, start_ns=start_ns)


# --- admission: in order per camera, once --------------------------------------------------------

@pytest.mark.parametrize(
    ("frames", "reasons"),
    [
        # (camera, stamp ms, seq, host clock ms) per frame
        ([("c1", 0, 0, 5), ("c1", 100, 1, 105), ("c1", 100, 2, 205)], [None, None, "duplicate"]),       # same stamp again
        ([("c1", 0, 5, 5), ("c1", 100, 5, 105)], [None, "duplicate"]),                                 # same frame re-stamped
        ([("c1", 0, 5, 5), ("c1", 100, 4, 105)], [None, "seq_backwards"]),                             # seq back, no restart
        ([("c1", 0, 5, 5), ("c1", 1500, 0, 1505)], [None, None]),                                      # seq back after 1.5 s: a restart
        ([("c1", 0, 0, 5), ("c1", 900, 1, 5), ("c1", 70, 2, 75), ("c1", 140, 3, 145)], [None] * 4),    # 0.9 s ahead blinds nothing
        ([("c1", 0, 0, 5), ("c1", 900, 1, 5), ("c1", 900, 2, 910)], [None, None, "duplicate"]),
        ([("c1", 100, 0, 105), ("c1", 50, 1, 110)], [None, "late"]),                                   # older than its last
        ([("c1", 100, 0, 105), ("c2", 50, 0, 110), ("c1", 200, 1, 205)], [None, None, None]),          # order is per camera
        ([("c1", 100, 0, 105), ("c1", 0, 1, 110), ("c1", 50, 2, 115), ("c1", 150, 3, 155)], [None, "late", "late", None]),
        ([("c1", 0, 0, 2500)], ["stale"]),                                                             # older than remove_after_s
        ([("c9", 0, 0, 5)], ["unknown_camera"]),                                                       # not in the site file
    ],
)
def test_frames_are_admitted_in_order_per_camera_whatever_their_stamps(frames, reasons):
    tl = timeline()
    got = [tl.admit(frame(cam, T0 + t * MS, seq), T0 + now * MS) for cam, t, seq, now in frames]
    assert got == reasons
    for why in {r for r in reasons if r not in (None, "unknown_camera")}:
        assert sum(c.dropped[why] for c in tl.cameras.values()) == reasons.count(why)


def test_reset_camera_admits_a_restarted_node_at_once():
    tl = timeline()
    assert tl.admit(frame("c1", T0, 50), T0) is None
    assert tl.admit(frame("c1", T0 + S // 10, 0), T0 + S // 10) == "seq_backwards"
    tl.reset_camera("c1")
    assert tl.admit(frame("c1", T0 + S // 5, 0), T0 + S // 5) is None


# --- measurement ---------------------------------------------------------------------------------

def test_delay_period_and_rate_are_measured_per_camera():
    tl = timeline()
    rng = np.random.default_rng(0)
    for k in range(100):
        t = T0 + k * S // 10
        tl.admit(frame("c1", t, k), t + 800 * MS + int(rng.normal(0, 20) * MS))  # 10 fps, 0.8 s late, 20 ms jitter
        if k % 2 == 0:
            tl.admit(frame("c3", t + 30 * MS, k), t + 130 * MS)  # 5 fps, 0.1 s late
    c1, c3 = tl.cameras["c1"], tl.cameras["c3"]
    assert c1.delay_s(50) == pytest.approx(0.8, abs=0.01) and 0.82 < c1.delay_s(95) < 0.9
    assert c1.fps == pytest.approx(10.0) and c3.fps == pytest.approx(5.0) and c3.delay_s(50) == pytest.approx(0.1)
    assert np.isnan(tl.cameras["c2"].delay_s(50)) and np.isnan(tl.cameras["c2"].fps) and tl.cameras["c2"].period_s == pytest.approx(0.1)


# --- the watermark and release -------------------------------------------------------------------

def test_the_watermark_waits_for_the_latest_camera_and_releases_in_capture_order():
    tl = timeline(start_ns=T0)  # started with the cameras: it waits for those it has not heard of yet
    delays = {"c1": 100 * MS, "c2": 1200 * MS, "c3": 400 * MS}
    arrivals = sorted((T0 + k * S // 10 + j * 7 * MS + delays[c], c, T0 + k * S // 10 + j * 7 * MS)
                      for k in range(40) for j, c in enumerate(delays))
    released: list[Observation] = []
    marks = []
    for k, (arrive, cam, stamp) in enumerate(arrivals):
        assert tl.admit(frame(cam, stamp, k), arrive) is None  # nobody is too late: everyone waits for c2
        marks.append((arrive, tl.watermark(arrive)))
        released += tl.release(1000)
    stamps = [o.stamp_ns for o in released]
    assert stamps == sorted(stamps)  # one capture order across all cameras
    assert {o.camera for o in released} == set(delays)
    # The watermark trails the host's clock by c2's delay (and at most a frame more), never more.
    lag = [(now - mark) / S for now, mark in marks[len(marks) // 2:]]
    assert 1.2 <= min(lag) and max(lag) <= 1.2 + 0.1 + 0.03
    # Every frame released was captured no later than the watermark when it was released.
    assert max(stamps) <= tl.mark_ns


def test_a_camera_later_than_max_delay_holds_nobody_back_and_its_frames_are_too_late():
    tl = timeline(max_delay_s=1.0, start_ns=T0 - 10 * S)
    whys = []
    for k in range(50):
        t = T0 + k * S // 10
        tl.admit(frame("c1", t, k), t + 50 * MS)
        tl.admit(frame("c2", t + 3 * MS, k), t + 53 * MS)
        tl.watermark(t + 60 * MS)
        whys.append(tl.admit(frame("c3", t - 1500 * MS, k), t + 60 * MS))  # 1.5 s after capture
        tl.release(1000)
    now = T0 + 49 * S // 10 + 60 * MS
    assert now - tl.mark_ns < 0.2 * S  # the others are fused within a frame or two
    assert whys.count("too_late") >= 45 and tl.cameras["c3"].dropped["too_late"] == whys.count("too_late")
    problems = tl.problems(now)
    assert problems["c3"][0].startswith("too_late:") and problems["c1"] == [] and problems["c2"] == []


def test_just_started_the_watermark_waits_for_cameras_not_heard_of_yet():
    tl = timeline(max_delay_s=1.5, start_ns=T0)
    assert tl.admit(frame("c1", T0, 0), T0 + 10 * MS) is None
    assert tl.watermark(T0 + 20 * MS) == T0 + 20 * MS - int(1.5 * S)
    assert tl.admit(frame("c2", T0 - 900 * MS, 0), T0 + 100 * MS) is None  # a slow camera's first frame is not too late
    assert [o.camera for o in (tl.watermark(T0 + 1700 * MS), tl.release(10))[1]] == ["c2", "c1"]


def test_a_slow_camera_that_joins_late_stops_the_watermark_until_it_catches_up():
    tl = timeline(start_ns=T0 - 10 * S)
    for k in range(30):  # c1 and c2, 0.1 s late; c3 joins at 1 s, 0.6 s late
        t = T0 + k * S // 10
        tl.admit(frame("c1", t, k), t + 100 * MS)
        tl.admit(frame("c2", t + 2 * MS, k), t + 102 * MS)
        if k >= 10:
            tl.admit(frame("c3", t - 500 * MS + 4 * MS, k), t + 104 * MS)
        tl.watermark(t + 105 * MS)
    c3 = tl.cameras["c3"]
    assert c3.dropped["too_late"] == 0 and c3.admitted == 20  # its first frames, behind the watermark, are used all the same
    assert (T0 + 29 * S // 10 + 105 * MS) - tl.mark_ns == pytest.approx(0.6 * S, abs=0.11 * S)  # everyone waits for it
    assert tl.problems(T0 + 3 * S)["c3"] == []
    released = tl.release(1000)
    assert {o.camera for o in released} == {"c1", "c2", "c3"}


def test_release_is_bounded_and_released_to_says_how_far():
    tl = timeline(start_ns=T0 - 10 * S)
    for k in range(10):
        tl.admit(frame("c1", T0 + k * MS, k), T0 + 20 * MS)
    tl.watermark(T0 + 20 * MS)  # only c1 delivers: its newest frame is the mark
    assert len(tl.release(4)) == 4 and tl.released_to() == T0 + 4 * MS - 1
    assert len(tl.release(100)) == 6 and tl.released_to() == tl.mark_ns == T0 + 9 * MS and tl.pending == 0


# --- problems the status reports -----------------------------------------------------------------

def test_a_second_publisher_on_a_key_shows_and_one_node_in_order_does_not():
    tl = timeline(start_ns=T0 - 10 * S)
    for k in range(60):  # 6 s at 10 fps; a stranger re-sends each frame with the next sequence number
        t = T0 + k * S // 10
        tl.admit(frame("c1", t, 2 * k), t + 20 * MS)
        tl.admit(frame("c1", t, 2 * k + 1), t + 25 * MS)
        tl.admit(frame("c2", t + 5 * MS, k), t + 25 * MS)
    now = T0 + 6 * S
    assert tl.cameras["c1"].recent(now)["duplicate"] >= DISORDER_MIN
    assert tl.problems(now)["c1"][0].startswith("two_publishers:") and tl.problems(now)["c2"] == []


def test_silent_and_slow_cameras_show():
    tl = timeline(start_ns=T0 - 10 * S)
    for k in range(30):
        t = T0 + k * S // 2  # c1 at 2 fps (its site says 10)
        tl.admit(frame("c1", t, k), t + 20 * MS)
    now = T0 + 15 * S
    p = tl.problems(now)
    assert p["c1"][0].startswith("slow: 2.0 fps") and p["c2"] == ["silent: no frame received yet"]


# --- the rate limit ------------------------------------------------------------------------------

def test_the_rate_limit_lets_a_camera_through_at_its_rate_and_drops_a_flood():
    limit = RateLimit(SITE, factor=2.0)  # c1: 10 fps -> 20/s, burst 10
    allowed = {"c1": 0, "c2": 0}
    for k in range(2000):  # one second: c1 floods at 2000/s, c2 sends its 10
        now = T0 + k * S // 2000
        allowed["c1"] += limit.allow("c1", now)
        if k % 200 == 0:
            allowed["c2"] += limit.allow("c2", now)
    assert 20 <= allowed["c1"] <= 31 and allowed["c2"] == 10
    assert limit.allow("elsewhere", T0)  # not the site's: the decoder refuses it


def test_the_start_up_wait_ends_once_every_camera_has_spoken():
    tl = timeline(max_delay_s=1.5, start_ns=T0)
    for k, cam in enumerate(("c1", "c2", "c3")):
        assert tl.admit(frame(cam, T0 + k * MS, 0), T0 + 50 * MS) is None
    assert tl.watermark(T0 + 60 * MS) == T0  # the oldest newest frame, not 1.5 s back
