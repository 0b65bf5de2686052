"""Host speed: observation -> pose latency and the highest sustained observation rate, one core.

    python -m benchmarks.host_bench [--model models/site-independent.fp32.onnx] [--seconds 6]
                                    [--configs 3x10,10x10] [--cpu-time] [--zenoh] [--json-out F]

(from the repository; ``python benchmarks/host_bench.py`` works too.)

For 3, 6 and 10 cameras x 1, 5 and 10 people (or ``--configs``): a ring of cameras (30 fps) around an 8 x 6 m
room, simulated people, every camera's observations encoded beforehand. Then, with this
process pinned to one core:

- processing: the host's real path (decode and validate, tracker, set S, graph building, one
  batched ONNX call for the people whose views changed, filter, PoseArray encoding) driven by a
  queue simulation on measured costs: observations arrive at their real rate (30 fps per
  camera), the host drains what has arrived, steps and publishes. Latency = publication -
  arrival (p50/p99). The highest sustained rate: the arrival rate is raised until the backlog
  grows (p99 over 100 ms).
- with ``--zenoh``: the host as its own process pinned to one core, a feeder process publishing
  the observations over loopback Zenoh at their capture times (30 fps per camera), and the
  latency from each observation's capture to the arrival of the PoseArray it first appears in.

Absolute times on shared machines move 2-3x between runs and machines, so each figure comes with
a ratio against a reference timed in the same run on the same core:

- ``step_us_per_obs_over_json_loads``: the host's cost per observation at the real rate (ingest
  to PoseArray encoding; ``step_us_per_obs``) over ``json.loads`` of the same payloads, timed
  after each step (``json_loads_us_per_obs``).
- with ``--zenoh``, ``e2e_p50_over_zenoh_rtt`` and ``e2e_p99_over_zenoh_rtt``: the end-to-end
  latency's p50 and p99, each over the median of Zenoh's own loopback round trip
  (``zenoh_rtt_p50_ms``; its p99 ``zenoh_rtt_p99_ms`` is given too, but a p99 of a few hundred
  round trips jumps with any load, so it is no divisor): payloads of the observations' median
  size, at their rate, put by this process and echoed by a process on the host's core, peers
  on 127.0.0.1 as ``edge.transport.session_config`` makes them (multicast scouting off).

``--json-out F`` writes ``{"CxP": {p50_ms, p99_ms, ..., step_us_per_obs, json_loads_us_per_obs,
step_us_per_obs_over_json_loads[, e2e_p50_ms, ..., zenoh_rtt_p50_ms, e2e_p50_over_zenoh_rtt, ...]}}``.

The estimator is the site-independent model (it serves any number of cameras); per-person cost
does not depend on its weights. Without it, the analytic estimator is used and said so.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from superbody.edge import transport
from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.messages import wire
from superbody.edge.resources import model_path
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import Site, dump_site
from superbody.host.aggregator import Aggregator
from superbody.host.estimation import build_estimator
from superbody.host.messages import pose as pose_msg

ROOT = Path(__file__).resolve().parents[1]  # the repository: the feeder and echo processes import benchmarks.host_bench from it
FPS = 30.0


def ring_site(n: int) -> Site:
    """``n`` 720p cameras on the walls of an 8 x 6 m room, 2.6 m up, looking at its centre."""
    w, d = 8.0, 6.0
    cams = []
    for i in range(n):
        a = 2 * math.pi * i / n
        v = np.array([math.cos(a), math.sin(a)])
        s = min((w / 2 - 0.1) / max(abs(v[0]), 1e-9), (d / 2 - 0.1) / max(abs(v[1]), 1e-9))
        pos = np.array([w / 2 + s * v[0], d / 2 + s * v[1], 2.6])
        R = look_at_rotation(pos, np.array([w / 2, d / 2, 0.9]))
        cams.append(Camera(id=f"c{i}", width=1280, height=720, fps=FPS, fx=800.0, fy=800.0, cx=640.0, cy=360.0,
                           position=tuple(map(float, pos)), rotation=tuple(tuple(map(float, r)) for r in R)))
    return Site(name=f"ring{n}", cameras=tuple(cams), floor=((0.0, 0.0), (w, 0.0), (w, d), (0.0, d)))


def frames(site: Site, people: int, seconds: float, t0_ns: int) -> list[tuple[int, str, bytes]]:
    """(capture ns, camera, payload) of every camera's frames, in capture order."""
    world = World(site, people, seed=5)
    cams = [SimCamera(world, c.id) for c in site.cameras]
    out = []
    for k in range(int(seconds * FPS)):
        for i, cam in enumerate(cams):
            stamp = t0_ns + int((k + i / len(cams)) * 1e9 / FPS)
            out.append((stamp, cam.camera.id, wire.encode(cam.observe(stamp)[0])))
    return out


CLOCK = time.perf_counter  # main(cpu_time=True) swaps in time.thread_time


def processing(site: Site, estimator, name: str, data: list, speed: float, reference: bool = False) -> dict:
    """The host loop on measured costs, observations arriving at ``speed`` x their real rate.

    A queue simulation on this core: observations arrive at (capture - first capture) / speed;
    the host drains every observation that has arrived (decode and validate, tracker), then
    steps (set S, graphs, one ONNX call, filter) and encodes the PoseArray; each step's cost is
    measured with perf_counter (``--cpu-time``: this thread's CPU time, which other processes
  sharing the core do not inflate: a dedicated core's cost) and advances the clock. Latency = publication - arrival.

    ``reference``: after each step, the same clock also times ``json.loads`` of the payloads that
    step ingested (outside the simulated clock), so that the step's cost per observation comes
    with a reference measured on the same core, the same bytes and in the same seconds:
    ``step_us_per_obs``, ``json_loads_us_per_obs`` and their ratio
    ``step_us_per_obs_over_json_loads`` (means over the steps after the first third, as latency).
    """
    agg = Aggregator(site, estimator, name)
    keys = {c.id: transport.observation_key(site.name, c.id) for c in site.cameras}
    arrive = (np.array([s for s, _, _ in data]) - data[0][0]) / 1e9 / speed
    now, i, lat, people, batches = 0.0, 0, np.zeros(len(data)), [], 0
    cost, ref = np.zeros(len(data)), np.zeros(len(data))  # seconds per observation: the host's step, json.loads
    while i < len(data):
        now = max(now, arrive[i])
        j = int(np.searchsorted(arrive, now, side="right"))
        t = CLOCK()
        for stamp, cam, payload in data[i:j]:
            agg.ingest(payload, keys[cam], stamp)
        arr = agg.step(data[j - 1][0])
        pose_msg.encode(arr)
        dt = CLOCK() - t
        now += dt
        cost[i:j] = dt / (j - i)
        if reference:  # interleaved with the steps, not on the simulated clock
            t = CLOCK()
            for _, _, payload in data[i:j]:
                json.loads(payload)
            ref[i:j] = (CLOCK() - t) / (j - i)
        lat[i:j] = now - arrive[i:j]
        people.append(len(arr.people))
        batches += 1
        i = j
    warm = lat[len(lat) // 3 :] * 1e3  # after the tracker's first seconds of confirming people
    out = {"p50_ms": float(np.percentile(warm, 50)), "p99_ms": float(np.percentile(warm, 99)),
           # People published at the end (a median over steps would favour the many small early steps).
           "obs_per_step": len(data) / batches, "people_tracked": people[-1],
           "backlog_s": float(lat[-1]), "rejected": dict(agg.rejected)}
    if reference:
        step_us, ref_us = float(cost[len(cost) // 3 :].mean() * 1e6), float(ref[len(ref) // 3 :].mean() * 1e6)
        out.update(step_us_per_obs=step_us, json_loads_us_per_obs=ref_us,
                   step_us_per_obs_over_json_loads=step_us / ref_us if ref_us > 0 else math.nan)
    return out


def sustained(site: Site, estimator, name: str, data: list, offered: float) -> float:
    """The highest observation rate (obs/s) at which the backlog stays bounded (p99 < 100 ms)."""
    best = 0.0
    for speed in (1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32):
        r = processing(site, estimator, name, data, speed)
        if r["p99_ms"] > 100 or r["backlog_s"] > 0.1:
            break
        best = offered * speed
    return best


def _feeder(port: int, data_path: str, site_name: str) -> None:
    """Publishes the pre-encoded observations at their capture times (a separate process)."""
    import pickle

    import zenoh

    data = pickle.loads(Path(data_path).read_bytes())
    with zenoh.open(transport.session_config("peer", connect=[f"tcp/127.0.0.1:{port}"])) as s:
        pubs = {}
        for stamp, cam, payload in data:
            pub = pubs.get(cam) or pubs.setdefault(cam, s.declare_publisher(transport.observation_key(site_name, cam)))
            delay = (stamp - time.time_ns()) / 1e9
            if delay > 0:
                time.sleep(delay)
            pub.put(payload)


def free_port() -> int:
    """A free TCP port on 127.0.0.1 (for the benchmark's own listening session)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _child(call: str, core: set[int], **popen) -> subprocess.Popen:
    """``python -c "from benchmarks.host_bench import ...; <call>"`` run from the repository (its
    folder is the child's first import path: no sys.path edits), on the given cores."""
    name = call.split("(")[0]
    return subprocess.Popen([sys.executable, "-c", f"from benchmarks.host_bench import {name}; {call}"], cwd=ROOT,
                            preexec_fn=lambda: os.sched_setaffinity(0, core), **popen)


def _echo(port: int, key: str) -> None:
    """Puts every payload that arrives on ``key``/ping back on ``key``/pong, until stdin closes (a
    separate process: Zenoh's own round trip, the reference for the end-to-end latency)."""
    import zenoh

    with zenoh.open(transport.session_config("peer", connect=[f"tcp/127.0.0.1:{port}"])) as s:
        pub = s.declare_publisher(f"{key}/pong")
        sub = s.declare_subscriber(f"{key}/ping", lambda sample: pub.put(sample.payload.to_bytes()))
        sys.stdin.read()
        sub.undeclare()


def zenoh_round_trip(session, key: str, size: int, rate_hz: float, seconds: float = 1.0, min_pings: int = 100) -> dict:
    """Zenoh's own loopback round trip: ``size``-byte payloads put on ``key``/ping at ``rate_hz``
    (for ``seconds``, at least ``min_pings``), echoed by ``_echo`` on ``key``/pong; the time from
    each put to its echo's arrival in this session's callback (as the PoseArrays' arrivals are
    taken), p50 and p99 in ms."""
    import threading

    got: dict[int, int] = {}
    answered = threading.Event()

    def on_pong(sample) -> None:
        got[int.from_bytes(sample.payload.to_bytes()[:8], "little")] = time.perf_counter_ns()
        answered.set()

    sub = session.declare_subscriber(f"{key}/pong", on_pong)
    pub = session.declare_publisher(f"{key}/ping")
    pad = bytes(max(size - 8, 0))
    try:
        deadline = time.monotonic() + 30.0  # the echo process may still be connecting
        k = 2**62
        while not answered.wait(0.05):
            if time.monotonic() > deadline:
                return {"zenoh_rtt_p50_ms": math.nan, "zenoh_rtt_p99_ms": math.nan, "zenoh_rtt_payload_bytes": size}
            pub.put(k.to_bytes(8, "little") + pad)
            k += 1
        time.sleep(0.2)
        n = max(min_pings, int(seconds * rate_hz))
        sent = np.zeros(n, dtype=np.int64)
        start = time.perf_counter()
        for i in range(n):
            delay = start + i / rate_hz - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            payload = i.to_bytes(8, "little") + pad
            sent[i] = time.perf_counter_ns()
            pub.put(payload)
        time.sleep(0.2)
    finally:
        sub.undeclare()
        pub.undeclare()
    rtt = np.array([(got[i] - sent[i]) / 1e6 for i in range(n) if i in got])
    if len(rtt) == 0:
        return {"zenoh_rtt_p50_ms": math.nan, "zenoh_rtt_p99_ms": math.nan, "zenoh_rtt_payload_bytes": size}
    return {"zenoh_rtt_p50_ms": float(np.percentile(rtt, 50)), "zenoh_rtt_p99_ms": float(np.percentile(rtt, 99)),
            "zenoh_rtt_payload_bytes": size, "zenoh_rtt_pings": int(len(rtt))}


def over_zenoh(site: Site, model: str | None, people: int, seconds: float, gen_s: float) -> dict:
    """Host process on one core, feeder process, loopback Zenoh: capture -> PoseArray arrival.

    Then, in the same session, Zenoh's own round trip on that core (``zenoh_round_trip``: an echo
    process pinned where the host ran, payloads of the observations' median size at their rate),
    and the end-to-end latency's p50 and p99 over its median (``e2e_p50_over_zenoh_rtt``,
    ``e2e_p99_over_zenoh_rtt``).
    """
    import pickle

    import zenoh

    port = free_port()
    tmp = Path(tempfile.mkdtemp(prefix="host-bench-"))
    (tmp / "site.toml").write_text(dump_site(site))
    t0 = time.time_ns() + int((4.0 + 1.5 * gen_s) * 1e9)  # after generating the data again and starting the processes
    data = frames(site, people, seconds, t0)
    (tmp / "data.pkl").write_bytes(pickle.dumps(data))
    arrivals: list[tuple[int, pose_msg.PoseArray]] = []
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    core = min(os.sched_getaffinity(0))
    others = set(os.sched_getaffinity(0)) - {core} or {core}
    echo_key = f"superbody-bench/{site.name}/echo"
    host_args = [sys.executable, "-m", "superbody.edge.cli", "host", "run", "--site", str(tmp / "site.toml"), "--connect", f"tcp/127.0.0.1:{port}",
                 *(["--model", model] if model else ["--estimator", "analytic"])]
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(transport.people_key(site.name), lambda s: arrivals.append((time.time_ns(), pose_msg.decode(s.payload.to_bytes()))))
        host = subprocess.Popen(host_args, stderr=subprocess.DEVNULL, preexec_fn=lambda: os.sched_setaffinity(0, {core}))
        # Started now, idle until the host is done: it connects while the host starts.
        echo = _child(f"_echo({port}, {echo_key!r})", {core}, stdin=subprocess.PIPE)
        try:
            feeder = _child(f"_feeder({port}, {str(tmp / 'data.pkl')!r}, {site.name!r})", others)
            feeder.wait(timeout=seconds + 120)
            time.sleep(0.5)
            host.terminate()
            host.wait(timeout=20)
            sub.undeclare()
            sizes = [len(p) for _, _, p in data]
            rtt = zenoh_round_trip(session, echo_key, int(np.median(sizes)), len(site.cameras) * FPS)
        finally:
            echo.stdin.close()
            try:
                echo.wait(timeout=10)
            except subprocess.TimeoutExpired:
                echo.kill()
    # Latency of an observation = arrival of the first PoseArray whose newest view is at least as new.
    stamps = np.array(sorted(s for s, _, _ in data if s > t0 + 2.5e9))
    arr_t = np.array([a for a, p in arrivals if p.people])
    arr_s = np.array([max(q.stamp_ns for q in p.people) for _, p in arrivals if p.people])
    out = {"e2e_p50_ms": math.nan, "e2e_p99_ms": math.nan, "observations": 0}
    if len(arr_s) and len(stamps):
        order = np.argsort(arr_s)
        best = np.minimum.accumulate(arr_t[order][::-1])[::-1]  # earliest arrival among arrays at least this new
        idx = np.searchsorted(arr_s[order], stamps)
        ok = idx < len(order)
        if ok.any():
            lat = (best[idx[ok]] - stamps[ok]) / 1e6
            out = {"e2e_p50_ms": float(np.percentile(lat, 50)), "e2e_p99_ms": float(np.percentile(lat, 99)), "observations": int(ok.sum())}
    out.update(rtt)
    ref = rtt["zenoh_rtt_p50_ms"]  # the median round trip: the p99 of a few hundred jumps with any load
    for q in ("p50", "p99"):
        out[f"e2e_{q}_over_zenoh_rtt"] = out[f"e2e_{q}_ms"] / ref if ref > 0 else math.nan
    return out


def _configs(text: str) -> list[tuple[int, int]]:
    try:
        out = [tuple(int(v) for v in c.lower().split("x")) for c in text.split(",")]
        if all(len(c) == 2 and 1 <= c[0] <= 64 and 1 <= c[1] <= 64 for c in out):
            return out  # type: ignore[return-value]
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"--configs must be CAMERASxPEOPLE pairs, each 1 to 64, comma-separated, got {text!r}")


def main(model: str | None, seconds: float, use_zenoh: bool, json_out: str | None,
         configs: list[tuple[int, int]] | None = None, cpu_time: bool = False) -> int:
    global CLOCK
    CLOCK = time.thread_time if cpu_time else time.perf_counter
    allowed = os.sched_getaffinity(0)
    core = min(allowed)
    os.sched_setaffinity(0, {core})  # one core for the in-process measurement (and the host process's)
    if model and not Path(model).is_file():
        print(f"no model at {model}: using the analytic estimator", file=sys.stderr)
        model = None
    results = {}
    print(f"estimator: {Path(model).name if model else 'analytic'}; {FPS:.0f} fps per camera; one core; "
          f"costs in {'thread CPU time' if cpu_time else 'wall time'}; load average {os.getloadavg()[0]:.2f}")
    print("ratios against references timed in the same run on the same core: step = the host's cost per observation "
          "(ingest to PoseArray encoding) over json.loads of the same payloads"
          + ("; e2e = capture to PoseArray arrival, its p50 and p99 over the median of Zenoh's own loopback round trip (rtt p50)"
             if use_zenoh else ""))
    header = (f"{'cameras':>7} {'people':>6} {'obs/s':>6} {'p50 ms':>7} {'p99 ms':>7} {'obs/step':>8} {'tracked':>7} {'max sustained obs/s':>19}"
              f" {'step us/obs':>11} {'json.loads us':>13} {'step/json':>9}")
    if use_zenoh:
        header += f" {'e2e p50':>8} {'e2e p99':>8} {'rtt p50':>8} {'rtt p99':>8} {'e2e p50/rtt':>11} {'e2e p99/rtt':>11}"
    print(header)
    configs = configs or [(n, people) for n in (3, 6, 10) for people in (1, 5, 10)]
    for n in sorted({n for n, _ in configs}):
        site = ring_site(n)
        estimator, name = build_estimator(site, "onnx" if model else "analytic", model)
        for people in [p for c, p in configs if c == n]:
            t_gen = time.monotonic()
            data = frames(site, people, seconds, 1_700_000_000 * 10**9)
            gen_s = time.monotonic() - t_gen
            r = processing(site, estimator, name, data, 1.0, reference=True)
            r["max_sustained_obs_per_s"] = sustained(site, estimator, name, data, n * FPS)
            if use_zenoh:
                os.sched_setaffinity(0, allowed)  # over_zenoh pins the host process to min(allowed), this same core
                r.update(over_zenoh(site, model, people, seconds, gen_s))
                os.sched_setaffinity(0, {core})
            results[f"{n}x{people}"] = r
            line = (f"{n:>7} {people:>6} {n * FPS:>6.0f} {r['p50_ms']:>7.2f} {r['p99_ms']:>7.2f} {r['obs_per_step']:>8.2f} "
                    f"{r['people_tracked']:>7} {r['max_sustained_obs_per_s']:>19.0f}"
                    f" {r['step_us_per_obs']:>11.0f} {r['json_loads_us_per_obs']:>13.1f} {r['step_us_per_obs_over_json_loads']:>9.1f}")
            if use_zenoh:
                line += (f" {r['e2e_p50_ms']:>8.2f} {r['e2e_p99_ms']:>8.2f} {r['zenoh_rtt_p50_ms']:>8.3f} {r['zenoh_rtt_p99_ms']:>8.3f}"
                         f" {r['e2e_p50_over_zenoh_rtt']:>11.1f} {r['e2e_p99_over_zenoh_rtt']:>11.1f}")
            print(line, flush=True)
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default=str(model_path("site-independent.fp32.onnx")), help="a rays-variant model")
    p.add_argument("--seconds", type=float, default=6.0, help="simulated seconds per configuration")
    p.add_argument("--zenoh", action="store_true", help="also measure end to end over loopback Zenoh, host in its own process")
    p.add_argument("--configs", type=_configs, help="cameras x people to run, e.g. 3x10,10x10 (default: 3, 6, 10 x 1, 5, 10)")
    p.add_argument("--cpu-time", action="store_true", help="cost each step in this thread's CPU time, not wall time (a shared machine)")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.model, a.seconds, a.zenoh, a.json_out, a.configs, a.cpu_time))
