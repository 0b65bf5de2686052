"""Argument types and option groups that several commands share (argparse lives in CLI modules)."""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from typing import TYPE_CHECKING

from superbody.edge.clock import WorldClock
from superbody.edge.transport import DEFAULT_ENDPOINT, session_config

if TYPE_CHECKING:
    import zenoh

__all__ = ["positive", "int_in", "float_in", "add_clock_args", "clock_from_args", "add_session_args", "config_from_args", "fail", "stop_on_signals"]


def positive(text: str) -> float:
    """argparse type: a positive finite number."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def int_in(lo: int, hi: int, name: str):
    """argparse type: an integer in [lo, hi]; the error names the option."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}], got {text!r}") from None
        if not lo <= n <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be in [{lo}, {hi}], got {n}")
        return n
    return parse


def number_in(text: str, name: str, lo: float, hi: float, error: type[Exception] = ValueError) -> float:
    """``text`` as a finite number in [lo, hi], else ``error`` naming the option and the range."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and lo <= v <= hi):
        raise error(f"{name} must be a number in [{lo:g}, {hi:g}], got {text!r}")
    return v


def float_in(lo: float, hi: float, name: str):
    """argparse type: a finite number in [lo, hi]; the error names the option and the range."""
    def parse(text: str) -> float:
        return number_in(text, name, lo, hi, argparse.ArgumentTypeError)
    return parse


def add_clock_args(parser: argparse.ArgumentParser) -> None:
    """``--clock-scale`` and ``--clock-anchor-ns``: every process of a run must get the same."""
    parser.add_argument("--clock-scale", type=positive, default=1.0, help="world seconds per wall second (simulation speed-up)")
    parser.add_argument("--clock-anchor-ns", type=int, default=0, help="wall time (UNIX ns) at which world and wall clocks agree; a simulated source's scene starts there")


def clock_from_args(args: argparse.Namespace) -> WorldClock:
    return WorldClock(args.clock_anchor_ns, args.clock_scale)


def add_session_args(parser: argparse.ArgumentParser) -> None:
    """Add the Zenoh examples' session options to a parser."""
    g = parser.add_argument_group("zenoh session")
    g.add_argument("--mode", choices=("peer", "client", "router"), default=None, help="Zenoh mode (default: the --config file's, else peer)")
    g.add_argument("-e", "--connect", action="append", metavar="ENDPOINT", help=f"endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})")
    g.add_argument("-l", "--listen", action="append", metavar="ENDPOINT", help="endpoint to listen on (repeatable)")
    g.add_argument("-c", "--config", metavar="FILE", help="Zenoh JSON5 configuration file")
    g.add_argument("--cfg", action="append", metavar="KEY:VALUE",
                   help='a Zenoh config setting, JSON5 value, applied last (repeatable), e.g. --cfg transport/link/tx/lease:3000')


def config_from_args(args: argparse.Namespace) -> zenoh.Config:
    return session_config(args.mode, args.connect, args.listen, args.config, getattr(args, "cfg", None))


def fail(command: str, message: str) -> int:
    """Print ``superbody COMMAND: error: MESSAGE`` on stderr; the exit code of a bad argument, 2."""
    print(f"superbody {command}: error: {message}", file=sys.stderr)
    return 2


def stop_on_signals() -> threading.Event:
    """An event that SIGTERM (systemd, docker stop) and SIGINT (Ctrl-C) set: a process's clean stop.

    The first of them sets it; later ones are ignored, the stop being under way. A handler that
    set the event again could run while the first still holds the event's lock (a signal handler
    runs in the main thread, between any two of its steps) and wait for that lock forever: two
    SIGTERMs in a row (``timeout`` and ``make`` each passing one on) left ``superbody demo`` hung,
    its router, cameras and host running.
    """
    stop = threading.Event()

    def first(signum: int, frame: object) -> None:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, _ignore)
        stop.set()

    signal.signal(signal.SIGTERM, first)
    signal.signal(signal.SIGINT, first)
    return stop


def _ignore(signum: int, frame: object) -> None:
    """A later SIGTERM or SIGINT: the stop is under way (``stop_on_signals``)."""
