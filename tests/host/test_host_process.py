"""The host as a separate process over real Zenoh on loopback, with simulated camera processes."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import zenoh

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.demo import DemoConfig, run_demo
from tests.conftest import WTF_SITE, HostWatch, free_port

SITE = str(WTF_SITE)


# The model card's simulated figures for the shipped model as the host runs it (fp32 hybrid; the
# same demo, no camera killed) when these bounds were set: position MAE 64 mm, yaw MAE 7.6 deg
# (December 2026: one network, the floor without a range cut-off, where the simulated people also
# walk far from every camera; before, 41 mm and 12.0 deg on the smaller floor). Bounds here: 1.5
# times those (camera 3 dies half way). Kept, not re-derived from each card: the card's figure
# is one run, and runs vary.
CARD_POSITION_MM, CARD_YAW_DEG = 64.0, 7.6


@pytest.mark.slow

def start_site(processes, port: int, people: int, cameras=None, node_args=None) -> None:
    """The analytic host (status every 0.5 s) and a simulated node per camera (``cameras``, default
    the site's; one may appear twice), seed 3, all on loopback port ``port``."""
    processes.start("host", "run", "--site", SITE, "--estimator", "analytic", "--status-every", "0.5",
                    "--connect", f"tcp/127.0.0.1:{port}")
    for cam in cameras or load_site(SITE).camera_ids:
        processes.start("edge", "run", "--site", SITE, "--camera", cam, "--seed", "3", "--people", str(people),
                        *(node_args or {}).get(cam, ()), "--connect", f"tcp/127.0.0.1:{port}")

def test_three_people_sixty_seconds_and_a_camera_killed():
    """3 cameras, 3 people in distinct clothing, 60 simulated seconds at 3x, the shipped
    model; camera 3 dies at 30 s."""
    summary = run_demo(DemoConfig(site=SITE, people=3, seed=7, duration_s=60, clock_scale=3.0, port=free_port(),
                                  kill_camera="3", kill_at_s=30, table=False))
    assert summary["people_confirmed"] == 3, summary
    assert summary["tracks"] == 3, summary  # exactly three people, never a fourth
    assert all(d <= 3.0 for d in summary["confirm_delay_s"].values()), summary
    assert summary["id_switches"] == 0, summary
    assert summary["position_mae_mm"] <= 1.5 * CARD_POSITION_MM, summary
    assert summary["yaw_mae_deg"] <= 1.5 * CARD_YAW_DEG, summary
    # After camera 3 died the host kept publishing from the other two and reported it gone.
    assert summary["pose_arrays_after_kill"] > 100, summary
    assert summary["cameras_alive_at_end"] == ["1", "2"], summary
    assert summary["host_reported_camera_gone"], summary


def test_malformed_payloads_are_counted_and_the_host_keeps_publishing(processes):
    port = free_port()
    site = load_site(SITE)
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    with zenoh.open(conf) as session:
        watch = HostWatch(session, site.name)
        start_site(processes, port, 2)
        assert watch.wait(lambda: any(s["cameras_alive"] == ["1", "2", "3"] for s in watch.status), timeout=30)
        good = json.loads(wire.encode(SimCamera(World(site, 1, seed=0), "1").observe(time.time_ns())[0]))
        bad = {
            "not_json": b"{{{",
            "not_utf8": b"\xc3\x28",
            "version": json.dumps({**good, "version": 7}).encode(),
            "range": json.dumps({**good, "image": [640, 10**6]}).encode(),
            "unknown_camera": json.dumps({**good, "camera": "42"}).encode(),
        }
        rounds = 10
        for _ in range(rounds):  # bounded: 50 bad payloads, paced: camera 1 may send 2 x its 15 fps, it sends 15 itself
            for reason, payload in bad.items():
                cam = "42" if reason == "unknown_camera" else "1"
                # blocking: Zenoh's default (DROP) may drop puts on a loaded machine, and this
                # test is about the host's counting, not the network's
                session.put(transport.observation_key(site.name, cam), payload, congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.4)
        n_before = len(watch.arrays)

        def all_counted() -> bool:
            return bool(watch.status) and all(watch.status[-1]["rejected"].get(r, 0) >= rounds for r in bad)

        assert watch.wait(all_counted, timeout=20), watch.status[-1]["rejected"] if watch.status else None
        # Still publishing people from the real cameras afterwards.
        assert watch.wait(lambda: len(watch.arrays) > n_before + 20 and watch.arrays[-1].people, timeout=20)
        for s in watch.subs:
            s.undeclare()


def test_a_flood_on_one_camera_key_never_stops_the_host_nor_the_other_cameras(processes):
    """Issue 37: 2,000 valid-looking frames a second on one camera's key, on a loaded machine,
    silenced the host for 12 s (it drained its whole queue before it published, and the flood
    pushed the other cameras' frames out of the one queue). Now the flood is cut at camera 1's
    rate limit before it is decoded, every camera has a queue of its own, a tick's work is
    bounded and the status goes out on its own schedule."""
    port = free_port()
    site = load_site(SITE)
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    with zenoh.open(conf) as session:
        watch = HostWatch(session, site.name)
        start_site(processes, port, 3)
        seen_by_others = lambda a: any({"2", "3"} & set(p.cameras) for p in a.people)  # noqa: E731
        assert watch.wait(lambda: sum(map(seen_by_others, watch.arrays[-20:])) >= 10, timeout=40), "the host never fused cameras 2 and 3"
        doc = json.loads(wire.encode(SimCamera(World(site, 2, seed=3), "1").observe(time.time_ns())[0]))
        pub = session.declare_publisher(transport.observation_key(site.name, "1"))
        with watch.cv:
            before = watch.status[-1]
        t0 = time.monotonic()
        sent = 0
        while time.monotonic() - t0 < 5.0 and sent < 12_000:  # bounded: 5 s at 2,000 frames a second
            for _ in range(20):
                pub.put(json.dumps({**doc, "seq": 10**6 + sent, "stamp_ns": time.time_ns()}))
                sent += 1
            ahead = t0 + sent / 2000 - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
        t1 = time.monotonic()
        assert watch.wait(lambda: len(watch.status_arrived) and watch.status_arrived[-1] > t1 + 0.2, timeout=10)
        pub.undeclare()
        with watch.cv:
            times = [t for t in watch.arrived if t0 <= t <= t1]
            arrays = [a for a, t in zip(watch.arrays, watch.arrived) if t0 + 1.0 <= t <= t1]
            status_times = [t for t in watch.status_arrived if t0 <= t <= t1 + 0.5]
            after = watch.status[-1]
        print(f"sent {sent} frames in {t1 - t0:.1f} s; {len(times)} pose arrays, {len(status_times)} status messages; "
              f"{sum(map(seen_by_others, arrays))} of {len(arrays)} with cameras 2 or 3")
        assert sent >= 5_000, "the flood was not a flood"
        gaps = np.diff([t0, *times, t1])
        assert gaps.max() < 1.0, f"no pose array for {gaps.max():.1f} s during the flood"
        assert np.diff([t0, *status_times]).max() < 1.5  # every 0.5 s, give or take a tick
        # The other cameras' frames all came through (15 fps each) and their views went into the poses.
        cams = [{c["id"]: c for c in st["cameras"]} for st in (before, after)]
        for cam in ("2", "3"):
            assert cams[1][cam]["frames"] - cams[0][cam]["frames"] >= 0.8 * 15 * (t1 - t0), (cam, cams[0][cam], cams[1][cam])
        assert sum(cams[1][c]["fused"] - cams[0][c]["fused"] for c in ("2", "3")) >= 15 * (t1 - t0)
        assert sum(map(seen_by_others, arrays)) >= 0.5 * len(arrays)
        assert cams[1]["1"]["dropped"].get("over_rate", 0) > 0.8 * sent and after["health"]["state"] == "degraded"
        assert any(r.startswith("camera 1: over_rate") for r in after["health"]["reasons"]), after["health"]
        for s in watch.subs:
            s.undeclare()


def test_cameras_late_by_different_delays_are_all_fused_and_the_status_says_how_late(processes):
    """Issue 37: with cameras 0.8 s late the host published nobody, and with mixed delays it left
    the late cameras out while its status said nothing. Three node processes deliver 0.1, 0.8 and
    1.2 s after capture (50 ms jitter): the host publishes everyone from all three cameras, each
    array as old as the latest camera makes it, and the status gives each camera's delay."""
    port = free_port()
    site = load_site(SITE)
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    delays = {"1": 0.1, "2": 0.8, "3": 1.2}
    with zenoh.open(conf) as session:
        watch = HostWatch(session, site.name)
        start_site(processes, port, 3, node_args={c: ("--delay", str(d), "--jitter", "0.05") for c, d in delays.items()})
        fused_all = lambda a: any(set(p.cameras) == {"1", "2", "3"} for p in a.people)  # noqa: E731
        assert watch.wait(lambda: sum(map(fused_all, watch.arrays[-30:])) >= 15, timeout=60), "no person fused from all three cameras"
        t0 = time.monotonic()
        with watch.cv:
            before = {c["id"]: c for c in watch.status[-1]["cameras"]}
        assert watch.wait(lambda: watch.arrived[-1] > t0 + 4.0 and watch.status_arrived[-1] > t0 + 4.0, timeout=20)
        with watch.cv:
            arrays = [a for a, t in zip(watch.arrays, watch.arrived) if t >= t0]
            status = watch.status[-1]
        empty = sum(not a.people for a in arrays) / len(arrays)
        ages = np.array([a.latency_ns / 1e9 for a in arrays])
        cams = {c["id"]: c for c in status["cameras"]}
        fused = {c: cams[c]["fused"] - before[c]["fused"] for c in delays}
        print(f"{len(arrays)} arrays, {empty:.1%} empty, age p50 {np.median(ages):.2f} s, views fused in 4 s {fused}")
        assert empty <= 0.02
        # As old as the latest camera makes it, and said so: its frames come 1.2 s late give or take
        # the 50 ms jitter (a normal spread both ways), so the median age may fall a little below
        # 1.2 s (1.21-1.25 s in 20 runs); without that camera it would be about 0.8.
        assert 1.15 <= np.median(ages) <= 1.5
        for cam, d in delays.items():
            assert abs(cams[cam]["delay_ms"]["p50"] / 1e3 - d) < 0.1, cams[cam]
            assert cams[cam]["state"] == "ok" and fused[cam] >= 15, (cam, fused)  # every camera's views go into the poses
        assert status["health"]["state"] == "ok", status["health"]
        for s in watch.subs:
            s.undeclare()


def test_a_camera_key_with_two_publishers_is_named_in_the_status(processes):
    """Issue 37: a second node publishing under a camera's key (a restarted node still running, or
    a stranger) took the camera over with only "duplicate" and "late" counts as a trace. The
    status names it; the other cameras stay fine."""
    port = free_port()
    site = load_site(SITE)
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    with zenoh.open(conf) as session:
        watch = HostWatch(session, site.name)
        start_site(processes, port, 2, cameras=(*site.camera_ids, "1"))  # camera 1 twice

        def named() -> bool:
            cams = {c["id"]: c for c in watch.status[-1]["cameras"]} if watch.status else {}
            return bool(cams) and cams["1"]["state"] == "two_publishers"

        assert watch.wait(named, timeout=40), watch.status[-1] if watch.status else None
        last = watch.status[-1]
        assert any(r.startswith("camera 1: two_publishers") for r in last["health"]["reasons"]) and last["health"]["state"] == "degraded"
        assert all(c["state"] == "ok" for c in last["cameras"] if c["id"] != "1"), last["cameras"]
        for s in watch.subs:
            s.undeclare()
