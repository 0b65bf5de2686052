"""Zenoh session options and key names, shared by every superbody process.

Options follow the Zenoh examples (``--mode``, ``--connect``, ``--listen``, ``--config``).
The default is a peer on loopback with multicast scouting off that connects to
``tcp/127.0.0.1:7447`` and keeps retrying until something listens there, so processes may
start in any order; it listens on loopback only (``tcp/127.0.0.1:0``), never on every
interface, and sets Zenoh's ``transport/link/rx/max_message_size`` to ``MAX_MESSAGE_BYTES``
(the default is 1 GiB). Measured with eclipse-zenoh 1.10.2: a 5 MB put between two peers on
loopback is still delivered with that limit set, so the host's own size check before copying
(host.aggregator) is what bounds the memory a large payload costs. It also turns Zenoh's shared
memory transport off (``transport/shared_memory/enabled: false``; eclipse-zenoh 1.x enables it
with a 16 MiB pool and a 3072-byte threshold): with it, every process on the machine that
sends a message of 3 KB or more (a camera seeing 3 people, or any stranger) makes each
receiver map that sender's 16 MiB pool, and the receiver's resident memory grows with the
pool pages it touches: measured, +19 MB in a subscriber after two 4 KB puts from a peer, and
the host's RSS rose for minutes in the soak (benchmarks/soak.py) as the cameras' pools were
touched, then stepped when an attacker's pool was mapped. Our messages are at most a few tens
of KB, so copying them costs nothing that matters, and no peer gets to put memory into the
host. Endpoints given on the command line
are checked (``check_endpoint``) so a typo is a one-line error, not a retry loop for ever.
Secured deployments pass a config file (``--config``, see deploy/zenoh/): it is used as
written, except for options given on the command line; ``--cfg KEY:VALUE`` (as in the Zenoh
examples) sets any other config path and wins over both.

Keys (everything under ``superbody/<site>/``):

- ``superbody/<site>/cameras/<camera>/observations``: Observations (edge/messages/wire.py).
- ``superbody/<site>/cameras/<camera>/alive``: the camera node's liveliness token.
- ``superbody/<site>/people``: the host's PoseArray.
- ``superbody/<site>/host/alive``: the host's liveliness token.
- ``superbody/<site>/host/status``: the host's periodic status (JSON, see host/aggregator.py).
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "DEFAULT_ENDPOINT",
    "Mode",
    "session_config",
    "observation_key",
    "camera_alive_key",
    "people_key",
    "host_alive_key",
    "host_status_key",
    "camera_from_key",
    "check_endpoint",
    "parse_cfg",
    "ConfigError",
    "MAX_MESSAGE_BYTES",
    "LOOPBACK_LISTEN",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
LOOPBACK_LISTEN = "tcp/127.0.0.1:0"
# Our largest message is a PoseArray (host.messages.pose.MAX_PAYLOAD_BYTES, 512 KiB): 1 MiB leaves room.
MAX_MESSAGE_BYTES = 1024 * 1024
_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream")
_ENDPOINT_RE = re.compile(r"^(?P<proto>[a-z-]+)/(?P<addr>[^?#]+?)(?P<rest>[?#].*)?$")


class ConfigError(ValueError):
    """A Zenoh option (endpoint, mode, config file) that cannot work; the message names it."""


def check_endpoint(text: str, option: str = "--connect", listen: bool = False) -> str:
    """A Zenoh endpoint ``<proto>/<host>:<port>`` with a known protocol and a port in range.

    Args:
        text: the endpoint.
        option: the option it came from, for the error message.
        listen: port 0 (any free port) is allowed when listening.

    Raises:
        ConfigError: naming the option, the value and what is allowed.
    """
    lo = 0 if listen else 1
    m = _ENDPOINT_RE.match(text) if isinstance(text, str) else None
    if m is None or m["proto"] not in _PROTOCOLS:
        raise ConfigError(f"{option} {text!r}: an endpoint is <protocol>/<host>:<port>, protocol one of "
                          f"{', '.join(_PROTOCOLS)}, e.g. {DEFAULT_ENDPOINT}")
    if m["proto"] == "unixsock-stream":
        return text
    host, sep, port = m["addr"].rpartition(":")
    if not sep or not host or not port.isdigit() or not lo <= int(port) <= 65535:
        raise ConfigError(f"{option} {text!r}: the port must be an integer in [{lo}, 65535] after the host, e.g. {DEFAULT_ENDPOINT}")
    return text
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


def parse_cfg(text: str) -> tuple[str, str]:
    """``KEY:VALUE`` as the Zenoh examples' ``--cfg`` takes it: a config path and a JSON5 value,
    e.g. ``transport/link/tx/lease:3000`` or ``connect/endpoints:["tcp/10.0.0.1:7447"]``.

    Raises:
        ConfigError: no ``:``, or an empty key or value.
    """
    key, sep, value = str(text).partition(":")
    if not sep or not key.strip() or not value.strip():
        raise ConfigError(f"--cfg {text!r}: must be KEY:VALUE, a Zenoh config path and a JSON5 value, "
                          'e.g. transport/link/tx/lease:3000 or connect/endpoints:["tcp/127.0.0.1:7447"]')
    return key.strip(), value.strip()


def session_config(
    mode: Mode | None = "peer",
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    config_file: str | None = None,
    cfg: list[str] | None = None,
) -> zenoh.Config:
    """Build a Zenoh config.

    Args:
        mode: peer, client or router; None keeps the config file's (peer without one).
        connect: endpoints to connect to; None means ``[DEFAULT_ENDPOINT]`` unless listening.
        listen: endpoints to listen on; None means loopback only (``LOOPBACK_LISTEN``) for a
            peer without a config file.
        config_file: a Zenoh JSON5 config file; the other arguments override it where given.
        cfg: ``KEY:VALUE`` settings (``parse_cfg``) applied last, so they override everything.

    Connections are retried for ever (``connect/timeout_ms: -1``, ``exit_on_failure: false``),
    so a node started before its peer or router publishes as soon as it is reachable.

    Raises:
        ConfigError: an unknown mode, a malformed endpoint, a missing or invalid config file.
    """
    import zenoh

    if mode is None and not config_file:
        mode = "peer"
    if mode is not None and mode not in ("peer", "client", "router"):
        raise ConfigError(f"mode must be one of peer, client, router; got {mode!r}")
    for e in connect or ():
        check_endpoint(e, "--connect")
    for e in listen or ():
        check_endpoint(e, "--listen", listen=True)
    if config_file:
        try:
            conf = zenoh.Config.from_file(config_file)
        except Exception as e:  # zenoh raises ZError (not an OSError) for both missing and invalid files
            why = re.sub(r" at \S+\.rs:\d+\.?$", "", " ".join(str(e).split()))[:300] or type(e).__name__
            raise ConfigError(f"--config {config_file}: not a readable Zenoh JSON5 config: {why}") from None
    else:
        conf = zenoh.Config()
    if mode is not None:
        conf.insert_json5("mode", json.dumps(mode))
    if connect is None:
        connect = [] if (listen or config_file or mode == "router") else [DEFAULT_ENDPOINT]
    if connect or not config_file:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen is None and not config_file and mode == "peer":
        listen = [LOOPBACK_LISTEN]
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if not config_file:
        conf.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE_BYTES))
        conf.insert_json5("transport/shared_memory/enabled", "false")  # see the module docstring
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/timeout_ms", "-1")
        conf.insert_json5("connect/exit_on_failure", "false")
        conf.insert_json5("connect/retry", '{"period_init_ms": 200, "period_max_ms": 2000, "period_increase_factor": 2}')
    for item in cfg or ():
        key, value = parse_cfg(item)
        try:
            conf.insert_json5(key, value)
        except Exception as e:  # zenoh's ZError: an unknown key or a value of the wrong type
            why = re.sub(r" at \S+\.rs:\d+\.?$", "", " ".join(str(e).split()))[:200] or type(e).__name__
            raise ConfigError(f"--cfg {item!r}: Zenoh refuses it: {why}") from None
    return conf


