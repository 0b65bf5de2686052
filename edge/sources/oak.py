"""The OAK frame source: a Luxonis OAK camera running the pose detector on the device.

One depthai v3 pipeline per device::

    Camera (CAM_A) --NN-sized frames--> DetectionNetwork (YOLO-pose NN archive) --> detections,
                                        |                                          17 keypoints
                                        +-- passthrough (the frame the NN saw) --> image, stamp
    with --depth:
    Depth (StereoDepth, aligned to the NN frame) --> SpatialLocationCalculator (spatial keypoints)

The host reads the detections and the NN's passthrough frame, pairs them by sequence number
and yields one ``Frame`` each: the people (keypoints in the NN frame's pixels, 3D joints in
metres in the camera's OpenCV frame), the NN-sized BGR image (the node takes each person's
colour signature from it) and the capture time in UNIX ns.

The NN archive comes from the Luxonis model zoo by name (cached under
``~/.cache/superbody/oak-models`` for offline use; ``DEPTHAI_ZOO_INTERNET_CHECK=0`` makes
depthai use the cache without looking online) or from ``nn_archive``. Its input size is the
frame size: it must equal the site camera's ``width`` x ``height``. The intrinsics of that
frame come from the device's calibration through depthai's frame transformation; the source
warns when the site's disagree (``superbody calibrate oak-intrinsics`` writes them).

depthai is imported only here, lazily. ``DEPTHAI_SEARCH_TIMEOUT`` (ms) is set before the
import when unset, so a missing device fails in seconds. The pure conversions live in
``edge/sources/oak_convert.py``; the device nodes are built by ``build_device_graph`` only, so tests
run everything else (the real ``DetectionParser`` and ``SpatialLocationCalculator`` on the
host) with a stand-in for the camera, network and stereo.
"""

from __future__ import annotations

import datetime
import logging
import os
import re
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.camera import Camera
from superbody.edge.site import Site
from superbody.edge.sources.oak_convert import (
    detection_arrays,
    intrinsics_disagreement,
    monotonic_to_unix_ns,
    people_from_arrays,
    timedelta_ns,
)
from superbody.edge.sources.source import Frame, SourceError

__all__ = [
    "DEFAULT_MODEL",
    "OakOptions",
    "OakGraph",
    "OakSource",
    "open_oak_source",
    "import_depthai",
    "load_nn_archive",
    "check_nn_archive",
    "open_device",
    "build_device_graph",
    "add_spatial_keypoints",
    "read_device_intrinsics",
    "default_cache_dir",
]

log = logging.getLogger("superbody.edge.sources.oak")

DEFAULT_MODEL = "luxonis/yolov8-nano-pose-estimation:coco-512x288"

# How long depthai looks for a device before giving up (ms), unless the user set it.
_SEARCH_TIMEOUT_MS = 3000
# A zoo model reference: "owner/slug", optionally ":variant" and ":version".
_MODEL_RE = re.compile(r"^[A-Za-z0-9_.-]+/[A-Za-z0-9_.-]+(:[A-Za-z0-9_.-]+){0,2}$")
# Queue poll period: how quickly frames() notices close().
_POLL_S = 0.2


@dataclass(frozen=True)
class OakOptions:
    """Tuning of the OAK source (the defaults suit the zoo's YOLOv8-pose models).

    Attributes:
        confidence: detection confidence threshold of the on-device parser, (0, 1).
        min_keypoint_score: joints below this keypoint confidence are sent as missing, (0, 1].
        keypoint_radius_px: radius around each keypoint over which depth is averaged.
        depth_range_mm: (near, far) depths used; outside it a joint has no depth.
        frame_timeout_s: no frame for this long is an error (device unplugged, pipeline stuck).
        cache_dir: where zoo models are cached; None for ``default_cache_dir()``.
    """

    confidence: float = 0.5
    min_keypoint_score: float = 0.5
    keypoint_radius_px: int = 4
    depth_range_mm: tuple[int, int] = (200, 12000)
    frame_timeout_s: float = 5.0
    cache_dir: str | None = None

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise ValueError(f"OakOptions.confidence must be in (0, 1), got {self.confidence}")
        if not 0 < self.min_keypoint_score <= 1:
            raise ValueError(f"OakOptions.min_keypoint_score must be in (0, 1], got {self.min_keypoint_score}")
        if not 1 <= self.keypoint_radius_px <= 64:
            raise ValueError(f"OakOptions.keypoint_radius_px must be in [1, 64], got {self.keypoint_radius_px}")
        near, far = self.depth_range_mm
        if not 0 <= near < far <= 65535:
            raise ValueError(f"OakOptions.depth_range_mm must be (near, far) with 0 <= near < far <= 65535, got {self.depth_range_mm}")
        if not 0 < self.frame_timeout_s <= 600:
            raise ValueError(f"OakOptions.frame_timeout_s must be in (0, 600], got {self.frame_timeout_s}")


class OakGraph(NamedTuple):
    """The two pipeline outputs the source reads.

    Attributes:
        detections: ``ImgDetections`` (or ``SpatialImgDetections`` with depth) per NN frame.
        passthrough: the ``ImgFrame`` the NN ran on, same sequence number.
        spatial: whether ``detections`` carries spatial keypoints.
    """

    detections: Any
    passthrough: Any
    spatial: bool


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/superbody/oak-models`` (``~/.cache/...`` when unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "superbody" / "oak-models"


def import_depthai():
    """The ``depthai`` module; ``SourceError`` when the ``oak`` extra is not installed."""
    os.environ.setdefault("DEPTHAI_SEARCH_TIMEOUT", str(_SEARCH_TIMEOUT_MS))
    try:
        import depthai
    except ImportError as e:
        raise SourceError(f"oak: depthai is not installed ({e}); install the oak extra: pip install 'superbody[oak]'") from None
    return depthai


def _label(device_id: str | None) -> str:
    return f"oak:{device_id}" if device_id else "oak"


def open_device(dai, device_id: str | None):
    """Open an OAK by id (MX id / serial, IP address or USB path), or the first one found.

    Raises:
        SourceError: no device, or none with that id; the message lists the devices found.
    """
    label = _label(device_id)
    if device_id is None:
        found = dai.Device.getAllAvailableDevices()
        if not found:
            raise SourceError(f"{label}: no OAK device found (USB or network); plug one in, or name it (oak:DEVICE_ID, --device)")
        info = found[0]
    else:
        info = dai.DeviceInfo(device_id)
    try:
        return dai.Device(info)
    except RuntimeError as e:
        found = ", ".join(f"{d.getDeviceId()} ({d.name})" for d in dai.Device.getAllAvailableDevices()) or "none"
        raise SourceError(f"{label}: cannot open the OAK device: {e}; devices found: {found}") from None


def load_nn_archive(dai, model: str, nn_archive: str | None, platform: str, cache_dir: str | os.PathLike | None = None):
    """The NN archive: the file ``nn_archive``, else ``model`` from the Luxonis zoo (cached).

    Args:
        dai: the depthai module.
        model: zoo reference, e.g. ``luxonis/yolov8-nano-pose-estimation:coco-512x288``.
        nn_archive: path of a local ``.tar.xz`` NN archive, or None.
        platform: the device's platform (``RVC2``, ``RVC4``): zoo models are per platform.
        cache_dir: zoo cache directory, None for ``default_cache_dir()``.

    Raises:
        SourceError: the file is missing or not an NN archive, or the model is neither
            downloadable nor cached.
    """
    if nn_archive is not None:
        path = Path(nn_archive)
        if not path.is_file():
            raise SourceError(f"oak: --nn-archive {path}: no such file")
        try:
            return dai.NNArchive(str(path))
        except RuntimeError as e:
            raise SourceError(f"oak: --nn-archive {path}: not a readable NN archive ({e})") from None
    if not _MODEL_RE.fullmatch(model):
        raise SourceError(f"oak: model {model!r} must look like OWNER/MODEL[:VARIANT[:VERSION]], e.g. {DEFAULT_MODEL}")
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    try:
        path = dai.getModelFromZoo(dai.NNModelDescription(model, platform), useCached=True, cacheDirectory=str(cache))
        return dai.NNArchive(str(path))
    except RuntimeError as e:
        raise SourceError(
            f"oak: cannot get model {model!r} for {platform} from the Luxonis model zoo and it is not cached in "
            f"{cache} ({e}); run once with network access, or pass --nn-archive PATH"
        ) from None


def check_nn_archive(archive, cam: Camera, label: str = "oak") -> None:
    """Check that the archive is a COCO-17 YOLO-pose detector whose frame is the camera's size.

    Raises:
        SourceError: naming the model's frame size and the site's, or what the head lacks.
    """
    width, height = archive.getInputWidth(), archive.getInputHeight()
    if (width, height) != (cam.width, cam.height):
        raise SourceError(
            f"{label}: the NN frame is {width}x{height} but site camera {cam.id!r} is {cam.width}x{cam.height}; "
            f"set the camera's width, height and intrinsics for the NN frame (superbody calibrate oak-intrinsics)"
        )
    heads = archive.getConfigV1().model.heads or []
    if not heads or heads[0].parser != "YOLO" or heads[0].metadata.nKeypoints != NUM_KEYPOINTS:
        what = [(h.parser, h.metadata.nKeypoints) for h in heads]
        raise SourceError(f"{label}: the NN archive must have a YOLO head with {NUM_KEYPOINTS} keypoints (COCO pose), has (parser, keypoints) {what}")


def _nn_frame_type(dai, archive):
    """The frame type the archive's input expects (e.g. BGR888p), default BGR888p."""
    inputs = archive.getConfigV1().model.inputs
    name = inputs[0].preprocessing.daiType if inputs else None
    return getattr(dai.ImgFrame.Type, name or "BGR888p", dai.ImgFrame.Type.BGR888p)


def _request_nn_frames(dai, camera, size: tuple[int, int], frame_type, fps: float | None):
    """The camera output the NN runs on: ``size``, centre-cropped (square pixels kept).

    ``read_device_intrinsics`` requests the same output, so it sees the same intrinsics.
    """
    return camera.requestOutput(size, frame_type, dai.ImgResizeMode.CROP, fps)


def add_spatial_keypoints(dai, pipeline, detections, depth, options: OakOptions):
    """A ``SpatialLocationCalculator`` giving each detection's keypoints a 3D position.

    Args:
        dai: the depthai module.
        pipeline: the pipeline to add to.
        detections: output of ``ImgDetections`` with keypoints.
        depth: output of depth frames (uint16 mm) aligned to the NN frame.
        options: keypoint radius and depth range.

    Returns:
        The calculator's ``outputDetections`` (``SpatialImgDetections``, millimetres).
    """
    slc = pipeline.create(dai.node.SpatialLocationCalculator)
    config = slc.initialConfig
    config.setCalculateSpatialKeypoints(True)
    config.setKeypointRadius(options.keypoint_radius_px)
    config.setDepthThresholds(*options.depth_range_mm)
    # The median is robust to the background pixels a keypoint's disc catches at limb edges.
    config.setCalculationAlgorithm(dai.SpatialLocationCalculatorAlgorithm.MEDIAN)
    detections.link(slc.inputDetections)
    depth.link(slc.inputDepth)
    return slc.outputDetections


def build_device_graph(dai, pipeline, archive, cam: Camera, depth: bool, options: OakOptions) -> OakGraph:
    """The device nodes: camera, detection network and (with ``depth``) stereo depth."""
    camera = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
    frames = _request_nn_frames(dai, camera, (cam.width, cam.height), _nn_frame_type(dai, archive), cam.fps)
    nn = pipeline.create(dai.node.DetectionNetwork).build(frames, archive, options.confidence)
    if not depth:
        return OakGraph(nn.out, nn.passthrough, spatial=False)
    stereo = pipeline.create(dai.node.Depth).build(dai.node.Depth.Algorithm.STEREO, fps=cam.fps)
    stereo.setAlignTo(nn.passthrough)  # depth in the NN frame's pixels and size
    return OakGraph(add_spatial_keypoints(dai, pipeline, nn.out, stereo.depth, options), nn.passthrough, spatial=True)


class OakSource:
    """Frames from a running OAK pipeline (a ``FrameSource``).

    Args:
        pipeline: the depthai pipeline holding ``graph``'s nodes, not started yet.
        graph: the outputs to read.
        camera: the site's camera (frame size checked, intrinsics compared).
        label: how errors and logs name this source, e.g. ``oak:1844301011B546F500``.
        options: thresholds and timeouts.
        device: the ``dai.Device`` to close with the source, if any.
    """

    def __init__(self, pipeline, graph: OakGraph, camera: Camera, label: str = "oak", options: OakOptions = OakOptions(), device=None):
        self._pipeline = pipeline
        self._graph = graph
        self._cam = camera
        self._label = label
        self._options = options
        self._device = device
        self._closed = threading.Event()
        self._queue_closed = import_depthai().MessageQueue.QueueException
        self._pending = None  # a passthrough frame newer than the detections read so far
        self.intrinsics: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        """(K (3, 3), distortion (14,)) of the NN frame, from the first frame's transformation."""
        self.dropped = 0
        """Detections whose frame never came (queues overflowed)."""
        # Latest-frame semantics: a slow consumer drops old frames rather than lagging behind.
        self._det_q = graph.detections.createOutputQueue(4, False)
        self._frame_q = graph.passthrough.createOutputQueue(4, False)
        pipeline.start()

    def _get(self, queue, what: str):
        """The next message, None once closed; ``SourceError`` after ``frame_timeout_s`` of silence."""
        deadline = time.monotonic() + self._options.frame_timeout_s
        while not self._closed.is_set():
            try:
                msg = queue.get(datetime.timedelta(seconds=_POLL_S))
            except self._queue_closed:  # the pipeline stopped
                if self._closed.is_set():
                    return None
                raise SourceError(f"{self._label}: the pipeline stopped ({what} queue closed)") from None
            if msg is not None:
                return msg
            if time.monotonic() > deadline:
                raise SourceError(f"{self._label}: no {what} for {self._options.frame_timeout_s:g} s (device unplugged or stalled?)")
        return None

    def _frame_for(self, seq: int):
        """The passthrough frame with sequence number ``seq``, or None when it was dropped."""
        for _ in range(64):  # bounded: the queue holds 4, the device sends in order
            frame = self._pending if self._pending is not None else self._get(self._frame_q, "frames")
            self._pending = None
            if frame is None:
                return None
            n = frame.getSequenceNum()
            if n == seq:
                return frame
            if n > seq:  # this detection's frame was dropped; keep the newer one
                self._pending = frame
                return None
        return None

    def _check_intrinsics(self, frame) -> None:
        tr = frame.getTransformation()
        K = np.asarray(tr.getIntrinsicMatrix(), dtype=np.float64)
        dist = np.asarray(tr.getDistortionCoefficients(), dtype=np.float64)
        self.intrinsics = (K, dist)
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            log.warning("%s: the frames carry no calibration; cannot check the site's intrinsics", self._label)
            return
        diff = intrinsics_disagreement(self._cam, K, frame.getWidth(), frame.getHeight())
        if diff:
            log.warning(
                "%s: site camera %r intrinsics disagree with the device's calibration: %s "
                "(superbody calibrate oak-intrinsics writes the device's)", self._label, self._cam.id, diff,
            )

    def to_frame(self, detections, image_frame) -> Frame:
        """One detections message and its passthrough frame as a ``Frame``."""
        image = image_frame.getCvFrame()  # (H, W, 3) BGR whatever the NN's input type
        height, width = image.shape[:2]
        if (width, height) != (self._cam.width, self._cam.height):
            raise SourceError(f"{self._label}: frames are {width}x{height} but site camera {self._cam.id!r} is {self._cam.width}x{self._cam.height}")
        if self.intrinsics is None:
            self._check_intrinsics(image_frame)
        boxes, kps, xyz = detection_arrays(detections, self._graph.spatial)
        people = people_from_arrays(boxes, kps, xyz, width, height, self._options.min_keypoint_score)
        # The frame's timestamp is the host-synced capture time on time.monotonic()'s clock.
        stamp = monotonic_to_unix_ns(timedelta_ns(image_frame.getTimestamp()), time.monotonic_ns(), time.time_ns())
        return Frame(stamp_ns=stamp, width=width, height=height, image=np.ascontiguousarray(image), people=people)

    def frames(self) -> Iterator[Frame]:
        """Frames as the device delivers them, until ``close()``.

        Raises:
            SourceError: no frame for ``frame_timeout_s``, the pipeline stopped, or a frame
                of the wrong size.
        """
        while not self._closed.is_set():
            detections = self._get(self._det_q, "detections")
            if detections is None:
                return
            frame = self._frame_for(detections.getSequenceNum())
            if frame is None:
                if self._closed.is_set():
                    return
                self.dropped += 1
                continue
            yield self.to_frame(detections, frame)

    def close(self) -> None:
        """Stop the pipeline and release the device (idempotent, any thread)."""
        if self._closed.is_set():
            return
        self._closed.set()
        try:
            self._pipeline.stop()
            self._pipeline.wait()  # its host threads have ended: nothing runs on after close
        finally:
            if self._device is not None:
                self._device.close()


def open_oak_source(
    site: Site,
    camera_id: str,
    device_id: str | None,
    nn_archive: str | None,
    model: str = DEFAULT_MODEL,
    depth: bool = False,
    options: OakOptions = OakOptions(),
) -> OakSource:
    """Open an OAK device, build its pipeline and start it.

    Args:
        site: the site.
        camera_id: the site camera this device is.
        device_id: the device's MX id / serial, IP address or USB path; None for the first found.
        nn_archive: a local NN archive, or None to use ``model`` from the zoo.
        model: zoo model reference (ignored with ``nn_archive``).
        depth: add stereo depth per keypoint (OAK-D models).
        options: thresholds and timeouts.

    Raises:
        SourceError: depthai missing, no device, model unavailable or not a COCO-17 pose model,
            NN frame size differing from the site camera's.
    """
    label = _label(device_id)
    try:
        cam = site.camera(camera_id)
    except KeyError as e:
        raise SourceError(f"{label}: {e.args[0]}") from None
    dai = import_depthai()
    archive = None
    if nn_archive is not None:  # check the file before looking for a device
        archive = load_nn_archive(dai, model, nn_archive, "", options.cache_dir)
        check_nn_archive(archive, cam, label)
    device = open_device(dai, device_id)
    try:
        label = _label(device_id or device.getDeviceId())
        if archive is None:
            archive = load_nn_archive(dai, model, None, device.getPlatformAsString(), options.cache_dir)
            check_nn_archive(archive, cam, label)
        pipeline = dai.Pipeline(device)
        graph = build_device_graph(dai, pipeline, archive, cam, depth, options)
        source = OakSource(pipeline, graph, cam, label, options, device=device)
    except BaseException:
        device.close()
        raise
    log.info("%s: camera %r, %dx%d NN frames, depth %s", label, cam.id, cam.width, cam.height, "on" if depth else "off")
    return source


def read_device_intrinsics(device_id: str | None, width: int, height: int, timeout_s: float = 10.0) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """The intrinsics of the device's NN-sized frames, as the OAK source will see them.

    Starts a camera-only pipeline requesting the same output as the source (``width`` x
    ``height``, centre crop) and reads the transformation of its first frame.

    Returns:
        ``(K (3, 3), distortion (14,), device id)``.

    Raises:
        SourceError: no device, or no frame within ``timeout_s``.
    """
    dai = import_depthai()
    device = open_device(dai, device_id)
    label = _label(device_id or device.getDeviceId())
    try:
        pipeline = dai.Pipeline(device)
        camera = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
        out = _request_nn_frames(dai, camera, (width, height), dai.ImgFrame.Type.BGR888i, None)
        queue = out.createOutputQueue(1, False)
        pipeline.start()
        try:
            frame = queue.get(datetime.timedelta(seconds=timeout_s))
        finally:
            pipeline.stop()
        if frame is None:
            raise SourceError(f"{label}: no frame within {timeout_s:g} s")
        tr = frame.getTransformation()
        K = np.asarray(tr.getIntrinsicMatrix(), dtype=np.float64)
        dist = np.asarray(tr.getDistortionCoefficients(), dtype=np.float64)
        return K, dist, device.getDeviceId()
    finally:
        device.close()
