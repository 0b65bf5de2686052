"""The host process loop around the pure ``Aggregator`` (host/aggregator.py).

A Zenoh subscriber whose callback only queues the raw payload, stamped with its arrival on the
world clock (heavy work stays off Zenoh's thread). Before it queues, a payload larger than the
decoder accepts is counted and dropped, and so is a frame beyond its camera's rate limit
(``host.timeline.RateLimit``: ``HostConfig.max_rate_factor`` times the camera's site fps); each
camera has a queue of its own, bounded in messages and bytes, so one camera's flood only ever
costs that camera's frames. The loop ticks: it takes at most ``HostConfig.max_frames_per_step``
payloads from the cameras' queues in turn, ingests them, steps the aggregator (which fuses, in
capture order, the frames captured up to its watermark) and hands the PoseArray to the output
sinks (host/outputs/: Zenoh first, then serial, ROS 2, ...). So however much arrives, a tick's
work is bounded and the host publishes at its rate. A PoseArray computed before a stall of the
process (a frozen host, a swapped-out machine) is never published after it. The status goes out
on its own schedule, every ``status_every_s``, as one log line and as JSON on
``superbody/<site>/host/status`` (``host.messages.status.HostStatus``, docs/status-schema.md):
counters, capture-to-publish latency, the overall health, every camera's timing and its
calibration health (``host.calibration.health``; the monitor's one-camera test, bundle
adjustments of up to a second, runs in a thread of its own, never in the loop).

``superbody host run --site SITE.toml [--model M.onnx | --estimator analytic]``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from superbody.edge import transport
from superbody.edge.clock import WorldClock
from superbody.edge.messages import wire
from superbody.host.aggregator import Aggregator
from superbody.host.calibration.health import attribute
from superbody.host.health import CameraWatch, camera_statuses, health_of
from superbody.host.memory import release_free_memory
from superbody.host.messages import pose as pose_msg
from superbody.host.messages import status as host_status
from superbody.host.outputs import Sink
from superbody.host.outputs.zenoh_sink import ZenohSink
from superbody.host.timeline import RateLimit

__all__ = ["run_host"]

log = logging.getLogger("superbody.host")


# A PoseArray whose step began longer ago than this (the process was frozen, or starved of CPU)
# is dropped, never published late: its poses are that much older than it says ("stalled").
STALL_S = 0.5


def _percentiles(values: deque) -> tuple[float, float]:
    if not values:
        return math.nan, math.nan
    a = np.fromiter(values, float)
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


class _Intake:
    """What Zenoh's thread hands the loop: payloads in one bounded queue per camera (and one for
    every other key), liveliness events, and the counts of what was refused before queueing."""

    def __init__(self, aggregator: Aggregator, clock: WorldClock) -> None:
        cfg = aggregator.config
        self.clock = clock
        self.wake = threading.Condition()
        self.queues: dict[str, deque[tuple[bytes, str, int]]] = {c.id: deque() for c in aggregator.site.cameras}
        self.queues[""] = deque()  # keys of no camera of the site: refused once decoded
        self._bytes = dict.fromkeys(self.queues, 0)
        self._per_queue = max(16, cfg.queue_size // len(self.queues))
        self._per_queue_bytes = max(wire.MAX_PAYLOAD_BYTES, cfg.queue_bytes // len(self.queues))
        self._limit = RateLimit(aggregator.site, cfg.max_rate_factor)
        self.alive_events: deque[tuple[str, bool]] = deque()
        self.oversize: list[tuple[str, int]] = []  # (key, size), the first 1000 of a flood
        self.refused: Counter[tuple[str, str]] = Counter()  # (camera or "", over_rate | queue_full | oversize) -> n
        self.queue_dropped = 0

    def on_sample(self, sample) -> None:
        # Only queue here: decoding and estimation run on the host loop, off Zenoh's thread.
        size = len(sample.payload)
        key = str(sample.key_expr)
        cam = transport.camera_from_key(key)
        q = cam if cam and cam in self.queues else ""
        with self.wake:
            if size > wire.MAX_PAYLOAD_BYTES:  # never copied: the decoder would refuse it anyway
                if len(self.oversize) < 1000:
                    self.oversize.append((key[:200], size))
                self.refused["", "oversize"] += 1
                self.wake.notify()
                return
            arrival = self.clock.now_ns()
            if q and not self._limit.allow(q, arrival):
                self.refused[q, "over_rate"] += 1
                return
            pending = self.queues[q]
            while pending and (len(pending) >= self._per_queue or self._bytes[q] + size > self._per_queue_bytes):
                self._bytes[q] -= len(pending.popleft()[0])
                self.refused[q, "queue_full"] += 1
                self.queue_dropped += 1
            pending.append((sample.payload.to_bytes(), key, arrival))
            self._bytes[q] += size
            self.wake.notify()

    def on_alive(self, sample) -> None:
        import zenoh

        with self.wake:  # applied on the host loop, like everything else that changes the aggregator
            if len(self.alive_events) < 4096:  # bounded even if a peer flaps tokens faster than we loop
                self.alive_events.append((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))
            self.wake.notify()

    def wait(self, timeout_s: float) -> None:
        with self.wake:
            if not any(self.queues.values()) and not self.alive_events:
                self.wake.wait(timeout=timeout_s)

    def hand_over(self, aggregator: Aggregator) -> Counter[str]:
        """Apply liveliness events and count what was refused on Zenoh's thread; returns those counts by reason."""
        with self.wake:
            events, big, refused = list(self.alive_events), self.oversize[:], self.refused.copy()
            self.alive_events.clear()
            self.oversize.clear()
            self.refused.clear()
        now = self.clock.now_ns()
        for key, alive in events:
            aggregator.camera_liveliness(key, alive)
        by_reason: Counter[str] = Counter()
        for (cam, reason), n in refused.items():
            by_reason[reason] += n
            if reason == "oversize":
                for i in range(n):
                    key, size = big[i] if i < len(big) else ("?", 0)
                    aggregator._reject("oversize", f"{key}: {size} bytes, more than the {wire.MAX_PAYLOAD_BYTES} allowed")
            else:
                aggregator.timeline.count_drop(cam, reason, now, n)
                if reason == "over_rate":
                    aggregator.rejected["over_rate"] += n
        return by_reason

    def take(self, budget: int) -> list[tuple[bytes, str, int]]:
        """Up to ``budget`` payloads, one per camera queue in turn (a flooded camera waits its turn)."""
        out: list[tuple[bytes, str, int]] = []
        with self.wake:
            while len(out) < budget:
                ready = [q for q, pending in self.queues.items() if pending]
                if not ready:
                    break
                for q in ready[: budget - len(out)]:
                    item = self.queues[q].popleft()
                    self._bytes[q] -= len(item[0])
                    out.append(item)
        return out


def run_host(
    conf,
    aggregator: Aggregator,
    clock: WorldClock = WorldClock(),
    stop: threading.Event | None = None,
    duration_s: float | None = None,
    sinks: Sequence[Sink] = (),
) -> dict:
    """Run the aggregator on Zenoh until ``stop`` is set or ``duration_s`` of wall time passes.

    Args:
        conf: Zenoh config (edge.transport.session_config).
        aggregator: the core.
        clock: the world clock (capture stamps are in its time).
        stop: set it to stop.
        duration_s: optional wall-clock limit.
        sinks: outputs after the host's own Zenoh one (host/outputs/: serial, ROS 2, a callback),
            in order; the caller closes them.

    Returns:
        Final counters: published, accepted, rejected (by reason), queue_dropped, latency p50/p99 ms.
    """
    import zenoh

    stop = stop or threading.Event()
    site = aggregator.site
    cfg = aggregator.config
    intake = _Intake(aggregator, clock)
    counters: Counter[str] = Counter()
    latencies: deque[float] = deque(maxlen=20_000)
    end = None if duration_s is None else time.monotonic() + duration_s
    min_period = 1.0 / cfg.min_publish_hz
    max_period = 1.0 / cfg.max_publish_hz if cfg.max_publish_hz > 0 else 0.0
    stall_ns = int(STALL_S * 1e9 * clock.scale)
    watch = CameraWatch()
    # The calibration monitor's one-camera test (bundle adjustments: up to a second) runs in a
    # thread of its own, never in the loop; its result is applied in the loop when it is done.
    checker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="calibration")
    check: Future | None = None
    with zenoh.open(conf) as session:
        token = session.liveliness().declare_token(transport.host_alive_key(site.name))
        outputs: list[Sink] = [ZenohSink(session, site.name), *sinks]
        live = session.liveliness().declare_subscriber(transport.camera_alive_key(site.name), intake.on_alive, history=True)
        status_pub = session.declare_publisher(transport.host_status_key(site.name), encoding=host_status.zenoh_encoding())
        sub = session.declare_subscriber(transport.observation_key(site.name), intake.on_sample)
        log.info("host for site %s: %d cameras, estimator %s, publishing on %s (waiting up to %.2f s for late cameras)",
                 site.name, len(site.cameras), aggregator.estimator_name, transport.people_key(site.name), cfg.max_delay_s)
        last_pub = last_status = time.monotonic()
        obs_since_status = people = 0
        recent: Counter[str] = Counter()  # the host's own trouble since the last status: queue_full, stalled
        while not stop.is_set() and (end is None or time.monotonic() < end):
            intake.wait(min(min_period, 0.05))
            recent.update({k: n for k, n in intake.hand_over(aggregator).items() if k == "queue_full"})
            batch = intake.take(cfg.max_frames_per_step)  # bounded work per tick, every camera in turn
            for payload, key, arrival in batch:
                aggregator.ingest(payload, key, arrival)
            obs_since_status += len(batch)
            tick = time.monotonic()
            if (batch or tick - last_pub >= min_period) and tick - last_pub >= max_period:
                stepped = clock.now_ns()
                arr = aggregator.step(stepped)
                published_ns = clock.now_ns()
                if published_ns - stepped > stall_ns:  # frozen between the step and now: these poses are stale
                    aggregator.rejected["stalled"] += 1
                    recent["stalled"] += 1
                    log.warning("a pose array computed %.1f s ago was dropped, not published (the host stalled)",
                                (published_ns - stepped) / 1e9 / clock.scale)
                elif _publish(outputs, aggregator, arr, published_ns):
                    if aggregator.timeline.released:  # once a camera's frame is in: before, an array describes nothing
                        latencies.append((published_ns - (aggregator.as_of_ns or published_ns)) / 1e6)
                    counters["published"] += 1
                    people = len(arr.people)
                last_pub = time.monotonic()
            if check is not None and check.done():
                aggregator.calibration.apply(check.result())
                check = None
            if time.monotonic() - last_status >= cfg.status_every_s:  # its own schedule, published or not
                now = clock.now_ns()
                due = aggregator.calibration.check_due(now) if check is None and cfg.watch_calibration_s > 0 else None
                if due is not None:
                    check = checker.submit(attribute, *due)
                status = _status(aggregator, now, watch, recent, obs_since_status / (time.monotonic() - last_status), people,
                                 latencies, intake.queue_dropped, counters["published"])
                status_pub.put(host_status.encode(status))
                last_status, obs_since_status = time.monotonic(), 0
                recent.clear()
                release_free_memory()  # what a burst of work left free goes back to the system (host.memory)
        sub.undeclare()
        status_pub.undeclare()
        live.undeclare()
        outputs[0].close()
        token.undeclare()
    checker.shutdown(wait=False, cancel_futures=True)
    counters["queue_dropped"] = intake.queue_dropped
    p50, p99 = _percentiles(latencies)
    return {"published": counters["published"], "accepted": aggregator.accepted, "rejected": dict(aggregator.rejected),
            "queue_dropped": counters["queue_dropped"], "latency_ms": {"p50": p50, "p99": p99}}


def _publish(outputs: Sequence[Sink], aggregator: Aggregator, arr: pose_msg.PoseArray, published_ns: int) -> bool:
    """Hand the PoseArray to every sink, its ``latency_ns`` the age of the instant it describes; False if unpublishable."""
    age = max(0, published_ns - (aggregator.as_of_ns or published_ns))
    arr = pose_msg.PoseArray(arr.site, arr.seq, arr.stamp_ns, arr.people, age, arr.cameras_alive, arr.estimator)
    try:
        outputs[0].publish(arr)  # Zenoh first: what it cannot encode goes nowhere
    except ValueError as e:  # e.g. a filter glitch no subscriber would accept
        aggregator.rejected["unpublishable"] += 1
        log.error("pose array not published: %s", e)
        return False
    for sink in outputs[1:]:
        sink.publish(arr)
    return True


def _status(aggregator: Aggregator, now_ns: int, watch: CameraWatch, recent: Counter[str], obs_per_s: float, people: int,
            latencies: deque, queue_dropped: int, published: int) -> host_status.HostStatus:
    """The status now, and its log line; a camera whose problems start or end is logged too."""
    site = aggregator.site
    calibration = aggregator.calibration.report(now_ns, check=False) if aggregator.config.watch_calibration_s > 0 else None
    cameras = camera_statuses(aggregator.timeline, aggregator.cameras_alive, aggregator.cameras_gone, now_ns, calibration)
    watch.update(cameras)
    reasons = {"queue_full": "host: {n} frames dropped unread, their camera's queue was full: the host is slower than its cameras",
               "stalled": "host: {n} pose arrays dropped, computed before the host stalled"}
    health = health_of(cameras, [reasons[k].format(n=n) for k, n in recent.items() if n and k in reasons])
    p50, p99 = _percentiles(latencies)
    status = host_status.HostStatus(
        cameras_alive=sorted(aggregator.cameras_alive), cameras_total=len(site.cameras), people=people, obs_per_s=obs_per_s,
        latency_ms=host_status.latency(p50, p99), rejected=dict(aggregator.rejected), queue_dropped=queue_dropped,
        published=published, health=health, cameras=cameras,
    )
    rej = ", ".join(f"{k} {v}" for k, v in sorted(aggregator.rejected.items())) or "none"
    log.info("%s | cameras alive %d/%d (%s) | people %d | obs/s %.0f | capture-to-publish p50 %.0f ms p99 %.0f ms | rejected: %s | "
             "queue dropped %d", health.state, len(aggregator.cameras_alive), len(site.cameras), ",".join(status.cameras_alive) or "-",
             people, obs_per_s, p50, p99, rej, queue_dropped)
    return status
