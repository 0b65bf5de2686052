"""Calibration health: whether each camera still sits where the site file says, from the people
walking by.

``CalibrationHealth`` is fed each confirmed person's set S as the host tracks them
(``observe``) and keeps, per camera, the leave-one-out residuals of its joints
(``host.calibration.residuals``) over a sliding window; ``report`` gives per camera their
median in pixels and degrees, the counts, and whether the camera ``moved``.

Why the median residual alone cannot say which camera moved: a joint triangulated from the
other cameras carries the moved camera's error into every camera's residual. With three
cameras the others of each camera are two, one of them the moved one whenever it is not
itself: on WheresTheFellow a camera turned 2 deg and shifted 10 cm gives the two untouched
cameras median residuals as large as its own (``docs/calibration.md``). So ``moved`` is
decided by a test of each hypothesis "this camera alone moved" (``attribute``): over recent
instants, a bundle adjustment that frees only that camera (``host.calibration.bundle``). The
camera that moved is the one whose freeing removes most of the people's misfit, clearly more
than any other; it is flagged when that share (``EXPLAINED_MIN``), its lead (``LEAD_MIN``)
and the image shift its refinement implies (``SHIFT_MIN_DEG``) all pass. The test runs once
``MIN_CHECK_INSTANTS`` instants of three or more views are in the window, at most once per
``check_every_s`` (it costs a bundle adjustment per camera); everything else is medians over
the window. A camera whose median is above ``SUSPECT_DEG`` but that the test does not single out
is "suspect": the calibration is off, the people do not say where. The constants are measured
in ``docs/calibration.md`` (``python -m benchmarks.people_calibration``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
from numpy.typing import NDArray

from superbody.edge.camera import Camera
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.host.calibration.bundle import MIN_FIXED, build_problem, refine_cameras
from superbody.host.calibration.residuals import Instant, instant_from_views, instant_residuals

__all__ = ["CameraHealth", "CalibrationHealth", "Attribution", "attribute", "image_shift_deg", "HealthState", "SUSPECT_DEG",
           "EXPLAINED_MIN", "LEAD_MIN", "SHIFT_MIN_DEG", "MIN_SAMPLES",
           "MIN_CHECK_INSTANTS"]

HealthState = Literal["unknown", "ok", "suspect", "moved"]

# A camera's window needs this many joint residuals (about 10 views) before its median counts.
MIN_SAMPLES: Final[int] = 100
# Above this median residual a camera is suspect: healthy real cameras stay under 1.4 deg over
# 15-30 s (WheresTheFellow, OpenPifPaf); simulated ones under 0.5.
SUSPECT_DEG: Final[float] = 2.0
# The test flags a camera when freeing it alone removes at least this share of the misfit (on
# the healthy WheresTheFellow site up to 0.28) ...
EXPLAINED_MIN: Final[float] = 0.35
# ... and at least this share of what freeing the runner-up leaves, (best - second) / (1 - second):
# on the knocked WheresTheFellow sites (24 knocks, the test every 2 s) a wrong camera led at 0.15
# once and at 0.1 four times, never at 0.2; a knocked simulated camera leads by 0.5-0.98 ...
LEAD_MIN: Final[float] = 0.3
# ... and its refined pose moves the image of its people's joints by at least this much (up to
# 0.85 deg on the healthy WheresTheFellow site: how far its joints disagree with its calibration).
SHIFT_MIN_DEG: Final[float] = 1.0
_CHECK_INSTANTS: Final[int] = 60  # instants the test adjusts over, evenly spread over the window
# The test waits for this many kept instants of three or more views: on fewer, each hypothesis's
# six unknowns fit the detector's noise (WheresTheFellow: with 12, a wrong camera once in 24
# knocks; with 20 or 30, never).
MIN_CHECK_INSTANTS: Final[int] = 30
_CHECK_NFEV: Final[int] = 30


@dataclass(frozen=True)
class CameraHealth:
    """One camera's health over the monitor's window.

    Attributes:
        camera: the camera id.
        residual_px: median leave-one-out residual of its joints, pixels (NaN without samples).
        residual_deg: the same as an angle between rays, degrees (any resolution alike).
        samples: joint residuals in the window.
        views: views they came from.
        state: "unknown" (fewer than ``MIN_SAMPLES``), "ok", "suspect" (median above
            ``SUSPECT_DEG`` but not found to have moved) or "moved".
        moved: ``state == "moved"``.
        explained: share of the people's misfit that refining this camera alone removes, from
            the last test (NaN when none ran).
        shift_deg: how far that refinement moves the image of its people's joints, median, degrees (NaN likewise).
        correction_deg, correction_m: that refinement's rotation and optical-centre shift (NaN likewise).
    """

    camera: str
    residual_px: float
    residual_deg: float
    samples: int
    views: int
    state: HealthState
    moved: bool
    explained: float = math.nan
    shift_deg: float = math.nan
    correction_deg: float = math.nan
    correction_m: float = math.nan


@dataclass(frozen=True)
class Attribution:
    """The one-camera test's result.

    Attributes:
        moved: the cameras found to have moved (at most one per test round).
        explained: camera id -> share of the misfit that freeing it alone removes.
        shift_deg: camera id -> median image shift of its joints under that refinement, degrees.
        correction: camera id -> (rotation deg, optical-centre shift m) of that refinement.
        cameras: the cameras as the test refined them (the moved ones changed).
    """

    moved: tuple[str, ...]
    explained: dict[str, float]
    shift_deg: dict[str, float]
    correction: dict[str, tuple[float, float]]
    cameras: tuple[Camera, ...]


def image_shift_deg(before: Camera, after: Camera, points: NDArray) -> float:
    """Median angle (degrees) by which the rays from a camera to world points (N, 3) turn between two poses of it."""
    if not len(points):
        return math.nan
    a = (points - before.t) @ before.R  # (N, 3) camera frame
    b = (points - after.t) @ after.R
    cos = np.einsum("nc,nc->n", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return float(np.degrees(np.median(np.arccos(np.clip(cos, -1.0, 1.0)))))


def attribute(cameras: Sequence[Camera], instants: Sequence[Instant], candidates: Sequence[str] | None = None,
              max_nfev: int = _CHECK_NFEV) -> Attribution:
    """Test "this camera alone moved" for each candidate (default: every camera) over ``instants``.

    A bundle adjustment of the points alone gives the misfit with every camera as it is; one
    that also frees camera h gives what is left if h alone moved. h moved when its share
    removed is at least ``EXPLAINED_MIN``, it removes at least ``LEAD_MIN`` of what freeing
    the runner-up leaves, and its refined pose shifts the image of its joints by at least
    ``SHIFT_MIN_DEG``.

    Returns:
        The ``Attribution``; nothing moved when fewer than ``MIN_FIXED + 1`` cameras or no
        joint two cameras saw.
    """
    cams = tuple(cameras)
    ids = [c.id for c in cams]
    cands = [c for c in (ids if candidates is None else candidates) if c in ids]
    prob = build_problem(instants, cams)
    empty = Attribution((), {}, {}, {}, cams)
    if len(cams) < MIN_FIXED + 1 or not len(prob.points) or not cands:
        return empty
    base = refine_cameras(cams, prob, [], max_nfev=max_nfev)
    if not base.cost_after > 0:
        return empty
    explained, shift, corr, refined = {}, {}, {}, {}
    for h in cands:
        i = ids.index(h)
        seen = np.unique(prob.point[prob.camera == i])
        if len(seen) < 3:
            continue
        r = refine_cameras(cams, prob, [h], max_nfev=max_nfev)
        explained[h] = 1.0 - r.cost_after / base.cost_after
        shift[h] = image_shift_deg(cams[i], r.cameras[i], prob.points[seen])
        corr[h] = (r.changes[h].rotation_deg, r.changes[h].position_m)
        refined[h] = r.cameras
    if not explained:
        return empty
    order = sorted(explained, key=lambda c: -explained[c])
    best = order[0]
    second = explained[order[1]] if len(order) > 1 else 0.0
    lead = (explained[best] - second) / max(1.0 - second, 1e-12)  # of the misfit the runner-up leaves, the share the leader removes
    moved = (best,) if explained[best] >= EXPLAINED_MIN and lead >= LEAD_MIN and shift[best] >= SHIFT_MIN_DEG else ()
    return Attribution(moved, explained, shift, corr, refined[best] if moved else cams)


class CalibrationHealth:
    """Per-camera calibration health from people's views over a sliding window.

    Args:
        site: the site whose calibration is watched.
        window_s: the window, seconds of capture time.
        check_every_s: the one-camera test runs at most this often (it costs a bundle
            adjustment per camera and one more, over up to 60 instants: 0.1-0.3 s for 3 cameras, 0.5 s for 5).
        reservoir_every_s: at most one instant per person this often is kept for the test.
        max_views: each camera keeps at most this many views' residuals (memory bound).
    """

    def __init__(self, site: Site, window_s: float = 30.0, check_every_s: float = 10.0, reservoir_every_s: float = 0.2,
                 max_views: int = 20_000) -> None:
        for name, v, lo, hi in (("window_s", window_s, 1.0, 3600.0), ("check_every_s", check_every_s, 0.0, 3600.0),
                                ("reservoir_every_s", reservoir_every_s, 0.0, 60.0)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"CalibrationHealth: {name} must be in [{lo}, {hi}], got {v!r}")
        self.site = site
        self.cameras = {c.id: c for c in site.cameras}
        self.window_ns = round(window_s * 1e9)
        self.check_ns = round(check_every_s * 1e9)
        self.keep_ns = round(reservoir_every_s * 1e9)
        # Per camera: (capture stamp, degrees (M,), pixels (M,)) of each measured view.
        self._res: dict[str, deque[tuple[int, NDArray[np.float64], NDArray[np.float64]]]] = {
            c: deque(maxlen=max_views) for c in self.cameras}
        self._measured: dict[tuple[int, str], int] = {}  # (person, camera) -> newest view stamp measured
        self._instants: deque[Instant] = deque(maxlen=max(1, max_views // 4))
        self._kept: dict[tuple[int, int], int] = {}  # (person, 2 or 3+ views) -> stamp of the last instant kept
        self._last_check: int | None = None
        self._attribution: Attribution | None = None
        self._calls = 0

    def observe(self, views: Mapping[str, PersonView], stamp_ns: int, *, stamps: Mapping[str, int] | None = None,
                velocity: Sequence[float] | None = None, person: int = -1) -> int:
        """Measure one person's set S.

        Args:
            views: camera id -> the person's latest view (the host's set S); unknown cameras are ignored.
            stamp_ns: the set's time (the newest view's capture time).
            stamps: each view's capture time; with ``person``, a view already measured is not
                counted again when the same set comes back at the next step.
            velocity: the person's floor velocity (vx, vy), m/s: views captured at other times
                are moved to ``stamp_ns`` by it.
            person: the person's track id.

        Returns:
            The number of joint residuals added.
        """
        known = {c: v for c, v in views.items() if c in self.cameras}
        if len(known) < 2:
            return 0
        return self.observe_instant(instant_from_views(known, stamp_ns, stamps, velocity, person),
                                    None if stamps is None else {c: int(stamps[c]) for c in known})

    def observe_instant(self, instant: Instant, stamps: Mapping[str, int] | None = None) -> int:
        """Measure one ``Instant`` (every view's own capture time in ``stamps``, default the instant's)."""
        if len(instant.cameras) < 2 or any(c not in self.cameras for c in instant.cameras):
            return 0
        new = [i for i, c in enumerate(instant.cameras)
               if (stamps or {}).get(c, instant.stamp_ns) > self._measured.get((instant.person, c), -1) or instant.person < 0]
        if not new:
            return 0
        self._calls += 1
        if self._calls % 1000 == 0:  # bounded memory even if nobody asks for a report
            self._forget(instant.stamp_ns)
        self._keep(instant)
        rows = np.zeros(len(instant.cameras), dtype=bool)
        rows[new] = True
        deg, px = instant_residuals(instant, self.cameras, rows)  # (V, 17) each, NaN but for the new views
        added = 0
        for i in new:
            c = instant.cameras[i]
            self._measured[(instant.person, c)] = (stamps or {}).get(c, instant.stamp_ns)
            m = ~np.isnan(deg[i])
            if m.any():
                self._res[c].append((instant.stamp_ns, deg[i, m], px[i, m]))
                added += int(m.sum())
        return added

    def _keep(self, instant: Instant) -> None:
        # Throttled per person and apart for views of three or more cameras, the ones that tell
        # which camera is off: a stream of two-view instants must not crowd them out.
        key = (instant.person, min(len(instant.cameras), 3))
        last = self._kept.get(key)
        if last is None or instant.stamp_ns - last >= self.keep_ns or instant.person < 0:
            self._instants.append(instant)
            self._kept[key] = instant.stamp_ns

    def _forget(self, now_ns: int) -> None:
        old = now_ns - self.window_ns
        for q in self._res.values():
            while q and q[0][0] < old:
                q.popleft()
        while self._instants and self._instants[0].stamp_ns < old:
            self._instants.popleft()
        self._measured = {k: t for k, t in self._measured.items() if t >= old}
        self._kept = {k: t for k, t in self._kept.items() if t >= old}

    def check_due(self, now_ns: int) -> tuple[list[Camera], list[Instant], list[str]] | None:
        """The one-camera test's inputs if it is due at ``now_ns`` (enough instants of three or more
        views, ``check_every_s`` since the last), else None; for a caller that runs ``attribute``
        elsewhere (the host process: in a thread of its own) and hands the result to ``apply``."""
        self._forget(now_ns)
        if sum(len(ins.cameras) >= 3 for ins in self._instants) < MIN_CHECK_INSTANTS:
            self._attribution = None
            return None
        if self._last_check is not None and now_ns - self._last_check < self.check_ns:
            return None
        self._last_check = now_ns
        known = [c for c, q in self._res.items() if sum(len(d) for _, d, _ in q) >= MIN_SAMPLES]
        return list(self.site.cameras), self._sample(), known

    def apply(self, attribution: Attribution | None) -> None:
        """The result of a test ``check_due`` handed out, for the reports from now on."""
        self._attribution = attribution

    def report(self, now_ns: int, check: bool = True) -> dict[str, CameraHealth]:
        """Every camera's health over the window ending at ``now_ns`` (module docstring).

        ``check``: run the one-camera test here when it is due (a bundle adjustment per camera,
        up to a second); False: use the last result handed to ``apply``.
        """
        if check:
            due = self.check_due(now_ns)
            if due is not None:
                self._attribution = attribute(*due)
        self._forget(now_ns)
        stats: dict[str, tuple[float, float, int, int]] = {}  # camera -> (median px, median deg, joints, views)
        for c, q in self._res.items():
            degs = np.concatenate([d for _, d, _ in q]) if q else np.zeros(0)
            pxs = np.concatenate([p for _, _, p in q]) if q else np.zeros(0)
            stats[c] = (float(np.median(pxs)) if len(pxs) else math.nan, float(np.median(degs)) if len(degs) else math.nan, len(degs), len(q))
        known = [c for c, s in stats.items() if s[2] >= MIN_SAMPLES]
        suspect = [c for c in known if stats[c][1] > SUSPECT_DEG]
        a = self._attribution
        out = {}
        for c, (px, deg, n, views) in stats.items():
            state: HealthState = "unknown" if c not in known else "moved" if a is not None and c in a.moved else (
                "suspect" if c in suspect else "ok")
            corr = a.correction.get(c, (math.nan, math.nan)) if a is not None else (math.nan, math.nan)
            out[c] = CameraHealth(c, px, deg, n, views, state, state == "moved",
                                  a.explained.get(c, math.nan) if a is not None else math.nan,
                                  a.shift_deg.get(c, math.nan) if a is not None else math.nan, corr[0], corr[1])
        return out

    def _sample(self) -> list[Instant]:
        """Up to ``_CHECK_INSTANTS`` of the kept instants, evenly spread in time; those three or
        more cameras saw when there are enough of them (they tell which camera is off)."""
        pool = list(self._instants)
        many = [ins for ins in pool if len(ins.cameras) >= 3]
        pool = many if len(many) >= _CHECK_INSTANTS // 2 else pool
        if not pool:
            return []
        idx = np.unique(np.linspace(0, len(pool) - 1, min(len(pool), _CHECK_INSTANTS)).round().astype(int))
        return [pool[i] for i in idx]
