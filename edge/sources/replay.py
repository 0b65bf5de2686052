"""A ``superbody record`` MCAP file replayed as one camera's frame source.

``superbody edge run --site S --camera ID --source replay:F.mcap`` re-publishes the
Observations that camera published while the file was recorded (host/outputs/record.py), with their
original timing:

- it reads the channel ``superbody/<site>/cameras/<ID>/observations``, decodes each message with
  ``edge.messages.wire.decode`` (a message that does not decode is counted in ``rejected``, logged and
  skipped) and yields a ``Frame`` carrying its people and their colour signatures (no image);
- **capture stamps are shifted by one constant**, ``shift = start_ns - t0``, where ``t0`` is the
  earliest Observation stamp of the site in the whole recording (every camera, not only this
  one) and ``start_ns`` is the replay's start: the wall clock when the frames start, or
  ``start_ns`` when given (``--replay-start-ns``). The first frame of the recording is thus
  stamped at the replay's start, and the gaps between stamps (within a camera and across
  cameras) are kept. The shift is needed because the host rejects stale and future stamps;
- each frame is delivered when the wall clock reaches its shifted stamp, as the live camera
  delivered it. A frame already later than ``max_late_s`` (a node started after the given
  ``start_ns``, a stalled machine) is skipped and counted in ``skipped``, as a live camera
  drops what a slow node cannot take;
- ``loop=True`` starts again at the end: each pass adds the recording's span plus one frame
  period of the site's fastest camera to the shift, so stamps keep counting up;
- ``fps`` thins the camera's frames to a lower rate (edge/sources/subsample.py, ``edge run
  --fps``); a rate above the camera's recorded one (1 / its median gap between frames) is an error.

Several cameras replayed from one file by separate nodes keep their relative timing only if
they share ``start_ns``: give every node the same ``--start-at`` (UNIX seconds, a few seconds
ahead, e.g. ``$(( $(date +%s) + 5 ))``) or ``--replay-start-ns`` (the same in ns). Without it
each node starts at its own start.

Opening reads the file through once (the channels and the site's first and last stamps), so a
long recording takes a moment to open. Errors (``SourceError``, one line naming the file): no
such file, not an MCAP file, a recording of another site, no channel for this camera (the
cameras present are listed), an image size other than the site's.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.site import Site
from superbody.edge.sources.source import Frame, SourceError
from superbody.edge.sources.subsample import Subsampler

__all__ = ["ReplaySource", "RecordingInfo", "scan_recording"]

log = logging.getLogger("superbody.edge.sources.replay")

_NS = 1_000_000_000


@dataclass(frozen=True)
class RecordingInfo:
    """What a recording holds, as far as replay needs it.

    Attributes:
        cameras: site name -> sorted camera ids that have an observations channel.
        t0_ns: the earliest observation stamp of the site asked for (MCAP publish time, which
            ``superbody record`` sets to the capture stamp), or None without observations.
        t_end_ns: the latest one, or None.
        fps: camera of the site asked for -> its recorded frame rate (1 / the median gap between
            its stamps), for cameras with two stamps or more.
    """

    cameras: dict[str, tuple[str, ...]]
    t0_ns: int | None
    t_end_ns: int | None
    fps: dict[str, float] = field(default_factory=dict)


def _observation_topic(topic: str) -> tuple[str, str] | None:
    """``(site, camera)`` for an observations key, None for any other topic."""
    parts = topic.split("/")
    if len(parts) == 5 and parts[0] == "superbody" and parts[2] == "cameras" and parts[4] == "observations":
        return parts[1], parts[3]
    return None


def _open_reader(path: Path, name: str):
    """An open binary file and its MCAP reader; ``SourceError`` when it is missing or not MCAP."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    if not path.is_file():
        raise SourceError(f"{name}: no such file")
    f = open(path, "rb")
    try:
        magic = f.read(8)
        f.seek(0)
        if magic != b"\x89MCAP0\r\n":
            raise SourceError(f"{name}: not an MCAP file (it does not start with the MCAP magic; record one with `superbody record`)")
        return f, make_reader(f)
    except (SourceError, McapError, OSError) as e:
        f.close()
        raise e if isinstance(e, SourceError) else SourceError(f"{name}: cannot read it as MCAP: {e}") from None


def scan_recording(path: str | Path, site: str) -> RecordingInfo:
    """Read a recording through once: its observation channels and ``site``'s stamp range.

    Raises:
        SourceError: no such file, not an MCAP file, or a damaged one.
    """
    from mcap.exceptions import McapError

    path = Path(path)
    name = f"replay:{path}"
    f, reader = _open_reader(path, name)
    cameras: dict[str, set[str]] = {}
    stamps: dict[str, list[int]] = {}
    t0 = t_end = None
    try:
        for _schema, channel, message in reader.iter_messages():
            sc = _observation_topic(channel.topic)
            if sc is None:
                continue
            cameras.setdefault(sc[0], set()).add(sc[1])
            if sc[0] == site:
                t = int(message.publish_time)
                t0 = t if t0 is None else min(t0, t)
                t_end = t if t_end is None else max(t_end, t)
                stamps.setdefault(sc[1], []).append(t)
    except (McapError, ValueError, OSError, EOFError) as e:  # a truncated or corrupt file
        raise SourceError(f"{name}: damaged MCAP file ({type(e).__name__}: {e})") from None
    finally:
        f.close()
    fps = {}
    for cam, ts in stamps.items():
        gaps = np.diff(np.unique(np.asarray(ts, dtype=np.int64)))
        if len(gaps):
            fps[cam] = 1e9 / float(np.median(gaps))
    return RecordingInfo({s: tuple(sorted(c)) for s, c in cameras.items()}, t0, t_end, fps)


class ReplaySource:
    """A ``FrameSource`` re-publishing one camera's recorded Observations with their timing.

    Args:
        path: the MCAP file (``superbody record``).
        site: the site; the recording must hold its observations.
        camera_id: the camera whose observations are replayed.
        start_ns: wall time (UNIX ns) at which the recording's first observation is replayed;
            None: when ``frames()`` is first called. Nodes replaying one file together must
            share it.
        loop: start again at the end (stamps keep counting up).
        max_late_s: frames later than this when their time comes are skipped.
        fps: thin the frames to this rate (None: every frame); at most the recorded rate.

    Raises:
        SourceError: see the module docstring.
    """

    def __init__(self, path: str | Path, site: Site, camera_id: str, *, start_ns: int | None = None, loop: bool = False,
                 max_late_s: float = 0.5, fps: float | None = None):
        if not (isinstance(max_late_s, (int, float)) and math.isfinite(max_late_s) and 0 < max_late_s <= 60):
            raise ValueError(f"max_late_s must be in (0, 60], got {max_late_s!r}")
        self.path = Path(path)
        self.name = f"replay:{path}"
        self.site, self.camera_id = site, camera_id
        self.topic = transport.observation_key(site.name, camera_id)
        self.start_ns, self.loop, self.max_late_ns = start_ns, loop, int(max_late_s * _NS)
        self.target_fps = fps
        self.skipped = 0
        self.rejected = 0
        self._closed = threading.Event()
        info = scan_recording(self.path, site.name)
        if not info.cameras:
            raise SourceError(f"{self.name}: the recording holds no camera observations")
        if site.name not in info.cameras:
            raise SourceError(f"{self.name}: a recording of site(s) {', '.join(sorted(info.cameras))}, not of site {site.name!r} "
                              f"(give the site file it was recorded with)")
        present = info.cameras[site.name]
        if camera_id not in present:
            raise SourceError(f"{self.name}: no observations of camera {camera_id!r} of site {site.name!r}; "
                              f"cameras present: {', '.join(present)}")
        assert info.t0_ns is not None and info.t_end_ns is not None
        self.fps = info.fps.get(camera_id)  # None: a single frame
        if fps is not None and self.fps is not None and fps > self.fps * 1.01:  # 1%: a recording's jitter
            raise SourceError(f"--fps {fps:g} is above camera {camera_id}'s recorded frame rate in {self.name} ({self.fps:.3g} fps): "
                              f"a recording can only be thinned, give --fps in (0, {self.fps:.3g}]")
        self.t0_ns, self.t_end_ns = info.t0_ns, info.t_end_ns
        fastest = max((c.fps for c in site.cameras), default=30.0)
        self.loop_period_ns = (info.t_end_ns - info.t0_ns) + int(_NS / fastest)
        cam = site.camera(camera_id)
        first = next(self._observations(), None)
        if first is None:
            raise SourceError(f"{self.name}: camera {camera_id}'s channel holds no valid observation ({self.rejected} rejected)")
        if (first.width, first.height) != (cam.width, cam.height):
            raise SourceError(f"{self.name}: camera {camera_id} was recorded at {first.width}x{first.height}, the site's camera is "
                              f"{cam.width}x{cam.height}: give the site file the recording was made with")

    def _observations(self) -> Iterator:
        """This camera's decoded Observations in recorded order; invalid ones counted and skipped."""
        from mcap.exceptions import McapError

        f, reader = _open_reader(self.path, self.name)
        try:
            for _schema, _channel, message in reader.iter_messages(topics=[self.topic]):
                try:
                    obs = wire.decode(message.data, expected_site=self.site.name)
                    if obs.camera != self.camera_id:
                        raise ValueError(f"camera: {obs.camera!r} on camera {self.camera_id}'s channel")
                except ValueError as e:  # wire.DecodeError is a ValueError
                    self.rejected += 1
                    if self.rejected <= 3 or self.rejected % 1000 == 0:
                        log.warning("%s: message %d skipped (%d so far): %s", self.name, message.sequence, self.rejected, e)
                    continue
                yield obs
        except (McapError, ValueError, OSError, EOFError) as e:
            raise SourceError(f"{self.name}: damaged MCAP file ({type(e).__name__}: {e})") from None
        finally:
            f.close()

    def frames(self) -> Iterator[Frame]:
        if self.start_ns is None:
            self.start_ns = time.time_ns()
        shift = self.start_ns - self.t0_ns
        wait_s = (self.start_ns - time.time_ns()) / _NS
        log.info("%s: camera %s, %.1f s recorded, replay starts %s", self.name, self.camera_id, (self.t_end_ns - self.t0_ns) / _NS,
                 f"in {wait_s:.1f} s" if wait_s > 0 else f"{-wait_s:.1f} s ago (frames later than {self.max_late_ns / _NS:g} s are skipped)")
        rate = Subsampler(self.target_fps) if self.target_fps is not None else None
        while not self._closed.is_set():
            any_obs = False
            for obs in self._observations():
                any_obs = True
                t_ns = obs.stamp_ns + shift
                if rate is not None and not rate.keep(t_ns):
                    continue
                late = time.time_ns() - t_ns
                if late > self.max_late_ns:
                    self.skipped += 1
                    continue
                if late < 0 and self._closed.wait(-late / _NS):
                    return
                if self._closed.is_set():
                    return
                yield Frame(t_ns, obs.width, obs.height, None, obs.people)
            if not (self.loop and any_obs):
                return
            shift += self.loop_period_ns

    def close(self) -> None:
        self._closed.set()
