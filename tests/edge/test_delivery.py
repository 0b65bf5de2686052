"""A camera node's delivery model (edge/delivery.py): delay, jitter, in order, bounded, never blocking capture."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from superbody.edge.clock import WorldClock
from superbody.edge.delivery import DeliveryModel, DeliveryScheduler, delivery_times

MS = 1_000_000
S = 1_000_000_000

# (capture stamps ms, drawn delays ms, expected delivery times ms)
DELIVERY_CASES = [
    ([], [], []),  # nothing captured
    ([0, 100, 200], [500, 500, 500], [500, 600, 700]),  # a constant delay: each frame that late
    ([0, 100, 200], [500, 300, 500], [500, 500, 700]),  # frame 1 would overtake frame 0: it leaves with it
    ([0, 100, 200], [900, 0, 0], [900, 900, 900]),  # one slow frame holds back the ones behind it: a burst
    ([0, 100, 200], [0, 0, 0], [0, 100, 200]),  # prompt: delivered at capture
    ([0, 0, 50], [10, 5, 0], [10, 10, 50]),  # equal stamps keep their order
]


@pytest.mark.parametrize("stamps,delays,expected", DELIVERY_CASES)
def test_delivery_times_are_in_order_and_never_before_capture(stamps, delays, expected):
    got = delivery_times(np.array(stamps, np.int64) * MS, np.array(delays, np.int64) * MS)
    assert got.dtype == np.int64 and got.tolist() == [e * MS for e in expected]


def test_delays_are_the_mean_with_a_normal_spread_clipped_at_zero():
    rng = np.random.default_rng(3)
    assert DeliveryModel(0.4).delays_ns(5, rng).tolist() == [400 * MS] * 5
    d = DeliveryModel(0.8, 0.05).delays_ns(20000, rng) / S
    assert d.mean() == pytest.approx(0.8, abs=0.002) and d.std() == pytest.approx(0.05, rel=0.03)
    clipped = DeliveryModel(0.01, 0.05).delays_ns(20000, rng)
    assert clipped.min() == 0 and np.mean(clipped == 0) == pytest.approx(0.42, abs=0.02)  # P(N(0.01, 0.05) < 0)


# (arguments, fragment of the error)
BAD_MODELS = [
    ((-0.1, 0.0), "delay_s must be in [0, 30]"),
    ((30.5, 0.0), "delay_s must be in [0, 30]"),
    ((float("nan"), 0.0), "delay_s"),
    ((0.5, -0.01), "jitter_s must be in [0, 10]"),
    ((0.5, float("inf")), "jitter_s"),
]


@pytest.mark.parametrize("args,fragment", BAD_MODELS)
def test_bad_models_name_the_field_and_range(args, fragment):
    with pytest.raises(ValueError, match=fragment.replace("[", r"\[")):
        DeliveryModel(*args)


class Received:
    """What a scheduler published: (world time of the publish, payload), with a condition to wait on."""

    def __init__(self, clock: WorldClock):
        self.clock = clock
        self.items: list[tuple[int, bytes]] = []
        self.cv = threading.Condition()

    def publish(self, payload: bytes) -> None:
        with self.cv:
            self.items.append((self.clock.now_ns(), payload))
            self.cv.notify_all()

    def wait_for(self, n: int, timeout: float) -> bool:
        with self.cv:
            return self.cv.wait_for(lambda: len(self.items) >= n, timeout=timeout)


@pytest.mark.parametrize("scale", [1.0, 5.0])  # the wall clock; a world clock five times faster
def test_each_payload_is_published_at_its_delivery_time_on_the_world_clock(scale):
    clock = WorldClock(time.time_ns(), scale)
    got = Received(clock)
    with DeliveryScheduler(got.publish, DeliveryModel(0.5), clock) as sched:
        t0 = clock.now_ns()
        dues = [sched.submit(t0 + i * 50 * MS, bytes([i])) for i in range(6)]
        assert dues == [t0 + i * 50 * MS + 500 * MS for i in range(6)]
        assert got.wait_for(6, timeout=5)
    assert [p for _, p in got.items] == [bytes([i]) for i in range(6)]
    late = (np.array([t for t, _ in got.items]) - np.array(dues)) / MS  # world ms after the due time
    assert (late >= 0).all() and (late < 60 * scale).all(), late  # a loaded machine wakes up late, never early


def test_jitter_never_reorders_a_cameras_frames():
    clock = WorldClock()
    got = Received(clock)
    with DeliveryScheduler(got.publish, DeliveryModel(0.05, 0.1), clock, rng=np.random.default_rng(1)) as sched:
        t0 = clock.now_ns()
        dues = [sched.submit(t0 + i * 5 * MS, i.to_bytes(2, "big")) for i in range(40)]  # 200 fps, jitter 20 periods
        assert got.wait_for(40, timeout=5)
    assert dues == sorted(dues) and len(set(dues)) < 40  # some frames would have overtaken: they leave together
    assert [int.from_bytes(p, "big") for _, p in got.items] == list(range(40))


def test_a_full_queue_drops_the_oldest_and_submit_never_blocks():
    clock = WorldClock()
    got = Received(clock)
    release = threading.Event()

    def stuck(payload: bytes) -> None:  # a publisher that hangs (a network that stalls)
        release.wait(10)
        got.publish(payload)

    sched = DeliveryScheduler(stuck, DeliveryModel(), clock, capacity=3).start()
    try:
        t0 = time.monotonic()
        for i in range(50):
            sched.submit(clock.now_ns(), bytes([i]))
        assert time.monotonic() - t0 < 0.5  # capture went on while publishing was stuck
        assert sched.pending <= 3 and sched.dropped >= 46
        release.set()
        sched.finish()
    finally:
        release.set()
        sched.abort()
    assert [p for _, p in got.items][-3:] == [bytes([47]), bytes([48]), bytes([49])]  # the newest were kept
    assert sched.delivered + sched.dropped == 50


def test_finish_delivers_what_is_waiting_unless_stopped():
    clock = WorldClock()
    got = Received(clock)
    sched = DeliveryScheduler(got.publish, DeliveryModel(0.2), clock).start()
    for i in range(3):
        sched.submit(clock.now_ns(), bytes([i]))
    sched.finish()
    assert len(got.items) == 3 and sched.pending == 0
    stop = threading.Event()
    sched = DeliveryScheduler(got.publish, DeliveryModel(20.0), clock).start()
    sched.submit(clock.now_ns(), b"x")
    stop.set()
    t0 = time.monotonic()
    sched.finish(stop)
    assert time.monotonic() - t0 < 1.0 and sched.delivered == 0  # a stopped node does not wait 20 s


def test_a_publisher_that_fails_stops_the_next_submit():
    def broken(payload: bytes) -> None:
        raise OSError("session closed")

    sched = DeliveryScheduler(broken, DeliveryModel(0.01)).start()
    try:
        sched.submit(time.time_ns(), b"a")
        with pytest.raises(RuntimeError, match="session closed"):
            sched.finish()  # the node's end: the failure is not lost
        with pytest.raises(RuntimeError, match="session closed"):
            sched.submit(time.time_ns(), b"b")
    finally:
        sched.abort()
