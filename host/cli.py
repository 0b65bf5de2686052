"""The host package's ``superbody`` subcommands."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add the host's commands (``host run``, ``demo``)."""
