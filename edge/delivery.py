"""When a camera node's Observations reach the network: capture-to-delivery delay, jitter, in order.

Real camera nodes deliver each Observation 0.1-1.5 s after its capture (the detector, the
encoder, the network), each camera at its own lag. ``superbody edge run --delay S --jitter S``
reproduces that in our own tools, always keeping each Observation's capture stamp:

- frame i, captured at ``c_i``, gets a delay ``d_i = max(0, delay + e_i)`` with ``e_i`` drawn from a
  normal distribution of standard deviation ``jitter`` (clipped so that no frame arrives before
  it was captured);
- a node publishes in order, so a camera's frames never overtake each other:
  ``t_i = max(t_{i-1}, c_i + d_i)`` (``delivery_times``); a frame whose draw would overtake its
  predecessor leaves with it, as a burst.

``DeliveryScheduler`` applies this to a running node: the capture loop hands it each encoded
payload (never blocking), and a thread of its own publishes the payload when the world clock
(edge/clock.py, which may run faster than the wall) reaches its delivery time. Its queue is
bounded: when it is full the oldest payload still waiting is dropped and counted, as a node
that cannot keep up drops frames rather than falling ever further behind.
"""

from __future__ import annotations

import collections
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from superbody.edge.clock import WorldClock

__all__ = ["MAX_DELAY_S", "MAX_JITTER_S", "DeliveryModel", "delivery_times", "DeliveryScheduler"]

log = logging.getLogger("superbody.edge.delivery")

MAX_DELAY_S = 30.0  # a capture-to-delivery delay beyond this is no camera node's
MAX_JITTER_S = 10.0
_NS = 1_000_000_000


@dataclass(frozen=True)
class DeliveryModel:
    """A camera's capture-to-delivery delay.

    Attributes:
        delay_s: mean delay, seconds, in [0, ``MAX_DELAY_S``].
        jitter_s: standard deviation of a normal spread around it, seconds, in [0, ``MAX_JITTER_S``];
            each draw is clipped so that the delay is never negative.
    """

    delay_s: float = 0.0
    jitter_s: float = 0.0

    def __post_init__(self) -> None:
        for name, v, hi in (("delay_s", self.delay_s, MAX_DELAY_S), ("jitter_s", self.jitter_s, MAX_JITTER_S)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0.0 <= v <= hi):
                raise ValueError(f"{name} must be in [0, {hi:g}] seconds, got {v!r}")

    @property
    def prompt(self) -> bool:
        """Delivered at capture time: no delay and no jitter."""
        return self.delay_s == 0.0 and self.jitter_s == 0.0

    def delays_ns(self, n: int, rng: np.random.Generator) -> NDArray[np.int64]:
        """(n,) delays of n frames, ns: ``max(0, delay + N(0, jitter))``."""
        if self.jitter_s == 0.0:
            return np.full(n, round(self.delay_s * _NS), dtype=np.int64)
        d = np.maximum(self.delay_s + rng.normal(0.0, self.jitter_s, n), 0.0)
        return np.round(d * _NS).astype(np.int64)


def delivery_times(stamps_ns: NDArray[np.int64], delays_ns: NDArray[np.int64]) -> NDArray[np.int64]:
    """In-order delivery times of one camera's frames.

    Args:
        stamps_ns: (n,) capture stamps in capture order.
        delays_ns: (n,) each frame's drawn delay (``DeliveryModel.delays_ns``).

    Returns:
        (n,) int64 ``t_i = max(t_{i-1}, stamp_i + delay_i)``: never before capture, never
        before the previous frame.
    """
    due = np.asarray(stamps_ns, dtype=np.int64) + np.asarray(delays_ns, dtype=np.int64)
    return np.maximum.accumulate(due) if len(due) else due


class DeliveryScheduler:
    """Holds encoded payloads until their delivery time, then publishes them in order, on its own thread.

    Args:
        publish: called with each payload at its delivery time (on the scheduler's thread).
        model: the delay and jitter.
        clock: the world clock the capture stamps and delivery times are on.
        capacity: most payloads waiting at once; beyond it the oldest is dropped (``dropped``).
        rng: the jitter's random draws (default: fresh entropy).

    Use as a context manager, or ``start()`` then ``finish()`` / ``abort()``.
    """

    def __init__(self, publish: Callable[[bytes], None], model: DeliveryModel, clock: WorldClock = WorldClock(),
                 capacity: int = 4096, rng: np.random.Generator | None = None):
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.publish, self.model, self.clock, self.capacity = publish, model, clock, capacity
        self.rng = rng or np.random.default_rng()
        self.delivered = self.dropped = 0
        self._queue: collections.deque[tuple[int, bytes]] = collections.deque()
        self._last_due = -(2**62)
        self._cv = threading.Condition()
        self._draining = self._aborted = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="delivery", daemon=True)

    def start(self) -> DeliveryScheduler:
        self._thread.start()
        return self

    def __enter__(self) -> DeliveryScheduler:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.abort()

    def submit(self, stamp_ns: int, payload: bytes) -> int:
        """Queue a payload captured at ``stamp_ns``; returns its delivery time (world ns). Never blocks.

        Raises:
            RuntimeError: the publisher failed (its exception is the cause).
        """
        if self._error is not None:
            raise RuntimeError(f"delivery stopped: {self._error}") from self._error
        due = int(stamp_ns) + int(self.model.delays_ns(1, self.rng)[0])
        with self._cv:
            due = self._last_due = max(self._last_due, due)
            if len(self._queue) >= self.capacity:
                self._queue.popleft()
                self.dropped += 1
                if self.dropped <= 3 or self.dropped % 1000 == 0:
                    log.warning("delivery queue full (%d payloads): the oldest dropped (%d so far)", self.capacity, self.dropped)
            self._queue.append((due, payload))
            self._cv.notify_all()
        return due

    @property
    def pending(self) -> int:
        with self._cv:
            return len(self._queue)

    def _run(self) -> None:
        while True:
            with self._cv:
                while True:
                    if self._aborted or (self._draining and not self._queue):
                        return
                    if self._queue:
                        wait_ns = self.clock.wall_ns(self._queue[0][0]) - time.time_ns()
                        if wait_ns <= 0:
                            _, payload = self._queue.popleft()
                            break
                        self._cv.wait(wait_ns / _NS)
                    else:
                        self._cv.wait()
            try:
                self.publish(payload)
            except BaseException as e:  # surfaced by the next submit() or finish()
                self._error = e
                return
            self.delivered += 1

    def finish(self, stop: threading.Event | None = None) -> None:
        """Deliver everything still queued (each at its time), then stop; stops at once if ``stop`` is set."""
        with self._cv:
            self._draining = True
            self._cv.notify_all()
        while self._thread.is_alive():
            self._thread.join(0.05)
            if stop is not None and stop.is_set():
                self.abort()
        self._raise()

    def abort(self) -> None:
        """Stop now; payloads not yet delivered are discarded."""
        with self._cv:
            self._aborted = True
            self._cv.notify_all()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join()

    def _raise(self) -> None:
        if self._error is not None:
            raise RuntimeError(f"delivery stopped: {self._error}") from self._error
