"""A real-image camera node beside simulated ones: one host, four processes, loopback Zenoh.

Camera 1 of the apartment is a video node (a lossless video of a real photo through the real
BlazePose); cameras 2 and 3 are simulated nodes. The host must see all three cameras and
publish people whose views include camera 1's.
"""

from __future__ import annotations

import zenoh

from superbody.edge import transport
from tests.conftest import WTF_SITE, HostWatch, free_port
from tests.edge.photos import astronaut_video

SITE = str(WTF_SITE)


def test_video_node_and_two_simulated_nodes_feed_one_host(processes, tmp_path):
    clip = tmp_path / "astronaut.avi"
    astronaut_video(clip, frames=30, fps=15.0)  # 2 s, played in a loop
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    with zenoh.open(conf) as session:
        watch = HostWatch(session, "wtf-apartment")
        host = processes.start("host", "run", "--site", SITE, "--status-every", "0.5", "--connect", endpoint)
        video = processes.start("edge", "run", "--site", SITE, "--camera", "1", "--source", f"video:{clip}", "--loop",
                                "--detector", "blazepose", "--connect", endpoint)
        for cam in ("2", "3"):
            processes.start("edge", "run", "--site", SITE, "--camera", cam, "--seed", "3", "--people", "1", "--connect", endpoint)

        def alive() -> bool:
            return any(s["cameras_alive"] == ["1", "2", "3"] for s in watch.status)

        assert watch.wait(alive, timeout=30), (watch.status[-1:], video.poll(), host.poll())

        def uses_camera_1() -> bool:
            return any("1" in p.cameras for a in watch.arrays for p in a.people)

        assert watch.wait(uses_camera_1, timeout=30), ([a.people for a in watch.arrays[-3:]], watch.status[-1:])
        # The simulated cameras' person is there too, and nothing was rejected on the way.
        assert watch.wait(lambda: any({"2", "3"} & set(p.cameras) for a in watch.arrays for p in a.people), timeout=10)
        assert not watch.status[-1]["rejected"], watch.status[-1]
        for p in (p for a in watch.arrays for p in a.people if "1" in p.cameras):
            assert p.views >= 1 and 0.0 <= p.confidence <= 1.0
        assert video.poll() is None and host.poll() is None  # both still running
