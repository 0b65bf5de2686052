"""The host aggregator: Observations from every camera of a site in, PoseArrays out.

The pure core, clock-injected, in capture time: ``ingest()`` validates one payload as it arrives
and hands it to the cameras' timeline (``host.timeline``), which admits it once (frames out of
order, duplicated, stale, from the future or behind the watermark are rejected by reason) and
measures each camera's delivery delay and frame rate; ``camera_liveliness()`` admits only the
site's own cameras, so no name a peer puts in a liveliness key ever reaches an encoder.
``step()`` moves the watermark (the newest capture instant every camera still delivering has
delivered up to), feeds the tracker the frames captured up to it in capture order (a bounded
number per step), an instant at a time (every delivering camera's frame of it together; an
instant the watermark has not wholly passed waits for the next step), prunes, takes each confirmed
person's set S as of the end of each instant (their latest view per camera, fresh then, so no
view goes unestimated however seldom the host steps),
estimates the people whose views changed in one batched call per instant, filters (each
estimate taken at the mean capture time of its views, the pose predicted on to the newest
view's time), and returns the PoseArray. So a late camera's views are fused with the
other cameras' views of the same instant, and the poses describe the world as of the watermark:
``PoseArray.latency_ns`` is the host clock at the step minus that instant. Bad payloads are
counted by reason and dropped, never fatal. The process around it is ``host/service.py``.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.calibration.health import CalibrationHealth
from superbody.host.estimation.estimator import Estimator, detailed
from superbody.host.filtering.pose_filter import FilterConfig, PoseFilter, predict_many, update_many
from superbody.host.messages import pose as pose_msg
from superbody.host.messages.pose_rules import MAX_SPEED
from superbody.host.timeline import Timeline
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.tracker import Tracker

__all__ = ["HostConfig", "Aggregator", "confidence", "confidences"]

log = logging.getLogger("superbody.host")

_NS = 1_000_000_000


@dataclass(frozen=True)
class HostConfig:
    """Host parameters.

    Attributes:
        freshness_s: a camera's latest view of a person counts in set S while it was captured at
            most this long before the instant the host fuses (the watermark).
        max_delay_s: the longest the host waits for a camera's frames after their capture: the
            poses it publishes are at most this old (plus processing). A camera that delivers
            later is too late to be useful: its frames are dropped ("too_late") and the status
            says so. 1.5 s: real nodes deliver 0.1-1.5 s after capture.
        restart_gap_s: a camera whose sequence number goes back is taken as restarted (its
            frames are admitted again) after this long without frames from it, when the frame
            after a refused one continues the new count, or when its liveliness token comes
            back; otherwise such frames are dropped as "seq_backwards". A forged frame with a
            high sequence number therefore costs a camera one real frame, never its view.
        max_rate_factor: a camera may send this many times its site fps; the host process drops
            the excess ("over_rate", ``host.timeline.RateLimit``) before decoding it.
        max_frames_per_step: frames fed to the tracker per step at most; the rest wait for the
            next step (bounded work per tick, however much arrived).
        watch_calibration_s: each person's set S goes to the calibration monitor
            (``host.calibration.health``: whether each camera still sits where the site file says)
            at most this often, seconds of capture time (0: the monitor is off). 0.2: 0.5 ms a
            call, so 10 people cost 25 ms a second.
        max_future_s: observations stamped further ahead of the host's clock are rejected
            (nodes are NTP-synced to milliseconds; a looser limit lets a peer's stamps run ahead).
        queue_size: observations waiting to be processed; beyond it the oldest are dropped.
        queue_bytes: the same bound in payload bytes (16 MiB: seconds of a 10-camera site's
            traffic; a backlog longer than that is stale anyway).
        min_publish_hz: publish at least this often even with no new data.
        max_publish_hz: publish at most this often (0: after every batch of arrivals).
        status_every_s: period of the one-line status log.
        tracker: tracker parameters (the paper's by default).
        filter: temporal filter parameters; ``filter.enabled=False`` gives per-frame output.
    """

    freshness_s: float = 0.5
    max_delay_s: float = 1.5
    restart_gap_s: float = 1.0
    max_rate_factor: float = 2.0
    max_frames_per_step: int = 256
    watch_calibration_s: float = 0.2
    max_future_s: float = 0.25
    queue_size: int = 4096
    queue_bytes: int = 16 * 1024 * 1024
    min_publish_hz: float = 5.0
    max_publish_hz: float = 0.0
    status_every_s: float = 10.0
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)

    def __post_init__(self) -> None:
        for name, lo, hi in (("freshness_s", 0.01, 60.0), ("max_delay_s", 0.0, 60.0), ("restart_gap_s", 0.0, 600.0),
                             ("max_rate_factor", 1.0, 1000.0), ("watch_calibration_s", 0.0, 60.0), ("max_future_s", 0.0, 3600.0), ("min_publish_hz", 0.1, 1000.0),
                             ("max_publish_hz", 0.0, 1000.0), ("status_every_s", 0.1, 3600.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"HostConfig.{name} must be in [{lo}, {hi}], got {v!r}")
        if not (type(self.max_frames_per_step) is int and 1 <= self.max_frames_per_step <= 1_000_000):
            raise ValueError(f"HostConfig.max_frames_per_step must be an integer in [1, 1000000], got {self.max_frames_per_step!r}")
        if self.max_delay_s >= self.tracker.remove_after_s:
            raise ValueError(f"HostConfig.max_delay_s ({self.max_delay_s}) must be shorter than tracker.remove_after_s "
                             f"({self.tracker.remove_after_s}): a person would be removed before their late views could arrive")
        if not 1 <= self.queue_size <= 1_000_000:
            raise ValueError(f"HostConfig.queue_size must be in [1, 1000000], got {self.queue_size!r}")
        if not wire.MAX_PAYLOAD_BYTES <= self.queue_bytes <= 2**34:
            raise ValueError(f"HostConfig.queue_bytes must be in [{wire.MAX_PAYLOAD_BYTES}, {2**34}], got {self.queue_bytes!r}")


def confidence(views: dict[str, PersonView]) -> float:
    """A heuristic in [0, 1]: how much of the body was seen, and how surely.

    The sum over views of the detected joints' scores, over 25 (a person seen whole by one
    camera and half by another scores about 1). Use the covariance for uncertainty in metres.
    """
    return float(confidences([views])[0]) if views else 0.0


def confidences(view_sets: list[dict[str, PersonView]]) -> NDArray[np.float64]:
    """``confidence`` of each of a batch of non-empty view sets (B,), in one pass."""
    scores = np.stack([v.keypoints[:, 2] for views in view_sets for v in views.values()])  # (V, 17)
    per_view = np.where(np.isfinite(scores), scores, 0.0).sum(axis=1, dtype=np.float64)  # (V,)
    starts = np.cumsum([0] + [len(views) for views in view_sets[:-1]])  # (B,) each set's first view
    return np.minimum(1.0, np.add.reduceat(per_view, starts) / 25.0)


class Aggregator:
    """Tracks people and estimates their poses; clock injected, no threads, no I/O.

    Args:
        site: the site.
        estimator: turns view sets into (x, y, yaw) (host.estimation.estimator).
        estimator_name: reported in every PoseArray, e.g. ``onnx:wtf-apartment.int8.onnx``.
        config: parameters.
        start_ns: when the host started, its clock (the watermark waits ``max_delay_s`` from
            then for cameras it has not heard from yet); the first ``step``'s clock by default.
    """

    def __init__(self, site: Site, estimator: Estimator, estimator_name: str, config: HostConfig = HostConfig(),
                 start_ns: int | None = None):
        self.site = site
        self.estimator = estimator
        self.estimator_name = estimator_name
        self.config = config
        self.tracker = Tracker(site, config.tracker)
        self.timeline = Timeline(site, config.max_delay_s, config.tracker.remove_after_s, config.restart_gap_s, start_ns)
        self.as_of_ns: int | None = None  # the instant the last step fused every camera up to
        self.calibration = CalibrationHealth(site)
        self._watched: dict[int, int] = {}  # track -> stamp of the set S last given to the calibration monitor
        self.rejected: Counter[str] = Counter()
        self.accepted = 0
        self.cameras_alive: set[str] = set()
        self.cameras_gone: set[str] = set()  # liveliness token dropped and not back
        self._filters: dict[int, PoseFilter] = {}
        self._last_input: dict[int, int] = {}  # track -> newest view stamp already estimated
        self._poses: dict[int, tuple[pose_msg.PersonPose, int]] = {}  # track -> (pose, newest stamp)
        self._open: list[Observation] = []  # the frames of the instant still open: released, not associated yet
        self._fused_ns: int | None = None  # capture time of the last frame associated
        self._sets: tuple[int, dict[int, dict[str, PersonView]]] | None = None  # the last sets S estimated, and as of when
        self._cam_size = {c.id: (c.width, c.height) for c in site.cameras}
        self._cam_order = {c.id: i for i, c in enumerate(site.cameras)}
        self._seq = 0
        # Reached by one call per instant estimated: the estimator's own sigmas and sources, or its poses with the
        # host's estimator name as every person's source.
        self._estimate = detailed(estimator, estimator_name.split(":", 1)[0]).estimate_detailed

    def ingest(self, payload: bytes, key: str | None, now_ns: int) -> bool:
        """Validate one observation payload and feed the tracker.

        Returns:
            True if accepted; otherwise the reason is counted in ``rejected`` and it is dropped.
        """
        try:
            obs = wire.decode(payload, expected_site=self.site.name)
        except wire.DecodeError as e:
            return self._reject(e.reason, f"{key}: {e}")
        key_camera = transport.camera_from_key(key) if key else obs.camera
        if key_camera != obs.camera:
            return self._reject("key_mismatch", f"{key}: payload camera {obs.camera!r} differs from the key's")
        size = self._cam_size.get(obs.camera)
        if size is None:
            return self._reject("unknown_camera", f"camera {obs.camera!r} is not in site {self.site.name!r}")
        if size != (obs.width, obs.height):
            return self._reject("image_size", f"camera {obs.camera}: image {obs.width}x{obs.height}, the site says {size[0]}x{size[1]}")
        if obs.stamp_ns > now_ns + self.config.max_future_s * _NS:
            return self._reject("future_stamp", f"camera {obs.camera}: stamp {(obs.stamp_ns - now_ns) / _NS:.1f} s ahead of the host clock")
        why = self.timeline.admit(obs, now_ns)
        if why is not None:
            return self._reject(why, f"camera {obs.camera}: frame {obs.seq} captured {(now_ns - obs.stamp_ns) / _NS:.2f} s ago "
                                     f"({_DROP_DETAIL.get(why, why)})")
        self.accepted += 1
        return True

    def camera_liveliness(self, key: str, alive: bool) -> bool:
        """A camera's liveliness token appeared (``alive``) or went; only the site's cameras count.

        A token under ``superbody/<site>/cameras/`` may be declared by any peer: its camera name
        is untrusted. Unknown names are counted as ``unknown_camera_alive`` and ignored, so
        ``cameras_alive`` only ever holds the site's camera ids.

        Returns:
            True if the key named a camera of the site.
        """
        cam = transport.camera_from_key(key)
        if cam not in self._cam_size:
            return self._reject("unknown_camera_alive", f"liveliness token {str(key)[:200]!r} names no camera of site {self.site.name!r}")
        if alive:
            if cam not in self.cameras_alive:
                log.info("camera %s is alive", cam)
                self.timeline.reset_camera(cam)  # a (re)started node counts its frames from 0 again
            self.cameras_alive.add(cam)
            self.cameras_gone.discard(cam)
        else:
            self.cameras_alive.discard(cam)
            self.cameras_gone.add(cam)
            log.warning("camera %s is gone (liveliness token dropped); it stops contributing", cam)
        return True

    def _reject(self, reason: str, detail: str) -> bool:
        self.rejected[reason] += 1
        # Log the first few of each reason, then every 1000th: a flood must not flood the log.
        n = self.rejected[reason]
        if n <= 3 or n % 1000 == 0:
            log.warning("rejected observation (%s, %d so far): %s", reason, n, detail)
        return False

    def step(self, now_ns: int) -> pose_msg.PoseArray:
        """Fuse the frames the watermark passed, prune, estimate the people with new views, filter,
        and build the PoseArray as of the fused instant (``as_of_ns``).

        The frames come in capture order and are grouped into instants: an instant ends when every
        camera still delivering (``Timeline.delivering``) has a frame in it, or before a camera's
        next frame, or before a frame of the site's first delivering camera (so two hosts fed the
        same frames group them alike, wherever each started). Then, and only then, its frames are
        associated with the people together
        (``Tracker.update_instant``) and the people estimated as of its end (``_estimate_sets``), so
        a set S of one instant is estimated before the next frame replaces one of its views. An
        instant still open at the step's end is held for the next step (at most one frame per
        camera) and the PoseArray describes the instant before it: however the cameras deliver
        (at once, in bunches, late), the tracker sees the same instants."""
        self.timeline.watermark(now_ns)
        delivering = self.timeline.delivering(now_ns)
        first = min(delivering, key=self._cam_order.__getitem__, default=None)
        for obs in self.timeline.release(self.config.max_frames_per_step):
            if self._open and (obs.camera == first or any(f.camera == obs.camera for f in self._open)):
                self._close_instant()  # an instant starts at the site's first delivering camera, and has one frame per camera
            self._open.append(obs)
            if delivering <= {f.camera for f in self._open}:  # every camera that delivers is in: it ends here
                self._close_instant()
        t = self.timeline.released_to()
        assert t is not None  # the watermark has been moved
        if self._open:  # the people as of the last instant associated
            t = min(t, self._fused_ns if self._fused_ns is not None else int(self._open[0].stamp_ns) - 1)
        self.as_of_ns = t
        for tr in self.tracker.prune(t):
            self._watched.pop(tr.id, None)
            self._filters.pop(tr.id, None)
            self._last_input.pop(tr.id, None)
            self._poses.pop(tr.id, None)
        sets = self._estimate_sets(t)
        people = tuple(p for tid, (p, _) in sorted(self._poses.items()) if tid in sets)
        self._seq += 1
        return pose_msg.PoseArray(
            site=self.site.name, seq=self._seq, stamp_ns=now_ns, people=people, latency_ns=max(0, int(now_ns) - t),
            cameras_alive=tuple(sorted(self.cameras_alive)), estimator=self.estimator_name,
        )

    def _close_instant(self) -> None:
        """Associate the open instant's frames with the people together and estimate the people as of its end."""
        self.tracker.update_instant(self._open)
        self._sets = None  # the tracker has changed
        self._fused_ns = int(self._open[-1].stamp_ns)
        self._open = []
        self._estimate_sets(self._fused_ns)

    def _estimate_sets(self, t: int) -> dict[int, dict[str, PersonView]]:
        """Estimate and filter the people whose set S as of ``t`` holds a view not estimated yet; return every set S.

        The tracker changes only when an instant is associated, and that estimates its sets: the
        sets as of that instant again (a step that leaves the next instant open) are the same, less
        the tracks pruned since."""
        if self._sets is not None and self._sets[0] == t:
            return {tid: views for tid, views in self._sets[1].items() if self.tracker.track(tid) is not None}
        sets = self.tracker.view_sets(t, self.config.freshness_s)
        self._sets = t, sets
        stamps_of: dict[int, list[int]] = {}
        for tid, views in sets.items():
            track = self.tracker.track(tid)
            assert track is not None  # view_sets lists live tracks only
            stamps_of[tid] = [track.views[c].stamp_ns for c in views]
        newest = {tid: max(st) for tid, st in stamps_of.items()}
        todo = [tid for tid in sets if newest[tid] > self._last_input.get(tid, -1)]
        if todo:
            # Every person whose views changed since their last estimate, once, in one batched call.
            est = self._estimate([sets[tid] for tid in todo])
            for tid in todo:
                self._last_input[tid] = newest[tid]
            ok = np.isfinite(est.pose).all(axis=1)  # (B,)
            if not ok.all():
                self.rejected["no_estimate"] += int((~ok).sum())
            rows = np.flatnonzero(ok)
            tids = [todo[i] for i in rows]
            for tid in tids:
                for cam in sets[tid]:
                    self.timeline.cameras[cam].fused += 1
            stamps = [newest[tid] for tid in tids]
            filters = [self._filters.setdefault(tid, PoseFilter(self.config.filter)) for tid in tids]
            # The cameras are not synchronised: set S mixes views captured up to a frame or more
            # apart, and an estimate from them describes the person at about the mean of their
            # capture times. The filter takes it there (never before its own state's time: it would
            # drop it) and the pose is predicted on to the newest view's time.
            measured = [max(sum(stamps_of[tid]) // len(stamps_of[tid]), f.stamp_ns or 0) for tid, f in zip(tids, filters)]
            # The estimator's own sigma is the measurement noise: a poor single-view yaw moves a track less.
            # A position where one body with the person's views could not stand (set S gone wrong:
            # partial views through a doorway, 1-3 m off) is not taken: the track's own is. An
            # estimator that gives no sigma is not tested (the filter's default is a setting, not
            # its error: at 3 cm, dev.json's live figures got worse, 69.0 -> 72.3 mm in x).
            pose, std = est.pose[rows].copy(), est.std[rows].copy()
            var = np.eye(2) * np.where(std[:, :2] > 0, std[:, :2], np.nan)[:, None, :] ** 2  # (B, 2, 2) diagonal
            off, pred, pcov = self.tracker.off_track(tids, pose[:, :2], measured, var)
            pose[off, :2], std[off, :2] = pred[off], np.sqrt(np.diagonal(pcov[off], axis1=1, axis2=2))
            if off.any():
                self.rejected["estimate_off_track"] += int(off.sum())
            update_many(filters, measured, pose, std)
            fps = predict_many(filters, stamps)
            self._watch_calibration(tids, sets, stamps_of, newest, fps)
            conf = confidences([sets[tid] for tid in tids]).tolist() if tids else []
            for i, tid, fp, c in zip(rows, tids, fps, conf):
                views = sets[tid]
                # Rates beyond what the message allows (a finite difference over estimates a few
                # ms apart, without the filter) are clamped: one person's field, never the array.
                vx, vy, yaw_rate = (min(max(v, -MAX_SPEED), MAX_SPEED) for v in (fp.vx, fp.vy, fp.yaw_rate))
                self._poses[tid] = (pose_msg.PersonPose(
                    id=tid, x=fp.x, y=fp.y, yaw=fp.yaw, vx=vx, vy=vy, yaw_rate=yaw_rate,
                    cov=fp.cov, confidence=c, cameras=tuple(sorted(views)),
                    stamp_ns=newest[tid], views=len(views), estimator=est.source[i],
                ), newest[tid])
        return sets

    def _watch_calibration(self, tids: list[int], sets: dict[int, dict[str, PersonView]], stamps_of: dict[int, list[int]],
                           newest: dict[int, int], poses: list) -> None:
        """Each person's set S of two views or more to the calibration monitor, at most every ``watch_calibration_s``."""
        every = round(self.config.watch_calibration_s * _NS)
        if every <= 0:
            return
        for tid, fp in zip(tids, poses):
            views = sets[tid]
            if len(views) >= 2 and newest[tid] - self._watched.get(tid, -every) >= every:
                self._watched[tid] = newest[tid]
                self.calibration.observe(views, newest[tid], stamps=dict(zip(views, stamps_of[tid])), velocity=(fp.vx, fp.vy), person=tid)


_DROP_DETAIL = {
    "late": "older than one already processed",
    "duplicate": "the same stamp or sequence number as the last one",
    "seq_backwards": "sequence number went back without a restart",
    "stale": "too old to keep anyone alive",
    "too_late": "captured before the instant the host had already fused: it delivers later than --max-delay",
}


