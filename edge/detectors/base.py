"""The ``Detector`` protocol and the image maths the ONNX detectors share.

Sources without a detector of their own (video files, webcams, RTSP streams) hand their images
to a ``Detector`` (chosen by name in ``edge/detectors/__init__.py``); the camera node turns its
output into ``PersonView`` objects (adding the colour signature of each box). The shared maths
is pure functions: the letterbox (resize keeping the aspect ratio, pad to the network's input)
and its inverse, and non-maximum suppression.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS

__all__ = ["Detector", "DetectorError", "Letterbox", "letterbox", "unletterbox", "nms", "select_people", "onnx_session", "input_size", "empty_detections"]


class DetectorError(RuntimeError):
    """A detector cannot start or cannot go on (the message says which and why)."""


class Detector(Protocol):
    """A pose detector for BGR images."""

    def detect(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """People in one image.

        Args:
            image: (H, W, 3) uint8 BGR pixels.

        Returns:
            keypoints: (N, 17, 3) float32 COCO-17 (u, v, score) in the image's pixels, score in
                (0, 1]; rows of NaN for joints not detected.
            boxes: (N, 4) float32 (x0, y0, x1, y1) pixel boxes, inside the image.
        """
        ...

    def close(self) -> None: ...


def empty_detections() -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """No people: (0, 17, 3) keypoints and (0, 4) boxes."""
    return np.zeros((0, NUM_KEYPOINTS, 3), np.float32), np.zeros((0, 4), np.float32)


class Letterbox(NamedTuple):
    """How an image was placed in a network input: input = image * scale + (dx, dy)."""

    scale: float
    dx: float
    dy: float


def letterbox(
    image: NDArray[np.uint8], size: tuple[int, int], *, centre: bool = True, pad: int = 114
) -> tuple[NDArray[np.uint8], Letterbox]:
    """Resize an image keeping its aspect ratio and pad it to a network's input size.

    Args:
        image: (H, W, 3) uint8.
        size: (width, height) of the network input.
        centre: pad equally on both sides (Ultralytics) or only right and bottom (MMPose RTMO).
        pad: grey level of the padding.

    Returns:
        The (height, width, 3) padded image and the placement, for ``unletterbox``.
    """
    h, w = image.shape[:2]
    out_w, out_h = size
    scale = min(out_w / w, out_h / h)
    new_w, new_h = min(out_w, round(w * scale)), min(out_h, round(h * scale))
    resized = image if (new_w, new_h) == (w, h) else cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    dx, dy = ((out_w - new_w) // 2, (out_h - new_h) // 2) if centre else (0, 0)
    out = np.full((out_h, out_w, 3), pad, np.uint8)
    out[dy:dy + new_h, dx:dx + new_w] = resized
    return out, Letterbox(scale, float(dx), float(dy))


def unletterbox(xy: NDArray, box: Letterbox) -> NDArray[np.float32]:
    """Network-input pixel coordinates back to the original image's.

    Args:
        xy: (..., 2k) coordinates laid out as x, y, x, y, ... (points or x0, y0, x1, y1 boxes).
        box: the placement ``letterbox`` returned.

    Returns:
        Same shape, float32: (x - dx) / scale, (y - dy) / scale.
    """
    out = np.array(xy, dtype=np.float32, copy=True)
    out[..., 0::2] = (out[..., 0::2] - box.dx) / box.scale
    out[..., 1::2] = (out[..., 1::2] - box.dy) / box.scale
    return out


def nms(boxes: NDArray, scores: NDArray, iou_threshold: float) -> NDArray[np.intp]:
    """Greedy non-maximum suppression.

    Args:
        boxes: (N, 4) x0, y0, x1, y1.
        scores: (N,) higher is better.
        iou_threshold: a box overlapping a better kept box by more than this IoU is dropped.

    Returns:
        Indices of the kept boxes, best first.
    """
    boxes = np.asarray(boxes, np.float64)
    order = np.argsort(-np.asarray(scores), kind="stable")
    area = np.clip(boxes[:, 2] - boxes[:, 0], 0, None) * np.clip(boxes[:, 3] - boxes[:, 1], 0, None)  # (N,)
    keep: list[int] = []
    while order.size:
        i, rest = order[0], order[1:]
        keep.append(int(i))
        # IoU of box i with every remaining box.
        iw = np.clip(np.minimum(boxes[i, 2], boxes[rest, 2]) - np.maximum(boxes[i, 0], boxes[rest, 0]), 0, None)
        ih = np.clip(np.minimum(boxes[i, 3], boxes[rest, 3]) - np.maximum(boxes[i, 1], boxes[rest, 1]), 0, None)
        inter = iw * ih
        iou = inter / np.maximum(area[i] + area[rest] - inter, 1e-12)
        order = rest[iou <= iou_threshold]
    return np.asarray(keep, dtype=np.intp)


def select_people(
    boxes: NDArray,
    scores: NDArray,
    keypoints: NDArray,
    placement: Letterbox,
    width: int,
    height: int,
    *,
    score_threshold: float,
    iou_threshold: float,
    keypoint_threshold: float,
    max_people: int = 64,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The people of a multi-person network's raw candidates, in the original image's pixels.

    Keeps candidates scoring at least ``score_threshold``, suppresses overlaps (``nms``), keeps
    the best ``max_people``, undoes the letterbox, clips boxes to the image, and marks joints
    missing (NaN) whose score is below ``keypoint_threshold`` or that fall outside the image.

    Args:
        boxes: (N, 4) x0, y0, x1, y1 in network-input pixels.
        scores: (N,) person scores in [0, 1].
        keypoints: (N, 17, 3) (x, y, score) in network-input pixels.
        placement: the letterbox that made the network input.
        width: original image width in pixels.
        height: original image height in pixels.

    Returns:
        keypoints (M, 17, 3) and boxes (M, 4), float32, as ``Detector.detect`` returns them.
    """
    scores = np.asarray(scores, np.float32)
    ok = np.isfinite(scores) & (scores >= score_threshold) & np.isfinite(boxes).all(axis=1)
    boxes, scores, keypoints = np.asarray(boxes)[ok], scores[ok], np.asarray(keypoints)[ok]
    if len(scores) == 0:
        return empty_detections()
    keep = nms(boxes, scores, iou_threshold)[:max_people]
    out_boxes = unletterbox(boxes[keep], placement)  # (M, 4)
    out_boxes[:, 0::2] = np.clip(out_boxes[:, 0::2], 0, width)
    out_boxes[:, 1::2] = np.clip(out_boxes[:, 1::2], 0, height)
    kp = np.asarray(keypoints[keep], np.float32).copy()  # (M, 17, 3)
    kp[..., :2] = unletterbox(kp[..., :2], placement)
    u, v, s = kp[..., 0], kp[..., 1], kp[..., 2]
    seen = (s >= keypoint_threshold) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    kp[..., 2] = np.clip(s, 1e-3, 1.0)  # the wire's scores are in (0, 1]
    kp[~seen] = np.nan
    return kp, out_boxes


def onnx_session(path: Path, threads: int = 1):
    """An onnxruntime CPU session for a user's model file; ``DetectorError`` naming the file otherwise."""
    import onnxruntime as ort

    if not Path(path).is_file():
        raise DetectorError(f"model file {str(path)!r} does not exist")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    except Exception as e:  # onnxruntime raises its own exception types for bad files
        raise DetectorError(f"cannot load ONNX model {str(path)!r}: {e}") from None


def input_size(session, default: int = 640) -> tuple[int, int]:
    """(width, height) of an image network's single (1, 3, H, W) input; dynamic sides get ``default``."""
    inputs = session.get_inputs()
    if len(inputs) != 1 or len(inputs[0].shape) != 4 or inputs[0].shape[1] not in (3, "3"):
        shapes = [tuple(i.shape) for i in inputs]
        raise DetectorError(f"expected one image input of shape (1, 3, H, W), the model has {shapes}")
    h, w = inputs[0].shape[2:]
    return (w if isinstance(w, int) and w > 0 else default, h if isinstance(h, int) and h > 0 else default)
