"""A source's frames thinned to a lower capture rate (``superbody edge run --fps F`` on video and replay).

The rule, on capture stamps alone: keep the first frame at or after each instant of a grid at
``fps`` that starts at the first frame's stamp. A 10 fps file at 4 fps keeps frames 0, 3, 5, 8,
10, ... (0, 0.3, 0.5, 0.8, 1.0 s): 4 frames a second, each with its own capture stamp, unevenly
spaced as any camera that drops frames to a rate. When frames are missing (a gap in a
recording), the grid instants inside the gap are passed over rather than made up in a burst.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["Subsampler", "subsample"]

_TOLERANCE_NS = 100_000  # stamps rounded to the ns land within this of a grid instant they are on


class Subsampler:
    """Decides, frame by frame in capture order, which frames a lower rate keeps.

    Args:
        fps: the rate to reach, frames per second (> 0).
    """

    def __init__(self, fps: float):
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.fps = fps
        self.period_ns = 1e9 / fps
        self._first: int | None = None
        self._next_k = 0  # the grid instant the next kept frame must reach

    def keep(self, stamp_ns: int) -> bool:
        """Whether the frame captured at ``stamp_ns`` is kept (stamps must not go back)."""
        if self._first is None:
            self._first = stamp_ns
        rel = stamp_ns - self._first + _TOLERANCE_NS
        if rel < self._next_k * self.period_ns:
            return False
        self._next_k = math.floor(rel / self.period_ns) + 1
        return True


def subsample(stamps_ns: NDArray[np.int64], fps: float) -> NDArray[np.bool_]:
    """(n,) which frames of ``stamps_ns`` (capture order) ``Subsampler(fps)`` keeps."""
    s = Subsampler(fps)
    return np.array([s.keep(int(t)) for t in stamps_ns], dtype=bool)
