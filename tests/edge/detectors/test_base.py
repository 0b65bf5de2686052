"""Host detectors: spec parsing, letterbox and NMS maths, and the YOLO-pose and RTMO decoders
run under real onnxruntime on small ONNX graphs built here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.detectors import DetectorSpec, open_detector, parse_detector
from superbody.edge.detectors.base import (
    DetectorError,
    Letterbox,
    letterbox,
    nms,
    select_people,
    unletterbox,
)
from superbody.edge.detectors.rtmo import Rtmo, decode_rtmo
from superbody.edge.detectors.yolo_pose import YoloPose, decode_yolo_pose

onnx = pytest.importorskip("onnx")  # in the train extra, which `make test` installs
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

# -- parsing -------------------------------------------------------------------------------------

# (text, expected spec)
GOOD_SPECS = [
    ("blazepose", DetectorSpec("blazepose")),
    ("yolo-pose:models/y.onnx", DetectorSpec("yolo-pose", Path("models/y.onnx"))),
    ("rtmo:/abs/path/rtmo-s.onnx", DetectorSpec("rtmo", Path("/abs/path/rtmo-s.onnx"))),
    ("yolo-pose:C:/odd:name.onnx", DetectorSpec("yolo-pose", Path("C:/odd:name.onnx"))),  # only the first ':' splits
]


@pytest.mark.parametrize("text,spec", GOOD_SPECS)
def test_parse_detector(text, spec):
    assert parse_detector(text) == spec
    assert str(parse_detector(text)) == text


# (text, fragment of the error)
BAD_SPECS = [
    ("", "got ''"),
    ("openpose", "must be one of blazepose, yolo-pose:PATH.onnx, rtmo:PATH.onnx, movenet[:PATH.onnx][@SHORT], got 'openpose'"),
    ("yolo-pose", "got 'yolo-pose'"),  # the model path is required
    ("yolo-pose:", "names no model file"),
    ("rtmo:", "names no model file"),
    ("blazepose:x", "got 'blazepose:x'"),
]


@pytest.mark.parametrize("text,fragment", BAD_SPECS)
def test_parse_detector_rejects(text, fragment):
    with pytest.raises(ValueError, match=None) as e:
        parse_detector(text)
    assert fragment in str(e.value)


# -- letterbox -------------------------------------------------------------------------------------

# (image width, height, network width, height, centred, expected (scale, dx, dy))
LETTERBOXES = [
    (640, 480, 640, 640, True, (1.0, 0, 80)),  # pad top and bottom
    (640, 480, 640, 640, False, (1.0, 0, 0)),  # RTMO: pad right and bottom only
    (1280, 720, 640, 640, True, (0.5, 0, 140)),  # shrink, then pad
    (480, 640, 640, 640, True, (1.0, 80, 0)),  # portrait: pad left and right
    (320, 240, 512, 288, True, (1.2, 64, 0)),  # grow to a wide network input
    (641, 480, 640, 640, True, (640 / 641, 0, 80)),  # odd size: the rounding of the resized side
]


@pytest.mark.parametrize("w,h,nw,nh,centre,expected", LETTERBOXES)
def test_letterbox_places_the_image_and_unletterbox_inverts_it(w, h, nw, nh, centre, expected):
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    out, place = letterbox(image, (nw, nh), centre=centre)
    assert out.shape == (nh, nw, 3) and out.dtype == np.uint8
    assert place.scale == pytest.approx(expected[0]) and (place.dx, place.dy) == expected[1:]
    new_w, new_h = round(w * place.scale), round(h * place.scale)
    dx, dy = int(place.dx), int(place.dy)
    # Padding is grey 114 everywhere outside the placed image.
    mask = np.ones((nh, nw), bool)
    mask[dy:dy + new_h, dx:dx + new_w] = False
    assert (out[mask] == 114).all()
    if place.scale == 1.0:
        assert np.array_equal(out[dy:dy + h, dx:dx + w], image)
    # Image corners map to the placed image's corners and back.
    corners = np.array([[0, 0, w, h]], np.float32)
    placed = corners * place.scale + np.array([place.dx, place.dy, place.dx, place.dy], np.float32)
    assert np.allclose(placed, [[dx, dy, dx + w * place.scale, dy + h * place.scale]])
    assert np.allclose(unletterbox(placed, place), corners, atol=1e-4)


# -- NMS -------------------------------------------------------------------------------------------

# (boxes, scores, iou threshold, kept indices)
NMS_CASES = [
    (np.zeros((0, 4)), np.zeros(0), 0.5, []),  # nothing
    ([[0, 0, 10, 10]], [0.3], 0.5, [0]),  # one box
    ([[0, 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]], [0.6, 0.9, 0.7], 0.5, [1, 2]),  # overlap 0.68 dropped
    ([[0, 0, 10, 10], [5, 0, 15, 10]], [0.9, 0.8], 0.5, [0, 1]),  # overlap 1/3 kept
    ([[0, 0, 10, 10], [5, 0, 15, 10]], [0.9, 0.8], 0.3, [0]),  # ... unless the threshold is lower
    ([[0, 0, 10, 10], [0, 0, 10, 10]], [0.5, 0.5], 0.5, [0]),  # identical boxes, equal scores: the first
    ([[0, 0, 0, 0], [0, 0, 0, 0]], [0.9, 0.8], 0.5, [0, 1]),  # empty boxes overlap nothing
]


@pytest.mark.parametrize("boxes,scores,iou,kept", NMS_CASES)
def test_nms(boxes, scores, iou, kept):
    assert nms(np.asarray(boxes, float), np.asarray(scores, float), iou).tolist() == kept


def test_select_people_thresholds_and_clips():
    place = Letterbox(0.5, 0.0, 140.0)  # a 1280 x 720 image in a 640 x 640 input
    boxes = np.array([[100, 200, 300, 500], [400, 150, 700, 600], [10, 10, 20, 20]], np.float32)
    scores = np.array([0.9, 0.8, 0.2], np.float32)
    kps = np.zeros((3, NUM_KEYPOINTS, 3), np.float32)
    kps[:, :, :2] = [200, 300]
    kps[:, :, 2] = 0.9
    kps[0, 3, 2] = 0.1  # low score: missing
    kps[1, 4, :2] = [700, 300]  # outside the image once unletterboxed (x = 1400): missing
    k, b = select_people(boxes, scores, kps, place, 1280, 720, score_threshold=0.5, iou_threshold=0.5, keypoint_threshold=0.5)
    assert k.shape == (2, NUM_KEYPOINTS, 3) and b.shape == (2, 4)
    assert np.allclose(b[0], [200, 120, 600, 720])  # y1 = (500 - 140) / 0.5 = 720
    assert np.allclose(b[1], [800, 20, 1280, 720])  # x1 = 1400 and y1 = 920 clipped to the image
    assert np.allclose(k[0, 0], [400, 320, 0.9])
    assert np.isnan(k[0, 3]).all() and np.isnan(k[1, 4]).all()
    assert np.isfinite(k[0, 4]).all() and np.isfinite(k[1, 3]).all()


def test_select_people_with_no_candidate():
    k, b = select_people(np.zeros((0, 4)), np.zeros(0), np.zeros((0, 17, 3)), Letterbox(1, 0, 0), 64, 64,
                         score_threshold=0.5, iou_threshold=0.5, keypoint_threshold=0.5)
    assert k.shape == (0, 17, 3) and b.shape == (0, 4)


# -- ONNX graphs -----------------------------------------------------------------------------------


def _save(tmp_path: Path, name: str, nodes, inputs, outputs, initializers=()) -> Path:
    graph = helper.make_graph(nodes, name, inputs, outputs, initializer=list(initializers))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    path = tmp_path / f"{name}.onnx"
    onnx.save(model, str(path))
    return path


def _image_input(w: int, h: int):
    return helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, h, w])


def constant_model(tmp_path: Path, name: str, w: int, h: int, outputs: dict[str, np.ndarray]) -> Path:
    """A model that ignores its (1, 3, h, w) input and emits the given tensors."""
    nodes = [helper.make_node("Constant", [], [k], value=numpy_helper.from_array(v.astype(np.float32), k)) for k, v in outputs.items()]
    outs = [helper.make_tensor_value_info(k, TensorProto.FLOAT, list(v.shape)) for k, v in outputs.items()]
    return _save(tmp_path, name, nodes, [_image_input(w, h)], outs)


def red_centroid_model(tmp_path: Path, name: str, w: int, h: int, *, kind: str) -> Path:
    """A model whose one person stands at the centroid of the input's red pixels.

    "Red" is relu(channel[red] - channel[green] - t): for YOLO (RGB, [0, 1]) red is channel 0
    and t = 0.5; for RTMO (BGR, [0, 255]) red is channel 2 and t = 128. A blue patch scores 0,
    so a detector that feeds the wrong channel order finds the blue patch instead. Output: a
    20 px box around the centroid, score 0.9, all 17 keypoints at the centroid with score 0.9.
    """
    red, t = (0, 0.5) if kind == "yolo" else (2, 128.0)
    xs = np.broadcast_to(np.arange(w, dtype=np.float32), (1, 1, h, w))  # pixel x of each input pixel
    ys = np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (1, 1, h, w))
    init = [numpy_helper.from_array(np.ascontiguousarray(a), n) for a, n in [
        (xs, "xs"), (ys, "ys"), (np.array(t, np.float32), "t"), (np.array([red], np.int64), "r0"),
        (np.array([red + 1], np.int64), "r1"), (np.array([1], np.int64), "g0"), (np.array([2], np.int64), "g1"),
        (np.array([1], np.int64), "ax1"), (np.array([0], np.int64), "ax0"),
        (np.array([10.0], np.float32), "half"), (np.array([20.0], np.float32), "size"), (np.array([0.9], np.float32), "score"),
        (np.array([17], np.int64), "reps"),
    ]]
    nodes = [
        helper.make_node("Slice", ["images", "r0", "r1", "ax1"], ["R"]),  # (1, 1, H, W)
        helper.make_node("Slice", ["images", "g0", "g1", "ax1"], ["G"]),
        helper.make_node("Sub", ["R", "G"], ["RG"]),
        helper.make_node("Sub", ["RG", "t"], ["RGt"]),
        helper.make_node("Relu", ["RGt"], ["F"]),
        helper.make_node("ReduceSum", ["F"], ["S"], keepdims=0),  # scalar
        helper.make_node("Mul", ["F", "xs"], ["FX"]),
        helper.make_node("Mul", ["F", "ys"], ["FY"]),
        helper.make_node("ReduceSum", ["FX"], ["SX"], keepdims=0),
        helper.make_node("ReduceSum", ["FY"], ["SY"], keepdims=0),
        helper.make_node("Div", ["SX", "S"], ["cx0"]),
        helper.make_node("Div", ["SY", "S"], ["cy0"]),
        helper.make_node("Unsqueeze", ["cx0", "ax0"], ["cx"]),  # (1,)
        helper.make_node("Unsqueeze", ["cy0", "ax0"], ["cy"]),
        helper.make_node("Concat", ["cx", "cy", "score"], ["kp"], axis=0),  # (3,)
        helper.make_node("Tile", ["kp", "reps"], ["kps"]),  # (51,)
    ]
    if kind == "yolo":
        nodes += [
            helper.make_node("Concat", ["cx", "cy", "size", "size", "score", "kps"], ["row"], axis=0),  # (56,)
            helper.make_node("Reshape", ["row", "shape"], ["output0"]),
        ]
        init.append(numpy_helper.from_array(np.array([1, 56, 1], np.int64), "shape"))
        outs = [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 56, 1])]
    else:
        nodes += [
            helper.make_node("Sub", ["cx", "half"], ["x0"]), helper.make_node("Sub", ["cy", "half"], ["y0"]),
            helper.make_node("Add", ["cx", "half"], ["x1"]), helper.make_node("Add", ["cy", "half"], ["y1"]),
            helper.make_node("Concat", ["x0", "y0", "x1", "y1", "score"], ["det"], axis=0),  # (5,)
            helper.make_node("Reshape", ["det", "dshape"], ["dets"]),
            helper.make_node("Reshape", ["kps", "kshape"], ["keypoints"]),
        ]
        init += [numpy_helper.from_array(np.array([1, 1, 5], np.int64), "dshape"),
                 numpy_helper.from_array(np.array([1, 1, 17, 3], np.int64), "kshape")]
        outs = [helper.make_tensor_value_info("dets", TensorProto.FLOAT, [1, 1, 5]),
                helper.make_tensor_value_info("keypoints", TensorProto.FLOAT, [1, 1, 17, 3])]
    return _save(tmp_path, name, nodes, [_image_input(w, h)], outs, init)


def _patches(w: int, h: int, red_xy: tuple[int, int], blue_xy: tuple[int, int], size: int = 40) -> np.ndarray:
    """A dark BGR image with a pure red and a pure blue square; returns the image."""
    image = np.full((h, w, 3), 30, np.uint8)
    (rx, ry), (bx, by) = red_xy, blue_xy
    image[ry:ry + size, rx:rx + size] = (0, 0, 255)  # BGR red
    image[by:by + size, bx:bx + size] = (255, 0, 0)  # BGR blue
    return image


# (image size, network input size): same scale, shrink, grow, different aspect ratios
SIZES = [((640, 480), (640, 640)), ((1280, 720), (640, 640)), ((320, 240), (640, 384)), ((480, 640), (512, 288))]


@pytest.mark.parametrize("image_size,net_size", SIZES)
@pytest.mark.parametrize("kind", ["yolo", "rtmo"])
def test_detector_finds_the_red_patch_through_letterbox_and_colour_order(tmp_path, kind, image_size, net_size):
    (w, h), (nw, nh) = image_size, net_size
    path = red_centroid_model(tmp_path, f"{kind}-red", nw, nh, kind=kind)
    det = YoloPose(path) if kind == "yolo" else Rtmo(path)
    assert det.size == (nw, nh)
    size = max(8, min(w, h) // 8)
    red, blue = (w // 5, h // 4), (w * 3 // 5, h * 3 // 5)
    image = _patches(w, h, red, blue, size)
    kps, boxes = det.detect(image)
    assert kps.shape == (1, NUM_KEYPOINTS, 3) and boxes.shape == (1, 4)
    # The centroid of the red square, in pixel-index coordinates of the original image.
    centre = np.array([red[0] + (size - 1) / 2, red[1] + (size - 1) / 2])
    # Resampling moves a centroid by at most half an original pixel (plus a net pixel when growing).
    tol = 0.5 + 1.0 / min(nw / w, nh / h)
    assert np.allclose(kps[0, :, :2], centre, atol=tol), (kps[0, 0], centre)
    assert np.allclose(kps[0, :, 2], 0.9)
    scale = min(nw / w, nh / h)
    half = 10 / scale  # the network's 20 px box, in original pixels
    assert np.allclose(boxes[0], [centre[0] - half, centre[1] - half, centre[0] + half, centre[1] + half], atol=tol)
    # And the swapped image (red and blue exchanged) moves the person to the other patch.
    kps2, _ = det.detect(image[:, :, ::-1].copy())
    centre2 = np.array([blue[0] + (size - 1) / 2, blue[1] + (size - 1) / 2])
    assert np.allclose(kps2[0, 0, :2], centre2, atol=tol)
    det.close()


def _yolo_columns(people: list[tuple[tuple[float, float, float, float], float, np.ndarray]]) -> np.ndarray:
    """(1, 56, N) from (box cx, cy, w, h), score and (17, 3) keypoints per candidate."""
    cols = [np.concatenate([np.asarray(box, np.float32), [score], kp.ravel()]) for box, score, kp in people]
    return np.stack(cols, axis=1)[None].astype(np.float32)


def _kps(x: float, y: float, score: float = 0.9) -> np.ndarray:
    kp = np.zeros((NUM_KEYPOINTS, 3), np.float32)
    kp[:, 0] = x + np.arange(NUM_KEYPOINTS)  # joint j at (x + j, y + 2 j)
    kp[:, 1] = y + 2 * np.arange(NUM_KEYPOINTS)
    kp[:, 2] = score
    return kp


def test_yolo_pose_decodes_a_known_output(tmp_path):
    """A 640 x 480 image in a 640 x 640 input: 80 px of padding above; two people, a duplicate, a low score."""
    a, b = _kps(100, 200), _kps(400, 150)
    a[5, 2] = 0.3  # left shoulder not visible
    out = _yolo_columns([
        ((150, 300, 100, 200), 0.92, a),  # person A
        ((450, 300, 120, 260), 0.85, b),  # person B
        ((152, 302, 100, 200), 0.60, _kps(0, 0)),  # A again, weaker: suppressed
        ((300, 300, 50, 50), 0.10, _kps(0, 0)),  # below the score threshold
    ])
    path = constant_model(tmp_path, "yolo-known", 640, 640, {"output0": out})
    kps, boxes = YoloPose(path).detect(np.zeros((480, 640, 3), np.uint8))
    assert kps.shape == (2, NUM_KEYPOINTS, 3)
    assert np.allclose(boxes, [[100, 120, 200, 320], [390, 90, 510, 350]])  # y - 80
    expected_a = a.copy()
    expected_a[:, 1] -= 80
    expected_a[5] = np.nan
    assert np.allclose(kps[0], expected_a, equal_nan=True)
    assert np.allclose(kps[1, :, :2], b[:, :2] - [0, 80]) and np.allclose(kps[1, :, 2], 0.9)
    # The pure decoder on the same tensor agrees with the detector.
    k2, b2 = decode_yolo_pose(out, Letterbox(1.0, 0.0, 80.0), 640, 480)
    assert np.array_equal(k2, kps, equal_nan=True) and np.array_equal(b2, boxes)


def test_rtmo_decodes_a_known_output(tmp_path):
    """A 1280 x 960 image in a 640 x 640 input, top-left placed at half scale (no offset)."""
    a, b = _kps(100, 100), _kps(300, 200)
    b[0, 2] = 0.1  # nose not visible
    dets = np.array([[[50, 60, 150, 300, 0.95], [280, 180, 400, 420, 0.7], [52, 62, 150, 300, 0.5], [0, 0, 5, 5, 0.2]]], np.float32)
    keypoints = np.stack([a, b, _kps(0, 0), _kps(0, 0)])[None]
    path = constant_model(tmp_path, "rtmo-known", 640, 640, {"dets": dets, "keypoints": keypoints})
    kps, boxes = Rtmo(path).detect(np.zeros((960, 1280, 3), np.uint8))
    assert np.allclose(boxes, [[100, 120, 300, 600], [560, 360, 800, 840]])  # x 2
    assert np.allclose(kps[0, :, :2], a[:, :2] * 2)
    assert np.isnan(kps[1, 0]).all() and np.allclose(kps[1, 1:, :2], b[1:, :2] * 2)
    k2, b2 = decode_rtmo(dets, keypoints, Letterbox(0.5, 0.0, 0.0), 1280, 960)
    assert np.array_equal(k2, kps, equal_nan=True) and np.array_equal(b2, boxes)


def test_models_with_the_wrong_layout_are_refused_with_the_expected_one(tmp_path):
    wrong = constant_model(tmp_path, "det-only", 640, 640, {"output0": np.zeros((1, 84, 10), np.float32)})
    with pytest.raises(DetectorError, match=r"not a YOLO-pose export: expected one output of shape \(1, 56, N\)"):
        YoloPose(wrong)
    with pytest.raises(DetectorError, match=r"not an RTMO export: expected outputs dets \(1, N, 5\) and keypoints"):
        Rtmo(wrong)
    with pytest.raises(DetectorError, match="does not exist"):
        open_detector(parse_detector(f"yolo-pose:{tmp_path / 'missing.onnx'}"))
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(DetectorError, match="cannot load ONNX model"):
        open_detector(parse_detector(f"rtmo:{junk}"))
