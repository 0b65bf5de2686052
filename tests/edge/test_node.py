"""Camera nodes as separate processes over real Zenoh on loopback."""

from __future__ import annotations

import threading
import time
from collections import defaultdict

import numpy as np
import pytest
import zenoh

from superbody.edge import transport, wire
from superbody.edge.simulator import SimCamera, World
from superbody.edge.site import load_site
from tests.conftest import LAB_SITE, free_port

SITE = str(LAB_SITE)


class Listener:
    """A subscriber session listening on a loopback port, recording what arrives."""

    def __init__(self, port: int, site: str = "lab-example"):
        self.received: dict[str, list[tuple[float, object]]] = defaultdict(list)
        self.errors: list[str] = []
        self.alive: list[tuple[str, str]] = []
        self.event = threading.Condition()
        conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
        self.session = zenoh.open(conf)
        self.sub = self.session.declare_subscriber(transport.observation_key(site), self._on_obs)
        self.live = self.session.liveliness().declare_subscriber(transport.camera_alive_key(site), self._on_alive, history=True)

    def _on_obs(self, sample) -> None:
        try:
            obs = wire.decode(sample.payload.to_bytes())
            with self.event:
                self.received[obs.camera].append((time.monotonic(), obs))
                self.event.notify_all()
        except wire.DecodeError as e:
            self.errors.append(str(e))

    def _on_alive(self, sample) -> None:
        with self.event:
            kind = "PUT" if sample.kind == zenoh.SampleKind.PUT else "DELETE"
            self.alive.append((transport.camera_from_key(str(sample.key_expr)), kind))
            self.event.notify_all()

    def wait_for(self, predicate, timeout: float) -> bool:
        with self.event:
            return self.event.wait_for(predicate, timeout=timeout)

    def close(self) -> None:
        self.session.close()


@pytest.fixture
def listener():
    port = free_port()
    lst = Listener(port)
    lst.port = port
    yield lst
    lst.close()


def _node(processes, port: int, camera: str, *extra: str):
    return processes.start("edge", "run", "--site", SITE, "--camera", camera, "--source", "sim", "--seed", "7",
                           "--connect", f"tcp/127.0.0.1:{port}", *extra)


def test_three_nodes_publish_decodable_observations_at_their_fps(processes, listener):
    cams = ("nw", "ne", "se")
    for c in cams:
        _node(processes, listener.port, c)
    assert listener.wait_for(lambda: all(len(listener.received[c]) >= 2 for c in cams), timeout=30), dict(listener.received)
    # Measure over 4 s once all three publish.
    counts0 = {c: len(listener.received[c]) for c in cams}
    t0 = time.monotonic()
    listener.wait_for(lambda: time.monotonic() - t0 > 4.0, timeout=4.5)
    elapsed = time.monotonic() - t0
    assert not listener.errors
    for c in cams:
        rate = (len(listener.received[c]) - counts0[c]) / elapsed
        assert abs(rate - 15.0) <= 1.5, f"camera {c}: {rate:.2f} msgs/s, expected 15 +- 10%"
        stamps = np.array([o.stamp_ns for _, o in listener.received[c]])
        np.testing.assert_allclose(np.diff(stamps), 1e9 / 15, rtol=0.01)  # capture grid at the fps
        seqs = [o.seq for _, o in listener.received[c]]
        assert seqs == sorted(seqs)
    assert {c for c, kind in listener.alive if kind == "PUT"} >= set(cams)


def test_nodes_share_the_world_clock(processes, listener):
    """What a node process publishes is what any process computes for the same site, seed and instant."""
    _node(processes, listener.port, "ne")
    assert listener.wait_for(lambda: len(listener.received["ne"]) >= 3, timeout=30)
    _, obs = listener.received["ne"][-1]
    here = SimCamera(World(load_site(SITE), 3, seed=7), "ne").observe(obs.stamp_ns)[0]
    # Compare after the same wire rounding.
    assert wire.decode(wire.encode(here)).people == obs.people and len(obs.people) > 0


def test_node_started_before_the_listener_retries_and_publishes(processes):
    port = free_port()
    _node(processes, port, "sw")
    time.sleep(1.5)  # the node is up with nothing to connect to
    lst = Listener(port)
    try:
        assert lst.wait_for(lambda: len(lst.received["sw"]) >= 5, timeout=20)
    finally:
        lst.close()


def test_killed_node_drops_its_liveliness_token(processes, listener):
    proc = _node(processes, listener.port, "nw")
    assert listener.wait_for(lambda: ("nw", "PUT") in listener.alive, timeout=30)
    proc.kill()
    assert listener.wait_for(lambda: ("nw", "DELETE") in listener.alive, timeout=10)


# (arguments, text the error must contain)
BAD_ARGS = [
    (["--camera", "zz"], "nw, ne, se, sw"),  # unknown camera lists the valid ones
    (["--camera", "nw", "--people", "500"], "--people must be in [0, 64]"),
    (["--camera", "nw", "--source", "kinect"], "--source must be one of sim, oak[:DEVICE_ID], video:PATH, webcam:INDEX, rtsp://..., got 'kinect'"),
    (["--camera", "nw", "--clock-scale", "-1"], "positive"),
]


@pytest.mark.parametrize("args,message", BAD_ARGS)
def test_bad_arguments_exit_2_with_a_clear_message(processes, args, message):
    p = processes.start("edge", "run", "--site", SITE, *args)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and message in err, err


def test_missing_site_file(processes, tmp_path):
    p = processes.start("edge", "run", "--site", str(tmp_path / "none.toml"), "--camera", "1")
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "cannot read site file" in err


def test_a_frame_that_cannot_be_encoded_is_skipped_not_fatal(listener):
    """A source that produces an invalid observation: the node logs it, skips it and goes on."""
    import numpy as np

    from superbody.edge.node import run_node
    from superbody.edge.observation import PersonView
    from superbody.edge.sim_source import SimSource
    from superbody.edge.source import Frame

    site = load_site(SITE)
    bad_view = PersonView(np.full((17, 3), np.nan, np.float32), np.array([5, 5, 1, 1], np.float32), np.zeros((16, 8), np.float32))

    class EveryOtherBad:
        """The simulated camera's frames, every other one with a view no subscriber accepts."""

        def __init__(self):
            self.sim = SimSource(site, "nw", seed=0, people=1)

        def frames(self):
            for f in self.sim.frames():
                if (f.stamp_ns // (10**9 // 15)) % 2:
                    f = Frame(f.stamp_ns, f.width, f.height, None, (bad_view,))
                yield f

        def close(self):
            self.sim.close()

    conf = transport.session_config("peer", connect=[f"tcp/127.0.0.1:{listener.port}"])
    published = run_node(conf, site, "nw", EveryOtherBad(), duration_s=2.0)
    assert 10 <= published <= 22  # about half of 2 s x 15 fps
    assert listener.wait_for(lambda: len(listener.received["nw"]) >= 10, timeout=10)
    assert not listener.errors
