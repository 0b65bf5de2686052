"""Real test media and fetched models, from the cache outside the repository that ``make test`` fills.

- ``make media`` (scripts/opencv_media.sh): OpenCV's sample media from Debian's ``opencv-doc``
  package: ``vtest.avi`` (768 x 576, 795 frames at 10 fps, pedestrians seen by a fixed camera),
  ``basketball1.png`` (640 x 480, two people close up), ``messi5.jpg`` (548 x 342, one player);
- ``make movenet`` (scripts/movenet_convert.py): MoveNet MultiPose converted to ONNX;
- ``make qemu`` (scripts/qemu_user.sh): QEMU's x86-64 user-mode emulator, to run a program as on
  another CPU.

All land under ``$XDG_CACHE_HOME/superbody`` (``~/.cache/superbody``); a missing file fails the
test with the target to run, never skips it.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import cv2
import numpy as np

__all__ = ["MEDIA", "media_path", "image", "vtest_frames", "movenet_model", "qemu_x86_64", "VTEST_SIZE"]

MEDIA = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "superbody" / "opencv-media"
VTEST_SIZE = (768, 576)  # (width, height)


def media_path(name: str) -> Path:
    """A file of OpenCV's sample media; fails naming ``make media`` when it is not there."""
    path = MEDIA / name
    assert path.is_file(), f"{path} is missing: run `make media` (make test does)"
    return path


def image(name: str) -> np.ndarray:
    """(H, W, 3) uint8 BGR."""
    img = cv2.imread(str(media_path(name)))
    assert img is not None, f"OpenCV cannot read {media_path(name)}"
    return img


@cache
def _vtest(indices: tuple[int, ...]) -> dict[int, np.ndarray]:
    wanted, frames = set(indices), {}
    cap = cv2.VideoCapture(str(media_path("vtest.avi")))
    try:
        for i in range(max(indices) + 1):
            ok, frame = cap.read()
            assert ok, f"vtest.avi ended before frame {i}"
            if i in wanted:
                frames[i] = frame
    finally:
        cap.release()
    return frames


def vtest_frames(indices) -> dict[int, np.ndarray]:
    """Frames of vtest.avi by index, read in order (seeking this codec is not frame-exact); the
    same set of indices is read once per process."""
    return dict(_vtest(tuple(sorted(set(indices)))))


def movenet_model() -> Path:
    """The converted MoveNet model; fails naming ``make movenet`` when it is not there."""
    from superbody.edge.detectors.movenet import default_model_path

    path = default_model_path()
    assert path.is_file(), f"{path} is missing: run `make movenet` (make test does)"
    return path


def qemu_x86_64() -> Path:
    """QEMU's static x86-64 user-mode emulator; fails naming ``make qemu`` when it is not there."""
    path = MEDIA.parent / "qemu" / "qemu-x86_64-static"
    assert path.is_file(), f"{path} is missing: run `make qemu` (make test does)"
    return path
