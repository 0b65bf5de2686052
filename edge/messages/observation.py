"""The Observation message: what one camera saw in one frame.

This module holds the in-memory types. The wire codec (``encode``/``decode``) and its schema
live in ``edge/messages/wire.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.colour import HIST_BINS

__all__ = ["PersonView", "Observation", "empty_keypoints", "empty_histogram"]


@dataclass(frozen=True, eq=False)
class PersonView:
    """One person detected in one camera frame.

    Attributes:
        keypoints: (17, 3) float32, per COCO-17 joint (u, v, score): pixels and detector
            confidence in (0, 1]. Missing joints are rows of NaN.
        bbox: (4,) float32 (x0, y0, x1, y1) in pixels.
        histogram: ``HIST_BINS`` float32 hue-saturation histogram, summing to 1 (or all zeros).
        points3d: optional (17, 3) float32 joint positions in the camera frame, metres (depth
            cameras); NaN rows for joints without depth.
    """

    keypoints: NDArray[np.float32]
    bbox: NDArray[np.float32]
    histogram: NDArray[np.float32]
    points3d: NDArray[np.float32] | None = None

    @property
    def visible(self) -> NDArray[np.bool_]:
        """(17,) mask of the joints that were detected."""
        return ~np.isnan(self.keypoints[:, 0])

    @property
    def num_visible(self) -> int:
        return int(self.visible.sum())

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PersonView):
            return NotImplemented
        same_3d = (self.points3d is None and other.points3d is None) or (
            self.points3d is not None and other.points3d is not None
            and np.array_equal(self.points3d, other.points3d, equal_nan=True)
        )
        return (
            np.array_equal(self.keypoints, other.keypoints, equal_nan=True)
            and np.array_equal(self.bbox, other.bbox)
            and np.array_equal(self.histogram, other.histogram)
            and same_3d
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class Observation:
    """Everything one camera publishes for one frame.

    Attributes:
        site: site name.
        camera: camera id within the site.
        seq: frame sequence number, counting up from 0 for each node run.
        stamp_ns: capture time, UNIX nanoseconds, from the camera node's clock.
        width: image width in pixels.
        height: image height in pixels.
        people: the people detected in this frame (possibly none).
    """

    site: str
    camera: str
    seq: int
    stamp_ns: int
    width: int
    height: int
    people: tuple[PersonView, ...] = ()


def empty_keypoints() -> NDArray[np.float32]:
    """A (17, 3) keypoint array with every joint missing."""
    return np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)


def empty_histogram() -> NDArray[np.float32]:
    return np.zeros(HIST_BINS, dtype=np.float32)
