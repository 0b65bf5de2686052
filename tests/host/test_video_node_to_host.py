"""A real-image camera node beside a simulated one: one host, three processes, loopback Zenoh.

Camera 1 of the apartment is a video node (a lossless video of a real photo through the real
BlazePose); camera 2 is a simulated node. The host must see both cameras, accept everything they
send, and publish the photo's person from camera 1's views.

The site is the apartment without camera 3: the photo's person stands (1.1 m from camera 1) where
camera 3 clearly looks, and a person that one camera reports where another clearly sees nobody is a
detector's false positive to the tracker (``host.tracking.evidence``), never confirmed. Camera 2
does not clearly see that spot. The same rule holds back the simulated person while they walk
where camera 1 (which sees only the photo) clearly looks; and they are somebody else than the
photo's person, whose view their set S leaves out (``evidence.one_body``). So the test does not
wait for them.
"""

from __future__ import annotations

from pathlib import Path

import zenoh

from superbody.edge import transport
from tests.conftest import WTF_SITE, HostWatch, free_port
from tests.edge.photos import astronaut_video


def _without_camera_3(path: Path) -> Path:
    """The apartment's site file less camera 3 (the last camera), under another name."""
    text = WTF_SITE.read_text()
    text = text[: text.rindex("[[cameras]]")].replace('name = "wtf-apartment"', 'name = "wtf-two"')
    path.write_text(text)
    return path


def test_video_node_and_a_simulated_node_feed_one_host(processes, tmp_path):
    site = str(_without_camera_3(tmp_path / "wtf-two.toml"))
    clip = tmp_path / "astronaut.avi"
    astronaut_video(clip, frames=30, fps=15.0)  # 2 s, played in a loop
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    conf = transport.session_config("peer", connect=[], listen=[endpoint])
    with zenoh.open(conf) as session:
        watch = HostWatch(session, "wtf-two")
        host = processes.start("host", "run", "--site", site, "--estimator", "analytic", "--status-every", "0.5", "--connect", endpoint)
        video = processes.start("edge", "run", "--site", site, "--camera", "1", "--source", f"video:{clip}", "--loop",
                                "--detector", "blazepose", "--connect", endpoint)
        processes.start("edge", "run", "--site", site, "--camera", "2", "--seed", "3", "--people", "1", "--connect", endpoint)

        def alive() -> bool:
            return any(s["cameras_alive"] == ["1", "2"] for s in watch.status)

        assert watch.wait(alive, timeout=30), (watch.status[-1:], video.poll(), host.poll())

        def uses_camera_1() -> bool:
            return any("1" in p.cameras for a in watch.arrays for p in a.people)

        assert watch.wait(uses_camera_1, timeout=30), ([a.people for a in watch.arrays[-3:]], watch.status[-1:])
        # Nothing was rejected on the way.
        assert not watch.status[-1]["rejected"], watch.status[-1]
        for p in (p for a in watch.arrays for p in a.people if "1" in p.cameras):
            assert p.views >= 1 and 0.0 <= p.confidence <= 1.0
        assert video.poll() is None and host.poll() is None  # both still running
