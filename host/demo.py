"""``superbody demo``: the whole product on one machine with no hardware.

Starts a Zenoh router on loopback, one simulated camera node per camera of the site (separate
processes, sharing the world clock and seed, so they see the same simulated people) and the
host with the shipped fp32 model, then watches the people it publishes: a live table (id, x, y,
yaw, cameras, error against the simulated truth) and, on exit, a summary.

The truth: the demo builds the same simulated world from the same site and seed. For every
observation a camera publishes it recomputes locally which simulated person each view is (the
simulation is deterministic), so it knows when each person first appeared and which person a
published track follows: identity switches are counted exactly. Each published person is
scored against the truth at their own capture stamp (``PersonPose.stamp_ns``), never at the
array's publish time: a host may publish people as they were a moment ago.

Camera timing (``DemoConfig``: ``--delay``, ``--camera-delay ID=S``, ``--jitter``, ``--camera-fps
ID=F``): each camera node publishes its observations that long after their capture, in order,
and captures at its own rate (``superbody edge run --delay --jitter --fps``), as real nodes do.
"""

from __future__ import annotations

import logging
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from superbody.edge import transport
from superbody.edge.angles import wrap_angle
from superbody.edge.clock import WorldClock
from superbody.edge.messages import wire
from superbody.edge.resources import site_path
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.messages import pose as pose_msg

__all__ = ["DemoConfig", "run_demo", "stop_processes"]

log = logging.getLogger("superbody.demo")

DEFAULT_SITE = site_path("wtf-apartment")  # shipped with the package (edge/resources.py)
_MATCH_GATE_M = 1.0
DEMO_PORT = 17447  # not zenohd's 7447


@dataclass
class DemoConfig:
    """What the demo runs.

    Attributes:
        site: site file.
        people: simulated people.
        seed: simulator seed.
        duration_s: stop after this many simulated seconds (None: until Ctrl-C).
        clock_scale: simulated seconds per wall second.
        port: loopback port of the demo's Zenoh router; 0 picks a free one. The default, 17447, is
            not Zenoh's 7447, so a zenohd already running on the machine does not collide with it.
        estimator: "auto", "hybrid", "onnx" or "analytic" (host.estimation.build_estimator).
        model: ONNX model (default: the shipped one for the site).
        kill_camera: a camera id to kill mid-run (fault injection), or None.
        kill_at_s: when to kill it, in simulated seconds from the start.
        table: print the live table.
        log_dir: where the processes' logs go (default: a temporary folder).
        delay_s: every camera's capture-to-delivery delay, seconds (``edge run --delay``).
        camera_delay_s: camera id -> its own delay, instead of ``delay_s``.
        jitter_s: the delays' standard deviation, every camera (``edge run --jitter``).
        camera_fps: camera id -> its capture rate, instead of the site's (``edge run --fps``).
    """

    site: str = str(DEFAULT_SITE)
    people: int = 3
    seed: int = 7
    duration_s: float | None = None
    clock_scale: float = 1.0
    port: int = DEMO_PORT
    estimator: str = "auto"
    model: str | None = None
    kill_camera: str | None = None
    kill_at_s: float = 0.0
    table: bool = True
    log_dir: str | None = None
    extra_host_args: tuple[str, ...] = ()
    delay_s: float = 0.0
    camera_delay_s: dict[str, float] = field(default_factory=dict)
    jitter_s: float = 0.0
    camera_fps: dict[str, float] = field(default_factory=dict)

    def check_cameras(self, site) -> None:
        """``KeyError`` naming the site's cameras when a per-camera setting names another."""
        for flag, per_camera in (("--camera-delay", self.camera_delay_s), ("--camera-fps", self.camera_fps)):
            for cam in per_camera:
                if cam not in site.camera_ids:
                    raise KeyError(f"{flag} {cam}=...: camera {cam!r} is not in site {site.name!r}; cameras: {', '.join(site.camera_ids)}")

    def camera_timing(self, camera_id: str) -> dict[str, float | None]:
        """One camera's delay, jitter and fps (None: the site's)."""
        return {"delay_s": self.camera_delay_s.get(camera_id, self.delay_s), "jitter_s": self.jitter_s,
                "fps": self.camera_fps.get(camera_id)}

    def node_args(self, camera_id: str) -> list[str]:
        """The ``edge run`` timing flags of one camera's node."""
        t = self.camera_timing(camera_id)
        args = ["--delay", repr(t["delay_s"]), "--jitter", repr(t["jitter_s"])]
        return args + (["--fps", repr(t["fps"])] if t["fps"] is not None else [])


@dataclass
class _Score:
    """What the demo measured."""

    appeared_ns: dict[int, int] = field(default_factory=dict)  # person -> first observation of them
    confirmed_ns: dict[int, int] = field(default_factory=dict)  # person -> first pose of a track following them
    track_of: dict[int, int] = field(default_factory=dict)  # person -> last track id
    switches: int = 0
    pos_err: list[float] = field(default_factory=list)
    yaw_err: list[float] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    arrays: int = 0
    tracks_seen: set[int] = field(default_factory=set)
    cameras_alive_last: tuple[str, ...] = ()
    camera_gone_reported: set[str] = field(default_factory=set)
    arrays_after_kill: int = 0
    rows: list[tuple] = field(default_factory=list)


class _Watcher:
    """Subscribes to observations and poses; scores the poses against the simulated truth."""

    def __init__(self, site, world: World, t0_ns: int, fps: dict[str, float] | None = None):
        self.site = site
        self.world = world
        self.t0_ns = t0_ns
        # The cameras' own rates: a simulated frame's noise (hence who each view is) follows its frame number.
        self.cams = {c.id: SimCamera(world, c.id, fps=(fps or {}).get(c.id)) for c in site.cameras}
        self.score = _Score()
        self.lock = threading.Lock()
        self.killed_ns: int | None = None
        # A person counts as appeared only once the host publishes: before that the delay is
        # the host's start-up (seconds on a loaded machine), not the tracker's.
        self.host_up = False

    def on_observation(self, sample) -> None:
        try:
            obs = wire.decode(sample.payload.to_bytes(), expected_site=self.site.name)
        except wire.DecodeError:
            return
        if obs.stamp_ns < self.t0_ns:
            return
        _, who = self.cams[obs.camera].observe(obs.stamp_ns)
        with self.lock:
            if not self.host_up:
                return
            for k, view in zip(who, obs.people):
                if k >= 0 and view.num_visible >= 6:  # enough for the tracker to start a candidate
                    self.score.appeared_ns.setdefault(k, obs.stamp_ns)

    def on_people(self, sample) -> None:
        try:
            arr = pose_msg.decode(sample.payload.to_bytes(), expected_site=self.site.name)
        except pose_msg.PoseDecodeError:
            return
        with self.lock:
            self.host_up = True
            s = self.score
            s.arrays += 1
            s.latency_ms.append(arr.latency_ns / 1e6)
            s.cameras_alive_last = arr.cameras_alive
            if self.killed_ns is not None:
                s.arrays_after_kill += 1
            if not arr.people:
                s.rows = []
                return
            # Match each pose to the true person nearest at that pose's own capture time (people
            # of one array were seen at different instants, up to the host's freshness apart).
            states = [self.world.states(p.stamp_ns * 1e-9) for p in arr.people]
            truth = np.array([[[st.x, st.y] for st in sts] for sts in states])  # (poses, people, 2)
            poses = np.array([[p.x, p.y] for p in arr.people])
            cost = np.linalg.norm(truth - poses[:, None], axis=2)
            from scipy.optimize import linear_sum_assignment  # here: every superbody command imports this module

            rows, cols = linear_sum_assignment(cost)
            assigned = {r: c for r, c in zip(rows, cols) if cost[r, c] < _MATCH_GATE_M}
            s.rows = []
            for i, p in enumerate(arr.people):
                s.tracks_seen.add(p.id)
                k = assigned.get(i)
                if k is None:
                    s.rows.append((p, None, math.nan, math.nan))
                    continue
                st = states[i][k]
                e_pos = math.hypot(p.x - st.x, p.y - st.y)
                e_yaw = abs(float(wrap_angle(p.yaw - st.yaw)))
                s.pos_err.append(e_pos)
                s.yaw_err.append(e_yaw)
                s.confirmed_ns.setdefault(k, arr.stamp_ns)
                if k in s.track_of and s.track_of[k] != p.id:
                    s.switches += 1
                s.track_of[k] = p.id
                s.rows.append((p, k, e_pos, e_yaw))

    def table(self, elapsed_s: float) -> str:
        with self.lock:
            s = self.score
            lines = [f"superbody demo  t={elapsed_s:6.1f} s  cameras alive: {','.join(s.cameras_alive_last) or '-'}  "
                     f"pose arrays: {s.arrays}"]
            if not self.host_up:  # the router, the cameras and the host (its model) start in a few seconds
                lines.append("starting: waiting for the host's first pose array (router, cameras and the model load in a few seconds)")
            lines.append(f"{'id':>4} {'x m':>7} {'y m':>7} {'yaw deg':>8} {'cameras':<10} {'person':>6} {'err cm':>7} {'err deg':>8}")
            for p, k, e_pos, e_yaw in s.rows:
                lines.append(f"{p.id:>4} {p.x:7.2f} {p.y:7.2f} {math.degrees(p.yaw):8.1f} {','.join(p.cameras):<10} "
                             f"{'-' if k is None else k:>6} {e_pos * 100:7.1f} {math.degrees(e_yaw):8.1f}")
            if s.pos_err:
                lines.append(f"running MAE: position {np.mean(s.pos_err) * 1000:.0f} mm, yaw {math.degrees(np.mean(s.yaw_err)):.1f} deg, "
                             f"identity switches {s.switches}")
            return "\n".join(lines)

    def summary(self, people: int) -> dict:
        with self.lock:
            s = self.score
            lat = np.array(s.latency_ms) if s.latency_ms else np.array([math.nan])
            delays = {str(k): (s.confirmed_ns[k] - s.appeared_ns[k]) / 1e9 for k in s.confirmed_ns if k in s.appeared_ns}
            return {
                "people_simulated": people,
                "people_confirmed": len(s.confirmed_ns),
                "id_switches": s.switches,
                "position_mae_mm": float(np.mean(s.pos_err) * 1000) if s.pos_err else None,
                "yaw_mae_deg": float(math.degrees(np.mean(s.yaw_err))) if s.yaw_err else None,
                "latency_ms": {"p50": float(np.nanpercentile(lat, 50)), "p99": float(np.nanpercentile(lat, 99))},
                "poses_published": s.arrays,
                "tracks": len(s.tracks_seen),
                "confirm_delay_s": delays,
                "cameras_alive_at_end": list(s.cameras_alive_last),
                "pose_arrays_after_kill": s.arrays_after_kill,
            }


def _spawn(args: list[str], log_path: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    out = open(log_path, "w")
    return subprocess.Popen([sys.executable, "-m", "superbody.edge.cli", *args], stdout=out, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True)


def demo_port(port: int) -> int:
    """``port`` if it is free on 127.0.0.1 (0: a free one); ``RuntimeError`` naming it if it is taken."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        # As the router will: a port left in TIME_WAIT by the previous demo is free, a listener is not.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            s.listen(1)
        except OSError:
            raise RuntimeError(f"port {port} on 127.0.0.1 is taken (another demo, or a Zenoh router?); "
                               "pass --port P for another, or --port 0 for any free one") from None
        return s.getsockname()[1]


def run_demo(cfg: DemoConfig, stop: threading.Event | None = None) -> dict:
    """Run the demo until ``stop`` or ``cfg.duration_s``; returns the summary."""
    import zenoh

    stop = stop or threading.Event()
    site = load_site(cfg.site)
    cfg.check_cameras(site)
    site_file = str(Path(cfg.site).resolve())  # the processes get absolute paths: no dependence on their folder
    log_dir = Path(cfg.log_dir or tempfile.mkdtemp(prefix="superbody-demo-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{demo_port(cfg.port)}"
    # The world clock starts a little in the future so every process starts on the same grid.
    anchor = time.time_ns()
    clock = WorldClock(anchor, cfg.clock_scale)
    common = ["--clock-scale", str(cfg.clock_scale), "--clock-anchor-ns", str(anchor), "--connect", endpoint]
    procs: dict[str, subprocess.Popen] = {}
    try:
        procs["router"] = _spawn(["router", "--listen", endpoint], log_dir / "router.log")
        for cam in site.camera_ids:
            procs[f"camera-{cam}"] = _spawn(["edge", "run", "--site", site_file, "--camera", cam, "--source", "sim",
                                            "--seed", str(cfg.seed), "--people", str(cfg.people), *cfg.node_args(cam), *common],
                                           log_dir / f"camera-{cam}.log")
        host_args = ["host", "run", "--site", site_file, "--estimator", cfg.estimator, *common, *cfg.extra_host_args]
        if cfg.model:
            host_args += ["--model", str(Path(cfg.model).resolve())]
        procs["host"] = _spawn(host_args, log_dir / "host.log")
        print(f"superbody demo: router on {endpoint}, {len(site.cameras)} cameras and the host started; logs in {log_dir}", file=sys.stderr)

        watcher = _Watcher(site, World(site, cfg.people, cfg.seed, epoch_s=anchor * 1e-9), clock.now_ns(), cfg.camera_fps)
        tty = sys.stdout.isatty()
        if cfg.table:  # at once: the processes take a few seconds to start and the host to load its model
            print(("\x1b[2J\x1b[H" if tty else "") + watcher.table(0.0) + ("" if tty else "\n"), flush=True)
        conf = transport.session_config("peer", connect=[endpoint])
        with zenoh.open(conf) as session:
            subs = [session.declare_subscriber(transport.observation_key(site.name), watcher.on_observation),
                    session.declare_subscriber(transport.people_key(site.name), watcher.on_people)]
            start = clock.now_ns()
            last_table = time.monotonic()
            killed = False
            while not stop.is_set():
                elapsed = (clock.now_ns() - start) / 1e9
                if cfg.duration_s is not None and elapsed >= cfg.duration_s:
                    break
                for name, p in procs.items():
                    if p.poll() is not None and not (killed and name == f"camera-{cfg.kill_camera}"):
                        raise RuntimeError(f"the {name} process exited with code {p.returncode}; see {log_dir / (name + '.log')}")
                if cfg.kill_camera and not killed and elapsed >= cfg.kill_at_s:
                    procs[f"camera-{cfg.kill_camera}"].kill()
                    killed = True
                    watcher.killed_ns = clock.now_ns()
                    print(f"superbody demo: killed camera {cfg.kill_camera} at t={elapsed:.1f} s", file=sys.stderr)
                if cfg.table and time.monotonic() - last_table >= 1.0:
                    last_table = time.monotonic()
                    text = watcher.table(elapsed)
                    print(("\x1b[2J\x1b[H" if tty else "") + text + ("" if tty else "\n"), flush=True)
                time.sleep(0.05)
            for s in subs:
                s.undeclare()
        summary = watcher.summary(cfg.people)
        summary["camera_timing"] = {cam: cfg.camera_timing(cam) for cam in site.camera_ids}
        summary["log_dir"] = str(log_dir)
        if cfg.kill_camera:
            summary["killed_camera"] = cfg.kill_camera
            host_log = (log_dir / "host.log").read_text() if (log_dir / "host.log").exists() else ""
            summary["host_reported_camera_gone"] = f"camera {cfg.kill_camera} is gone" in host_log
        return summary
    finally:
        stop_processes(procs.values())


def stop_processes(procs: Iterable[subprocess.Popen], timeout_s: float = 10.0) -> None:
    """Stop child processes as systemd would: SIGTERM to all, then SIGKILL to any still running
    after ``timeout_s``."""
    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


