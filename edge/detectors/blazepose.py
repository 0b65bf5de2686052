"""MediaPipe BlazePose as a ``Detector``: one person per frame, 33 landmarks mapped to COCO-17.

Why a worker process: mediapipe 0.10.21 is the last release whose wheel bundles BlazePose's
weights (``solutions.pose``, ``pose_landmark_full``), and it needs numpy < 2 (and Python <= 3.12),
while the rest of superbody runs on numpy 2. So BlazePose lives in an interpreter of its own
(``make blazepose`` creates ``.venv-blazepose``; elsewhere set ``SUPERBODY_BLAZEPOSE_PYTHON``)
and ``edge/detectors/blazepose_worker.py`` runs there, fed images over a pipe. Copying a 640 x 480 image
through the pipe costs well under a millisecond; the network costs tens.

Every frame runs BlazePose's person detector before its landmark network (MediaPipe's
static-image mode) unless ``tracking=True``: on the test photo repeated as a video, tracking
mode (landmarks cropped from the previous frame's, then smoothed) drifted a shoulder 8 px
further than per-frame detection over 40 identical frames; per-frame detection costs about
twice as much (39 ms against 20 ms a 640 x 480 frame on our 2-core CPU).

Landmarks with a visibility below ``min_visibility``, or outside the image, are missing joints.
The person's box is the bounds of the visible landmarks (all 33, so hands and feet count),
grown by 10 % on each side and clipped to the image.
"""

from __future__ import annotations

import os
import select
import struct
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.detectors.base import DetectorError, empty_detections

__all__ = ["BlazePose", "coco_from_blazepose", "blazepose_python", "FROM_BLAZEPOSE", "PYTHON_ENV"]

PYTHON_ENV: Final[str] = "SUPERBODY_BLAZEPOSE_PYTHON"
WORKER: Final[Path] = Path(__file__).with_name("blazepose_worker.py")
NUM_LANDMARKS: Final[int] = 33
_HEADER = struct.Struct("<4sII")
_REPLY = struct.Struct("<4sI")

# BlazePose landmark index of each COCO-17 joint (both name the subject's left and right).
FROM_BLAZEPOSE: Final[tuple[int, ...]] = (
    0,   # 0 nose <- nose
    2,   # 1 left_eye <- left_eye (centre; 1 and 3 are its inner and outer corners)
    5,   # 2 right_eye <- right_eye
    7,   # 3 left_ear
    8,   # 4 right_ear
    11,  # 5 left_shoulder
    12,  # 6 right_shoulder
    13,  # 7 left_elbow
    14,  # 8 right_elbow
    15,  # 9 left_wrist
    16,  # 10 right_wrist
    23,  # 11 left_hip
    24,  # 12 right_hip
    25,  # 13 left_knee
    26,  # 14 right_knee
    27,  # 15 left_ankle
    28,  # 16 right_ankle
)
assert len(FROM_BLAZEPOSE) == NUM_KEYPOINTS


def coco_from_blazepose(
    landmarks: NDArray, width: int, height: int, min_visibility: float = 0.5, box_margin: float = 0.1
) -> tuple[NDArray[np.float32], NDArray[np.float32]] | None:
    """One BlazePose result as COCO-17 keypoints and a box.

    Args:
        landmarks: (33, 4) float (x, y, visibility, presence), x and y normalised to [0, 1].
        width: image width in pixels.
        height: image height in pixels.
        min_visibility: landmarks less visible than this are missing.
        box_margin: the box grows by this fraction of its size on each side.

    Returns:
        keypoints (17, 3) float32 (u, v, visibility) with NaN rows for missing joints, and the
        box (4,) float32; None when no landmark is visible inside the image.
    """
    lm = np.asarray(landmarks, np.float64)
    if lm.shape != (NUM_LANDMARKS, 4):
        raise ValueError(f"landmarks must be ({NUM_LANDMARKS}, 4), got {lm.shape}")
    u, v, vis = lm[:, 0] * width, lm[:, 1] * height, lm[:, 2]  # (33,) each
    seen = (vis >= min_visibility) & (u >= 0) & (u < width) & (v >= 0) & (v < height) & np.isfinite(u) & np.isfinite(v)
    if not seen.any():
        return None
    idx = np.asarray(FROM_BLAZEPOSE)
    kp = np.stack([u[idx], v[idx], np.clip(vis[idx], 1e-3, 1.0)], axis=1).astype(np.float32)  # (17, 3)
    kp[~seen[idx]] = np.nan
    x0, x1, y0, y1 = u[seen].min(), u[seen].max(), v[seen].min(), v[seen].max()
    mx, my = box_margin * (x1 - x0), box_margin * (y1 - y0)
    box = np.array([max(x0 - mx, 0), max(y0 - my, 0), min(x1 + mx, width), min(y1 + my, height)], np.float32)
    return kp, box


def blazepose_python() -> str:
    """The interpreter that has mediapipe 0.10.21: ``$SUPERBODY_BLAZEPOSE_PYTHON``, else the
    checkout's ``.venv-blazepose`` (``make blazepose``)."""
    env = os.environ.get(PYTHON_ENV)
    if env:
        return env
    return str(Path(__file__).resolve().parents[2] / ".venv-blazepose" / "bin" / "python")


class BlazePose:
    """BlazePose in a worker process; ``detect`` sends it an image and waits for the landmarks.

    Args:
        python: interpreter with mediapipe 0.10.21 (default ``blazepose_python()``).
        tracking: follow the person from frame to frame (MediaPipe's video mode) instead of
            running the person detector on every image.
        min_visibility: see ``coco_from_blazepose``.
        timeout_s: longest wait for the model to load, and for one image.
    """

    def __init__(self, *, python: str | None = None, tracking: bool = False, min_visibility: float = 0.5,
                 timeout_s: float = 60.0):
        self.python = python or blazepose_python()
        self.min_visibility = min_visibility
        self.timeout_s = timeout_s
        if not (os.path.isfile(self.python) and os.access(self.python, os.X_OK)):
            raise DetectorError(f"BlazePose needs its own Python with mediapipe==0.10.21, not found at {self.python}: "
                                f"run `make blazepose` in the checkout, or set {PYTHON_ENV} (see docs/cameras.md)")
        self._log = tempfile.TemporaryFile()
        env = dict(os.environ, GLOG_minloglevel="2", TF_CPP_MIN_LOG_LEVEL="2", PYTHONNOUSERSITE="1")
        env.pop("PYTHONPATH", None)
        cmd = [self.python, str(WORKER)] + ([] if tracking else ["--static"])
        self._proc: subprocess.Popen[bytes] | None = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, env=env)
        try:
            tag, _ = _REPLY.unpack(self._read(_REPLY.size, time.monotonic() + timeout_s, "load the model"))
            if tag != b"RDY0":
                raise DetectorError(f"BlazePose worker sent {tag!r} instead of its ready frame")
        except DetectorError:
            self.close()
            raise

    def _worker_log(self) -> str:
        self._log.seek(0)
        lines = [ln for ln in self._log.read().decode(errors="replace").splitlines() if ln.strip()]
        return lines[-1] if lines else "no message"

    def _read(self, n: int, deadline: float, doing: str) -> bytes:
        assert self._proc is not None and self._proc.stdout is not None  # open (callers check), stdout=PIPE
        fd = self._proc.stdout.fileno()
        buf = bytearray()
        while len(buf) < n:
            left = deadline - time.monotonic()
            ready, _, _ = select.select([fd], [], [], max(left, 0.0))
            if not ready:
                raise DetectorError(f"BlazePose worker did not {doing} within {self.timeout_s:g} s")
            chunk = os.read(fd, n - len(buf))
            if not chunk:
                self._proc.wait(timeout=5)
                raise DetectorError(f"BlazePose worker ({self.python}) exited with code {self._proc.returncode} "
                                    f"before it could {doing}: {self._worker_log()}")
            buf += chunk
        return bytes(buf)

    def landmarks(self, image: NDArray[np.uint8]) -> NDArray[np.float32] | None:
        """BlazePose's raw (33, 4) landmarks for one BGR image, or None when it sees no one."""
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"image must be (H, W, 3) uint8 BGR, got {image.shape} {image.dtype}")
        if self._proc is None:
            raise DetectorError("BlazePose worker is closed")
        h, w = image.shape[:2]
        assert self._proc.stdin is not None  # stdin=PIPE
        try:
            self._proc.stdin.write(_HEADER.pack(b"IMG0", h, w))
            self._proc.stdin.write(np.ascontiguousarray(image).data)
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError):
            self._proc.wait(timeout=5)
            raise DetectorError(f"BlazePose worker exited with code {self._proc.returncode}: {self._worker_log()}") from None
        deadline = time.monotonic() + self.timeout_s
        tag, n = _REPLY.unpack(self._read(_REPLY.size, deadline, "answer"))
        if tag != b"LMK0" or n > 1:
            raise DetectorError(f"BlazePose worker sent a bad reply header {tag!r} {n}")
        if n == 0:
            return None
        data = self._read(NUM_LANDMARKS * 4 * 4, deadline, "answer")
        return np.frombuffer(data, "<f4").reshape(NUM_LANDMARKS, 4).astype(np.float32)

    def detect(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        lm = self.landmarks(image)
        person = None if lm is None else coco_from_blazepose(lm, image.shape[1], image.shape[0], self.min_visibility)
        if person is None:
            return empty_detections()
        kp, box = person
        return kp[None], box[None]

    def close(self) -> None:
        proc, self._proc = getattr(self, "_proc", None), None
        if proc is None:
            return
        try:
            proc.stdin.close()  # end of input: the worker returns
            proc.wait(timeout=5)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        proc.stdout.close()
        self._log.close()

    def __del__(self) -> None:  # a worker must not outlive its detector
        try:
            self.close()
        except Exception:
            pass
