"""Event time (issue 37): late and out-of-step cameras through the aggregator, in-process and clock
injected. Each camera's frames are delivered late (its own delay, jitter, in order per camera) and
at its own rate, stamped with their capture time; the host must fuse views of the same instant,
publish everyone, and tell how old what it publishes is.

Before event time, with every camera 0.8 s late the host published nobody (a view counted for 0.5 s
after its capture, on the host's clock), and with mixed delays it left the late cameras out."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest

from superbody.edge.messages import wire
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.estimation.analytic import AnalyticEstimator
from superbody.host.health import camera_statuses
from tests.conftest import LAB_SITE

S = 1_000_000_000
T0 = 1_700_000_000 * S
SITE = load_site(LAB_SITE)  # 4 cameras in the corners of a 6 x 5 m room
SECONDS = 12.0
SETTLE_S = 4.5  # confirmation (2 s) and the longest wait (1.5 s), and a second more


def deliveries(delays_s, fps, jitter_s: float, seed: int = 1, people: int = 3, seconds: float = SECONDS) -> tuple[World, list[tuple[int, str, bytes]]]:
    """Every camera's frames as (arrival, camera, payload), in arrival order: camera k captures at
    ``fps[k]`` and delivers ``delays_s[k]`` (plus normal jitter) after capture, in order."""
    world = World(SITE, people, seed=seed, epoch_s=T0 / S)
    rng = np.random.default_rng(seed)
    out = []
    for k, cid in enumerate(SITE.camera_ids):
        cam = SimCamera(world, cid)
        period, phase = S / fps[k], S * k / (7 * fps[k])
        last = 0
        for j in range(int(seconds * fps[k])):
            stamp = T0 + int(phase + j * period)
            obs = cam.observe(stamp)[0]
            arrival = max(last, stamp + int((delays_s[k] + rng.normal(0.0, jitter_s)) * S) if jitter_s else stamp + int(delays_s[k] * S))
            arrival = max(arrival, stamp + 1)  # never before its capture
            last = arrival
            out.append((arrival, cid, wire.encode(obs)))
    out.sort(key=lambda d: d[0])
    return world, out


def replay(world: World, frames, fps=(15.0,) * 4, config: HostConfig = HostConfig()) -> dict:
    """The deliveries through a fresh aggregator, a step after each; what it published, scored.
    The site file gives each camera its ``fps``."""
    site = dataclasses.replace(SITE, cameras=tuple(dataclasses.replace(c, fps=float(f)) for c, f in zip(SITE.cameras, fps)))
    agg = Aggregator(site, AnalyticEstimator(site), "analytic", config, start_ns=T0)
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    empty = arrays = 0
    views, errors, ages = [], [], []
    for arrival, cam, payload in frames:
        agg.ingest(payload, keys[cam], arrival)
        arr = agg.step(arrival)
        if (arrival - T0) / S < SETTLE_S:
            continue
        arrays += 1
        ages.append(arr.latency_ns / S)
        empty += not arr.people
        for p in arr.people:
            views.append(p.views)
            truth = np.array([[s.x, s.y] for s in world.states(p.stamp_ns / S)])
            errors.append(np.linalg.norm(truth - [p.x, p.y], axis=1).min())
    end = T0 + int((SECONDS + 0.2) * S)  # the status as the cameras stop capturing (the late one still delivers)
    return {"empty": empty / arrays, "views": float(np.mean(views)), "error_m": float(np.median(errors)),
            "age_s": float(np.median(ages)), "people": len(agg.tracker.people(agg.as_of_ns)), "rejected": dict(agg.rejected),
            "cameras": {c.id: c for c in camera_statuses(agg.timeline, SITE.camera_ids, (), end)}}


@pytest.fixture(scope="module")
def prompt():
    return replay(*deliveries([0.005] * 4, [15] * 4, 0.0))


@pytest.mark.parametrize(
    ("delays_s", "fps", "jitter_s", "age_s"),
    [
        ([0.3] * 4, [15] * 4, 0.0, (0.3, 0.45)),                   # all 0.3 s late
        ([0.8] * 4, [15] * 4, 0.0, (0.8, 0.95)),                   # all 0.8 s late: nobody was published
        ([0.1, 0.4, 0.8, 1.2], [15] * 4, 0.05, (1.2, 1.45)),       # each its own delay, 50 ms jitter: two cameras were left out
        ([0.2] * 4, [25, 10, 5, 25], 0.05, (0.2, 0.55)),           # each its own rate, 0.2 s late, jitter
    ],
)
def test_late_and_out_of_step_cameras_are_fused_as_if_prompt(prompt, delays_s, fps, jitter_s, age_s):
    got = replay(*deliveries(delays_s, fps, jitter_s), fps=fps)
    assert got["people"] == 3 and got["empty"] <= 0.02, got
    assert got["views"] >= 0.9 * prompt["views"], (got["views"], prompt["views"])  # every camera's views are used
    assert got["error_m"] <= prompt["error_m"] * 1.25 + 0.01, (got["error_m"], prompt["error_m"])
    # The poses are as old as the latest camera makes them, and the arrays say so.
    assert age_s[0] <= got["age_s"] <= age_s[1], got["age_s"]
    assert got["rejected"] == {} and all(c.state == "ok" for c in got["cameras"].values()), got["cameras"]


def test_prompt_cameras_are_fused_within_a_frame(prompt):
    assert prompt["people"] == 3 and prompt["empty"] == 0.0 and prompt["age_s"] < 0.1
    assert prompt["views"] > 2.5 and prompt["error_m"] < 0.15


def test_a_camera_later_than_the_host_waits_is_left_out_and_named(prompt):
    got = replay(*deliveries([0.1, 0.2, 2.5, 0.1], [15] * 4, 0.02))
    assert got["people"] == 3 and got["empty"] <= 0.02
    assert got["age_s"] < 0.35  # the others are not held back by it
    slow, *others = SITE.camera_ids[2], SITE.camera_ids[0], SITE.camera_ids[1], SITE.camera_ids[3]
    late = got["cameras"][slow]
    assert late.state == "too_late" and late.fused == 0 and late.dropped.get("too_late", 0) + late.dropped.get("stale", 0) > 100
    assert late.delay_ms.p50 == pytest.approx(2500, abs=60)
    assert all(got["cameras"][c].state == "ok" for c in others)
    assert got["error_m"] <= prompt["error_m"] * 1.5 + 0.01


def test_work_per_step_is_bounded_however_much_arrived():
    # A host starved of CPU for a second gets every camera's backlog at once: each step feeds the
    # tracker at most max_frames_per_step frames, in capture order, and the rest follow.
    world, frames = deliveries([0.1] * 4, [15] * 4, 0.0)
    agg = Aggregator(SITE, AnalyticEstimator(SITE), "analytic", HostConfig(max_frames_per_step=16), start_ns=T0 - 10 * S)
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    burst_at = T0 + 5 * S
    backlog = [f for f in frames if burst_at - S <= f[0] < burst_at]  # a second of every camera
    for _, cam, payload in backlog:
        assert agg.ingest(payload, keys[cam], burst_at)
    fed, stamps = [], []
    for k in range(10):
        before = agg.tracker.stats["observations"]
        agg.step(burst_at + k * S // 100)
        fed.append(agg.tracker.stats["observations"] - before)
        stamps.append(agg.as_of_ns)
    assert fed[:3] == [16, 16, 16] and agg.timeline.released == len(backlog) - agg.timeline.pending
    assert agg.timeline.released - len(SITE.cameras) < sum(fed) <= agg.timeline.released  # but an instant still open
    assert stamps == sorted(stamps)  # the fused instant moves on step by step


def test_the_status_names_a_camera_knocked_after_calibration_within_30_s():
    """Issue 40: a camera knocked 2 deg and 10 cm after calibration went unnoticed. The people
    walking by (3 simulated, 4 cameras, the detector's noise) show it: the host's status names it
    within 30 s of capture time, and no other camera."""
    from benchmarks.people_calibration import knock
    from superbody.host.calibration.health import attribute

    world, frames = deliveries([0.1] * 4, [15] * 4, 0.02, seconds=16.0)
    knocked = knock(SITE, SITE.camera_ids[1], seed=0, view=True)
    agg = Aggregator(knocked, AnalyticEstimator(knocked), "analytic", start_ns=T0)
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    found_at, others = None, set()
    next_status = T0 + 10 * S
    for arrival, cam, payload in frames:
        agg.ingest(payload, keys[cam], arrival)
        agg.step(arrival)
        if arrival >= next_status:  # as the host process does at each status: the test's inputs, run, applied
            next_status += 2 * S
            due = agg.calibration.check_due(arrival)
            if due is not None:
                agg.calibration.apply(attribute(*due))
            states = {c.id: c.state for c in camera_statuses(agg.timeline, SITE.camera_ids, (), arrival, agg.calibration.report(arrival, check=False))}
            others |= {c for c, st in states.items() if st == "moved" and c != SITE.camera_ids[1]}
            if states[SITE.camera_ids[1]] == "moved" and found_at is None:
                found_at = (arrival - T0) / S
    print(f"camera {SITE.camera_ids[1]} named moved {found_at} s in")
    assert found_at is not None and found_at <= 30.0 and not others, (found_at, others)


class _Seen(AnalyticEstimator):
    """The real estimator, noting the identity of every view it is given."""

    def __init__(self, site) -> None:
        super().__init__(site)
        self.seen: set[bytes] = set()

    def estimate_detailed(self, view_sets):
        self.seen.update(v.keypoints.tobytes() for views in view_sets for v in views.values())
        return super().estimate_detailed(view_sets)


@pytest.mark.parametrize("every_s", [0.2, 0.5])
def test_a_host_that_steps_seldom_estimates_every_view_all_the_same(every_s):
    # A host that publishes at most 5 Hz (max_publish_hz, for a serial link) or falls behind its
    # cameras releases several frames of each camera per step. Each person was estimated once per
    # step, from their latest view per camera: the views between were tracked, never estimated
    # (at 0.2 s, 2 of every 3 of each camera's views; position p90 90 against 78 mm).
    world, frames = deliveries([0.3] * 4, [15] * 4, 0.0, seed=1)
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    seen = {}
    for step_s in (0.0, every_s):
        est = _Seen(SITE)
        agg = Aggregator(SITE, est, "analytic", HostConfig(), start_ns=T0)
        due = T0
        for arrival, cam, payload in frames:
            agg.ingest(payload, keys[cam], arrival)
            if arrival >= due:
                agg.step(arrival)
                due = arrival + int(step_s * S)
        agg.step(frames[-1][0] + 2 * S)
        seen[step_s] = est.seen
    stepped_each, seldom = seen[0.0], seen[every_s]
    assert len(stepped_each) > 1000
    assert len(seldom & stepped_each) >= 0.98 * len(stepped_each), (len(seldom & stepped_each), len(stepped_each))


def _instants(frames, skip_s: float = 0.0) -> tuple[list[list[tuple[str, int]]], Aggregator]:
    """The frames the tracker gets together (each ``Tracker.update_instant`` call, as (camera,
    stamp) pairs) from a host stepping after each delivery, fed the frames captured ``skip_s`` or
    more after T0 (a host that started then)."""
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    agg = Aggregator(SITE, AnalyticEstimator(SITE), "analytic", HostConfig(), start_ns=T0 + int(skip_s * S))
    calls: list[list[tuple[str, int]]] = []
    update_instant = agg.tracker.update_instant

    def spy(batch):
        calls.append([(o.camera, o.stamp_ns) for o in batch])
        return update_instant(batch)

    agg.tracker.update_instant = spy  # type: ignore[method-assign]
    for arrival, cam, payload in frames:
        if wire.decode(payload).stamp_ns >= T0 + skip_s * S:
            agg.ingest(payload, keys[cam], arrival)
            agg.step(arrival)
    agg.step(frames[-1][0] + 2 * S)
    return calls, agg


@pytest.mark.parametrize("delays_s, jitter_s", [([0.005] * 4, 0.0), ([0.3] * 4, 0.0), ([0.1, 0.3, 0.6, 0.45], 0.05), ([0.1, 0.4, 0.8, 1.2], 0.05)])
def test_the_tracker_gets_the_same_instants_however_the_cameras_deliver(delays_s, jitter_s):
    # Every camera's frame of an instant together (Tracker.update_instant), one per camera, in
    # capture order, every admitted frame once: whether the cameras deliver at once (each delivery
    # releases one frame: the instant is held until its last camera's is in), late, or late each
    # by its own delay (frames in bunches), and wherever the host started.
    prompt, _ = _instants(deliveries([0.005] * 4, [15] * 4, 0.0, seed=2)[1])
    calls, agg = _instants(deliveries(delays_s, [15] * 4, jitter_s, seed=2)[1])
    got = [f for c in calls for f in c]
    assert len(got) == len(set(got)) == agg.tracker.stats["observations"] > 0.95 * 4 * 15 * SECONDS
    assert all(len({cam for cam, _ in c}) == len(c) for c in calls)  # one frame per camera
    assert got == sorted(got, key=lambda f: f[1])  # capture order, across calls too

    def settled(instants):  # from 2 s on, and before the cameras stop (then nobody is still delivering)
        return [c for c in instants if T0 + 2 * S <= c[0][1] < T0 + (SECONDS - 0.2) * S]

    assert all(len(c) == 4 for c in settled(calls)), sorted(Counter(len(c) for c in settled(calls)).items())  # every camera's
    assert settled(calls) == settled(prompt)
    later, _ = _instants(deliveries(delays_s, [15] * 4, jitter_s, seed=2)[1], skip_s=1.03)  # a host started mid-instant
    assert settled(later) == settled(calls)


def test_a_held_instant_is_not_yet_what_the_poses_describe():
    # Prompt cameras out of step: the array after a delivery that leaves an instant open describes
    # the instant before it (its last frame's capture time), never a frame the tracker has not seen.
    world, frames = deliveries([0.005] * 4, [15] * 4, 0.0)
    keys = {c: f"superbody/{SITE.name}/cameras/{c}/observations" for c in SITE.camera_ids}
    agg = Aggregator(SITE, AnalyticEstimator(SITE), "analytic", HostConfig(), start_ns=T0)
    seen: list[int] = []
    update_instant = agg.tracker.update_instant
    agg.tracker.update_instant = lambda batch: (seen.extend(o.stamp_ns for o in batch), update_instant(batch))[1]  # type: ignore[method-assign]
    held = 0
    for arrival, cam, payload in frames:
        agg.ingest(payload, keys[cam], arrival)
        arr = agg.step(arrival)
        as_of = arr.stamp_ns - arr.latency_ns
        if seen:
            assert as_of == agg.as_of_ns <= max(seen)
            held += as_of < agg.timeline.released_to()
    assert held > 0.5 * len(frames)  # three deliveries in four leave an instant open
