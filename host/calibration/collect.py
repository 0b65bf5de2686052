"""People's near-simultaneous views from a recording: the observations through the host's own
aggregator (tracker, set S, filter) in-process, each confirmed person's views grouped into
``Instant``s.

The observations are fed in capture order, each batch of one stamp at its own capture time, and
the host steps after each batch (as ``models.evaluation.temporal`` replays a recording). After
each step, every published person's views that are new (camera, capture stamp) join that
person's open group; a group closes when a camera it holds sends its next frame or when a view
comes more than ``max_skew_s`` after the group's first, and becomes an ``Instant`` if two or
more cameras are in it. Its time is the mean of its views' stamps; each view's offset is the
person's filtered floor velocity (the published ``vx``, ``vy``) times its time from there. A
person's first ``TrackerConfig.confirm_after_s`` (about 2 s) give nothing: the tracker confirms
them first.

``read_recording`` reads the observations of a site from an MCAP file of ``superbody record``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.site import Site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.calibration.residuals import Instant
from superbody.host.estimation.analytic import AnalyticEstimator

__all__ = ["RecordingError", "Frame", "read_recording", "person_instants", "MAX_SKEW_S"]

# Views further apart than this are not one instant: a person's velocity carries each view to
# the instant's time, but not a swinging arm (1-2 m/s at the wrist, 10 cm in 0.1 s).
MAX_SKEW_S: Final[float] = 0.1
_NS: Final[float] = 1e9


class RecordingError(ValueError):
    """A recording that cannot be read; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Frame:
    """One camera frame of a recording: its capture stamp, camera id and payload as published."""

    stamp_ns: int
    camera: str
    payload: bytes


def read_recording(path: str | Path, site: Site) -> tuple[list[Frame], int]:
    """The site's camera frames from an MCAP recording (``superbody record``), in capture order.

    Returns:
        ``(frames, rejected)``: the frames, and how many observation messages did not decode
        (or belong to another site or camera than their channel's).

    Raises:
        RecordingError: no such file, not MCAP (or the ``mcap`` package is missing), damaged, or
            no observation of this site's cameras in it.
    """
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    try:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader
    except ImportError:
        raise RecordingError(f"{path}: reading MCAP needs the mcap package (pip install 'superbody[view]')") from None
    topics = {transport.observation_key(site.name, c.id): c.id for c in site.cameras}
    frames: list[Frame] = []
    rejected = 0
    others: set[str] = set()
    with open(path, "rb") as f:
        if f.read(8) != b"\x89MCAP0\r\n":
            raise RecordingError(f"{path}: not an MCAP file (record one with `superbody record`)")
        f.seek(0)
        try:
            for _schema, channel, message in make_reader(f).iter_messages():
                cam = topics.get(channel.topic)
                if cam is None:
                    if channel.topic.endswith("/observations"):
                        others.add(channel.topic.split("/")[1])
                    continue
                try:
                    obs = wire.decode(message.data, expected_site=site.name)
                except wire.DecodeError:
                    rejected += 1
                    continue
                if obs.camera != cam:
                    rejected += 1
                    continue
                frames.append(Frame(obs.stamp_ns, cam, bytes(message.data)))
        except (McapError, ValueError, OSError, EOFError) as e:
            raise RecordingError(f"{path}: damaged MCAP file ({type(e).__name__}: {e})") from None
    if not frames:
        seen = f"; it holds observations of site(s) {', '.join(sorted(others - {site.name}))}" if others - {site.name} else ""
        raise RecordingError(f"{path}: no observation of site {site.name!r}'s cameras ({', '.join(site.camera_ids)}){seen}")
    order = {c: i for i, c in enumerate(site.camera_ids)}
    frames.sort(key=lambda fr: (fr.stamp_ns, order[fr.camera]))
    return frames, rejected


@dataclass
class _Group:
    """A person's open group of views: camera -> (stamp, keypoints); the velocity last published."""

    first_ns: int
    views: dict[str, tuple[int, np.ndarray]] = field(default_factory=dict)
    velocity: tuple[float, float] = (0.0, 0.0)


def _close(group: _Group, person: int) -> Instant | None:
    if len(group.views) < 2:
        return None
    cams = tuple(group.views)
    stamps = np.array([group.views[c][0] for c in cams], dtype=np.int64)
    t = int(stamps.mean())
    offsets = np.zeros((len(cams), 3))
    offsets[:, :2] = ((stamps - t) / _NS)[:, None] * np.asarray(group.velocity)
    return Instant(t, cams, np.stack([group.views[c][1] for c in cams]).astype(np.float64), offsets, person)


def person_instants(frames: Sequence[Frame], site: Site, *, max_skew_s: float = MAX_SKEW_S, config: HostConfig = HostConfig(),
                    progress: Callable[[int], None] | None = None) -> tuple[list[Instant], dict[str, int]]:
    """Each tracked person's near-simultaneous views (module docstring).

    Args:
        frames: the recording's camera frames in capture order (``read_recording``).
        site: the site as the recording's host knew it (its calibration places people for the tracker).
        max_skew_s: views further apart than this are not one instant.
        config: the host's parameters.
        progress: called with the number of frames done so far.

    Returns:
        ``(instants, counts)``: the instants in time order, and counts ("frames", "accepted",
        "people": track ids seen, "views": views grouped).
    """
    if not (0 < max_skew_s <= 1.0 and math.isfinite(max_skew_s)):
        raise ValueError(f"person_instants: max_skew_s must be in (0, 1], got {max_skew_s!r}")
    skew_ns = round(max_skew_s * _NS)
    agg = Aggregator(site, AnalyticEstimator(site), "analytic", config)
    keys = {c.id: transport.observation_key(site.name, c.id) for c in site.cameras}
    used: set[tuple[int, str, int]] = set()
    groups: dict[int, _Group] = {}
    out: list[Instant] = []
    views = 0
    i = 0
    while i < len(frames):
        stamp = frames[i].stamp_ns
        while i < len(frames) and frames[i].stamp_ns == stamp:
            agg.ingest(frames[i].payload, keys[frames[i].camera], stamp)
            i += 1
        arr = agg.step(stamp)
        if progress is not None:
            progress(i)
        for p in arr.people:
            track = agg.tracker.track(p.id)
            if track is None:
                continue
            new = sorted((sv.stamp_ns, cam, sv.view) for cam, sv in track.views.items() if (p.id, cam, sv.stamp_ns) not in used)
            for t, cam, view in new:
                used.add((p.id, cam, t))
                g = groups.get(p.id)
                if g is not None and (cam in g.views or t - g.first_ns > skew_ns):
                    done = _close(g, p.id)
                    if done is not None:
                        out.append(done)
                    g = None
                if g is None:
                    g = groups[p.id] = _Group(t)
                g.views[cam] = (t, view.keypoints)
                g.velocity = (p.vx, p.vy)
                views += 1
    for pid, g in groups.items():
        done = _close(g, pid)
        if done is not None:
            out.append(done)
    out.sort(key=lambda ins: ins.stamp_ns)
    counts = {"frames": len(frames), "accepted": agg.accepted, "people": len(groups), "views": views}
    return out, counts
