"""``superbody router``: a Zenoh router in a Python process, for a site without zenohd.

The demo and the tests start one on loopback; production sites may run it (or zenohd) with
a config from deploy/zenoh/ (``--config``: TLS, mutual TLS, user/password and an ACL). Cameras and the host connect to it as peers or clients.
"""

from __future__ import annotations

import logging
import threading

from superbody.edge import transport

__all__ = ["run_router"]

log = logging.getLogger("superbody.router")


def run_router(listen: list[str], stop: threading.Event, config_file: str | None = None, cfg: list[str] | None = None) -> None:
    """Run a router listening on ``listen`` (empty: the config file's endpoints) until ``stop`` is set;
    ``cfg`` are ``KEY:VALUE`` Zenoh settings applied last."""
    import zenoh

    conf = transport.session_config("router", connect=[], listen=listen or None, config_file=config_file, cfg=cfg)
    with zenoh.open(conf):
        log.info("zenoh router listening on %s", ", ".join(listen) if listen else conf.get_json("listen/endpoints"))
        stop.wait()


