"""BlazePose: the 33 -> COCO-17 mapping, and the real model (mediapipe 0.10.21 in its own
interpreter, created by `make test`) on a real photo that scikit-image ships."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.body import INDEX, KEYPOINTS
from superbody.edge.detectors.base import DetectorError
from superbody.edge.detectors.blazepose import FROM_BLAZEPOSE, BlazePose, blazepose_python, coco_from_blazepose
from tests.edge.photos import ASTRONAUT, TOLERANCE_PX, astronaut_bgr


def test_mapping_names_the_same_joints():
    blaze = {0: "nose", 2: "left_eye", 5: "right_eye", 7: "left_ear", 8: "right_ear", 11: "left_shoulder",
             12: "right_shoulder", 13: "left_elbow", 14: "right_elbow", 15: "left_wrist", 16: "right_wrist",
             23: "left_hip", 24: "right_hip", 25: "left_knee", 26: "right_knee", 27: "left_ankle", 28: "right_ankle"}
    assert [blaze[i] for i in FROM_BLAZEPOSE] == list(KEYPOINTS)


def test_coco_from_blazepose_scales_thresholds_and_boxes():
    lm = np.zeros((33, 4), np.float32)
    lm[:, 0] = np.linspace(0.1, 0.9, 33)  # x
    lm[:, 1] = np.linspace(0.2, 0.8, 33)  # y
    lm[:, 2] = 0.9
    lm[11, 2] = 0.2  # left shoulder barely visible: missing
    lm[27, 0] = 1.2  # left ankle outside the image: missing
    kp, box = coco_from_blazepose(lm, 200, 100, min_visibility=0.5)
    assert kp.shape == (17, 3) and kp.dtype == np.float32
    assert np.allclose(kp[INDEX["nose"]], [0.1 * 200, 0.2 * 100, 0.9])
    assert np.allclose(kp[INDEX["right_hip"], :2], [lm[24, 0] * 200, lm[24, 1] * 100])
    assert np.isnan(kp[INDEX["left_shoulder"]]).all() and np.isnan(kp[INDEX["left_ankle"]]).all()
    # Box: the visible landmarks' bounds (x 20..180 without the ankle, y 20..80) grown by 10 %, clipped.
    assert np.allclose(box, [20 - 16, 20 - 6, 180 + 16, 80 + 6], atol=1e-4)


def test_coco_from_blazepose_nobody_visible():
    lm = np.zeros((33, 4), np.float32)
    lm[:, :2] = 0.5
    assert coco_from_blazepose(lm, 64, 64) is None  # visibility 0 everywhere
    with pytest.raises(ValueError, match=r"\(33, 4\)"):
        coco_from_blazepose(np.zeros((17, 4)), 64, 64)


def test_blazepose_finds_the_astronaut():
    """The real model on a real photo: nose, eyes and shoulders within 30 px of the marked joints."""
    bp = BlazePose()
    try:
        kps, boxes = bp.detect(astronaut_bgr())
        assert kps.shape == (1, 17, 3) and boxes.shape == (1, 4)
        for name, xy in ASTRONAUT.items():
            u, v, score = kps[0, INDEX[name]]
            assert np.hypot(u - xy[0], v - xy[1]) <= TOLERANCE_PX, (name, (u, v), xy)
            assert 0.5 <= score <= 1.0
        # Hips, knees and ankles are outside the photo: missing, not guessed.
        for name in ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle"):
            assert np.isnan(kps[0, INDEX[name]]).all(), name
        x0, y0, x1, y1 = boxes[0]
        assert x0 < 100 and x1 > 310 and y0 < 101 and y1 > 258  # the box holds the marked joints
        # Nobody in a plain grey image; and the worker goes on after it.
        k0, b0 = bp.detect(np.full((480, 640, 3), 128, np.uint8))
        assert k0.shape == (0, 17, 3) and b0.shape == (0, 4)
        # The mirrored photo: the joints mirror and swap sides.
        km, _ = bp.detect(astronaut_bgr()[:, ::-1].copy())
        for name in ASTRONAUT:
            u, v, _ = km[0, INDEX[name]]
            side = name.replace("left", "RIGHT").replace("right", "left").replace("RIGHT", "right")
            u0, v0 = ASTRONAUT[side]
            assert np.hypot(u - (511 - u0), v - v0) <= TOLERANCE_PX, (name, (u, v))
    finally:
        bp.close()
    assert bp._proc is None


def test_missing_interpreter_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setenv("SUPERBODY_BLAZEPOSE_PYTHON", str(tmp_path / "nope" / "python"))
    assert blazepose_python() == str(tmp_path / "nope" / "python")
    with pytest.raises(DetectorError, match="make blazepose"):
        BlazePose()


def test_a_worker_that_dies_is_reported(tmp_path, monkeypatch):
    """An interpreter without mediapipe: the worker's own error comes back in the message."""
    import sys

    monkeypatch.setenv("SUPERBODY_BLAZEPOSE_PYTHON", sys.executable)  # this venv has no mediapipe
    with pytest.raises(DetectorError, match="exited with code 1 before it could load the model: .*mediapipe"):
        BlazePose()
