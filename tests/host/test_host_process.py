"""The host as a separate process over real Zenoh on loopback, with simulated camera processes."""

from __future__ import annotations

import json
import time

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
        processes.start("host", "run", "--site", SITE, "--estimator", "analytic", "--status-every", "0.5",
                        "--connect", f"tcp/127.0.0.1:{port}")
        for cam in site.camera_ids:
            processes.start("edge", "run", "--site", SITE, "--camera", cam, "--seed", "3", "--people", "2",
                            "--connect", f"tcp/127.0.0.1:{port}")
        assert watch.wait(lambda: any(s["cameras_alive"] == ["1", "2", "3"] for s in watch.status), timeout=30)
        good = json.loads(wire.encode(SimCamera(World(site, 1, seed=0), "1").observe(time.time_ns())[0]))
        bad = {
            "not_json": b"{{{",
            "not_utf8": b"\xc3\x28",
            "version": json.dumps({**good, "version": 7}).encode(),
            "range": json.dumps({**good, "image": [640, 10**6]}).encode(),
            "unknown_camera": json.dumps({**good, "camera": "42"}).encode(),
        }
        for _ in range(20):  # bounded: 100 bad payloads
            for reason, payload in bad.items():
                cam = "42" if reason == "unknown_camera" else "1"
                # blocking: Zenoh's default (DROP) may drop puts on a loaded machine, and this
                # test is about the host's counting, not the network's
                session.put(transport.observation_key(site.name, cam), payload, congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.2)
        n_before = len(watch.arrays)

        def all_counted() -> bool:
            return bool(watch.status) and all(watch.status[-1]["rejected"].get(r, 0) >= 20 for r in bad)

        assert watch.wait(all_counted, timeout=20), watch.status[-1]["rejected"] if watch.status else None
        # Still publishing people from the real cameras afterwards.
        assert watch.wait(lambda: len(watch.arrays) > n_before + 20 and watch.arrays[-1].people, timeout=20)
        for s in watch.subs:
            s.undeclare()
