"""The OAK source without a device: the real depthai host nodes on synthetic device output.

What is real: depthai's ``DetectionParser`` configured from a YOLOv8-pose NN archive (the
same call the on-device ``DetectionNetwork`` makes), its ``SpatialLocationCalculator`` with
spatial keypoints, its queues and message types, and all of ``OakSource``. What is faked (we
have no OAK here): the camera, the network and the stereo depth, as one host node
(``FakeDevice``) that emits, for each frame it is given, the raw YOLOv8-pose head tensors of
the people scripted for that frame, the frame itself (the NN's passthrough) and a depth map.

The tensors follow what depthai 3.12's parser decodes (checked by hand): three "yolo" heads of
(6, H, W) for strides 8, 16, 32 holding (left, top, right, bottom) distances in stride units
from the cell centre, then objectness and the class score; and "kpt_output" heads of
(51, 2, H * W) holding (u, v) in pixels and the visibility logit per joint in row 0 (a second
row because ``NNData.addTensor`` gives a leading size-1 dimension a zero stride that the
parser refuses).
"""

from __future__ import annotations

import datetime
import io
import json
import logging
import os
import tarfile
import threading
import time

os.environ.setdefault("DEPTHAI_SEARCH_TIMEOUT", "1000")  # before depthai is imported

import depthai as dai  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from superbody.edge.messages.observation import Observation  # noqa: E402
from superbody.edge.messages.wire import decode, encode  # noqa: E402
from superbody.edge.site import parse_site  # noqa: E402
from superbody.edge.sources import oak  # noqa: E402
from superbody.edge.sources.source import SourceError  # noqa: E402

W, H = 512, 288  # the zoo model's NN frame
STRIDES = (8, 16, 32)
K = np.array([[402.5, 0.0, 257.0], [0.0, 401.0, 141.5], [0.0, 0.0, 1.0]])  # the "device calibration"
DIST = [0.05, -0.1, 0.001, -0.002, 0.02] + [0.0] * 9  # 14 coefficients, as depthai gives them


def _site(width=W, height=H, fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2]):
    return parse_site({
        "site": {"name": "oak-test"},
        "floor": {"polygon": [[-3.0, -3.0], [3.0, -3.0], [3.0, 3.0], [-3.0, 3.0]]},
        "cameras": [{
            "id": "front", "width": width, "height": height, "fps": 10.0, "fx": fx, "fy": fy, "cx": cx, "cy": cy,
            "position": [0.0, -3.0, 2.0], "look_at": [0.0, 0.0, 1.0],
        }],
    })


def _write_archive(path, width=W, height=H, n_keypoints=17):
    """An NN archive with the zoo YOLOv8-pose model's head; the model file is a placeholder."""
    grids = [(height // s, width // s) for s in STRIDES]
    yolo = [f"output{i + 1}_yolov8" for i in range(3)]
    kpts = [f"kpt_output{i + 1}" for i in range(3)]
    config = {
        "config_version": "1.0",
        "model": {
            "metadata": {"name": "yolov8-pose-test", "path": "model.onnx", "precision": "float32"},
            "inputs": [{
                "name": "images", "dtype": "float32", "input_type": "image", "shape": [1, 3, height, width], "layout": "NCHW",
                "preprocessing": {"mean": [0, 0, 0], "scale": [255, 255, 255], "reverse_channels": True,
                                  "interleaved_to_planar": False, "dai_type": "RGB888p"},
            }],
            "outputs": [{"name": n, "dtype": "float32", "shape": [1, 6, h, w], "layout": "NCHW"} for n, (h, w) in zip(yolo, grids)]
            + [{"name": n, "dtype": "float32", "shape": [1, 3 * n_keypoints, h * w], "layout": "NCD"} for n, (h, w) in zip(kpts, grids)],
            "heads": [{
                "parser": "YOLO", "outputs": yolo + kpts,
                "metadata": {"classes": ["person"], "n_classes": 1, "iou_threshold": 0.5, "conf_threshold": 0.5, "max_det": 50,
                             "anchors": None, "subtype": "yolov8", "n_keypoints": n_keypoints, "yolo_outputs": yolo,
                             "keypoints_outputs": kpts, "strides": list(STRIDES)},
            }],
        },
    }
    with tarfile.open(path, "w:xz") as tar:
        for name, data in (("config.json", json.dumps(config).encode()), ("model.onnx", b"placeholder")):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return str(path)


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    return dai.NNArchive(_write_archive(tmp_path_factory.mktemp("nn") / "yolov8-pose.tar.xz"))


def _person(x0, y0, x1, y1, score=0.9, logit=3.0, low=()):
    """A scripted detection: box in pixels, 17 keypoints spread over it, some of them low-confidence."""
    rng = np.random.default_rng(int(x0 * 7 + y0))
    uv = np.stack([rng.uniform(x0 + 2, x1 - 2, 17), rng.uniform(y0 + 2, y1 - 2, 17)], 1)
    logits = np.full(17, logit)
    logits[list(low)] = -3.0  # sigmoid(-3) = 0.047: below any sensible threshold
    return {"box": (x0, y0, x1, y1), "score": score, "uv": uv, "logits": logits}


def _head_tensors(people, width=W, height=H):
    """The YOLOv8-pose head outputs that make depthai's parser find ``people``."""
    tensors = {}
    for i, s in enumerate(STRIDES):
        h, w = height // s, width // s
        boxes = np.zeros((6, h, w), np.float32)
        kpts = np.zeros((51, 2, h * w), np.float32)
        if i == 0:
            for p in people:
                x0, y0, x1, y1 = p["box"]
                r, c = int((y0 + y1) / 2 // s), int((x0 + x1) / 2 // s)
                # (left, top, right, bottom) from the cell centre, in strides; objectness; class score
                boxes[:, r, c] = [c + 0.5 - x0 / s, r + 0.5 - y0 / s, x1 / s - c - 0.5, y1 / s - r - 0.5, p["score"], p["score"]]
                kpts[0::3, :, r * w + c] = p["uv"][:, :1]
                kpts[1::3, :, r * w + c] = p["uv"][:, 1:]
                kpts[2::3, :, r * w + c] = p["logits"][:, None]
        tensors[f"output{i + 1}_yolov8"] = boxes
        tensors[f"kpt_output{i + 1}"] = kpts
    return tensors


class FakeDevice(dai.node.ThreadedHostNode):
    """Camera, network and stereo of an OAK: for each frame in, its NN output, passthrough and depth."""

    def __init__(self):
        super().__init__()
        self.input = self.createInput()
        self.nn = self.createOutput()
        self.passthrough = self.createOutput()
        self.depth = self.createOutput()
        self.script = {}  # seq -> {"people": [...], "depth": (H, W) uint16 mm or None, "drop": bool}

    def run(self):
        while self.isRunning():
            try:
                frame = self.input.get(datetime.timedelta(seconds=0.05))  # bounded: notices stop()
            except Exception:  # the pipeline stopped
                return
            if frame is None:
                continue
            entry = self.script.get(frame.getSequenceNum(), {})
            nn = dai.NNData()
            for name, tensor in _head_tensors(entry.get("people", []), frame.getWidth(), frame.getHeight()).items():
                nn.addTensor(name, tensor, dai.TensorInfo.DataType.FP32)
            nn.setTransformation(frame.getTransformation())
            nn.setSequenceNum(frame.getSequenceNum())
            nn.setTimestamp(frame.getTimestamp())
            if entry.get("depth") is not None:
                depth = dai.ImgFrame()
                depth.setCvFrame(entry["depth"], dai.ImgFrame.Type.RAW16)
                depth.setTransformation(frame.getTransformation())  # aligned to the NN frame
                depth.setSequenceNum(frame.getSequenceNum())
                depth.setTimestamp(frame.getTimestamp())
                self.depth.send(depth)
            self.nn.send(nn)
            if not entry.get("drop"):
                self.passthrough.send(frame)


class Rig:
    """A host-only pipeline: FakeDevice -> real DetectionParser (-> real SpatialLocationCalculator) -> OakSource."""

    def __init__(self, archive, cam, depth=False, options=oak.OakOptions()):
        self.pipeline = dai.Pipeline(False)
        self.device = self.pipeline.create(FakeDevice)
        parser = self.pipeline.create(dai.node.DetectionParser)
        parser.setNNArchive(archive)  # what DetectionNetwork.build(frames, archive, ...) does on the device
        parser.setConfidenceThreshold(options.confidence)
        self.device.nn.link(parser.input)
        detections = parser.out
        if depth:
            detections = oak.add_spatial_keypoints(dai, self.pipeline, parser.out, self.device.depth, options)
        for node in self.pipeline.getAllNodes():  # the device-capable nodes run here instead
            if hasattr(node, "setRunOnHost"):
                node.setRunOnHost(True)
        self.frames_in = self.device.input.createInputQueue()
        self.source = oak.OakSource(self.pipeline, oak.OakGraph(detections, self.device.passthrough, depth), cam, "oak:test", options)

    def send(self, seq, image, people=(), depth=None, drop=False, age_s=0.25, K=K, dist=DIST):
        """Capture frame ``seq`` ``age_s`` ago on the host's monotonic clock; returns its expected UNIX stamp."""
        self.device.script[seq] = {"people": list(people), "depth": depth, "drop": drop}
        frame = dai.ImgFrame()
        frame.setCvFrame(image, dai.ImgFrame.Type.BGR888p)  # the NN's planar input
        tr = dai.ImgTransformation(image.shape[1], image.shape[0])
        tr.setIntrinsicMatrix(np.asarray(K).tolist())
        tr.setDistortionCoefficients(list(dist))
        frame.setTransformation(tr)
        frame.setSequenceNum(seq)
        mono = time.monotonic_ns()
        frame.setTimestamp(datetime.timedelta(microseconds=(mono - int(age_s * 1e9)) // 1000))
        expected = time.time_ns() - int(age_s * 1e9)
        self.frames_in.send(frame)
        return expected

    def take(self, n):
        """The next ``n`` frames (each within the source's frame timeout)."""
        it = self.source.frames()
        return [next(it) for _ in range(n)]


@pytest.fixture
def rig(archive):
    rigs = []

    def make(**kw):
        cam = kw.pop("cam", None) or _site().camera("front")
        r = Rig(archive, cam, **kw)
        rigs.append(r)
        return r

    yield make
    for r in rigs:
        r.source.close()


def _image(seed=0, width=W, height=H):
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def test_keypoints_boxes_image_and_capture_stamp(rig):
    r = rig(options=oak.OakOptions(frame_timeout_s=10.0))
    a = _person(40, 30, 140, 270, score=0.92, low=(3, 4))  # ears hidden
    b = _person(300, 20, 420, 250, score=0.81, logit=1.0)  # sigmoid(1) = 0.73
    faint = _person(200, 100, 260, 200, score=0.3)  # below the detection threshold
    img = _image(1)
    expected = r.send(5, img, [a, b, faint])
    (frame,) = r.take(1)

    assert (frame.width, frame.height) == (W, H)
    assert frame.image.shape == (H, W, 3) and frame.image.dtype == np.uint8
    np.testing.assert_array_equal(frame.image, img)  # the NN frame as BGR, for the colour signature
    # The capture instant, not the time it was read: 0.25 s before sending, on the UNIX clock.
    assert abs(frame.stamp_ns - expected) < 5_000_000, (frame.stamp_ns - expected) / 1e6

    people = sorted(frame.people, key=lambda p: p.bbox[0])
    assert len(people) == 2
    for p, want in zip(people, (a, b)):
        np.testing.assert_allclose(p.bbox, want["box"], atol=0.05)
        assert p.points3d is None
        assert p.histogram.sum() == 0  # the node computes it from frame.image
    pa, pb = people
    shown = np.ones(17, bool)
    shown[[3, 4]] = False
    np.testing.assert_array_equal(pa.visible, shown)
    np.testing.assert_allclose(pa.keypoints[shown, :2], a["uv"][shown], atol=0.01)
    np.testing.assert_allclose(pa.keypoints[shown, 2], 1 / (1 + np.exp(-3.0)), atol=1e-5)
    np.testing.assert_allclose(pb.keypoints[:, :2], b["uv"], atol=0.01)
    np.testing.assert_allclose(pb.keypoints[:, 2], 1 / (1 + np.exp(-1.0)), atol=1e-5)

    # What the node will publish survives the wire.
    obs = Observation("oak-test", "front", 0, frame.stamp_ns, frame.width, frame.height, frame.people)
    back = decode(encode(obs))
    np.testing.assert_allclose(back.people[0].keypoints, obs.people[0].keypoints, atol=0.01, equal_nan=True)


def test_spatial_keypoints_are_metres_in_the_opencv_camera_frame(rig):
    r = rig(depth=True)
    a = _person(30, 20, 230, 270, low=(0,))
    depth = np.full((H, W), 2500, np.uint16)  # a person 2.5 m away...
    depth[:, 130:] = 0  # ...with no stereo match on the right half of their box
    depth[:40, :130] = 15000  # ...and beyond the far limit above row 40
    r.send(1, _image(2), [a], depth=depth)
    (frame,) = r.take(1)
    (p,) = frame.people
    assert p.points3d is not None and p.points3d.shape == (17, 3)

    uv = a["uv"]
    radius = oak.OakOptions().keypoint_radius_px
    inside = (uv[:, 0] < 130 - radius) & (uv[:, 1] > 40 + radius)
    inside[0] = False  # the nose is below the keypoint threshold: no 3D either
    no_depth = (uv[:, 0] > 130 + radius) | (uv[:, 1] < 40 - radius)
    assert inside.sum() >= 3 and no_depth.sum() >= 3  # the case exercises both
    z = 2.5
    want = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * z, (uv[:, 1] - K[1, 2]) / K[1, 1] * z, np.full(17, z)], 1)
    np.testing.assert_allclose(p.points3d[inside], want[inside], atol=0.005)  # 5 mm
    assert np.isnan(p.points3d[no_depth]).all()  # z = 0 -> missing
    assert np.isnan(p.points3d[0]).all() and np.isnan(p.keypoints[0]).all()
    # Projecting a 3D joint lands on its keypoint (undistorted here: depthai's own pinhole).
    uv_back = p.points3d[inside, :2] / p.points3d[inside, 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    np.testing.assert_allclose(uv_back, p.keypoints[inside, :2], atol=0.05)


def test_frames_stay_in_order_and_a_dropped_frame_is_skipped(rig):
    r = rig()
    for seq in (1, 2, 3):
        r.send(seq, _image(seq), [_person(50 + 40 * seq, 40, 200 + 40 * seq, 260)], drop=seq == 2)
    f1, f3 = r.take(2)
    np.testing.assert_array_equal(f1.image, _image(1))
    np.testing.assert_array_equal(f3.image, _image(3))
    assert f3.people[0].bbox[0] == pytest.approx(170.0, abs=0.05)  # frame 3's person, not frame 2's
    assert r.source.dropped == 1
    assert f1.stamp_ns < f3.stamp_ns


def test_intrinsics_come_from_the_frame_and_disagreement_warns(rig, caplog):
    r = rig()
    r.send(1, _image(3))
    with caplog.at_level(logging.WARNING, logger="superbody.edge.sources.oak"):
        r.take(1)
    Kd, dist = r.source.intrinsics
    np.testing.assert_allclose(Kd, K, atol=1e-4)
    np.testing.assert_allclose(dist[:5], DIST[:5], atol=1e-6)
    assert not [m for m in caplog.messages if "disagree" in m]

    caplog.clear()
    r2 = rig(cam=_site(fx=450.0, cy=160.0).camera("front"))
    r2.send(1, _image(4))
    with caplog.at_level(logging.WARNING, logger="superbody.edge.sources.oak"):
        r2.take(1)
    (msg,) = [m for m in caplog.messages if "disagree" in m]
    assert "fx 450.00 (device 402.50)" in msg and "cy 160.00 (device 141.50)" in msg and "fy" not in msg


def test_a_frame_of_another_size_is_an_error(rig):
    r = rig(cam=_site(width=640, height=360, cx=320.0, cy=180.0).camera("front"))
    r.send(1, _image(5))
    with pytest.raises(SourceError, match=r"frames are 512x288 but site camera 'front' is 640x360"):
        r.take(1)


def test_silence_is_an_error_and_close_ends_frames(rig):
    r = rig(options=oak.OakOptions(frame_timeout_s=0.5))
    t0 = time.monotonic()
    with pytest.raises(SourceError, match="no detections for 0.5 s"):
        r.take(1)
    assert time.monotonic() - t0 < 3

    r2 = rig(options=oak.OakOptions(frame_timeout_s=30.0))
    closer = threading.Timer(0.3, r2.source.close)
    closer.start()
    t0 = time.monotonic()
    assert list(r2.source.frames()) == []
    assert time.monotonic() - t0 < 3
    closer.join()


@pytest.mark.parametrize("site_size, keypoints, match", [
    ((640, 480), 17, r"NN frame is 512x288 but site camera 'front' is 640x480"),  # wrong camera size
    ((W, H), 5, r"YOLO head with 17 keypoints"),  # not a COCO-17 pose model
])
def test_archive_checks(tmp_path, site_size, keypoints, match):
    archive = dai.NNArchive(_write_archive(tmp_path / "a.tar.xz", n_keypoints=keypoints))
    w, h = site_size
    cam = _site(width=w, height=h, cx=w / 2, cy=h / 2).camera("front")
    with pytest.raises(SourceError, match=match):
        oak.check_nn_archive(archive, cam)


def test_bad_nn_archive_fails_before_any_device_search(tmp_path):
    site = _site()
    t0 = time.monotonic()
    with pytest.raises(SourceError, match="no such file"):
        oak.open_oak_source(site, "front", None, str(tmp_path / "missing.tar.xz"))
    (tmp_path / "junk.tar.xz").write_bytes(b"not an archive")
    with pytest.raises(SourceError, match="not a readable NN archive"):
        oak.open_oak_source(site, "front", None, str(tmp_path / "junk.tar.xz"))
    wrong = _write_archive(tmp_path / "small.tar.xz", width=320, height=192)
    with pytest.raises(SourceError, match="NN frame is 320x192"):
        oak.open_oak_source(site, "front", "SOMEDEVICE", wrong)
    assert time.monotonic() - t0 < 2
    with pytest.raises(SourceError, match="'nope' is not in site"):
        oak.open_oak_source(site, "nope", None, None)


def test_without_a_device_open_fails_fast_and_clearly():
    site = _site()
    t0 = time.monotonic()
    with pytest.raises(SourceError, match=r"^oak: no OAK device found"):
        oak.open_oak_source(site, "front", None, None)
    with pytest.raises(SourceError, match=r"^oak:14442C10D13EABCE00: cannot open the OAK device.*devices found: none"):
        oak.open_oak_source(site, "front", "14442C10D13EABCE00", None)
    assert time.monotonic() - t0 < 15


def test_zoo_model_offline_and_uncached_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("DEPTHAI_ZOO_INTERNET_CHECK", "0")  # never download in tests
    with pytest.raises(SourceError, match=r"not cached in .*cache.*--nn-archive"):
        oak.load_nn_archive(dai, oak.DEFAULT_MODEL, None, "RVC2", tmp_path / "cache")
    with pytest.raises(SourceError, match="must look like OWNER/MODEL"):
        oak.load_nn_archive(dai, "yolov8 pose", None, "RVC2", tmp_path / "cache")


# --- pure conversions (edge/sources/oak_convert.py) ------------------------------------------------------


@pytest.mark.parametrize("coefficients, want", [
    ([0.0] * 14, ()),  # an ideal lens: no distortion
    ([0.1, -0.2, 0.001, 0.002] + [0.0] * 10, (0.1, -0.2, 0.001, 0.002)),  # k1, k2, p1, p2
    ([0.1, -0.2, 0.0, 0.0, 0.03] + [0.0] * 9, (0.1, -0.2, 0.0, 0.0, 0.03)),  # + k3
    ([0.1, 0, 0, 0, 0, 0.2, 0, 0.01] + [0.0] * 6, (0.1, 0, 0, 0, 0, 0.2, 0, 0.01)),  # rational model
    ([0.1, 0.2], (0.1, 0.2, 0.0, 0.0)),  # short lists are padded
    ([], ()),
])
def test_site_distortion(coefficients, want):
    from superbody.edge.sources.oak_convert import site_distortion

    assert site_distortion(coefficients) == pytest.approx(want)


def test_site_distortion_refuses_what_a_site_cannot_hold():
    from superbody.edge.sources.oak_convert import site_distortion

    with pytest.raises(ValueError, match="coefficient 9 .* is 0.01"):
        site_distortion([0.1] + [0.0] * 8 + [0.01] + [0.0] * 4)  # s2, a thin-prism term
    with pytest.raises(ValueError, match="finite"):
        site_distortion([np.nan])


@pytest.mark.parametrize("Kbad, match", [
    ([[400, 0, 600], [0, 400, 140], [0, 0, 1]], "inside the 512x288 frame"),  # principal point outside
    ([[-400, 0, 256], [0, 400, 140], [0, 0, 1]], "must be > 0"),
    ([[400, 5, 256], [0, 400, 140], [0, 0, 1]], r"\[\[fx, 0, cx\]"),  # skew
    ([[400, 0], [0, 400]], "3x3"),
])
def test_camera_with_intrinsics_checks_the_matrix(Kbad, match):
    from superbody.edge.sources.oak_convert import camera_with_intrinsics

    with pytest.raises(ValueError, match=match):
        camera_with_intrinsics(_site().camera("front"), Kbad, [], W, H)


def test_camera_with_intrinsics_keeps_the_pose():
    from superbody.edge.sources.oak_convert import camera_with_intrinsics

    cam = _site(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0).camera("front")
    new = camera_with_intrinsics(cam, K, DIST, W, H)
    assert (new.width, new.height, new.fx, new.fy, new.cx, new.cy) == (W, H, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    assert new.dist == pytest.approx(tuple(DIST[:5]))
    assert (new.id, new.fps, new.position, new.rotation) == (cam.id, cam.fps, cam.position, cam.rotation)


@pytest.mark.parametrize("site_kw, want", [
    ({}, None),  # identical
    ({"fx": K[0, 0] * 1.009}, None),  # within 1 %
    ({"fx": K[0, 0] * 1.02}, "fx"),
    ({"cx": K[0, 2] + 6.0}, "cx"),  # 6 px > 1 % of 512
    ({"width": 640, "height": 360, "cx": 320.0, "cy": 180.0}, "size 640x360 (device 512x288)"),
])
def test_intrinsics_disagreement(site_kw, want):
    from superbody.edge.sources.oak_convert import intrinsics_disagreement

    kw = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], **site_kw}
    got = intrinsics_disagreement(_site(**kw).camera("front"), K, W, H)
    assert got is None if want is None else want in got


@pytest.mark.parametrize("td, ns", [
    (datetime.timedelta(0), 0),
    (datetime.timedelta(seconds=1, microseconds=7), 1_000_007_000),
    (datetime.timedelta(days=3, seconds=5), (3 * 86400 + 5) * 10**9),  # a host up for days
])
def test_timedelta_ns(td, ns):
    from superbody.edge.sources.oak_convert import timedelta_ns

    assert timedelta_ns(td) == ns


def test_monotonic_to_unix_ns():
    from superbody.edge.sources.oak_convert import monotonic_to_unix_ns

    # Captured 40 ms before "now" on the monotonic clock -> 40 ms before "now" on the UNIX clock.
    assert monotonic_to_unix_ns(5_000_000_000, 5_040_000_000, 1_700_000_000_000_000_000) == 1_699_999_999_960_000_000


def test_people_from_arrays_edge_cases():
    from superbody.edge.sources.oak_convert import people_from_arrays

    assert people_from_arrays(np.zeros((0, 4)), np.zeros((0, 17, 3)), None, W, H, 0.5) == ()
    kp = np.full((1, 17, 3), 0.5)
    kp[0, :, 2] = 0.2  # every joint below the threshold: nobody
    assert people_from_arrays(np.array([[0.1, 0.1, 0.5, 0.9]]), kp, None, W, H, 0.5) == ()
    kp[0, 5, 2] = 0.9
    (p,) = people_from_arrays(np.array([[-0.1, 0.1, 1.2, 0.9]]), kp, np.zeros((1, 17, 3)), W, H, 0.5)
    np.testing.assert_allclose(p.bbox, [0, 0.1 * H, W, 0.9 * H], rtol=1e-6)  # clipped to the frame
    assert p.num_visible == 1 and np.isnan(p.points3d).all()  # z = 0 everywhere: no depth
    with pytest.raises(ValueError, match="2 boxes but 1 keypoint sets"):
        people_from_arrays(np.zeros((2, 4)), kp, None, W, H, 0.5)


# --- superbody calibrate oak-intrinsics -----------------------------------------------------------


def _site_file(path):
    path.write_text(
        "# A two-camera test site.\n# Second header line.\n\n"
        "[site]\nname = \"oak-test\"\n\n[floor]\npolygon = [[-3.0, -3.0], [3.0, -3.0], [3.0, 3.0], [-3.0, 3.0]]\n\n"
        "[[cameras]]\nid = \"front\"\nwidth = 640\nheight = 480\nfps = 10.0\nfx = 500.0\nfy = 500.0\ncx = 320.0\ncy = 240.0\n"
        "position = [0.0, -3.0, 2.0]\nlook_at = [0.0, 0.0, 1.0]\n\n"
        "[[cameras]]\nid = \"side\"\nwidth = 1280\nheight = 720\nfps = 15.0\nfx = 900.0\nfy = 900.0\ncx = 640.0\ncy = 360.0\n"
        "position = [3.0, 0.0, 2.0]\nlook_at = [0.0, 0.0, 1.0]\n",
        encoding="utf-8",
    )
    return path


def test_calibrate_oak_intrinsics_without_a_device_is_one_line_exit_2(tmp_path, capsys):
    from superbody.edge.cli import main

    site = _site_file(tmp_path / "site.toml")
    assert main(["calibrate", "oak-intrinsics", "--site", str(site), "--camera", "front", "--out", str(tmp_path / "o.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("superbody calibrate oak-intrinsics: error: oak: no OAK device found")
    assert not (tmp_path / "o.toml").exists()
    for bad, match in ((["--camera", "back"], "camera 'back' is not in site"), (["--camera", "front", "--size", "512"], "--size must be WIDTHxHEIGHT")):
        assert main(["calibrate", "oak-intrinsics", "--site", str(site), *bad]) == 2
        assert match in capsys.readouterr().err


def test_calibrate_oak_intrinsics_writes_the_device_intrinsics(tmp_path, capsys, monkeypatch):
    from superbody.edge.cli import main
    from superbody.edge.site import load_site

    calls = []

    def device_calibration(device_id, width, height, timeout_s=10.0):  # stands in for the OAK
        calls.append((device_id, width, height))
        return K.copy(), np.array(DIST), "14442C10D13EABCE00"

    monkeypatch.setattr(oak, "read_device_intrinsics", device_calibration)
    site, out = _site_file(tmp_path / "site.toml"), tmp_path / "out.toml"
    assert main(["calibrate", "oak-intrinsics", "--site", str(site), "--camera", "front", "--device", "14442C10D13EABCE00",
                 "--size", "512x288", "--out", str(out)]) == 0
    assert calls == [("14442C10D13EABCE00", 512, 288)]
    assert "402.500" in capsys.readouterr().out
    before, after = load_site(site), load_site(out)
    front = after.camera("front")
    assert (front.width, front.height, front.fx, front.fy, front.cx, front.cy) == (512, 288, 402.5, 401.0, 257.0, 141.5)
    assert front.dist == pytest.approx(tuple(DIST[:5]))
    np.testing.assert_allclose(front.R, before.camera("front").R, atol=1e-9)  # the pose is untouched
    side, side0 = after.camera("side"), before.camera("side")
    assert (side.width, side.height, side.fx, side.fy, side.cx, side.cy, side.dist) == (1280, 720, 900.0, 900.0, 640.0, 360.0, ())
    np.testing.assert_allclose(side.R, side0.R, atol=1e-9)  # the other camera is untouched (up to 1e-9 rounding)
    np.testing.assert_allclose(side.t, side0.t, atol=1e-9)
    text = out.read_text()
    assert text.startswith("# A two-camera test site.\n# Second header line.\n# Camera front intrinsics from OAK 14442C10D13EABCE00")



# --- the device nodes: only their API surface can be checked without a device --------------------


class _Spy:
    """Stands in for a device node or output: every attribute used must exist on the real class."""

    PROPERTY_TYPES = {"initialConfig": dai.SpatialLocationCalculatorConfig}

    def __init__(self, cls, name, calls):
        self._cls, self._name, self._calls = cls, name, calls

    def __getattr__(self, attr):
        assert hasattr(self._cls, attr), f"depthai {self._cls.__name__} has no attribute {attr!r}"
        if isinstance(getattr(self._cls, attr), property):  # an input/output or a config
            return _Spy(self.PROPERTY_TYPES.get(attr, dai.Node.Output), f"{self._name}.{attr}", self._calls)

        def method(*args, **kwargs):
            self._calls.append((f"{self._name}.{attr}", args, kwargs))
            if attr == "build":
                return self
            if attr == "requestOutput":
                return _Spy(dai.Node.Output, f"{self._name}.requestOutput()", self._calls)
            return None

        return method

    def __repr__(self):
        return self._name


class _SpyPipeline:
    def __init__(self):
        self.calls = []

    def create(self, cls):
        return _Spy(cls, cls.__name__, self.calls)


@pytest.mark.parametrize("depth", [False, True])
def test_device_graph_uses_only_real_depthai_api(archive, depth):
    pipeline = _SpyPipeline()
    graph = oak.build_device_graph(dai, pipeline, archive, _site().camera("front"), depth, oak.OakOptions())
    calls = {name: (args, kwargs) for name, args, kwargs in pipeline.calls}
    size, frame_type, resize, fps = calls["Camera.requestOutput"][0]
    assert (size, resize, fps) == ((W, H), dai.ImgResizeMode.CROP, 10.0)  # the NN frame, centre crop, site fps
    assert frame_type == dai.ImgFrame.Type.RGB888p  # the archive's input type
    assert calls["DetectionNetwork.build"][0][1] is archive
    assert repr(graph.passthrough) == "DetectionNetwork.passthrough" and graph.spatial == depth
    if depth:
        assert repr(calls["Depth.setAlignTo"][0][0]) == "DetectionNetwork.passthrough"  # depth in the NN frame
        assert repr(graph.detections) == "SpatialLocationCalculator.outputDetections"
        assert calls["SpatialLocationCalculator.initialConfig.setCalculateSpatialKeypoints"][0] == (True,)
    else:
        assert repr(graph.detections) == "DetectionNetwork.out" and "Depth.build" not in calls
