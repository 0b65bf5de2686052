"""Video files, webcams and RTSP streams as frame sources, on OpenCV's ``VideoCapture``.

Capture times (UNIX ns):

- webcams and streams: the wall clock when the frame is grabbed (webcams are asked to queue at
  most one frame, so that a slow node does not stamp old frames as new; streams buffer as
  FFmpeg does, so their times are late by the stream's latency);
- video files: the source's start plus the frame's position in the file (frame index / the
  file's fps). The start is when ``frames()`` is first called, or ``start_ns`` when given:
  nodes playing several files started separately share one capture clock when they are given
  the same start (``edge run --start-at``), so frame k of every file is stamped at the same
  world instant. Played in real time by default: each frame is delivered at its capture
  time (none before the start), and frames whose time has passed by more than a frame period
  are skipped, as a live camera drops what a slow node cannot take. ``realtime=False``
  delivers every frame as fast as the node takes them (tests, benchmarks), with the same
  capture times. ``fps`` below the file's rate thins the frames to that rate
  (edge/sources/subsample.py; the frames left out are not decoded); above it is an error.

The frame size is checked against the site's camera when the source opens (webcams are first
asked for that size) and again on every frame.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from superbody.edge.sources.source import Frame, SourceError
from superbody.edge.sources.subsample import Subsampler

__all__ = ["VideoSource", "VideoKind"]

VideoKind = Literal["video", "webcam", "rtsp"]


class VideoSource:
    """A ``FrameSource`` reading a video file, a webcam or an RTSP stream.

    Args:
        kind: ``video`` (a file), ``webcam`` (a device index) or ``rtsp`` (a URL).
        target: the file path, device index or URL.
        width: the image width the site's camera has.
        height: the image height the site's camera has.
        realtime: video files only: deliver frames at their capture times (else as fast as taken).
        max_wait_s: live sources only: give up after this long without a frame.
        loop: video files only: start again at the end (times keep counting up).
        fps: video files only: the capture rate to publish, at most the file's (None: the file's).
        start_ns: video files only: the wall time (UNIX ns) of the file's first frame (None: when
            ``frames()`` is first called).

    Attributes:
        fps: the file's frame rate (what OpenCV reports for live sources, possibly 0).
        target_fps: the rate published (``fps`` argument), or None for every frame.
    """

    def __init__(self, kind: VideoKind, target: str | int, width: int, height: int, *, realtime: bool = True,
                 max_wait_s: float = 5.0, loop: bool = False, fps: float | None = None, start_ns: int | None = None):
        self.kind, self.target = kind, target
        self.name = f"{kind}:{target}" if kind != "rtsp" else str(target)
        self.width, self.height = width, height
        self.realtime, self.max_wait_s, self.loop = realtime, max_wait_s, loop
        self.target_fps, self.start_ns = fps, start_ns
        self.skipped = 0
        if kind != "video" and (fps is not None or start_ns is not None):
            raise ValueError(f"{self.name}: fps and start_ns are for video files")
        if kind == "video" and not Path(str(target)).is_file():
            raise SourceError(f"{self.name}: no such file")
        self._cap: cv2.VideoCapture | None = cv2.VideoCapture(target) if kind == "webcam" else cv2.VideoCapture(str(target), cv2.CAP_FFMPEG)
        if not self._cap.isOpened():
            hint = {"video": "is it a video file?", "webcam": f"is /dev/video{target} there and free?",
                    "rtsp": "check the URL, the credentials and that the camera is reachable"}[kind]
            raise SourceError(f"{self.name}: OpenCV cannot open it ({hint})")
        if kind == "webcam":  # ask for the site's size; the check below says if the camera agreed
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            # A frame waiting in the driver's queue would get a late capture time: keep one.
            self._cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        w, h = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if (w, h) != (0, 0):  # some streams report no size before the first frame
            self._check_size(w, h)
        self.fps = float(self._cap.get(cv2.CAP_PROP_FPS))
        if kind == "video" and not (math.isfinite(self.fps) and 0 < self.fps <= 1000):
            self.close()
            raise SourceError(f"{self.name}: the file gives no frame rate (got {self.fps}); re-encode it with one")
        if fps is not None and fps > self.fps * (1 + 1e-9):
            self.close()
            raise SourceError(f"--fps {fps:g} is above the frame rate of {self.name} ({self.fps:g} fps): a file can only be thinned, "
                              f"give --fps in (0, {self.fps:g}]")

    def _check_size(self, w: int, h: int) -> None:
        if (w, h) != (self.width, self.height):
            self.close()
            raise SourceError(f"{self.name} delivers {w}x{h} images but the site's camera is {self.width}x{self.height}: "
                              f"fix the camera's width/height in the site file (and recalibrate) or the source's resolution")

    def frames(self) -> Iterator[Frame]:
        if self._cap is None:
            return
        yield from (self._file_frames() if self.kind == "video" else self._live_frames())

    def _file_frames(self) -> Iterator[Frame]:
        period_ns = 1e9 / self.fps
        if self.start_ns is None:
            self.start_ns = time.time_ns()
        start_ns = self.start_ns
        rate = Subsampler(self.target_fps) if self.target_fps is not None else None
        k = 0  # frames since start, across loops
        kept: tuple[int, bool] = (-1, True)  # (k, whether the rate keeps frame k): decided once, a rewind retries k
        self._read_since_rewind = 0
        while self._cap is not None:
            t_ns = start_ns + int(k * period_ns)  # the start stays an exact integer: UNIX ns do not fit a float
            if rate is not None and kept[0] != k:
                kept = (k, rate.keep(t_ns))
            if not kept[1]:  # thinned to the asked rate: not decoded
                if not self._cap.grab():
                    if not self._rewind():
                        return
                    continue
                self._read_since_rewind += 1
                k += 1
                continue
            if self.realtime:
                late = time.time_ns() - t_ns
                if late > period_ns:  # behind: drop this frame without decoding it
                    if not self._cap.grab():
                        if not self._rewind():
                            return
                        continue
                    self.skipped += 1
                    self._read_since_rewind += 1
                    k += 1
                    continue
                if late < 0:
                    time.sleep(-late * 1e-9)
            ok, image = self._cap.read()
            if not ok:
                if not self._rewind():
                    return
                continue
            self._read_since_rewind += 1
            yield self._frame(t_ns, image)
            k += 1

    def _rewind(self) -> bool:
        """At the end of the file: start again when looping (and when the last pass read a frame)."""
        if not (self.loop and self._cap is not None and self._read_since_rewind > 0):
            return False
        self._read_since_rewind = 0
        return bool(self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0))

    def _live_frames(self) -> Iterator[Frame]:
        last_ok = time.monotonic()
        while self._cap is not None:
            if not self._cap.grab():
                if time.monotonic() - last_ok > self.max_wait_s:
                    raise SourceError(f"{self.name}: no frame for {self.max_wait_s:g} s")
                time.sleep(0.01)
                continue
            t_ns = time.time_ns()  # capture time: the grab, before decoding
            ok, image = self._cap.retrieve()
            if not ok:
                continue
            last_ok = time.monotonic()
            yield self._frame(t_ns, image)

    def _frame(self, t_ns: int, image: np.ndarray) -> Frame:
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        h, w = image.shape[:2]
        if (w, h) != (self.width, self.height):
            self._check_size(w, h)
        return Frame(t_ns, w, h, np.ascontiguousarray(image, dtype=np.uint8), None)

    def close(self) -> None:
        cap, self._cap = getattr(self, "_cap", None), None
        if cap is not None:
            cap.release()
