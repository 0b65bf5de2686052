"""Attacks on the host over real Zenoh on loopback (issue 11 #1, #2, #3, #6): a stranger on the
network must not silence, blind or bloat it. The host runs ``run_host`` in a thread (or as its
own process where its memory is measured); the attacker is another Zenoh session."""

from __future__ import annotations

import json
import threading
import time

import pytest
import zenoh

from superbody.edge import transport, wire
from superbody.edge.clock import WorldClock
from superbody.edge.simulator import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.aggregator import Aggregator, HostConfig, run_host
from superbody.host.analytic import AnalyticEstimator
from superbody.host.pose import MAX_PEOPLE
from tests.conftest import WTF_SITE, free_port

SITE = load_site(WTF_SITE)


class HostThread:
    """``run_host`` in a thread on its own loopback port; records what it publishes."""

    def __init__(self, config: HostConfig = HostConfig(status_every_s=0.5)):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.agg = Aggregator(SITE, AnalyticEstimator(SITE), "analytic", config)
        self.published: list[tuple[float, object]] = []
        self.cv = threading.Condition()
        self.stop = threading.Event()
        conf = transport.session_config("peer", connect=[], listen=[self.endpoint])
        self.thread = threading.Thread(target=lambda: run_host(conf, self.agg, WorldClock(), self.stop, on_publish=self._on), daemon=True)

    def _on(self, arr) -> None:
        with self.cv:
            self.published.append((time.monotonic(), arr))
            self.cv.notify_all()

    def wait(self, predicate, timeout: float) -> bool:
        with self.cv:
            return self.cv.wait_for(predicate, timeout=timeout)

    def since(self, t: float) -> list:
        with self.cv:
            return [a for ts, a in self.published if ts >= t]

    def __enter__(self) -> "HostThread":
        self.thread.start()
        assert self.wait(lambda: len(self.published) >= 2, timeout=20), "the host never published"
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(timeout=20)


def _attacker(endpoint: str):
    return zenoh.open(transport.session_config("peer", connect=[endpoint]))


def test_hostile_liveliness_tokens_do_not_stop_the_output():
    """#1: a token ``cameras/ev.il/alive`` (or 65 tokens) made every PoseArray fail to encode."""
    with HostThread() as host, _attacker(host.endpoint) as evil:
        bad = ["ev.il"] + [f"x{i}" for i in range(65)]
        tokens = [evil.liveliness().declare_token(f"superbody/{SITE.name}/cameras/{name}/alive") for name in bad]
        real = evil.liveliness().declare_token(transport.camera_alive_key(SITE.name, "2"))
        assert host.wait(lambda: host.agg.rejected.get("unknown_camera_alive", 0) >= len(bad), timeout=20), host.agg.rejected
        t = time.monotonic()
        assert host.wait(lambda: len(host.since(t)) >= 10, timeout=20)  # still publishing at >= 5 Hz
        assert all(a.cameras_alive == ("2",) for a in host.since(t))
        assert host.agg.rejected.get("unpublishable", 0) == 0
        for tok in tokens + [real]:
            tok.undeclare()


def _flood_frames(stamp_ns: int) -> list[tuple[str, bytes]]:
    """Two cameras, each showing 64 copies of a different person: 128 views a frame."""
    world = World(SITE, 2, seed=4)
    out = []
    for cam_id, who_wanted in (("1", 0), ("2", 1)):
        obs, who = SimCamera(world, cam_id).observe(stamp_ns)
        views = [v for v, k in zip(obs.people, who) if k == who_wanted] or list(obs.people[:1])
        flood = obs.__class__(obs.site, obs.camera, obs.seq, obs.stamp_ns, obs.width, obs.height, tuple(views[:1]) * 64)
        out.append((cam_id, wire.encode(flood)))
    return out


def test_a_flood_of_fake_people_never_stops_publishing():
    """#2: more than 64 tracks and nothing was published ("people: must have at most 64 entries")."""
    with HostThread() as host, _attacker(host.endpoint) as evil:
        pubs = {c: evil.declare_publisher(transport.observation_key(SITE.name, c)) for c in ("1", "2")}
        t_start = time.monotonic()
        for k in range(35):  # 3.5 s at 10 frames/s: long enough for candidates to be confirmed
            now = time.time_ns()
            for cam_id, payload in _flood_frames(now):
                payload = json.loads(payload)
                payload["seq"] = k
                pubs[cam_id].put(json.dumps(payload))
            time.sleep(0.1)
        assert host.wait(lambda: host.agg.tracker.stats["confirmed"] >= MAX_PEOPLE, timeout=10), host.agg.tracker.stats
        t = time.monotonic()
        assert host.wait(lambda: len(host.since(t)) >= 5, timeout=10)  # still publishing
        arrays = host.since(t_start)
        assert max(len(a.people) for a in arrays) <= MAX_PEOPLE
        assert host.agg.tracker.stats["track_cap"] > 0
        assert host.agg.rejected.get("unpublishable", 0) == 0, host.agg.rejected


def test_near_future_stamps_over_zenoh_cannot_blind_a_camera():
    """#3: 2 empty frames a second stamped 0.9 s ahead kept camera 1 at 0 views."""
    with HostThread() as host, _attacker(host.endpoint) as evil, _attacker(host.endpoint) as cam_session:
        world = World(SITE, 1, seed=2)
        cam = SimCamera(world, "1")
        real = cam_session.declare_publisher(transport.observation_key(SITE.name, "1"))
        fake = evil.declare_publisher(transport.observation_key(SITE.name, "1"))
        forged = json.loads(wire.encode(cam.observe(time.time_ns())[0]))
        sent = 0
        for k in range(45):  # 3 s at 15 fps
            real.put(wire.encode(cam.observe(time.time_ns())[0]))
            sent += 1
            if k % 7 == 0:
                for ahead_s in (0.2, 0.9):
                    fake.put(json.dumps({**forged, "people": [], "seq": 0, "stamp_ns": time.time_ns() + int(ahead_s * 1e9)}))
            time.sleep(1 / 15)
        assert host.wait(lambda: host.agg.accepted + sum(host.agg.rejected.values()) >= sent + 2 * 7, timeout=10)
        # The real frames all count: none "late"; the 0.9 s ones are refused as from the future.
        assert host.agg.rejected.get("late", 0) == 0, host.agg.rejected
        assert host.agg.rejected.get("future_stamp", 0) == 7
        assert host.agg.accepted >= sent


def _vm_kb(pid: int, field: str) -> int:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise AssertionError(f"no {field} for {pid}")


@pytest.mark.slow
def test_oversize_payloads_cost_the_host_no_memory(processes):
    """#6: 100 x 5 MB payloads grew the host from ~200 MB to 445 MB, never returned."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    with zenoh.open(conf) as session:
        status: list[dict] = []
        cv = threading.Condition()

        def on_status(sample) -> None:
            with cv:
                status.append(json.loads(sample.payload.to_bytes()))
                cv.notify_all()

        sub = session.declare_subscriber(transport.host_status_key(SITE.name), on_status)
        host = processes.start("host", "run", "--site", str(WTF_SITE), "--estimator", "analytic", "--status-every", "0.5",
                               "--connect", endpoint)
        with cv:
            assert cv.wait_for(lambda: len(status) >= 2, timeout=30)
        before = _vm_kb(host.pid, "VmHWM")
        key = transport.observation_key(SITE.name, "1")
        big, mid = b"{" + b" " * (5 * 1024 * 1024), b"{" + b" " * (600 * 1024)
        for _ in range(100):  # bounded: 100 of each
            session.put(key, big)
            session.put(key, mid)
        with cv:
            assert cv.wait_for(lambda: status[-1]["rejected"].get("oversize", 0) >= 100, timeout=30), status[-1]
            n = len(status)
            assert cv.wait_for(lambda: len(status) >= n + 2, timeout=10)  # still alive and reporting
        grown_mb = (_vm_kb(host.pid, "VmHWM") - before) / 1024
        print(f"host peak memory: {before / 1024:.0f} MB before, grew {grown_mb:.1f} MB")
        assert grown_mb < 50, f"host peak memory grew {grown_mb:.0f} MB"
        assert host.poll() is None
        sub.undeclare()
