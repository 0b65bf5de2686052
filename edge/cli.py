"""The ``superbody`` console script.

One program, subcommands contributed by each package: every entry point in the
``superbody.commands`` group is a ``register(subparsers)`` function that adds its commands and
sets ``func`` on each parser. ``func(args)`` returns the exit code.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from importlib.metadata import entry_points

__all__ = ["main", "register", "build_parser"]


def _version() -> str:
    from superbody.edge.resources import package_version

    return package_version()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="superbody", description="Multi-camera torso pose appliance.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.add_argument("--version", action="version", version=f"superbody {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for ep in sorted(entry_points(group="superbody.commands"), key=lambda e: e.name):
        ep.load()(sub)
    return parser


def _init_zenoh_log() -> None:
    """Zenoh's own (Rust) logging from the environment, as its examples do: RUST_LOG=debug shows it."""
    try:
        import zenoh
    except ImportError:  # a broken install: the command itself will say so
        return
    init = getattr(zenoh, "init_log_from_env_or", None)
    if init is not None:
        init("error")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _init_zenoh_log()
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as e:
        # Zenoh's errors (a port already in use, an unreachable TLS file) are raised as ZError
        # from inside its Rust core: one line naming the cause, not a traceback.
        if type(e).__name__ != "ZError":
            raise
        why = re.sub(r" at \S+\.rs:\d+\.?", "", " ".join(str(e).split()))[:300]  # drop Rust source paths
        print(f"superbody {args.command}: error: zenoh: {why}", file=sys.stderr)
        return 2


def register(sub: argparse._SubParsersAction) -> None:
    """Add the edge package's commands: ``edge run``, ``router``."""
    from superbody.edge import node, router

    node.register(sub)
    router.register(sub)


if __name__ == "__main__":
    sys.exit(main())
