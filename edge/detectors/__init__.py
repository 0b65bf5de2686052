"""Pose detectors on the host CPU, by name (``--detector``): a BGR image in, each person's
COCO-17 keypoints and box out.

- ``blazepose``: MediaPipe BlazePose, one person per frame, in a worker process of its own
  interpreter (edge/detectors/blazepose.py);
- ``yolo-pose:PATH.onnx``: a user-exported Ultralytics YOLOv8/YOLO11-pose ONNX model on
  onnxruntime, many people (edge/detectors/yolo_pose.py);
- ``rtmo:PATH.onnx``: a user-exported MMPose RTMO ONNX model on onnxruntime, many people
  (edge/detectors/rtmo.py);
- ``movenet[:PATH.onnx][@SHORT]``: Google's MoveNet MultiPose, converted once by ``make movenet``,
  on onnxruntime, up to six people; ``@SHORT`` sets the network input's short side
  (edge/detectors/movenet.py).

The ``Detector`` protocol and the image maths the ONNX detectors share live in
``edge/detectors/base.py``; this module names the detectors and opens one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from superbody.edge.detectors.base import Detector

__all__ = ["DETECTOR_FORMS", "DetectorSpec", "parse_detector", "open_detector"]


DETECTOR_FORMS = ("blazepose", "yolo-pose:PATH.onnx", "rtmo:PATH.onnx", "movenet[:PATH.onnx][@SHORT]")


@dataclass(frozen=True)
class DetectorSpec:
    """A parsed ``--detector`` value.

    Attributes:
        kind: which detector.
        path: the ONNX model for ``yolo-pose`` and ``rtmo``; for ``movenet`` an explicit one
            (None: the one ``make movenet`` converted); else None.
        size: ``movenet``'s network input short side in pixels (None: its default).
    """

    kind: Literal["blazepose", "yolo-pose", "rtmo", "movenet"]
    path: Path | None = None
    size: int | None = None

    def __str__(self) -> str:
        text = self.kind if self.path is None else f"{self.kind}:{self.path}"
        return text if self.size is None else f"{text}@{self.size}"


def parse_detector(text: str) -> DetectorSpec:
    """Parse ``blazepose``, ``yolo-pose:PATH.onnx``, ``rtmo:PATH.onnx`` or ``movenet[:PATH.onnx][@SHORT]``.

    Raises:
        ValueError: naming the value and the valid forms. The file itself is checked when the
            detector opens.
    """
    forms = ", ".join(DETECTOR_FORMS)
    if text == "blazepose":
        return DetectorSpec("blazepose")
    if text == "movenet" or text.startswith(("movenet:", "movenet@")):
        return _parse_movenet(text)
    kind, sep, path = text.partition(":")
    if sep and kind in ("yolo-pose", "rtmo"):
        if not path:
            raise ValueError(f"--detector {text!r} names no model file; valid forms: {forms}")
        return DetectorSpec(kind, Path(path))  # type: ignore[arg-type]
    raise ValueError(f"--detector must be one of {forms}, got {text!r}")


def _parse_movenet(text: str) -> DetectorSpec:
    from superbody.edge.detectors.movenet import SHORT_SIDES

    rest, size = text.removeprefix("movenet"), None
    head, at, tail = rest.rpartition("@")
    if at and (tail.isdigit() or not head):  # after a path, '@' names a size only when digits follow
        rest, size = head, tail
        if not (size.isdigit() and int(size) in SHORT_SIDES):
            raise ValueError(f"--detector {text!r}: the input short side after '@' must be a multiple of 32 in "
                             f"[{SHORT_SIDES[0]}, {SHORT_SIDES[-1]}], got {size!r}")
    if rest and not (rest.startswith(":") and len(rest) > 1):
        raise ValueError(f"--detector {text!r}: expected movenet, movenet:PATH.onnx, movenet@SHORT or movenet:PATH.onnx@SHORT")
    return DetectorSpec("movenet", Path(rest[1:]) if rest else None, int(size) if size else None)


def open_detector(spec: DetectorSpec, *, threads: int = 1) -> Detector:
    """Start the detector a spec names (heavy imports happen here, not at import time).

    Args:
        spec: from ``parse_detector``.
        threads: onnxruntime intra-op threads for the ONNX detectors.

    Raises:
        DetectorError: the detector cannot start (missing model file, wrong model layout,
            BlazePose interpreter missing); the message says what to do.
    """
    if spec.kind == "blazepose":
        from superbody.edge.detectors.blazepose import BlazePose

        return BlazePose()
    if spec.kind == "movenet":
        from superbody.edge.detectors.movenet import DEFAULT_SHORT_SIDE, MoveNet

        return MoveNet(spec.path, threads=threads, short_side=spec.size or DEFAULT_SHORT_SIDE)
    assert spec.path is not None
    if spec.kind == "yolo-pose":
        from superbody.edge.detectors.yolo_pose import YoloPose

        return YoloPose(spec.path, threads=threads)
    from superbody.edge.detectors.rtmo import Rtmo

    return Rtmo(spec.path, threads=threads)
