"""Pose detectors on the host CPU, by name (``--detector``): a BGR image in, each person's
COCO-17 keypoints and box out.

- ``blazepose``: MediaPipe BlazePose, one person per frame, in a worker process of its own
  interpreter (edge/detectors/blazepose.py);
- ``yolo-pose:PATH.onnx``: a user-exported Ultralytics YOLOv8/YOLO11-pose ONNX model on
  onnxruntime, many people (edge/detectors/yolo_pose.py);
- ``rtmo:PATH.onnx``: a user-exported MMPose RTMO ONNX model on onnxruntime, many people
  (edge/detectors/rtmo.py).

The ``Detector`` protocol and the image maths the ONNX detectors share live in
``edge/detectors/base.py``; this module names the detectors and opens one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from superbody.edge.detectors.base import Detector

__all__ = ["DETECTOR_FORMS", "DetectorSpec", "parse_detector", "open_detector"]


DETECTOR_FORMS = ("blazepose", "yolo-pose:PATH.onnx", "rtmo:PATH.onnx")


@dataclass(frozen=True)
class DetectorSpec:
    """A parsed ``--detector`` value.

    Attributes:
        kind: which detector.
        path: the ONNX model for ``yolo-pose`` and ``rtmo``, else None.
    """

    kind: Literal["blazepose", "yolo-pose", "rtmo"]
    path: Path | None = None

    def __str__(self) -> str:
        return self.kind if self.path is None else f"{self.kind}:{self.path}"


def parse_detector(text: str) -> DetectorSpec:
    """Parse ``blazepose``, ``yolo-pose:PATH.onnx`` or ``rtmo:PATH.onnx``.

    Raises:
        ValueError: naming the value and the valid forms. The file itself is checked when the
            detector opens.
    """
    forms = ", ".join(DETECTOR_FORMS)
    if text == "blazepose":
        return DetectorSpec("blazepose")
    kind, sep, path = text.partition(":")
    if sep and kind in ("yolo-pose", "rtmo"):
        if not path:
            raise ValueError(f"--detector {text!r} names no model file; valid forms: {forms}")
        return DetectorSpec(kind, Path(path))  # type: ignore[arg-type]
    raise ValueError(f"--detector must be one of {forms}, got {text!r}")


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
    assert spec.path is not None
    if spec.kind == "yolo-pose":
        from superbody.edge.detectors.yolo_pose import YoloPose

        return YoloPose(spec.path, threads=threads)
    from superbody.edge.detectors.rtmo import Rtmo

    return Rtmo(spec.path, threads=threads)
