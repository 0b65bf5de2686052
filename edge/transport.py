"""Zenoh session options and key names, shared by every superbody process.

Options follow the Zenoh examples (``--mode``, ``--connect``, ``--listen``, ``--config``).
The default is a peer on loopback with multicast scouting off that connects to
``tcp/127.0.0.1:7447`` and keeps retrying until something listens there, so processes may
start in any order.

Keys (everything under ``superbody/<site>/``):

- ``superbody/<site>/cameras/<camera>/observations``: Observations (edge/wire.py).
- ``superbody/<site>/cameras/<camera>/alive``: the camera node's liveliness token.
- ``superbody/<site>/people``: the host's PoseArray.
- ``superbody/<site>/host/alive``: the host's liveliness token.
- ``superbody/<site>/host/status``: the host's periodic status (JSON, see host/aggregator.py).
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "DEFAULT_ENDPOINT",
    "Mode",
    "add_session_args",
    "session_config",
    "config_from_args",
    "observation_key",
    "camera_alive_key",
    "people_key",
    "host_alive_key",
    "host_status_key",
    "camera_from_key",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
Mode = Literal["peer", "client", "router"]


def _checked(site: str, camera: str | None = None) -> None:
    """Names become key chunks: reject anything that is not a valid site/camera id ("*" matches all cameras)."""
    from superbody.edge.site import NAME_RE

    for field, value in (("site", site), ("camera", camera)):
        if value is None or (field == "camera" and value == "*"):
            continue
        if not (isinstance(value, str) and NAME_RE.fullmatch(value)):
            raise ValueError(f"{field} must be 1-64 characters of letters, digits, '_' or '-', got {value!r}")


def observation_key(site: str, camera: str = "*") -> str:
    """Key of a camera's Observations; the default ``camera="*"`` matches every camera."""
    _checked(site, camera)
    return f"superbody/{site}/cameras/{camera}/observations"


def camera_alive_key(site: str, camera: str = "*") -> str:
    _checked(site, camera)
    return f"superbody/{site}/cameras/{camera}/alive"


def people_key(site: str) -> str:
    _checked(site)
    return f"superbody/{site}/people"


def host_alive_key(site: str) -> str:
    _checked(site)
    return f"superbody/{site}/host/alive"


def host_status_key(site: str) -> str:
    _checked(site)
    return f"superbody/{site}/host/status"


def camera_from_key(key: str) -> str | None:
    """The camera id in a ``superbody/<site>/cameras/<camera>/...`` key, or None."""
    parts = str(key).split("/")
    return parts[3] if len(parts) >= 5 and parts[0] == "superbody" and parts[2] == "cameras" else None


def session_config(
    mode: Mode = "peer",
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    config_file: str | None = None,
) -> "zenoh.Config":
    """Build a Zenoh config.

    Args:
        mode: peer, client or router.
        connect: endpoints to connect to; None means ``[DEFAULT_ENDPOINT]`` unless listening.
        listen: endpoints to listen on.
        config_file: a Zenoh JSON5 config file; the other arguments override it where given.

    Connections are retried for ever (``connect/timeout_ms: -1``, ``exit_on_failure: false``),
    so a node started before its peer or router publishes as soon as it is reachable.
    """
    import zenoh

    if mode not in ("peer", "client", "router"):
        raise ValueError(f"mode must be one of peer, client, router; got {mode!r}")
    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if connect is None:
        connect = [] if (listen or config_file or mode == "router") else [DEFAULT_ENDPOINT]
    if connect or not config_file:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if not config_file:
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/timeout_ms", "-1")
        conf.insert_json5("connect/exit_on_failure", "false")
        conf.insert_json5("connect/retry", '{"period_init_ms": 200, "period_max_ms": 2000, "period_increase_factor": 2}')
    return conf


def add_session_args(parser: argparse.ArgumentParser) -> None:
    """Add the Zenoh examples' session options to a parser."""
    g = parser.add_argument_group("zenoh session")
    g.add_argument("--mode", choices=("peer", "client", "router"), default="peer", help="Zenoh mode (default: peer)")
    g.add_argument("-e", "--connect", action="append", metavar="ENDPOINT", help=f"endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})")
    g.add_argument("-l", "--listen", action="append", metavar="ENDPOINT", help="endpoint to listen on (repeatable)")
    g.add_argument("-c", "--config", metavar="FILE", help="Zenoh JSON5 configuration file")


def config_from_args(args: argparse.Namespace) -> "zenoh.Config":
    return session_config(args.mode, args.connect, args.listen, args.config)
