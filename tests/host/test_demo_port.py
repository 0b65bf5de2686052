"""The demo's router port: not zenohd's default, and a clear error when it is taken."""

from __future__ import annotations

import socket

import pytest

from superbody.host.demo import DEMO_PORT, demo_port


def test_default_port_is_not_zenohs():
    assert DEMO_PORT != 7447


def test_a_taken_port_is_named():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(RuntimeError, match=f"port {port} on 127.0.0.1 is taken"):
            demo_port(port)


def test_port_zero_picks_a_free_one():
    port = demo_port(0)
    assert 1 <= port <= 65535
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))  # it was free
