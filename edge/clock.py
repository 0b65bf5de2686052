"""The world clock: UNIX time, optionally running faster than the wall clock.

Every superbody process reads time through a ``WorldClock``. At scale 1 it is the wall clock.
Tests and benchmarks run the simulation faster: ``now = anchor + (wall - anchor) * scale``,
the same for every process given the same anchor and scale, so simulated cameras and the host
agree on capture times.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

__all__ = ["WorldClock"]


@dataclass(frozen=True)
class WorldClock:
    """Args: anchor_ns: wall time (UNIX ns) at which world and wall agree; scale: world seconds per wall second."""

    anchor_ns: int = 0
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not 0.01 <= self.scale <= 100.0:
            raise ValueError(f"clock scale must be in [0.01, 100], got {self.scale}")

    def now_ns(self) -> int:
        wall = time.time_ns()
        return wall if self.scale == 1.0 else self.anchor_ns + int((wall - self.anchor_ns) * self.scale)

    def wall_ns(self, world_ns: int) -> int:
        """The wall time at which the world clock reads ``world_ns``."""
        return world_ns if self.scale == 1.0 else self.anchor_ns + int((world_ns - self.anchor_ns) / self.scale)

    def sleep_until(self, world_ns: int) -> None:
        delay = (self.wall_ns(world_ns) - time.time_ns()) * 1e-9
        if delay > 0:
            time.sleep(delay)
