"""A real photo for detector tests, and videos made from it.

NASA's portrait of Eileen Collins as scikit-image ships it (``skimage.data.astronaut()``,
512 x 512). ``ASTRONAUT`` holds her joints as marked by eye on the photo before any detector
ran: eye pupils, nose tip, and the shoulder joints under the suit (the suit's puffy outline is
~20 px outside them, so they are uncertain by ~15 px). Left and right are hers.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

ASTRONAUT: dict[str, tuple[float, float]] = {
    "nose": (224, 126),
    "left_eye": (246, 103),
    "right_eye": (203, 101),
    "left_shoulder": (310, 258),
    "right_shoulder": (100, 250),
}
TOLERANCE_PX = 30.0  # the acceptance bound for nose and shoulders


def astronaut_bgr() -> np.ndarray:
    """(512, 512, 3) uint8 BGR."""
    from skimage import data

    return np.ascontiguousarray(data.astronaut()[:, :, ::-1])


def astronaut_frame(width: int = 640, height: int = 480) -> tuple[np.ndarray, dict[str, tuple[float, float]]]:
    """The photo's top ``height`` rows (all of her head and shoulders) centred on a grey frame,
    unscaled, and where the marked joints land in it."""
    photo = astronaut_bgr()[:height, : min(512, width)]
    dx = (width - photo.shape[1]) // 2
    frame = np.full((height, width, 3), 90, np.uint8)
    frame[: photo.shape[0], dx:dx + photo.shape[1]] = photo
    marks = {k: (x + dx, y) for k, (x, y) in ASTRONAUT.items()}
    return frame, marks


def astronaut_video(path: Path, frames: int, fps: float, width: int = 640, height: int = 480,
                    fourcc: str = "FFV1") -> dict[str, tuple[float, float]]:
    """Write an AVI of ``astronaut_frame`` repeated; returns the marks in its pixels.

    Lossless (FFV1) by default, because BlazePose's right shoulder on this photo (a puffy suit) moves by 15-20 px
    under JPEG artefacts: the node's tests check the node, not the codec."""
    frame, marks = astronaut_frame(width, height)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (width, height))
    assert writer.isOpened(), f"OpenCV cannot write {path}"
    for _ in range(frames):
        writer.write(frame)
    writer.release()
    return marks
