"""The host's output in memory: ``PoseArray`` of ``PersonPose`` (``host/messages/pose.py`` is their wire codec)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["PersonPose", "PoseArray"]


@dataclass(frozen=True, eq=False)
class PersonPose:
    """One person's estimated torso pose at one tick.

    Attributes:
        id: stable track id, >= 0, never reused by a host run.
        x, y: floor position, metres, world frame (REP-103, z up).
        yaw: torso heading, radians counter-clockwise from +x, in (-pi, pi].
        vx, vy: floor velocity, m/s.
        yaw_rate: rad/s.
        cov: (3, 3) float64 covariance of (x, y, yaw): symmetric, non-negative diagonal;
            units m^2, m*rad, rad^2.
        confidence: in [0, 1].
        cameras: ids of the cameras whose views were used.
        stamp_ns: capture time of the newest view used, UNIX nanoseconds.
        views: number of views used (at least ``len(cameras)``; 0 when the pose is predicted).
        estimator: which estimator produced this person's pose: ``"hybrid"``, ``"onnx"``,
            ``"analytic"`` (version 2; a version 1 message gives its top-level ``estimator``).
    """

    id: int
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    cov: NDArray[np.float64]
    confidence: float
    cameras: tuple[str, ...]
    stamp_ns: int
    views: int
    estimator: str = "unknown"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PersonPose):
            return NotImplemented
        scalars = ("id", "x", "y", "yaw", "vx", "vy", "yaw_rate", "confidence", "cameras", "stamp_ns", "views", "estimator")
        return all(getattr(self, a) == getattr(other, a) for a in scalars) and np.array_equal(self.cov, other.cov)

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class PoseArray:
    """Everything the host publishes for one tick.

    Attributes:
        site: site name.
        seq: tick sequence number, counting up from 0 for each host run.
        stamp_ns: the tick's world time, UNIX nanoseconds.
        people: the people tracked at this tick (possibly none).
        latency_ns: host processing latency, from the arrival of the newest observation used
            to publication.
        cameras_alive: cameras whose liveliness tokens are present.
        estimator: what produced the poses, e.g. ``"onnx:wtf-apartment.int8.onnx"`` or ``"analytic"``.
    """

    site: str
    seq: int
    stamp_ns: int
    people: tuple[PersonPose, ...] = ()
    latency_ns: int = 0
    cameras_alive: tuple[str, ...] = ()
    estimator: str = "unknown"
