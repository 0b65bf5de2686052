"""MMPose RTMO, exported by the user to ONNX (MMDeploy ``end2end.onnx``), on onnxruntime (many people).

What this module relies on, as MMDeploy exports RTMO (``pose-detection_rtmo_onnxruntime``
configs) and MMPose's RTMO configs preprocess:

- input: (1, 3, H, W) float32, BGR, raw values in [0, 255] (the configs' mean is 0 and std 1,
  no channel swap), the image scaled to fit (W, H) and placed at the top-left corner with grey
  (114) padding on the right and bottom;
- outputs ``dets``: (1, N, 5) float32 boxes x0, y0, x1, y1 and a person score, and
  ``keypoints``: (1, N, 17, 3) float32 COCO keypoints (x, y, score); coordinates in
  network-input pixels. The export may or may not have suppressed overlaps already; we apply
  non-maximum suppression either way.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.detectors.base import (
    DetectorError,
    Letterbox,
    input_size,
    letterbox,
    onnx_session,
    select_people,
)

__all__ = ["Rtmo", "decode_rtmo"]


def decode_rtmo(
    dets: NDArray,
    keypoints: NDArray,
    placement: Letterbox,
    width: int,
    height: int,
    *,
    score_threshold: float = 0.5,
    iou_threshold: float = 0.65,
    keypoint_threshold: float = 0.3,
    max_people: int = 64,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """People from RTMO's two outputs.

    Args:
        dets: (1, N, 5) or (N, 5) x0, y0, x1, y1, score.
        keypoints: (1, N, 17, 3) or (N, 17, 3) x, y, score.
        placement: the letterbox that made the network input.
        width: original image width in pixels.
        height: original image height in pixels.
        iou_threshold: NMS overlap (MMPose's RTMO test config uses 0.65).

    Returns:
        keypoints (M, 17, 3) and boxes (M, 4), float32, in the image's pixels.
    """
    d = np.asarray(dets, np.float32)
    k = np.asarray(keypoints, np.float32)
    d = d[0] if d.ndim == 3 and d.shape[0] == 1 else d
    k = k[0] if k.ndim == 4 and k.shape[0] == 1 else k
    if d.ndim != 2 or d.shape[1] != 5 or k.shape != (d.shape[0], NUM_KEYPOINTS, 3):
        raise DetectorError(f"RTMO outputs must be dets (1, N, 5) and keypoints (1, N, {NUM_KEYPOINTS}, 3), "
                            f"got {tuple(np.shape(dets))} and {tuple(np.shape(keypoints))}")
    return select_people(d[:, :4], d[:, 4], k, placement, width, height, score_threshold=score_threshold,
                         iou_threshold=iou_threshold, keypoint_threshold=keypoint_threshold, max_people=max_people)


class Rtmo:
    """An RTMO ONNX model as a ``Detector``."""

    def __init__(self, path: Path | str, *, threads: int = 1, score_threshold: float = 0.5, keypoint_threshold: float = 0.3):
        self._session = onnx_session(Path(path), threads)
        self.size = input_size(self._session)  # (W, H)
        self._input = self._session.get_inputs()[0].name
        outputs = self._session.get_outputs()
        by_rank = {len(o.shape): o.name for o in outputs}
        names = {o.name for o in outputs}
        if {"dets", "keypoints"} <= names:
            self._outputs = ["dets", "keypoints"]
        elif len(outputs) == 2 and set(by_rank) == {3, 4}:
            self._outputs = [by_rank[3], by_rank[4]]
        else:
            got = {o.name: tuple(o.shape) for o in outputs}
            raise DetectorError(f"{path}: not an RTMO export: expected outputs dets (1, N, 5) and keypoints (1, N, 17, 3), the model has {got}")
        self._score, self._kp = score_threshold, keypoint_threshold

    def detect(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        padded, placement = letterbox(image, self.size, centre=False)
        blob = np.ascontiguousarray(padded.transpose(2, 0, 1)[None], dtype=np.float32)  # (1, 3, H, W) BGR 0-255
        dets, kps = self._session.run(self._outputs, {self._input: blob})
        return decode_rtmo(dets, kps, placement, image.shape[1], image.shape[0],
                           score_threshold=self._score, keypoint_threshold=self._kp)

    def close(self) -> None:
        self._session = None
