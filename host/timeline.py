"""The cameras' timelines: each frame admitted once, on arrival, and released to the tracker in capture order.

The host lives in capture time (DESIGN.md): real camera nodes deliver a frame 0.1-1.5 s after they
captured it, each camera at its own delay and frame rate, not in step with the others. ``Timeline``
is the one part of the host that knows it:

- **admission** (``admit``), once per frame, as it arrives. In order per camera: "late" (older
  than the camera's newest frame), "duplicate" (the same stamp or sequence number again),
  "seq_backwards" (the sequence number went back without a restart; a restarted node is recognised
  after ``restart_gap_s`` without frames, when the frame after a refused one continues the new
  count, or by ``reset_camera``). Across cameras: "stale" (older than anyone is kept) and
  "too_late" (captured before the watermark: the host has already fused that instant; a joining
  camera's first frames excepted, below). A camera's ordering reference is its newest stamp capped
  at the host's clock, so a frame stamped in the future cannot make the camera's real frames "late".
- **measurement**, per camera, continuously: the delivery delay (arrival minus capture) over its
  last frames, its frame period and rate, frames admitted, fused and dropped by reason (``stats``).
- **the watermark** (``watermark``): the newest capture instant up to which every camera still
  delivering has delivered. A camera's frames arrive in order, so once it has delivered a frame
  captured at t, nothing it sends later is older: every view captured up to the smallest of the
  cameras' newest stamps is in. Bounded by ``max_delay_s``: a camera whose newest frame is older
  than that (dead slow, stalled, gone) holds nobody back; its frames then arrive behind the
  watermark and are dropped as "too_late", counted and reported, never used silently out of time.
  A camera that joins (its first frame, or its first after a silence) behind the watermark stops
  it until its frames catch up, at most ``max_delay_s``; meanwhile its frames are used all the same,
  released at the next step a little out of order (the tracker and the filter take an older
  point with the distance walked since as extra noise), rather than lost.
  For the first ``max_delay_s`` after the host starts, until every camera of the site has
  delivered, the watermark waits that long, so a slow camera's first frames are not too late
  for want of having been heard of.
- **release** (``release``): the admitted frames captured up to the watermark, in capture order
  across all cameras, at most ``limit`` at a time (bounded work per tick): the tracker sees the
  world in the order it happened.

``RateLimit`` is the per-camera rate limit the host process applies before it even decodes a
payload: a camera may send a small multiple of its site fps; the excess is dropped and counted
against that camera, never against another camera's frames.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Final, NamedTuple

import numpy as np

from superbody.edge.messages.observation import Observation
from superbody.edge.site import Site

__all__ = ["ADMIT_REASONS", "DROP_REASONS", "CameraTimeline", "RateLimit", "Timeline"]

_NS = 1_000_000_000

# Why ``Timeline.admit`` refuses a frame, in the order checked.
ADMIT_REASONS: Final[tuple[str, ...]] = ("unknown_camera", "stale", "too_late", "late", "duplicate", "seq_backwards")
# Every reason a camera's frame is dropped after it arrived (``CameraTimeline.dropped``): the admission's, and
# "over_rate" (``RateLimit``).
DROP_REASONS: Final[tuple[str, ...]] = (*ADMIT_REASONS[1:], "over_rate")

_DELAYS_KEPT = 256  # delivery delays kept per camera for its percentiles: seconds of frames
_PERIODS_KEPT = 64  # stamp differences kept for its frame period
_EVENTS_KEPT = 4096  # arrivals kept per camera (admitted or why not), for the health window
HEALTH_WINDOW_S: Final[float] = 10.0  # the camera's health is judged on its last seconds of frames
# Health: a camera is "too_late" when more than this share of its frames in the window arrived
# behind the watermark; it shows "two_publishers" when at least this many of its frames in the
# window came out of order or repeated, and at least this share (one node in order has none).
TOO_LATE_SHARE: Final[float] = 0.05
DISORDER_MIN: Final[int] = 10
DISORDER_SHARE: Final[float] = 0.1
_DISORDER = frozenset({"late", "duplicate", "seq_backwards"})


class _Order(NamedTuple):
    """A camera's frame order: the reference its next frame must not be older than, and its newest frame."""

    ref_ns: int  # newest admitted stamp, capped at the host's clock when it was admitted
    stamp_ns: int  # stamp of the newest admitted frame
    seq: int  # its sequence number
    back_seq: int | None = None  # the last frame refused as seq_backwards since: its seq ...
    back_ns: int = 0  # ... and stamp


@dataclass(eq=False)
class CameraTimeline:
    """What the host knows of one camera's timing.

    Attributes:
        camera: the camera's id.
        site_fps: the frame rate the site file gives it.
        admitted: frames admitted.
        fused: views of this camera used in published poses.
        dropped: frames dropped, by reason (``DROP_REASONS``).
        newest_ns: capture stamp of its newest admitted frame (None before the first).
        last_arrival_ns: when its latest frame arrived, admitted or not, host clock (None before the first).
        released_ns: capture stamp of its newest frame released to the tracker (None before the first).
    """

    camera: str
    site_fps: float
    admitted: int = 0
    fused: int = 0
    dropped: Counter[str] = field(default_factory=Counter)
    newest_ns: int | None = None
    last_arrival_ns: int | None = None
    released_ns: int | None = None
    heard_ns: int | None = None  # newest stamp it delivered, admitted or too late: what the watermark waits for
    joined_ns: int | None = None  # when it last began delivering (first frame, or first after a silence of max_delay_s)
    _order: _Order | None = None
    _delays: deque[int] = field(default_factory=lambda: deque(maxlen=_DELAYS_KEPT))  # arrival - capture, ns
    _periods: deque[int] = field(default_factory=lambda: deque(maxlen=_PERIODS_KEPT))  # stamp differences, ns
    _events: deque[tuple[int, str]] = field(default_factory=lambda: deque(maxlen=_EVENTS_KEPT))  # (arrival, "admitted" or why not)

    def recent(self, now_ns: int, window_s: float = HEALTH_WINDOW_S) -> Counter[str]:
        """Its frames that arrived in the last ``window_s`` by outcome: "admitted" or the reason it was dropped."""
        since = now_ns - round(window_s * _NS)
        return Counter(what for at, what in self._events if at >= since)

    def delay_s(self, q: float = 50.0) -> float:
        """The ``q``-th percentile of its recent delivery delays (arrival minus capture), seconds; NaN before any frame."""
        return float(np.percentile(np.fromiter(self._delays, np.int64), q)) / _NS if self._delays else math.nan

    @property
    def period_s(self) -> float:
        """Its frame period measured from its recent stamps (median difference), else the site's."""
        if len(self._periods) >= 3:
            return float(np.median(np.fromiter(self._periods, np.int64))) / _NS
        return 1.0 / self.site_fps

    @property
    def fps(self) -> float:
        """Frames per second it has been capturing lately (NaN before three frames)."""
        return 1.0 / self.period_s if len(self._periods) >= 3 else math.nan


class Timeline:
    """Admission, timing and the watermark of one site's cameras; clock injected, no threads.

    Args:
        site: the site (its cameras and their fps).
        max_delay_s: the longest the host waits for a camera's frames after their capture: the
            watermark never lags the host's clock by more. A camera that delivers later than this
            is too late to be useful (its frames are dropped as "too_late" and the status says so).
        remove_after_s: a frame older than this could keep nobody alive ("stale").
        restart_gap_s: a camera whose sequence number goes back after this long without frames
            has restarted; before that its frames are "seq_backwards".
        start_ns: when the host started (its clock); the watermark waits ``max_delay_s`` from then.
    """

    def __init__(self, site: Site, max_delay_s: float, remove_after_s: float, restart_gap_s: float, start_ns: int | None = None) -> None:
        self.site = site
        self.cameras: dict[str, CameraTimeline] = {c.id: CameraTimeline(c.id, float(c.fps)) for c in site.cameras}
        self._max_delay_ns = round(max_delay_s * _NS)
        self._stale_ns = round(remove_after_s * _NS)
        self._restart_ns = round(restart_gap_s * _NS)
        self._start_ns = start_ns
        self._pending: list[tuple[int, int, Observation]] = []  # heap of (stamp, arrival order, frame)
        self._arrivals = itertools.count()
        self._mark_ns: int | None = None  # the watermark: every frame captured up to it has been released
        self.released = 0  # frames released to the tracker so far

    @property
    def mark_ns(self) -> int | None:
        """The watermark as last moved (``watermark``), or None before the first call."""
        return self._mark_ns

    @property
    def pending(self) -> int:
        """Admitted frames waiting for the watermark."""
        return len(self._pending)

    def admit(self, obs: Observation, now_ns: int) -> str | None:
        """Admit one frame that arrived at ``now_ns`` (host clock): None, and it waits for the
        watermark; or why it was dropped (one of ``ADMIT_REASONS``, counted against its camera)."""
        cam = self.cameras.get(obs.camera)
        if cam is None:
            return "unknown_camera"
        t, now = int(obs.stamp_ns), int(now_ns)
        if cam.last_arrival_ns is None or now - cam.last_arrival_ns > self._max_delay_ns:
            cam.joined_ns = now  # (re)joining: its first frames may be behind the watermark, and are used
        cam.last_arrival_ns = now
        cam._delays.append(now - t)  # of every frame that arrives: a camera too late to be used is measured too
        joining = cam.joined_ns is not None and now - cam.joined_ns <= self._max_delay_ns and t >= now - self._max_delay_ns
        why = self._refusal(cam, obs, t, now, joining)
        if why in (None, "too_late") and (cam.heard_ns is None or t > cam.heard_ns) and t <= now:
            # A camera that joins late (a restarted node, a slow one) holds the watermark from now
            # on: it stops until the camera's frames catch up with it, then they are used.
            cam.heard_ns = t
        if why is not None:
            cam.dropped[why] += 1
            cam._events.append((now, why))
            if why == "seq_backwards":  # remembered: if the next frame follows it, the node restarted
                assert cam._order is not None
                cam._order = cam._order._replace(back_seq=int(obs.seq), back_ns=t)
            return why
        prev = cam._order
        ref = min(t, now)  # a frame from the future is used, but cannot make the camera's real frames look late
        cam._order = _Order(ref if prev is None else max(prev.ref_ns, ref), t, int(obs.seq))
        if cam.newest_ns is not None and t > cam.newest_ns:
            cam._periods.append(t - cam.newest_ns)
        cam.newest_ns = t
        cam._events.append((now, "admitted"))
        cam.admitted += 1
        heapq.heappush(self._pending, (t, next(self._arrivals), obs))
        return None

    def _refusal(self, cam: CameraTimeline, obs: Observation, t: int, now: int, joining: bool) -> str | None:
        if now - t >= self._stale_ns:
            return "stale"
        if self._mark_ns is not None and t < self._mark_ns and not joining:
            return "too_late"
        o = cam._order
        if o is None:
            return None
        if t == o.stamp_ns or obs.seq == o.seq:
            return "duplicate"
        if t < o.ref_ns:
            return "late"
        restarted = t - o.stamp_ns >= self._restart_ns or (o.back_seq is not None and obs.seq == o.back_seq + 1 and t > o.back_ns)
        if obs.seq < o.seq and not restarted:
            return "seq_backwards"
        return None

    def count_drop(self, camera: str, reason: str, now_ns: int, n: int = 1) -> None:
        """Count ``n`` frames of a camera of the site dropped before admission (e.g. "over_rate") at ``now_ns``."""
        cam = self.cameras.get(camera)
        if cam is not None and n > 0:
            cam.dropped[reason] += n
            cam._events.extend([(int(now_ns), reason)] * min(n, _EVENTS_KEPT))

    def problems(self, now_ns: int) -> dict[str, list[str]]:
        """Per camera, what is wrong with its timing lately (empty lists for cameras that are fine).

        Each problem is a sentence for people and starts with a word for machines: "silent" (no
        frame yet, or none for longer than ``max_delay_s`` and three of its frame periods),
        "too_late" (it delivers later than the host waits: its p95 delay exceeds ``max_delay_s``,
        or more than ``TOO_LATE_SHARE`` of its recent frames arrived behind the watermark),
        "slow" (it captures at under half its site fps), "over_rate" (it sent faster than its rate
        limit), "two_publishers" (its frames come out of order or repeated, as when a second node
        publishes under its key).
        """
        now = int(now_ns)
        out: dict[str, list[str]] = {}
        max_delay = self._max_delay_ns / _NS
        started = self._start_ns is not None and now - self._start_ns >= self._max_delay_ns
        for cid, cam in self.cameras.items():
            found: list[str] = []
            out[cid] = found
            if cam.last_arrival_ns is None:
                if started:
                    found.append("silent: no frame received yet")
                continue
            quiet = (now - cam.last_arrival_ns) / _NS
            if quiet > max(max_delay, 3 * cam.period_s):
                found.append(f"silent: no frame for {quiet:.1f} s")
            recent = cam.recent(now)
            total = sum(recent.values())
            p95 = cam.delay_s(95)
            if p95 > max_delay:
                found.append(f"too_late: frames arrive {p95:.2f} s after capture (p95), later than the host waits "
                             f"({max_delay:.2f} s, --max-delay): its views are left out")
            elif total and recent["too_late"] > TOO_LATE_SHARE * total:
                found.append(f"too_late: {recent['too_late']} of its last {total} frames arrived after the host had fused their instant "
                             f"(p95 delay {p95:.2f} s, the host waits {max_delay:.2f} s)")
            if cam.fps < 0.5 * cam.site_fps and not quiet > max_delay:
                found.append(f"slow: {cam.fps:.1f} fps, the site file says {cam.site_fps:g}")
            if recent["over_rate"]:
                found.append(f"over_rate: {recent['over_rate']} frames in {HEALTH_WINDOW_S:g} s beyond its rate limit were dropped")
            disorder = sum(recent[k] for k in _DISORDER)
            if disorder >= DISORDER_MIN and disorder >= DISORDER_SHARE * total:
                found.append(f"two_publishers: {disorder} of its last {total} frames came out of order or repeated, as when two "
                             "nodes publish under its key (a restarted node still running, or a stranger: see docs/security.md)")
        return out

    def reset_camera(self, camera: str) -> None:
        """Forget a camera's frame order, e.g. when its node restarted (its liveliness token came back)."""
        cam = self.cameras.get(camera)
        if cam is not None:
            cam._order = None

    def watermark(self, now_ns: int) -> int:
        """Move the watermark for the host's clock reading ``now_ns`` and return it (never backwards).

        The smallest newest stamp of the cameras that delivered within ``max_delay_s`` (of a frame
        admitted or too late: a camera that joins behind the watermark stops it until its frames
        catch up), never further back than ``now_ns - max_delay_s`` nor later than ``now_ns``.
        """
        now = int(now_ns)
        floor = now - self._max_delay_ns
        if self._start_ns is None:
            self._start_ns = now
        waiting = list(self._heard_within(now).values())
        if now - self._start_ns < self._max_delay_ns and any(c.heard_ns is None for c in self.cameras.values()):
            waiting.append(floor)  # just started, and a camera has not spoken yet: it may be a slow one
        mark = min(min(waiting) if waiting else floor, now)
        mark = max(mark, floor)
        if self._mark_ns is None or mark > self._mark_ns:
            self._mark_ns = mark
        return self._mark_ns

    def delivering(self, now_ns: int) -> set[str]:
        """The cameras the watermark waits for at ``now_ns``: those that delivered within ``max_delay_s``."""
        return set(self._heard_within(now_ns))

    def _heard_within(self, now_ns: int) -> dict[str, int]:
        """The newest stamp of each camera that delivered within ``max_delay_s`` of ``now_ns``."""
        floor = int(now_ns) - self._max_delay_ns
        return {cid: c.heard_ns for cid, c in self.cameras.items() if c.heard_ns is not None and c.heard_ns >= floor}

    def release(self, limit: int) -> list[Observation]:
        """The admitted frames captured up to the watermark, in capture order (at most ``limit``)."""
        out: list[Observation] = []
        mark = self._mark_ns
        while self._pending and mark is not None and self._pending[0][0] <= mark and len(out) < limit:
            _, _, obs = heapq.heappop(self._pending)
            out.append(obs)
            self.cameras[obs.camera].released_ns = int(obs.stamp_ns)
        self.released += len(out)
        return out

    def released_to(self) -> int | None:
        """The instant the tracker has seen every frame up to: the watermark, or just before the
        oldest frame still waiting under it when ``release`` was limited."""
        if self._mark_ns is None:
            return None
        if self._pending and self._pending[0][0] <= self._mark_ns:
            return self._pending[0][0] - 1
        return self._mark_ns


class RateLimit:
    """A token bucket per camera: at most ``factor`` times the camera's site fps, with a burst of
    ``burst_s`` of that rate (at least 4 frames). Thread-safety is the caller's."""

    def __init__(self, site: Site, factor: float, burst_s: float = 0.5) -> None:
        self._rate = {c.id: factor * float(c.fps) for c in site.cameras}
        self._cap = {cid: max(4.0, r * burst_s) for cid, r in self._rate.items()}
        self._tokens = dict(self._cap)
        self._at: dict[str, int] = {}

    def allow(self, camera: str, now_ns: int) -> bool:
        """Whether a frame of ``camera`` arriving at ``now_ns`` is within its rate (cameras outside the site: always;
        the decoder refuses them)."""
        rate = self._rate.get(camera)
        if rate is None:
            return True
        last = self._at.get(camera, now_ns)
        self._at[camera] = now_ns
        tokens = min(self._cap[camera], self._tokens[camera] + rate * max(0, now_ns - last) / _NS)
        if tokens < 1.0:
            self._tokens[camera] = tokens
            return False
        self._tokens[camera] = tokens - 1.0
        return True
