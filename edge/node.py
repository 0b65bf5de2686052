"""The camera-node process: a frame source, a detector where the source has none, a Zenoh publisher.

``superbody edge run --site SITE.toml --camera ID --source SOURCE [--detector DETECTOR]``
publishes one Observation per frame on ``superbody/<site>/cameras/<camera>/observations`` and
holds a liveliness token on ``superbody/<site>/cameras/<camera>/alive`` while it runs.

Sources (``--source``):

- ``sim``: simulated people (edge/sources/sim_source.py), paced on the world clock;
- ``oak[:DEVICE_ID]``: a Luxonis OAK with the pose network on the device (edge/sources/oak.py, the
  ``oak`` extra);
- ``video:PATH``, ``webcam:INDEX``, ``rtsp://...``: OpenCV captures (edge/sources/video.py) whose images
  go through a host detector, ``--detector movenet | blazepose | yolo-pose:PATH.onnx | rtmo:PATH.onnx``
  (edge/detectors/);
- ``replay:PATH``: a ``superbody record`` MCAP file, this camera's Observations re-published
  with their original timing, stamps shifted to the replay's start (edge/sources/replay.py).

Every frame takes one path (edge/sources/source.py): detections from the source or from the detector,
each person's colour signature from their box in the image when there is one, then encode,
publish.

Timing (what real nodes do, reproduced; every Observation keeps its capture stamp):

- ``--fps F``: the capture rate. The simulator captures at F instead of the site camera's fps;
  video files and replays are thinned to F (edge/sources/subsample.py), which may not exceed
  their own rate. A video file whose rate differs from the site camera's ``fps`` plays at its
  own rate with a warning naming both (the file's timing is what happened; the site's fps is
  what the camera is set to), unless ``--fps`` says which rate to publish.
- ``--start-at UNIX_SECONDS``: video files and replays start on that capture clock, so nodes
  started separately stamp frame k of their files at the same instant.
- ``--delay S --jitter S``: each Observation is published S seconds after its capture, with a
  normal spread, in order (edge/delivery.py); capture never waits for publishing.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, replace
from typing import Literal
from urllib.parse import urlsplit

import numpy as np
from numpy.typing import NDArray

from superbody.edge import transport
from superbody.edge.clock import WorldClock
from superbody.edge.colour import hs_histogram
from superbody.edge.delivery import DeliveryModel, DeliveryScheduler
from superbody.edge.detectors.base import Detector
from superbody.edge.messages import wire
from superbody.edge.messages.observation import Observation, PersonView, empty_histogram
from superbody.edge.site import Site
from superbody.edge.sources.source import Frame, FrameSource, SourceError

__all__ = [
    "SOURCE_FORMS",
    "FPS_SOURCES",
    "START_SOURCES",
    "DEFAULT_OAK_MODEL",
    "SourceSpec",
    "parse_source",
    "open_source",
    "box_histogram",
    "frame_observation",
    "run_node",
]

log = logging.getLogger("superbody.edge")

SOURCE_FORMS = ("sim", "oak[:DEVICE_ID]", "video:PATH", "webcam:INDEX", "rtsp://...", "replay:PATH.mcap")
DEFAULT_OAK_MODEL = "luxonis/yolov8-nano-pose-estimation:coco-512x288"
_MAX_WEBCAM = 63
FPS_SOURCES = ("sim", "video", "replay")  # the sources ``--fps`` sets the capture rate of
START_SOURCES = ("video", "replay")  # the sources ``--start-at`` starts on a shared capture clock


@dataclass(frozen=True)
class SourceSpec:
    """A parsed ``--source`` value.

    Attributes:
        kind: which source.
        target: OAK device id (or None: the first device), video path, webcam index, RTSP URL or
            MCAP recording path.
    """

    kind: Literal["sim", "oak", "video", "webcam", "rtsp", "replay"]
    target: str | int | None = None

    @property
    def needs_detector(self) -> bool:
        """Sources that deliver images without detections."""
        return self.kind in ("video", "webcam", "rtsp")

    def __str__(self) -> str:
        if self.kind == "rtsp":
            return str(self.target)
        return self.kind if self.target is None else f"{self.kind}:{self.target}"


def parse_source(text: str) -> SourceSpec:
    """Parse a ``--source`` value; ``ValueError`` naming the value and the valid forms otherwise."""
    forms = ", ".join(SOURCE_FORMS)
    kind, sep, rest = text.partition(":")
    if text == "sim":
        return SourceSpec("sim")
    if kind == "oak":
        if sep and not rest:
            raise ValueError(f"--source {text!r}: the OAK device id after 'oak:' is empty (or write plain 'oak' for the first device)")
        return SourceSpec("oak", rest or None)
    if kind == "video" and sep:
        if not rest:
            raise ValueError(f"--source {text!r}: the video file path after 'video:' is empty")
        return SourceSpec("video", rest)
    if kind == "replay" and sep:
        if not rest:
            raise ValueError(f"--source {text!r}: the MCAP recording path after 'replay:' is empty")
        return SourceSpec("replay", rest)
    if kind == "webcam" and sep:
        if not (rest.isdigit() and int(rest) <= _MAX_WEBCAM):
            raise ValueError(f"--source {text!r}: the webcam index must be an integer in [0, {_MAX_WEBCAM}], got {rest!r}")
        return SourceSpec("webcam", int(rest))
    if kind in ("rtsp", "rtsps") and rest.startswith("//"):
        if not urlsplit(text).netloc:
            raise ValueError(f"--source {text!r}: the RTSP URL has no host")
        return SourceSpec("rtsp", text)
    raise ValueError(f"--source must be one of {forms}, got {text!r}")


def open_source(
    spec: SourceSpec,
    site: Site,
    camera_id: str,
    *,
    seed: int = 0,
    people: int = 3,
    depth: bool = False,
    clock: WorldClock = WorldClock(),
    nn_archive: str | None = None,
    oak_model: str = DEFAULT_OAK_MODEL,
    realtime: bool = True,
    loop: bool = False,
    replay_start_ns: int | None = None,
    fps: float | None = None,
    start_ns: int | None = None,
) -> FrameSource:
    """Open the source a spec names for one camera of a site.

    Args:
        fps: capture rate: the simulator's instead of the site camera's; video files and
            replays are thinned to it (``FPS_SOURCES`` only).
        start_ns: wall time (UNIX ns) of a video file's first frame or a replay's first
            observation (``START_SOURCES`` only; for replays the same as ``replay_start_ns``).

    Raises:
        SourceError: the source cannot open, delivers another image size than the site's
            camera, or has a lower frame rate than ``fps``; the message names the source.
        ValueError: ``fps`` or ``start_ns`` given for a source that does not take them.
    """
    cam = site.camera(camera_id)
    if fps is not None and spec.kind not in FPS_SOURCES:
        raise ValueError(f"--fps is for --source {', '.join(FPS_SOURCES)}, not --source {spec}")
    if start_ns is not None and spec.kind not in START_SOURCES:
        raise ValueError(f"--start-at is for --source {' and '.join(START_SOURCES)}, not --source {spec}")
    if spec.kind == "sim":
        from superbody.edge.sources.sim_source import SimSource

        return SimSource(site, camera_id, seed, people, depth, clock, fps=fps)
    if spec.kind == "oak":
        try:
            from superbody.edge.sources.oak import open_oak_source

            return open_oak_source(site, camera_id, spec.target, nn_archive, oak_model, depth)  # type: ignore[arg-type]
        except ImportError as e:
            raise SourceError(f"--source {spec}: OAK support is not installed (pip install 'superbody[oak]'): {e}") from None
    if spec.kind == "replay":
        from superbody.edge.sources.replay import ReplaySource

        try:
            return ReplaySource(str(spec.target), site, camera_id, start_ns=start_ns if start_ns is not None else replay_start_ns,
                                loop=loop, fps=fps)
        except ImportError as e:
            raise SourceError(f"--source {spec}: replay needs the mcap package (pip install 'superbody[view]'): {e}") from None
    from superbody.edge.sources.video import VideoSource

    if spec.kind != "video":
        return VideoSource(spec.kind, spec.target, cam.width, cam.height, realtime=realtime, loop=loop)  # type: ignore[arg-type]
    video = VideoSource("video", str(spec.target), cam.width, cam.height, realtime=realtime, loop=loop, fps=fps, start_ns=start_ns)
    if fps is None and not math.isclose(video.fps, cam.fps, rel_tol=0.01):
        log.warning("camera %s: %s runs at %.3g fps, the site's camera at %.3g fps: publishing every frame at the file's %.3g fps "
                    "(its own timing); --fps F thins it to F (at most %.3g)", camera_id, spec, video.fps, cam.fps, video.fps, video.fps)
    return video


def box_histogram(image: NDArray[np.uint8], box: NDArray) -> NDArray[np.float32]:
    """The colour signature of a person: the hue-saturation histogram of their box in the image.

    Args:
        image: (H, W, 3) uint8 BGR.
        box: (4,) x0, y0, x1, y1 pixels (clipped to the image here).

    Returns:
        ``HIST_BINS`` float32 histogram summing to 1 (zeros for an empty or invalid box).
    """
    h, w = image.shape[:2]
    if not np.isfinite(box).all():
        return empty_histogram()
    x0, x1 = (int(np.clip(round(float(v)), 0, w)) for v in (box[0], box[2]))
    y0, y1 = (int(np.clip(round(float(v)), 0, h)) for v in (box[1], box[3]))
    return hs_histogram(image[y0:y1, x0:x1])


def frame_observation(site: str, camera: str, seq: int, frame: Frame, detector: Detector | None = None) -> Observation:
    """One frame as one Observation: the node's single path for every source.

    People come from the frame (sources that detect) or from ``detector`` run on its image;
    when the frame has an image, each person's histogram is computed from their box in it.
    """
    people = frame.people
    if people is None:
        if frame.image is None or detector is None:
            raise ValueError("a frame without detections needs an image and a detector")
        keypoints, boxes = detector.detect(frame.image)
        people = tuple(PersonView(k, b, empty_histogram()) for k, b in zip(keypoints, boxes))
    if frame.image is not None:
        people = tuple(replace(p, histogram=box_histogram(frame.image, p.bbox)) for p in people)
    return Observation(site, camera, seq, frame.stamp_ns, frame.width, frame.height, people)


def run_node(
    conf,
    site: Site,
    camera_id: str,
    source: FrameSource,
    clock: WorldClock = WorldClock(),
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    status_every_s: float = 10.0,
    *,
    detector: Detector | None = None,
    delivery: DeliveryModel = DeliveryModel(),
    rng: np.random.Generator | None = None,
) -> int:
    """Publish an Observation per frame of ``source`` until it ends, ``stop`` is set or
    ``duration_s`` (world time) passes. Closes the source.

    With a ``delivery`` delay or jitter, each Observation is handed to a ``DeliveryScheduler``
    and published at its delivery time (world clock) while capture goes on; when the source
    ends (or ``duration_s`` passes) the Observations still waiting are delivered before the
    node stops, unless ``stop`` is set.

    Returns:
        The number of Observations published.

    Raises:
        SourceError, DetectorError: the source or the detector failed while running.
    """
    import zenoh

    cam = site.camera(camera_id)
    stop = stop or threading.Event()
    published = people = rejected = seq = 0
    with zenoh.open(conf) as session:
        token = session.liveliness().declare_token(transport.camera_alive_key(site.name, camera_id))
        pub = session.declare_publisher(transport.observation_key(site.name, camera_id), encoding=wire.zenoh_encoding())
        scheduler = None if delivery.prompt else DeliveryScheduler(pub.put, delivery, clock, rng=rng).start()
        start = clock.now_ns()
        end = None if duration_s is None else start + int(duration_s * 1e9)
        last_status = t0 = time.monotonic()
        log.info("camera %s of site %s publishing on %s%s", camera_id, site.name, transport.observation_key(site.name, camera_id),
                 "" if scheduler is None else f", each observation {delivery.delay_s:g} s (sd {delivery.jitter_s:g} s) after its capture")
        try:
            for frame in source.frames():
                if stop.is_set() or (end is not None and frame.stamp_ns > end):
                    break
                if (frame.width, frame.height) != (cam.width, cam.height):
                    raise SourceError(f"camera {camera_id}: the source delivered a {frame.width}x{frame.height} frame, "
                                      f"the site's camera is {cam.width}x{cam.height}")
                obs = frame_observation(site.name, camera_id, seq, frame, detector)
                seq += 1
                try:
                    payload = wire.encode(obs)
                except ValueError as e:  # a source produced something no subscriber would accept
                    rejected += 1
                    if rejected <= 3 or rejected % 1000 == 0:
                        log.error("camera %s: frame %d not published (%d so far): %s", camera_id, obs.seq, rejected, e)
                    continue
                if scheduler is None:
                    pub.put(payload)
                else:
                    scheduler.submit(obs.stamp_ns, payload)
                published += 1
                people += len(obs.people)
                if time.monotonic() - last_status > status_every_s:
                    last_status = time.monotonic()
                    log.info("camera %s: %d frames %s (%.1f/s), %d skipped, %.2f people/frame", camera_id, published,
                             "published" if scheduler is None else f"captured ({scheduler.delivered} delivered so far)",
                             published / (last_status - t0), getattr(source, "skipped", 0), people / max(published, 1))
            if scheduler is not None:
                scheduler.finish(stop)  # what was captured is still delivered, each at its time
        finally:
            if scheduler is not None:
                scheduler.abort()
                published = scheduler.delivered
                if scheduler.dropped:
                    log.warning("camera %s: %d observations dropped from a full delivery queue", camera_id, scheduler.dropped)
            source.close()
            pub.undeclare()
            token.undeclare()
    log.info("camera %s stopped after %d frames (%d skipped)", camera_id, published, getattr(source, "skipped", 0))
    return published
