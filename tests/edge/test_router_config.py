"""The shipped plain configs run: a router process from deploy/zenoh/loopback/router.json5 carries
a put between two sessions made from deploy/zenoh/loopback/node.json5 (client mode), all on
loopback, their port moved with --cfg so that they cannot collide with a zenohd on 7447."""

from __future__ import annotations

import threading

import zenoh

from superbody.edge.transport import session_config
from tests.conftest import ROOT, free_port


def test_router_from_the_plain_config_carries_messages(processes):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = processes.start("router", "--config", str(ROOT / "deploy" / "zenoh" / "loopback" / "router.json5"),
                             "--cfg", f'listen/endpoints:["{endpoint}"]')
    got = threading.Event()
    node = str(ROOT / "deploy" / "zenoh" / "loopback" / "node.json5")
    moved = [f'connect/endpoints:["{endpoint}"]']
    with zenoh.open(session_config(None, config_file=node, cfg=moved)) as sub_session, \
            zenoh.open(session_config(None, config_file=node, cfg=moved)) as pub_session:
        sub = sub_session.declare_subscriber("superbody/test/router", lambda s: got.set())
        for _ in range(100):  # bounded: 100 x 0.1 s while the router starts and the routes form
            pub_session.put("superbody/test/router", b"hello")
            if got.wait(0.1):
                break
        sub.undeclare()
    assert got.is_set(), router.stderr.read() if router.poll() is not None else "router running, nothing received"
    assert router.poll() is None
