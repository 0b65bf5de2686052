"""The host process loop around the pure ``Aggregator`` (host/aggregator.py).

A Zenoh subscriber whose callback only queues the raw payload (heavy work stays off Zenoh's
thread; a payload larger than the decoder accepts is counted and dropped before it is copied,
and the queue is bounded in bytes as well as in messages), a loop that drains the queue, steps
the aggregator and hands each PoseArray to the output sinks (host/outputs/: Zenoh first, then
serial, ROS 2, ...), camera liveliness, and a periodic one-line status, also published as JSON
on ``superbody/<site>/host/status`` (``host.messages.status.HostStatus``): ``{"cameras_alive":
[ids], "cameras_total": n, "people": n, "obs_per_s": f, "latency_ms": {"p50": f | null, "p99":
f | null}, "rejected": {reason: n}, "queue_dropped": n, "published": n}``.

``superbody host run --site SITE.toml [--model M.onnx | --estimator analytic]``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence

import numpy as np

from superbody.edge import transport
from superbody.edge.clock import WorldClock
from superbody.edge.messages import wire
from superbody.host.aggregator import Aggregator
from superbody.host.memory import release_free_memory
from superbody.host.messages import pose as pose_msg
from superbody.host.messages import status as host_status
from superbody.host.outputs import Sink
from superbody.host.outputs.zenoh_sink import ZenohSink

__all__ = ["run_host"]

log = logging.getLogger("superbody.host")


def _percentiles(values: deque) -> tuple[float, float]:
    if not values:
        return math.nan, math.nan
    a = np.fromiter(values, float)
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


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
    pending: deque[tuple[bytes, str, int]] = deque()
    wake = threading.Condition()
    counters: Counter[str] = Counter()
    queued_bytes = 0
    alive_events: deque[tuple[str, bool]] = deque()
    oversize: list[tuple[str, int]] = []  # (key, size) refused on Zenoh's thread, reported by the loop
    latencies: deque[float] = deque(maxlen=20_000)

    def on_sample(sample) -> None:
        # Only queue here: decoding and estimation run on the host loop, off Zenoh's thread.
        nonlocal queued_bytes
        size = len(sample.payload)
        if size > wire.MAX_PAYLOAD_BYTES:  # never copied: the decoder would refuse it anyway
            with wake:
                if len(oversize) < 1000:  # the details of a flood are not all kept
                    oversize.append((str(sample.key_expr)[:200], size))
                counters["oversize"] += 1
                wake.notify()
            return
        with wake:
            while pending and (len(pending) >= cfg.queue_size or queued_bytes + size > cfg.queue_bytes):
                queued_bytes -= len(pending.popleft()[0])
                counters["queue_dropped"] += 1
            pending.append((sample.payload.to_bytes(), str(sample.key_expr), time.time_ns()))
            queued_bytes += size
            wake.notify()

    def on_alive(sample) -> None:
        # Applied on the host loop, like everything else that changes the aggregator.
        with wake:
            if len(alive_events) < 4096:  # bounded even if a peer flaps tokens faster than we loop
                alive_events.append((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))
            wake.notify()

    end = None if duration_s is None else time.monotonic() + duration_s
    min_period = 1.0 / cfg.min_publish_hz
    max_period = 1.0 / cfg.max_publish_hz if cfg.max_publish_hz > 0 else 0.0
    with zenoh.open(conf) as session:
        token = session.liveliness().declare_token(transport.host_alive_key(site.name))
        outputs: list[Sink] = [ZenohSink(session, site.name), *sinks]
        live = session.liveliness().declare_subscriber(transport.camera_alive_key(site.name), on_alive, history=True)
        status_pub = session.declare_publisher(transport.host_status_key(site.name), encoding=host_status.zenoh_encoding())
        sub = session.declare_subscriber(transport.observation_key(site.name), on_sample)
        log.info("host for site %s: %d cameras, estimator %s, publishing on %s", site.name, len(site.cameras),
                 aggregator.estimator_name, transport.people_key(site.name))
        last_pub = last_status = time.monotonic()
        obs_since_status = 0
        while not stop.is_set() and (end is None or time.monotonic() < end):
            with wake:
                if not pending and not alive_events:
                    wake.wait(timeout=min(min_period, 0.05))
                events = list(alive_events)
                alive_events.clear()
                n_oversize, counters["oversize"] = counters["oversize"], 0
                big = oversize[:]
                oversize.clear()
            for key, alive in events:
                aggregator.camera_liveliness(key, alive)
            for i in range(n_oversize):
                key, size = big[i] if i < len(big) else ("?", 0)
                aggregator._reject("oversize", f"{key}: {size} bytes, more than the {wire.MAX_PAYLOAD_BYTES} allowed")
            if max_period and time.monotonic() - last_pub < max_period:
                time.sleep(max(0.0, max_period - (time.monotonic() - last_pub)))
            newest_arrival = None
            while True:
                with wake:
                    if not pending:
                        break
                    payload, key, arrival = pending.popleft()
                    queued_bytes -= len(payload)
                if aggregator.ingest(payload, key, clock.now_ns()):
                    newest_arrival = arrival
                obs_since_status += 1
            if newest_arrival is None and time.monotonic() - last_pub < min_period:
                continue
            arr = aggregator.step(clock.now_ns())
            now_wall = time.time_ns()
            if newest_arrival is not None:
                arr = pose_msg.PoseArray(arr.site, arr.seq, arr.stamp_ns, arr.people, now_wall - newest_arrival,
                                         arr.cameras_alive, arr.estimator)
                latencies.append((now_wall - newest_arrival) / 1e6)
            try:
                outputs[0].publish(arr)  # Zenoh first: what it cannot encode goes nowhere
            except ValueError as e:  # e.g. a filter glitch no subscriber would accept
                aggregator.rejected["unpublishable"] += 1
                log.error("pose array not published: %s", e)
                continue
            counters["published"] += 1
            for sink in outputs[1:]:
                sink.publish(arr)
            last_pub = time.monotonic()
            if last_pub - last_status >= cfg.status_every_s:
                p50, p99 = _percentiles(latencies)
                status = host_status.HostStatus(
                    cameras_alive=sorted(aggregator.cameras_alive), cameras_total=len(site.cameras), people=len(arr.people),
                    obs_per_s=obs_since_status / (last_pub - last_status), latency_ms=host_status.latency(p50, p99),
                    rejected=dict(aggregator.rejected), queue_dropped=counters["queue_dropped"], published=counters["published"],
                )
                status_pub.put(host_status.encode(status))
                rej = ", ".join(f"{k} {v}" for k, v in sorted(aggregator.rejected.items())) or "none"
                log.info("cameras alive %d/%d (%s) | people %d | obs/s %.0f | latency p50 %.2f ms p99 %.2f ms | rejected: %s | queue dropped %d",
                         len(aggregator.cameras_alive), len(site.cameras), ",".join(status.cameras_alive) or "-",
                         len(arr.people), status.obs_per_s, p50, p99, rej, counters["queue_dropped"])
                last_status, obs_since_status = last_pub, 0
                release_free_memory()  # what a burst of work left free goes back to the system (host.memory)
        sub.undeclare()
        status_pub.undeclare()
        live.undeclare()
        outputs[0].close()
        token.undeclare()
    p50, p99 = _percentiles(latencies)
    return {"published": counters["published"], "accepted": aggregator.accepted, "rejected": dict(aggregator.rejected),
            "queue_dropped": counters["queue_dropped"], "latency_ms": {"p50": p50, "p99": p99}}
