"""Ultralytics YOLOv8/YOLO11-pose, exported by the user to ONNX, on onnxruntime (many people).

Export (outside this project; the weights are Ultralytics'): ``yolo export model=yolov8n-pose.pt
format=onnx`` (add ``imgsz=640,384`` for another input size). What this module relies on, as
the exporter writes it (``nms=False``, the default):

- input ``images``: (1, 3, H, W) float32, RGB, values in [0, 1], the image letterboxed to
  (W, H) centred with grey (114) padding;
- output ``output0``: (1, 56, N) float32, one column per candidate (N = 8400 at 640 x 640):
  rows 0-3 the box centre x, y, width, height and row 4 the person score (after sigmoid), then
  17 COCO keypoints as (x, y, visibility) with the visibility after sigmoid; every coordinate
  in network-input pixels. No non-maximum suppression is applied inside.
"""

from __future__ import annotations

from pathlib import Path

import cv2
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

__all__ = ["YoloPose", "decode_yolo_pose", "ROWS"]

ROWS = 5 + 3 * NUM_KEYPOINTS  # 56: cx, cy, w, h, score, 17 x (x, y, visibility)


def decode_yolo_pose(
    output: NDArray,
    placement: Letterbox,
    width: int,
    height: int,
    *,
    score_threshold: float = 0.5,
    iou_threshold: float = 0.7,
    keypoint_threshold: float = 0.5,
    max_people: int = 64,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """People from a YOLO-pose output tensor.

    Args:
        output: (1, 56, N) or (56, N) network output.
        placement: the letterbox that made the network input.
        width: original image width in pixels.
        height: original image height in pixels.
        score_threshold: minimum person score.
        iou_threshold: NMS overlap above which the weaker person is dropped (Ultralytics' 0.7).
        keypoint_threshold: joints with a lower visibility are missing.

    Returns:
        keypoints (M, 17, 3) and boxes (M, 4), float32, in the image's pixels.
    """
    out = np.asarray(output, np.float32)
    if out.ndim == 3 and out.shape[0] == 1:
        out = out[0]
    if out.ndim != 2 or out.shape[0] != ROWS:
        raise DetectorError(f"YOLO-pose output must be (1, {ROWS}, N) (cx, cy, w, h, score, 17 x (x, y, visibility)), got {tuple(np.shape(output))}")
    pred = out.T  # (N, 56)
    cx, cy, w, h = pred[:, 0], pred[:, 1], pred[:, 2], pred[:, 3]
    boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1)  # (N, 4)
    keypoints = pred[:, 5:].reshape(-1, NUM_KEYPOINTS, 3)  # (N, 17, 3)
    return select_people(boxes, pred[:, 4], keypoints, placement, width, height, score_threshold=score_threshold,
                         iou_threshold=iou_threshold, keypoint_threshold=keypoint_threshold, max_people=max_people)


class YoloPose:
    """A YOLO-pose ONNX model as a ``Detector``."""

    def __init__(self, path: Path | str, *, threads: int = 1, score_threshold: float = 0.5, keypoint_threshold: float = 0.5):
        self._session = onnx_session(Path(path), threads)
        self.size = input_size(self._session)  # (W, H)
        self._input = self._session.get_inputs()[0].name
        outputs = self._session.get_outputs()
        shape = tuple(outputs[0].shape)
        if len(outputs) != 1 or len(shape) != 3 or shape[1] not in (ROWS, str(ROWS)):
            got = [tuple(o.shape) for o in outputs]
            raise DetectorError(f"{path}: not a YOLO-pose export: expected one output of shape (1, {ROWS}, N), the model has {got}")
        self._score, self._kp = score_threshold, keypoint_threshold

    def detect(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        padded, placement = letterbox(image, self.size, centre=True)
        rgb = cv2.cvtColor(padded, cv2.COLOR_BGR2RGB)
        blob = (rgb.transpose(2, 0, 1)[None] / np.float32(255.0)).astype(np.float32)  # (1, 3, H, W)
        (out,) = self._session.run(None, {self._input: blob})
        return decode_yolo_pose(out, placement, image.shape[1], image.shape[0],
                                score_threshold=self._score, keypoint_threshold=self._kp)

    def close(self) -> None:
        self._session = None
