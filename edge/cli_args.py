"""Argument types and option groups that several commands share (argparse lives in CLI modules)."""

from __future__ import annotations

import argparse
import math

from superbody.edge.clock import WorldClock

__all__ = ["positive", "int_in", "add_clock_args", "clock_from_args"]


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


def add_clock_args(parser: argparse.ArgumentParser) -> None:
    """``--clock-scale`` and ``--clock-anchor-ns``: every process of a run must get the same."""
    parser.add_argument("--clock-scale", type=positive, default=1.0, help="world seconds per wall second (simulation speed-up)")
    parser.add_argument("--clock-anchor-ns", type=int, default=0, help="wall time (UNIX ns) at which world and wall clocks agree; a simulated source's scene starts there")


def clock_from_args(args: argparse.Namespace) -> WorldClock:
    return WorldClock(args.clock_anchor_ns, args.clock_scale)
