"""``superbody router``: a Zenoh router in a Python process, for a site without zenohd.

The demo and the tests start one on loopback; production sites may run it (or zenohd) with
a config from deploy/zenoh/ (``--config``: TLS, mutual TLS, user/password and an ACL). Cameras and the host connect to it as peers or clients.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from superbody.edge import transport

__all__ = ["run_router", "register"]

log = logging.getLogger("superbody.router")


def run_router(listen: list[str], stop: threading.Event, config_file: str | None = None, cfg: list[str] | None = None) -> None:
    """Run a router listening on ``listen`` (empty: the config file's endpoints) until ``stop`` is set;
    ``cfg`` are ``KEY:VALUE`` Zenoh settings applied last."""
    import zenoh

    conf = transport.session_config("router", connect=[], listen=listen or None, config_file=config_file, cfg=cfg)
    with zenoh.open(conf):
        log.info("zenoh router listening on %s", ", ".join(listen) if listen else conf.get_json("listen/endpoints"))
        stop.wait()


def _run(args: argparse.Namespace) -> int:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        run_router(args.listen or ([] if args.config else [transport.DEFAULT_ENDPOINT]), stop, args.config, args.cfg)
    except transport.ConfigError as e:
        print(f"superbody router: error: {e}", file=sys.stderr)
        return 2
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="run a Zenoh router (loopback by default)")
    p.add_argument("-l", "--listen", action="append", metavar="ENDPOINT", help=f"endpoint to listen on (default {transport.DEFAULT_ENDPOINT})")
    p.add_argument("-c", "--config", metavar="FILE", help="Zenoh JSON5 configuration file")
    p.add_argument("--cfg", action="append", metavar="KEY:VALUE", help="a Zenoh config setting, JSON5 value, applied last (repeatable)")
    p.set_defaults(func=_run)
