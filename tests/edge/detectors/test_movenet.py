"""MoveNet MultiPose: spec parsing, the input-size rule and the output decoding on tables, then the
real converted model (``make movenet``) under onnxruntime on OpenCV's real sample media
(``make media``), alone and inside an ``edge run`` node publishing over Zenoh on loopback.

The pedestrians of vtest.avi were counted by eye on the frames below and a box drawn around each
one that is clearly visible (boxes first proposed by MoveNet at the video's full 768 x 576, then
checked one by one on the frames and kept only where they fit the person). Partly hidden people
(behind the sign in frames 50 and 550) are not counted, and may or may not be found. No frame
below has more than six, MoveNet's limit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from superbody.edge.body import INDEX, NUM_KEYPOINTS
from superbody.edge.detectors import DetectorSpec, open_detector, parse_detector
from superbody.edge.detectors.base import DetectorError, Letterbox
from superbody.edge.detectors.movenet import (
    COLUMNS,
    DEFAULT_SHORT_SIDE,
    PERSON_INPUT_PX,
    MoveNet,
    decode_movenet,
    default_model_path,
    network_size,
    person_in_image,
    short_side_for,
)
from tests.conftest import LAB_SITE, free_port
from tests.edge.test_node import Listener
from tests.media import VTEST_SIZE, image, media_path, movenet_model, vtest_frames

# frame -> (x0, y0, x1, y1) of each clearly visible pedestrian, in vtest.avi's pixels
VTEST_PEOPLE = {
    0: [(638, 240, 685, 322), (498, 157, 529, 233), (253, 219, 284, 308)],
    50: [(667, 256, 714, 371), (552, 213, 588, 303), (504, 216, 541, 310), (374, 180, 401, 259), (434, 176, 456, 246)],
    400: [(687, 300, 744, 411), (273, 200, 302, 285), (588, 140, 617, 205)],
    550: [(168, 368, 226, 513), (234, 374, 289, 511), (641, 303, 671, 412), (122, 166, 155, 232), (595, 166, 630, 243)],
    600: [(454, 303, 505, 419), (282, 432, 331, 575), (568, 199, 596, 288), (641, 304, 672, 412), (188, 144, 215, 215),
          (669, 207, 705, 296)],
}
PARTLY_HIDDEN = {50: 1, 550: 1}  # people beside or behind the sign, not counted above
STABLE = range(400, 450)  # 5 s: three walkers, one leaves on the right (~404), another comes in (~421)
STABLE_COUNTS = (2, 3)

# Joints marked by eye on the photos before the detector ran (left and right are the person's own).
BASKETBALL_LEFT_PLAYER = {"nose": (87, 123), "right_shoulder": (47, 157), "left_shoulder": (117, 150), "right_hip": (57, 283),
                          "left_hip": (113, 283), "right_knee": (67, 373), "left_knee": (117, 373), "right_ankle": (67, 460),
                          "left_ankle": (123, 453)}
MESSI = {"nose": (243, 107), "right_shoulder": (177, 123), "left_shoulder": (290, 127), "right_hip": (237, 247),
         "left_hip": (307, 227), "right_knee": (227, 283)}
TOLERANCE_PX = 30.0  # as for BlazePose on the astronaut photo


# -- parsing and the input size ------------------------------------------------------------------

# (text, expected spec)
GOOD_SPECS = [
    ("movenet", DetectorSpec("movenet")),  # the model `make movenet` converted
    ("movenet@384", DetectorSpec("movenet", None, 384)),  # a larger input for far people
    ("movenet:/m/movenet.onnx", DetectorSpec("movenet", Path("/m/movenet.onnx"))),  # another file
    ("movenet:/m/movenet.onnx@192", DetectorSpec("movenet", Path("/m/movenet.onnx"), 192)),
    ("movenet:/m/v@2.onnx", DetectorSpec("movenet", Path("/m/v@2.onnx"))),  # an '@' without digits after it is the path's
]


@pytest.mark.parametrize("text,spec", GOOD_SPECS)
def test_parse_movenet(text, spec):
    assert parse_detector(text) == spec
    assert str(parse_detector(text)) == text


# (text, fragment of the error)
BAD_SPECS = [
    ("movenet@300", "multiple of 32 in [96, 1024], got '300'"),
    ("movenet@64", "multiple of 32 in [96, 1024], got '64'"),
    ("movenet@", "got ''"),
    ("movenet:", "expected movenet, movenet:PATH.onnx, movenet@SHORT or movenet:PATH.onnx@SHORT"),
    ("movenet:@256", "expected movenet"),
    ("movenets", "must be one of"),
]


@pytest.mark.parametrize("text,fragment", BAD_SPECS)
def test_parse_movenet_rejects(text, fragment):
    with pytest.raises(ValueError) as e:
        parse_detector(text)
    assert fragment in str(e.value)


# (image width, height, short side, expected network (width, height))
SIZES = [
    (768, 576, 256, (352, 256)),  # vtest.avi, 4:3: 341 x 256 padded to 352
    (640, 480, 256, (352, 256)),
    (1280, 720, 256, (480, 256)),  # 16:9: 455 x 256 padded to 480
    (480, 640, 256, (256, 352)),  # portrait
    (548, 342, 256, (416, 256)),  # messi5.jpg
    (768, 576, 384, (512, 384)),  # movenet@384
    (768, 576, 576, (768, 576)),  # the full image
    (320, 240, 256, (352, 256)),  # a small image grows to the same input
    (4000, 10, 96, (38400, 96)),  # absurd aspect ratios stay multiples of 32
]


@pytest.mark.parametrize("w,h,short,expected", SIZES)
def test_network_size(w, h, short, expected):
    size = network_size(w, h, short)
    assert size == expected and all(s % 32 == 0 for s in size)


# -- decoding ------------------------------------------------------------------------------------


def _row(y, x, score, box, kp_score=0.9):
    """One output row: every joint at (y, x) normalised, then the box and the person score."""
    row = np.zeros(COLUMNS, np.float32)
    row[: 3 * NUM_KEYPOINTS] = np.tile([y, x, kp_score], NUM_KEYPOINTS)
    row[3 * NUM_KEYPOINTS:] = [*box, score]
    return row


def test_decode_maps_normalised_yx_to_image_pixels():
    # A 768 x 576 image letterboxed into 352 x 256 at the top-left: scale 256 / 576.
    placement = Letterbox(256 / 576, 0.0, 0.0)
    out = np.stack([
        _row(0.5, 0.25, 0.6, (0.25, 0.125, 0.75, 0.375)),  # a person
        _row(0.5, 0.75, 0.1, (0.25, 0.625, 0.75, 0.875)),  # person score below the threshold: dropped
        np.zeros(COLUMNS, np.float32),  # rows the network leaves empty
    ])[None]
    out[0, 0, 3 * INDEX["left_wrist"] + 2] = 0.2  # a joint below the keypoint threshold: missing
    kp, boxes = decode_movenet(out, placement, (352, 256), 768, 576, score_threshold=0.15, keypoint_threshold=0.3)
    assert kp.shape == (1, NUM_KEYPOINTS, 3) and boxes.shape == (1, 4) and kp.dtype == boxes.dtype == np.float32
    s = 576 / 256
    np.testing.assert_allclose(kp[0, INDEX["nose"]], [0.25 * 352 * s, 0.5 * 256 * s, 0.9], rtol=1e-5)
    np.testing.assert_allclose(boxes[0], [0.125 * 352 * s, 0.25 * 256 * s, 0.375 * 352 * s, 0.75 * 256 * s], rtol=1e-5)
    assert np.isnan(kp[0, INDEX["left_wrist"]]).all()
    # Joints in the padding (right of x = 341 in the input) are outside the image: missing.
    out2 = _row(0.5, 0.99, 0.6, (0.25, 0.9, 0.75, 1.0))[None, None]
    kp2, boxes2 = decode_movenet(out2, placement, (352, 256), 768, 576)
    assert np.isnan(kp2[0, :, 0]).all() and boxes2[0, 2] == 768  # box clipped to the image


def test_decode_nobody_and_wrong_shapes():
    kp, boxes = decode_movenet(np.zeros((1, 6, COLUMNS), np.float32), Letterbox(1.0, 0, 0), (256, 256), 256, 256)
    assert kp.shape == (0, NUM_KEYPOINTS, 3) and boxes.shape == (0, 4)
    with pytest.raises(DetectorError, match=r"\(1, N, 56\)"):
        decode_movenet(np.zeros((1, 6, 51)), Letterbox(1.0, 0, 0), (256, 256), 256, 256)


# -- errors before the model runs ------------------------------------------------------------------


def test_missing_model_says_to_run_make_movenet(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert default_model_path() == tmp_path / "superbody" / "movenet" / "movenet-multipose.onnx"
    with pytest.raises(DetectorError, match="make movenet") as e:
        open_detector(parse_detector("movenet"))
    assert str(tmp_path / "superbody" / "movenet" / "movenet-multipose.onnx") in str(e.value)
    with pytest.raises(DetectorError, match=r"'/no/such\.onnx' not found: run `make movenet`"):
        open_detector(parse_detector("movenet:/no/such.onnx"))


def test_a_model_of_another_layout_is_refused(tmp_path):
    from onnx import TensorProto, helper

    # A float image in, a (1, 6, 51) tensor out: neither is MoveNet's.
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 256, 256, 3])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 6, 51])
    shape = helper.make_node("Constant", [], ["s"], value=helper.make_tensor("s", TensorProto.INT64, [3], [1, 6, 51]))
    fill = helper.make_node("ConstantOfShape", ["s"], ["y"], value=helper.make_tensor("v", TensorProto.FLOAT, [1], [0.0]))
    path = tmp_path / "other.onnx"
    path.write_bytes(helper.make_model(helper.make_graph([shape, fill], "other", [x], [y]),
                                       opset_imports=[helper.make_opsetid("", 17)]).SerializeToString())
    with pytest.raises(DetectorError, match="not a MoveNet MultiPose model"):
        MoveNet(path)
    with pytest.raises(DetectorError, match=r"multiple of 32 in \[96, 1024\], got 100"):
        MoveNet(path, short_side=100)


# -- the real model on real media ------------------------------------------------------------------


@pytest.fixture(scope="module")
def movenet():
    det = MoveNet(movenet_model())
    yield det
    det.close()


def _iou(a, b) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def _inside(kp, box, margin: float) -> np.ndarray:
    """(J,) whether each visible joint lies in ``box`` grown by ``margin`` of its size on each side."""
    x0, y0, x1, y1 = box
    mx, my = margin * (x1 - x0), margin * (y1 - y0)
    u, v = kp[:, 0], kp[:, 1]
    return (u >= x0 - mx) & (u <= x1 + mx) & (v >= y0 - my) & (v <= y1 + my)


def test_every_clearly_visible_pedestrian_is_found_with_joints_in_the_body(movenet):
    frames = vtest_frames(list(VTEST_PEOPLE) + list(STABLE))
    for i, people in VTEST_PEOPLE.items():
        kp, boxes = movenet.detect(frames[i])
        assert kp.shape == (len(boxes), NUM_KEYPOINTS, 3)
        assert len(people) <= len(boxes) <= len(people) + PARTLY_HIDDEN.get(i, 0), (i, boxes.round())
        unused = set(range(len(boxes)))
        for truth in people:
            j = max(unused, key=lambda j: _iou(truth, boxes[j]), default=None)
            assert j is not None and _iou(truth, boxes[j]) >= 0.5, (i, truth, boxes.round())
            unused.discard(j)
            seen = kp[j][~np.isnan(kp[j, :, 0])]
            assert len(seen) >= 10, (i, truth, len(seen))  # most joints of a clearly visible walker
            assert _inside(seen, truth, 0.15).all(), (i, truth, seen.round())  # on the body, not a neighbour
            assert _inside(seen, boxes[j], 0.15).all(), (i, boxes[j], seen.round())  # and in the box sent with them
            assert (seen[:, 2] > 0).all() and (seen[:, 2] <= 1).all()


def test_people_found_are_stable_from_frame_to_frame(movenet):
    frames = vtest_frames(list(VTEST_PEOPLE) + list(STABLE))
    found = [movenet.detect(frames[i])[1] for i in STABLE]
    counts = [len(b) for b in found]
    assert set(counts) <= set(STABLE_COUNTS), counts  # nobody invented, nobody lost
    assert sum(a != b for a, b in zip(counts, counts[1:])) <= 4, counts  # the walker leaving and the one coming
    # Nearly every person found is found again in the next frame where they were (0.1 s later).
    again = sum(max((_iou(a, b) for b in nxt), default=0.0) >= 0.5 for cur, nxt in zip(found, found[1:]) for a in cur)
    assert again >= 0.9 * sum(len(cur) for cur in found[:-1]), (again, counts)


def test_two_players_close_up(movenet):
    kp, boxes = movenet.detect(image("basketball1.png"))
    assert len(boxes) == 2, boxes.round()
    left, right = np.argsort(boxes[:, 0])
    for name, xy in BASKETBALL_LEFT_PLAYER.items():
        u, v, score = kp[left, INDEX[name]]
        assert np.hypot(u - xy[0], v - xy[1]) <= TOLERANCE_PX, (name, (u, v), xy)
        assert 0.3 <= score <= 1.0
    # The right player: cut by the image's right edge, seen from the side, from the hips up.
    assert boxes[right, 0] > 400 and _inside(kp[right][~np.isnan(kp[right, :, 0])], (430, 0, 640, 480), 0.0).all()
    assert not np.isnan(kp[right, INDEX["nose"]]).any()


def test_one_player_mid_kick(movenet):
    kp, boxes = movenet.detect(image("messi5.jpg"))
    assert len(boxes) == 1, boxes.round()  # the blurred crowd behind him is nobody
    for name, xy in MESSI.items():
        u, v, _ = kp[0, INDEX[name]]
        assert np.hypot(u - xy[0], v - xy[1]) <= TOLERANCE_PX, (name, (u, v), xy)


def test_a_larger_input_still_finds_the_walkers(movenet):
    """``movenet@384``: 512 x 384 for vtest.avi, the same people (with more pixels each)."""
    big = MoveNet(movenet.path, short_side=384)
    try:
        for i, people in VTEST_PEOPLE.items():
            _, boxes = big.detect(vtest_frames(list(VTEST_PEOPLE) + list(STABLE))[i])
            assert all(max(_iou(t, b) for b in boxes) >= 0.5 for t in people), i
        # Nobody in a plain grey image.
        kp, boxes = big.detect(np.full((576, 768, 3), 128, np.uint8))
        assert kp.shape == (0, NUM_KEYPOINTS, 3) and boxes.shape == (0, 4)
    finally:
        big.close()
    with pytest.raises(DetectorError, match="after close"):
        big.detect(np.zeros((576, 768, 3), np.uint8))


# -- the input size from the site -------------------------------------------------------------------


def _hall_camera(f: float) -> tuple:
    """A 640 x 480 camera 3 m up on the short wall of a 16 x 12 m hall, aimed at its middle; the hall's floor."""
    from superbody.edge.camera import Camera, look_at_rotation

    pos, target = np.array([0.1, 6.0, 3.0]), np.array([8.0, 6.0, 1.0])
    R = look_at_rotation(pos, target)
    cam = Camera(id="hall", width=640, height=480, fps=15.0, fx=f, fy=f, cx=320.0, cy=240.0, position=tuple(pos),
                 rotation=tuple(tuple(float(v) for v in row) for row in R))
    return cam, ((0.0, 0.0), (16.0, 0.0), (16.0, 12.0), (0.0, 12.0))


def test_the_input_size_is_the_default_where_people_are_large_enough():
    from superbody.edge.resources import site_path
    from superbody.edge.site import load_site

    for site in (load_site(LAB_SITE), load_site(site_path("wtf-apartment"))):
        for cam in site.cameras:
            choice = short_side_for(cam, site.floor)
            assert choice is not None and choice.short_side == DEFAULT_SHORT_SIDE and choice.share > 0.98, (site.name, cam.id, choice)


@pytest.mark.parametrize("f", [500.0, 400.0])
def test_far_people_get_a_larger_input(f):
    # At the default size the far end of the hall's people are under 32 px tall in the input
    # (lost); the chosen size brings them back: the smallest that does.
    cam, floor = _hall_camera(f)
    choice = short_side_for(cam, floor)
    assert choice is not None
    smallest = choice.person_px[0] / min(cam.width, cam.height)
    assert smallest * DEFAULT_SHORT_SIDE < PERSON_INPUT_PX[0]
    assert choice.short_side > DEFAULT_SHORT_SIDE and choice.share > 0.98
    # The smallest input that gets there (within the 2% of the floor it may leave for speed).
    assert smallest * (choice.short_side - 32) < PERSON_INPUT_PX[0]


def test_a_camera_that_sees_no_floor_gets_no_size():
    cam, _ = _hall_camera(600.0)
    assert short_side_for(cam, ((-9.0, 0.0), (-8.0, 0.0), (-8.0, 1.0), (-9.0, 1.0))) is None  # behind the camera


def _hd_camera(position, target, up=None) -> object:
    """A 1920 x 1080 camera with a wide lens (f = 576 px: 118 degrees across) at ``position`` aimed at ``target``."""
    from superbody.edge.camera import Camera, look_at_rotation

    R = look_at_rotation(np.array(position), np.array(target), None if up is None else np.array(up))
    return Camera(id="c", width=1920, height=1080, fps=15.0, fx=576.0, fy=576.0, cx=960.0, cy=540.0, position=tuple(position),
                  rotation=tuple(tuple(float(v) for v in row) for row in R))


# A 9 x 7 m room whose floor polygon reaches all round the cameras (under and behind them).
ROOM = ((-1.0, -1.0), (8.0, -1.0), (8.0, 6.0), (-1.0, 6.0))
SIZED_CAMERAS = [
    # a ceiling camera looking straight down over a floor grid point (0.1 m cells centred at -0.95 + 0.1 k):
    # the person under it is a dot, and those beside it lie across the image's rows
    _hd_camera((3.05, 2.55, 2.8), (3.05, 2.5501, 0.0), up=(1.0, 0.0, 0.0)),
    # a camera in a corner of the ceiling, looking steeply down into the room
    _hd_camera((7.9, 5.9, 2.8), (6.0, 4.5, 0.0)),
    # a camera 2.8 m up on the west wall, steeply down (its lens sees under it); the floor reaches under it
    _hd_camera((-0.9, 2.5, 2.8), (0.5, 2.5, 0.0)),
]


@pytest.mark.parametrize("cam", SIZED_CAMERAS, ids=["ceiling", "ceiling-corner", "wall"])
def test_the_person_sizes_reported_are_those_of_people_seen_whole(cam):
    # Before: rows only, over every floor point with a torso in view: 0 px under the ceiling
    # camera, 6 px in the corner one's, 19 px for the heads at the wall camera's bottom edge. Now a person's length in the
    # image in any direction, over the people seen whole, 5th-95th percentile.
    from superbody.edge.camera import project
    from superbody.edge.floor import MIN_PERSON_PX, PERSON_HEIGHT_M, floor_points, seen_by

    choice = short_side_for(cam, ROOM)
    assert choice is not None and 0 < choice.whole < 1
    low, high = choice.person_px
    assert MIN_PERSON_PX < low < high <= np.hypot(cam.width, cam.height), choice
    # Most of the people seen whole are within the range: a person standing where the
    # camera sees them whole has feet and head in the image, and that is the length reported.
    xy = floor_points(ROOM, 0.1)
    xy = xy[seen_by(cam, xy)]
    feet, zf = project(np.column_stack([xy, np.zeros(len(xy))]), cam)
    head, zh = project(np.column_stack([xy, np.full(len(xy), PERSON_HEIGHT_M)]), cam)
    whole = (zf > 0.1) & (zh > 0.1) & np.all((feet >= 0) & (feet <= [cam.width, cam.height]) & (head >= 0) & (head <= [cam.width, cam.height]), axis=1)
    straight = np.linalg.norm(head - feet, axis=1)[whole]  # the body is nearly straight in the image: distortion is small here
    assert np.mean((straight >= low - 1) & (straight <= high + 1)) >= 0.85
    # a camera high above people's heads finds them at the default input size
    assert choice.short_side == DEFAULT_SHORT_SIDE and choice.share > 0.95


# (camera, floor point, what is expected)
PERSON_IN_IMAGE = [
    # straight down, a person 1 m to the side along the image's rows: 0 rows, but hundreds of columns
    (SIZED_CAMERAS[0], (3.05, 3.55), "across"),
    # under the ceiling camera: a dot
    (SIZED_CAMERAS[0], (3.05, 2.55), "dot"),
    # 2.9 m in front of the wall camera: whole
    (SIZED_CAMERAS[2], (2.0, 2.5), "whole"),
    # 3.9 m in front of it: the head above the image's top edge, the rest in view
    (SIZED_CAMERAS[2], (3.0, 2.5), "part"),
    # 0.6 m behind it (behind its wall): the head at the image's bottom edge
    (SIZED_CAMERAS[2], (-1.5, 2.5), "part"),
    # 1.1 m behind it: nothing in the image
    (SIZED_CAMERAS[2], (-2.0, 2.5), "unseen"),
]


@pytest.mark.parametrize("cam,point,expected", PERSON_IN_IMAGE)
def test_a_persons_length_in_the_image(cam, point, expected):
    from superbody.edge.camera import project
    from superbody.edge.floor import PERSON_HEIGHT_M

    length, whole = person_in_image(cam, np.array([point]))
    (feet, head), _ = project(np.array([[*point, 0.0], [*point, PERSON_HEIGHT_M]]), cam)
    if expected == "across":
        assert abs(head[1] - feet[1]) < 1 and whole[0]
        assert length[0] == pytest.approx(abs(head[0] - feet[0]), rel=1e-6) and length[0] > 200
    elif expected == "dot":
        assert length[0] < 1 and whole[0]
    elif expected == "whole":
        assert whole[0] and length[0] == pytest.approx(np.linalg.norm(head - feet), rel=1e-3)
    elif expected == "part":
        assert not whole[0] and 0 < length[0] < cam.height
    else:
        assert length[0] == 0 and not whole[0]


def test_the_node_sizes_movenet_for_its_camera_unless_told():
    import dataclasses

    from superbody.edge.cli import _sized_for_site
    from superbody.edge.site import load_site

    cam, floor = _hall_camera(400.0)
    site = dataclasses.replace(load_site(LAB_SITE), cameras=(cam,), floor=floor)
    chosen = _sized_for_site(parse_detector("movenet"), site, "hall")
    assert chosen.size == short_side_for(cam, floor).short_side > DEFAULT_SHORT_SIDE
    assert _sized_for_site(parse_detector("movenet@320"), site, "hall").size == 320
    assert _sized_for_site(parse_detector("blazepose"), site, "hall") == parse_detector("blazepose")


# -- a camera node on vtest.avi ----------------------------------------------------------------------


def _vtest_site(tmp_path) -> Path:
    """The lab's site with its cameras at vtest.avi's size."""
    w, h = VTEST_SIZE
    site = tmp_path / "vtest.toml"
    site.write_text(LAB_SITE.read_text().replace("width = 1280", f"width = {w}").replace("height = 720", f"height = {h}")
                    .replace("cx = 640.0", f"cx = {w / 2}").replace("cy = 360.0", f"cy = {h / 2}"))
    return site


def test_node_without_the_model_says_to_run_make_movenet(capsys, tmp_path):
    from superbody.edge.cli import main

    code = main(["edge", "run", "--site", str(_vtest_site(tmp_path)), "--camera", "nw", "--source", f"video:{media_path('vtest.avi')}",
                 "--detector", f"movenet:{tmp_path / 'none.onnx'}"])
    err = capsys.readouterr().err
    assert code == 2 and "superbody edge run: error: --detector movenet:" in err and "run `make movenet`" in err, err


def test_video_node_publishes_the_walkers(processes, tmp_path):
    """``superbody edge run --source video:vtest.avi --detector movenet`` as a process, in real
    time, to a subscriber on loopback: frames 0-11 hold three clearly visible walkers."""
    movenet_model()
    site = _vtest_site(tmp_path)
    port = free_port()
    listener = Listener(port)
    try:
        node = processes.start("edge", "run", "--site", str(site), "--camera", "nw", "--source", f"video:{media_path('vtest.avi')}",
                               "--detector", "movenet", "--connect", f"tcp/127.0.0.1:{port}")
        got = listener.received["nw"]
        assert listener.wait_for(lambda: len(got) >= 8 or node.poll() is not None, timeout=30), (len(got), node.poll())
        assert node.poll() is None, node.stderr.read() if node.stderr else ""
        assert not listener.errors
        obs = [o for _, o in list(got)]
        first = obs[0].stamp_ns
        # Frames 0-11 (10 fps; in real time a slow node skips some, as a live camera would).
        early = [o for o in obs if round((o.stamp_ns - first) * 10 / 1e9) <= 11]
        assert len(early) >= 3, [(o.seq, o.stamp_ns - first) for o in obs]
        for o in early:
            assert (o.width, o.height) == VTEST_SIZE
            assert len(o.people) == 3, (o.seq, [p.bbox.round() for p in o.people])
            for p in o.people:
                seen = p.keypoints[~np.isnan(p.keypoints[:, 0])]
                assert len(seen) >= 10 and _inside(seen, p.bbox, 0.15).all(), (o.seq, p.bbox, seen)
                assert abs(float(p.histogram.sum()) - 1.0) < 1e-3  # each person's colour signature, from their box
    finally:
        listener.close()
