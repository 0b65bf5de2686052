"""Angles: one wrapping convention for the whole project, (-pi, pi] (REP-103 yaw)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["wrap_angle"]


def wrap_angle(a: ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angles (radians) to (-pi, pi]; a float for a scalar, an array otherwise."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2 * np.pi)
    return float(w) if w.ndim == 0 else w
