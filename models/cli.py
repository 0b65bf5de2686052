"""The models package's ``superbody`` subcommands."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add the offline commands (``calibrate``, ``train``, ``eval``, ...)."""
