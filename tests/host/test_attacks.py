"""Attacks on the host over real Zenoh on loopback (issue 11 #1, #2, #3, #6): a stranger on the
network must not silence, blind or bloat it. The host runs ``run_host`` in a thread (or as its
own process where its memory is measured); the attacker is another Zenoh session."""

from __future__ import annotations

import json
import math
import threading
import time

import pytest
import zenoh

from superbody.edge import transport
from superbody.edge.clock import WorldClock
from superbody.edge.messages import wire
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.estimation.analytic import AnalyticEstimator
from superbody.host.messages.pose import MAX_PEOPLE
from superbody.host.outputs import CallbackSink
from superbody.host.service import run_host
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
        self.thread = threading.Thread(target=lambda: run_host(conf, self.agg, WorldClock(), self.stop, sinks=[CallbackSink(self._on)]), daemon=True)

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

    def __enter__(self) -> HostThread:
        self.thread.start()
        assert self.wait(lambda: len(self.published) >= 2, timeout=20), "the host never published"
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(timeout=20)


def _wait_matched(*publishers) -> None:
    """Every put must reach the host: wait until its subscriber matches each publisher (a put
    made before the route exists is dropped by Zenoh, by design)."""
    for _ in range(100):  # bounded: 100 x 0.05 s
        if all(p.matching_status.matching for p in publishers):
            return
        time.sleep(0.05)
    raise AssertionError("the host's subscriber never matched the attacker's publishers")


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


def _flood_frames() -> dict[str, dict]:
    """Two cameras, each showing 64 copies of a different person (128 views a frame), as JSON
    documents; the stamp and seq are set when sent. Deterministic: the first instant of the
    simulated world where camera 1 sees person 0 and camera 2 sees person 1 well, 1.8 m apart."""
    world = World(SITE, 2, seed=4)
    for k in range(3000):  # bounded search, 0.1 s steps
        t = 1_700_000_000 * 10**9 + k * 10**8
        a, b = world.states(t * 1e-9)
        if math.hypot(a.x - b.x, a.y - b.y) < 1.8:  # apart, so neither can pass for the other
            continue
        docs = {}
        for cam_id, wanted in (("1", 0), ("2", 1)):
            obs, who = SimCamera(world, cam_id).observe(t)
            views = [v for v, w in zip(obs.people, who) if w == wanted and v.num_visible >= 8]
            if views:
                docs[cam_id] = json.loads(wire.encode(obs.__class__(obs.site, obs.camera, 0, t, obs.width, obs.height, (views[0],) * 64)))
        if len(docs) == 2:
            return docs
    raise AssertionError("no instant where both cameras see their person")


def test_a_flood_of_fake_people_never_stops_publishing():
    """#2: more than 64 tracks and nothing was published ("people: must have at most 64 entries");
    issue 28: a flood of copies made one ghost per copy."""
    with HostThread() as host, _attacker(host.endpoint) as evil:
        pubs = {c: evil.declare_publisher(transport.observation_key(SITE.name, c)) for c in ("1", "2")}
        _wait_matched(*pubs.values())
        t_start = time.monotonic()
        flood = _flood_frames()
        for k in range(35):  # 3.5 s at 10 frames/s: long enough for candidates to be confirmed
            for cam_id, doc in flood.items():
                pubs[cam_id].put(json.dumps({**doc, "seq": k, "stamp_ns": time.time_ns()}))
            time.sleep(0.1)
        # The flood reached the host (70 frames sent; in 2 of 5 full-suite runs one of them never
        # arrived, cause not found: what is claimed below does not need every frame).
        assert host.wait(lambda: host.agg.tracker.stats["observations"] >= 60, timeout=20), \
            (dict(host.agg.tracker.stats), dict(host.agg.rejected), host.agg.accepted)
        t = time.monotonic()
        assert host.wait(lambda: len(host.since(t)) >= 5, timeout=10)  # still publishing
        arrays = host.since(t_start)
        # No ghost: each camera's 64 copies are one detection, so at most the two people shown.
        assert max(len(a.people) for a in arrays) <= 2 < MAX_PEOPLE
        st = host.agg.tracker.stats
        assert st["duplicate_views"] >= 60 * 63 and len(host.agg.tracker.tracks) <= 2, st
        assert host.agg.rejected.get("unpublishable", 0) == 0, host.agg.rejected


def test_near_future_stamps_over_zenoh_cannot_blind_a_camera():
    """#3: 2 empty frames a second stamped 0.9 s ahead kept camera 1 at 0 views."""
    with HostThread() as host, _attacker(host.endpoint) as evil, _attacker(host.endpoint) as cam_session:
        world = World(SITE, 1, seed=2)
        cam = SimCamera(world, "1")
        real = cam_session.declare_publisher(transport.observation_key(SITE.name, "1"))
        fake = evil.declare_publisher(transport.observation_key(SITE.name, "1"))
        _wait_matched(real, fake)
        forged = json.loads(wire.encode(cam.observe(time.time_ns())[0]))
        real.put(wire.encode(cam.observe(time.time_ns())[0]))  # the camera is known before the attack
        assert host.wait(lambda: host.agg.accepted == 1, timeout=10)
        sent, forged_n = 1, 0
        for k in range(1, 46):  # 3 s at 15 fps
            real.put(wire.encode(cam.observe(time.time_ns())[0]))
            sent += 1
            if k % 7 == 0:
                forged_n += 1
                for ahead_s in (0.2, 0.9):
                    fake.put(json.dumps({**forged, "people": [], "seq": 0, "stamp_ns": time.time_ns() + int(ahead_s * 1e9)}))
            time.sleep(1 / 15)
        assert host.wait(lambda: host.agg.accepted + sum(host.agg.rejected.values()) >= sent + 2 * forged_n, timeout=10)
        # The real frames all count: none "late"; the 0.9 s ones are refused as from the future.
        assert host.agg.rejected.get("late", 0) == 0, host.agg.rejected
        assert host.agg.rejected.get("future_stamp", 0) == forged_n
        assert host.agg.accepted == sent, host.agg.rejected


def _vm_kb(pid: int, field: str) -> int:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise AssertionError(f"no {field} for {pid}")


def _analytic_host_reporting(session, processes, endpoint: str):
    """A host process (analytic estimator, status every 0.5 s) connected to ``endpoint``, and a
    subscriber on its status; returns once it has reported twice.

    Returns:
        ``(host process, status messages so far, their condition variable, the subscriber)``.
    """
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
        assert cv.wait_for(lambda: len(status) >= 2, timeout=30), "the host never reported"
    return host, status, cv, sub


@pytest.mark.slow
def test_oversize_payloads_cost_the_host_no_memory(processes):
    """#6: 100 x 5 MB payloads grew the host from ~200 MB to 445 MB, never returned."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    with zenoh.open(conf) as session:
        host, status, cv, sub = _analytic_host_reporting(session, processes, endpoint)
        before = _vm_kb(host.pid, "VmHWM")
        # Blocking congestion control: every payload reaches the host (with Zenoh's default, DROP,
        # a loaded machine dropped more than half of the 560 MB and the count below never came).
        pub = session.declare_publisher(transport.observation_key(SITE.name, "1"), congestion_control=zenoh.CongestionControl.BLOCK)
        big, mid = b"{" + b" " * (5 * 1024 * 1024), b"{" + b" " * (600 * 1024)
        for _ in range(100):  # bounded: 100 of each
            pub.put(big)
            pub.put(mid)
        with cv:
            assert cv.wait_for(lambda: status[-1]["rejected"].get("oversize", 0) >= 100, timeout=30), status[-1]
            n = len(status)
            assert cv.wait_for(lambda: len(status) >= n + 2, timeout=10)  # still alive and reporting
        grown_mb = (_vm_kb(host.pid, "VmHWM") - before) / 1024
        print(f"host peak memory: {before / 1024:.0f} MB before, grew {grown_mb:.1f} MB")
        assert grown_mb < 50, f"host peak memory grew {grown_mb:.0f} MB"
        assert host.poll() is None
        pub.undeclare()
        sub.undeclare()


def _shm_maps(pid: int) -> list[str]:
    with open(f"/proc/{pid}/maps") as f:
        return [line.split()[-1] for line in f if "/dev/shm/" in line]


@pytest.mark.slow
def test_a_peer_cannot_map_its_shared_memory_into_the_host(processes):
    """The soak's memory step: Zenoh's shared memory transport (on by default, 16 MiB pool, for
    messages of 3 KB or more) made the host map every same-machine sender's pool, an attacker's
    included, and its RSS grew as the pool's pages were touched (+19 MB after two 4 KB puts)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    conf.insert_json5("transport/shared_memory/enabled", "true")  # a stranger keeps Zenoh's default
    with zenoh.open(conf) as evil:
        host, status, cv, sub = _analytic_host_reporting(evil, processes, endpoint)
        # BLOCK: every put is delivered (a burst with Zenoh's default DROP may lose some without shared memory).
        pub = evil.declare_publisher(transport.observation_key(SITE.name, "1"), congestion_control=zenoh.CongestionControl.BLOCK)
        _wait_matched(pub)
        before_kb = _vm_kb(host.pid, "VmRSS")
        for k in range(200):  # bounded: 200 payloads of 4-64 KB, each over Zenoh's 3 KB shared-memory threshold
            pub.put(b"{" + b" " * (4096 + 300 * k))
        with cv:
            assert cv.wait_for(lambda: sum(status[-1]["rejected"].values()) >= 200, timeout=30), status[-1]["rejected"]
        grown_mb = (_vm_kb(host.pid, "VmRSS") - before_kb) / 1024
        print(f"host RSS grew {grown_mb:.1f} MB; shared memory mapped: {_shm_maps(host.pid)}")
        assert grown_mb < 10, f"host RSS grew {grown_mb:.1f} MB"
        assert _shm_maps(host.pid) == [], "the host mapped a peer's shared memory"
        assert host.poll() is None
        sub.undeclare()


class _StallingClock(WorldClock):
    """The wall clock, but ``stall()`` makes it jump ahead: as a host process frozen (SIGSTOP) or
    starved for that long sees it when it runs again."""

    def __init__(self) -> None:
        super().__init__()
        object.__setattr__(self, "_ahead", [0])

    def stall(self, seconds: float) -> None:
        self._ahead[0] += int(seconds * 1e9)  # type: ignore[attr-defined]

    def now_ns(self) -> int:
        return super().now_ns() + self._ahead[0]  # type: ignore[attr-defined]


class _StallsOnce:
    """Geometry that stalls the host's clock by 5 s inside its n-th estimate: the host froze mid-step."""

    def __init__(self, clock: _StallingClock, n: int) -> None:
        self._inner, self._clock, self._left = AnalyticEstimator(SITE), clock, n

    def estimate(self, view_sets):
        self._left -= 1
        if self._left == 0:
            self._clock.stall(5.0)
        return self._inner.estimate(view_sets)


def test_a_pose_array_computed_before_a_stall_is_never_published_after_it():
    """Issue 37: a host frozen for 5 s sometimes published, once it resumed, an array computed
    before the freeze (positions 5 s old). A step the clock overtook by more than STALL_S is
    dropped and counted ("stalled"); the next array is computed afresh."""
    clock = _StallingClock()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agg = Aggregator(SITE, _StallsOnce(clock, n=20), "analytic", HostConfig(status_every_s=0.5))
    published: list[tuple[int, object]] = []
    cv = threading.Condition()

    def on(arr) -> None:
        with cv:
            published.append((clock.now_ns(), arr))
            cv.notify_all()

    stop = threading.Event()
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    host = threading.Thread(target=lambda: run_host(conf, agg, clock, stop, sinks=[CallbackSink(on)]), daemon=True)
    host.start()
    world = World(SITE, 2, seed=1)
    cams = [SimCamera(world, c) for c in SITE.camera_ids]
    try:
        with _attacker(endpoint) as camera_session:
            pubs = [camera_session.declare_publisher(transport.observation_key(SITE.name, c.camera.id)) for c in cams]
            _wait_matched(*pubs)
            for k in range(200):  # bounded: 200 frames per camera, 15 fps, until the stall happened and 30 arrays after it
                for cam, pub in zip(cams, pubs):
                    pub.put(wire.encode(replace_seq(cam.observe(clock.now_ns())[0], k)))
                time.sleep(1 / 15)
                with cv:
                    if agg.rejected.get("stalled") and sum(1 for t, a in published if a.stamp_ns > t - 10**9) > 30:
                        break
    finally:
        stop.set()
        host.join(timeout=20)
    assert agg.rejected.get("stalled") == 1, agg.rejected
    stale = [(t - a.stamp_ns) / 1e9 for t, a in published if t - a.stamp_ns > 0.5e9]
    assert stale == [], f"published {len(stale)} arrays computed {max(stale):.1f} s before"
    assert len(published) > 30


def replace_seq(obs, seq: int):
    return obs.__class__(obs.site, obs.camera, seq, obs.stamp_ns, obs.width, obs.height, obs.people)
