"""One training or evaluation sample: the views of one person at one instant, and the truth.

Both dataset sources (the WheresTheFellow JSON reader and the simulator) produce these, and the
superbody graph builder consumes their ``views`` exactly as the host does at run time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from superbody.edge.messages.observation import PersonView

__all__ = ["Sample"]


@dataclass(frozen=True, eq=False)
class Sample:
    """Views of one person and the ground-truth pose.

    Attributes:
        views: camera id -> what that camera saw of the person (1 or more cameras).
        truth: (3,) float64 ground truth (x, y, yaw) in REP-103: metres, radians in (-pi, pi].
        stamp_ns: capture time of the sample, UNIX nanoseconds (or simulated time).
    """

    views: dict[str, PersonView]
    truth: NDArray[np.float64]
    stamp_ns: int = 0
