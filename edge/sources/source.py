"""The frame-source seam of the camera node.

Every source (simulated, OAK with the detector on the device, video file, webcam, RTSP,
recording replay) yields ``Frame`` objects; the node turns each into one Observation through
one code path:

1. ``people`` = ``frame.people`` when the source detected them itself (simulator, OAK), else
   the node's detector run on ``frame.image``;
2. when the frame has an image, each person's colour signature is the hue-saturation histogram
   of their box (``edge.colour.hs_histogram``); otherwise the source's histograms are kept;
3. ``Observation(site, camera, seq, frame.stamp_ns, frame.width, frame.height, people)``.

A source checks its frame size against the site's camera when it opens and raises
``SourceError`` (naming the source, the size it delivers and the size the site expects).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from superbody.edge.messages.observation import PersonView

__all__ = ["Frame", "FrameSource", "SourceError"]


class SourceError(RuntimeError):
    """A frame source cannot open or cannot go on (message says which source and why)."""


@dataclass(frozen=True, eq=False)
class Frame:
    """One captured frame.

    Attributes:
        stamp_ns: capture time, UNIX nanoseconds (never the time it was read or sent).
        width: image width in pixels (the detector's image for on-device detection).
        height: image height in pixels.
        image: (height, width, 3) uint8 BGR pixels when the source has them, else None.
        people: the people the source detected itself (keypoints in this frame's pixels), or
            None when the node's detector must run on ``image``.
    """

    stamp_ns: int
    width: int
    height: int
    image: NDArray[np.uint8] | None = None
    people: tuple[PersonView, ...] | None = None


class FrameSource(Protocol):
    """Where a camera node's frames come from.

    ``frames()`` blocks until the next frame is captured and ends when the source is exhausted
    (end of a video file, end of a replay) or closed. Live sources pace themselves (the camera's
    frame rate); the simulator paces itself on the world clock.
    """

    def frames(self) -> Iterator[Frame]: ...

    def close(self) -> None: ...
