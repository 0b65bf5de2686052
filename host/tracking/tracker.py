"""The tracker: people from the observations of all cameras of a site.

The paper's tracker matches each detected person to a known one when the median Bhattacharyya
distance between its hue-saturation histogram and that person's last Q histograms is below
d_max; unmatched detections start candidates, a candidate matched for 2 s becomes a person,
and a person unseen for 2 s is removed. This one adds:

- a geometric gate: a view also needs its ground point (host.tracking.ground) within
  ``gate_m + sigma`` of the person's predicted position, sigma combining the ground point's and
  the prediction's uncertainty; a constant-velocity Kalman filter per track (host.tracking.motion)
  makes the gate follow a walking person;
- joint assignment: all people of one camera frame go to tracks at once
  (``scipy.optimize.linear_sum_assignment``) on colour plus normalised geometric distance,
  infeasible pairs forbidden, so one greedy choice cannot steal another view's only match;
- confirmed people are matched first, candidates then take the views left (else a candidate
  beside a person got their view by shifting a neighbour's view onto that person's track); a
  candidate its cameras do not corroborate pays ``evidence.UNCORROBORATED_COST`` per view;
- a cue must vouch for a pair (with ``use_geometry``): colours that point to that track
  (``association.clearly_best``) or a ground point surer than ``gate_m`` in the gate;
- care in starting people: a view starts a candidate only if it shows enough joints
  (``min_joints_new``), is placed on the floor (a ground point surer than ``gate_m``, 1 sigma)
  and does not stand inside the gate of a track that this frame did not see. Views that fail
  are usually a known person under another camera's light, or a partial view whose box puts
  them metres away; starting a candidate from them breeds duplicates that later split a
  person's views between two ids. (The ground rule applies only with ``use_geometry``.)
- one person is one detection: skeletons of one frame whose shared joints nearly coincide
  (``association.duplicate_views``: a detector's double report, a flood of replayed copies) are
  one view, the one with the most joints (counted as ``duplicate_views``);
- time from the messages: everything runs on capture stamps. The frames come from the host's
  timeline (``host.timeline``), which admits each frame once and releases them in capture order
  across all cameras, so the tracker sees the world in the order it happened. It refuses only
  frames that are not the site's ("wrong_site", "unknown_camera");
- a cap on tracks (``max_tracks``, at most what a PoseArray may carry): confirmed people are
  never evicted for newcomers; when the tracker is full, a view that would start a candidate
  replaces the stalest candidate not seen in this frame, or, if there is none, is ignored
  (counted as ``track_cap``). A flood of fake people therefore costs candidates, never the
  output nor the people already tracked.

- evidence before confirmation (``host.tracking.evidence``): a candidate is confirmed only if
  the cameras that clearly see where it stands matched it in ``confirm_min_support`` of their
  frames (a detector's false positive one camera reports is not corroborated by the others), and
  not within ``min_separation_m`` of a confirmed person (two people cannot stand inside each
  other); two confirmed tracks that stay that close are one person (``prune`` merges them);
- re-identification (``host.tracking.reid``): a removed person is remembered for
  ``reid_window_s``; a new person whose colours clearly match one of them, and who stands where
  they could have walked to, takes their id back. Without it, a person who stands where no
  working camera sees them for more than ``remove_after_s`` comes back as someone new.

For each confirmed person, ``view_sets`` gives the paper's set S: its latest view per camera,
if fresh, for the GNN.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.tracking.association import FrameViews, Match, _amplitudes, _median_over_history, assign, clearly_best, duplicate_views
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import UNCORROBORATED_COST, clearly_sees, coincident, corroborated, set_s_of_one_body, too_close
from superbody.host.tracking.ground import ground_points
from superbody.host.tracking.motion import _NS_PER_S, fuse_positions, predict_positions
from superbody.host.tracking.reid import REID_MARGIN, Lost, remembered_as
from superbody.host.tracking.track import _BINS, StampedView, Track

__all__ = ["Tracker"]

# A cue we cannot compute (empty histogram, no ground point) costs this much, normalised.
_UNKNOWN_COST = 0.5


_STATS = (
    "observations", "views", "wrong_site", "unknown_camera", "too_few_joints", "track_cap", "evicted_candidates", "too_few_joints_new", "no_ground_point", "no_signature",
    "unplaced_new", "suppressed", "duplicate_views", "matched", "new_candidates", "confirmed", "removed", "dropped_candidates", "reidentified",
    "merged", "views_of_another_body",
)


class Tracker:
    """People from the observations of one site's cameras.

    Args:
        site: the site; observations from other sites or unknown cameras are dropped.
        config: parameters (the paper's by default).
        id_prefix: prepended to ids in ``Track.label``.

    Attributes:
        stats: counters, e.g. ``too_few_joints``, ``new_candidates``, ``confirmed``, ``removed``.
    """

    def __init__(self, site: Site, config: TrackerConfig | None = None, id_prefix: str = "") -> None:
        self.site = site
        self.config = config or TrackerConfig()
        self.id_prefix = id_prefix
        self.stats: dict[str, int] = dict.fromkeys(_STATS, 0)
        self._cameras = {c.id: c for c in site.cameras}
        self._tracks: dict[int, Track] = {}
        self._lost: dict[int, Lost] = {}  # removed people, oldest first, for re-identification
        self._next_id = 1
        c = self.config
        self._confirm_ns = round(c.confirm_after_s * _NS_PER_S)
        self._remove_ns = round(c.remove_after_s * _NS_PER_S)
        self._gap_ns = round(c.confirm_max_gap_s * _NS_PER_S)
        self._reid_ns = round(c.reid_window_s * _NS_PER_S)

    @property
    def tracks(self) -> list[Track]:
        """All tracks, candidates included, oldest first."""
        return list(self._tracks.values())

    def track(self, track_id: int) -> Track | None:
        return self._tracks.get(track_id)

    def update(self, obs: Observation) -> list[Match]:
        """Match one camera frame's people to tracks.

        Frames come in capture order (``host.timeline``). The steps: measure the frame's views
        (joints, ground points, colours), associate them with the tracks (each track's position
        predicted to the frame's time), update the matched tracks, create candidates from the
        views no track took, and fuse the ground points into the tracks' positions. Removal is
        ``prune``'s.

        Args:
            obs: one frame of one camera.

        Returns:
            One ``Match`` per view of ``obs.people``, in order; empty when the frame is not the
            site's (``stats`` counts "wrong_site" and "unknown_camera").
        """
        t = int(obs.stamp_ns)
        st = self.stats
        st["observations"] += 1
        if obs.site != self.site.name or obs.camera not in self._cameras:
            st["wrong_site" if obs.site != self.site.name else "unknown_camera"] += 1
            return []
        st["views"] += len(obs.people)
        tracks = [tr for tr in self._tracks.values() if t - tr.last_seen_ns < self._remove_ns]
        views = self._measure(obs) if obs.people else None
        matches: list[Match | None] = [None] * len(obs.people)  # the views left None at the end were ignored
        if views is None or not len(views.idx):
            self._count_chances(obs.camera, tracks, np.empty(0, np.intp))  # a frame that sees nobody is evidence too
        else:
            rows, cols, colour_d, geo_d, near = self._associate(t, tracks, views.amps, views.has_colour, views.ground,
                                                                views.sigma, views.has_ground)
            self._count_chances(obs.camera, tracks, cols)
            fused = self._update_matched(obs, t, views, tracks, rows, cols, colour_d, geo_d, matches)
            fused += self._create(obs, t, views, tracks, rows, cols, near, matches)
            self._fuse(fused, views, t)
        return [Match(i, None, "ignored") if m is None else m for i, m in enumerate(matches)]

    def _measure(self, obs: Observation) -> FrameViews:
        """The frame's views with enough joints, and their ground points and colours."""
        st, cfg = self.stats, self.config
        n = len(obs.people)
        kps = np.array([p.keypoints for p in obs.people])  # (N, 17, 3)
        n_joints = (~np.isnan(kps[:, :, 0])).sum(axis=1)  # (N,)
        enough = n_joints >= cfg.min_joints
        st["too_few_joints"] += int(n - enough.sum())
        idx = np.flatnonzero(enough)  # (K,) the views we use
        copies = duplicate_views(kps[idx, :, :2], n_joints[idx])  # one person reported twice, or a flood of copies
        st["duplicate_views"] += int(copies.sum())
        idx = idx[~copies]
        if not len(idx):
            return FrameViews(idx, n_joints, np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool), np.zeros((0, _BINS), np.float32),
                          np.zeros(0, bool), np.zeros((0, _BINS)))
        bboxes = np.array([obs.people[i].bbox for i in idx])  # (K, 4)
        ground, sigma, _ = ground_points(kps[idx], bboxes, self._cameras[obs.camera])  # (K, 2), (K,)
        has_ground = ~np.isnan(sigma)  # (K,)
        st["no_ground_point"] += int((~has_ground).sum())
        hists = np.array([obs.people[i].histogram.reshape(-1) for i in idx])  # (K, B)
        return FrameViews(idx, n_joints, ground, sigma, has_ground, hists, hists.sum(axis=1) > 0, _amplitudes(hists))

    def _update_matched(self, obs: Observation, t: int, views: FrameViews, tracks: list[Track], rows: NDArray, cols: NDArray,
                        colour_d: NDArray, geo_d: NDArray, matches: list[Match | None]) -> list[tuple[Track, int]]:
        """Apply each matched view to its track; returns the (track, view row) pairs to fuse."""
        fused: list[tuple[Track, int]] = []
        for r, c in zip(rows, cols, strict=True):
            tr, i = tracks[c], int(views.idx[r])
            self._apply(tr, obs.camera, t, obs.people[i], views, r)
            fused.append((tr, r))
            matches[i] = Match(i, tr.id, "matched", float(colour_d[r, c]), float(geo_d[r, c]))
            self.stats["matched"] += 1
        return fused

    def _create(self, obs: Observation, t: int, views: FrameViews, tracks: list[Track], rows: NDArray, cols: NDArray,
                near: NDArray, matches: list[Match | None]) -> list[tuple[Track, int]]:
        """Start a candidate from each view no track took, where the rules allow (module
        docstring); returns the (track, view row) pairs to fuse."""
        st, cfg = self.stats, self.config
        taken = np.zeros(len(views.idx), dtype=bool)
        taken[rows] = True
        # A track this frame did not see, standing where an unmatched view stands: the view is
        # that person in another camera's light (or a partial view's odd colours), not a
        # newcomer. Starting a candidate there would breed a duplicate of them. (A newcomer
        # beside someone is still started by any camera that sees both in one frame.)
        lonely = np.ones(len(tracks), dtype=bool)
        lonely[cols] = False
        fused: list[tuple[Track, int]] = []
        for r in np.flatnonzero(~taken):
            i = int(views.idx[r])
            if not (views.has_colour[r] or (views.has_ground[r] and cfg.use_geometry)):
                st["no_signature"] += 1  # nothing to ever match it on again
                continue
            if views.n_joints[i] < cfg.min_joints_new:
                st["too_few_joints_new"] += 1
                continue
            if cfg.use_geometry and not views.sigma[r] < cfg.gate_m:  # no ground point, or one less sure than the gate
                st["unplaced_new"] += 1
                continue
            if (near[r] & lonely).any():
                st["suppressed"] += 1
                continue
            if len(self._tracks) >= cfg.max_tracks and not self._evict_candidate(t):
                st["track_cap"] += 1
                continue
            tr = Track(self._next_id, f"{self.id_prefix}{self._next_id}", "candidate", t, t, cfg.history_q)
            self._next_id += 1
            self._tracks[tr.id] = tr
            st["new_candidates"] += 1
            self._apply(tr, obs.camera, t, obs.people[i], views, int(r))
            fused.append((tr, int(r)))
            matches[i] = Match(i, tr.id, "created")
        return fused

    def _count_chances(self, camera: str, tracks: list[Track], cols: NDArray) -> None:
        """Each placed candidate's chance to be seen in this frame, and whether it was (``host.tracking.evidence``)."""
        idx = [j for j, tr in enumerate(tracks) if tr.state == "candidate" and tr._kf_t is not None]
        if not idx:
            return
        seen = clearly_sees(self._cameras[camera], np.array([tracks[j]._kf_x[0] for j in idx]), self.site.obstacles)
        matched = set(cols.tolist())
        for j, s in zip(idx, seen, strict=True):
            hit = j in matched
            tracks[j]._chances += int(hit or bool(s))
            tracks[j]._support += int(hit)

    def _may_confirm(self, tr: Track) -> bool:
        """A candidate with its 2 s of matches is a person if its views corroborate it and it stands
        in a room of its own (``host.tracking.evidence``)."""
        cfg = self.config
        if not corroborated(tr, cfg.confirm_min_support):
            return False
        if cfg.min_separation_m <= 0 or tr._kf_t is None:
            return True
        people = [p._kf_x[0] for p in self._tracks.values() if p.state == "confirmed" and p is not tr and p._kf_t is not None]
        return not too_close(tr._kf_x[0], people, cfg.min_separation_m)[0]

    def _fuse(self, fused: list[tuple[Track, int]], views: FrameViews, t: int) -> None:
        """The ground points of the views applied to their tracks' position filters."""
        fused = [(tr, r) for tr, r in fused if views.has_ground[r]]
        if fused:
            rs = np.array([r for _, r in fused])
            fuse_positions([tr for tr, _ in fused], views.ground[rs], views.sigma[rs], t, self.config.accel_std_mps2)

    def _associate(
        self, t: int, tracks: list[Track], amps: NDArray, has_colour: NDArray,
        ground: NDArray, sigma: NDArray, has_ground: NDArray,
    ) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """Cost, feasibility and joint assignment of K views to M tracks at time ``t``.

        Args:
            amps: (K, B) the views' histogram amplitudes; has_colour (K,) False for empty ones.
            ground, sigma, has_ground: (K, 2), (K,), (K,) the views' ground points.

        Returns:
            ``(rows, cols, colour_d, geo_d, near)``: matched view and track indices, the (K, M)
            colour and ground distances (NaN where unknown), and (K, M) whether each view's
            ground point lies inside each track's gate (all False without geometry).
        """
        cfg = self.config
        k, m = len(amps), len(tracks)
        geo_d = np.full((k, m), np.nan)
        near = np.zeros((k, m), dtype=bool)
        if m == 0:
            return np.empty(0, np.intp), np.empty(0, np.intp), np.full((k, 0), np.nan), geo_d, near
        q = cfg.history_q
        history = np.array([tr._amp for tr in tracks]).reshape(m * q, _BINS)  # (M*Q, B)
        counts = np.array([min(tr._n_hist, q) for tr in tracks])  # (M,)
        # d = sqrt(1 - BC), BC the dot product of amplitudes (see _amplitudes)
        d = np.sqrt(np.clip(1.0 - amps @ history.T, 0.0, 1.0)).reshape(k, m, q)  # (K, M, Q)
        colour_d = _median_over_history(d, counts)  # (K, M)
        colour_d[~has_colour] = np.nan
        colour_known = ~np.isnan(colour_d)
        with np.errstate(invalid="ignore"):
            feasible = ~colour_known | (colour_d < cfg.d_max)  # (K, M)
        cost = np.where(colour_known, colour_d / cfg.d_max, _UNKNOWN_COST)
        vouched = colour_known
        if cfg.use_geometry:
            has_pos = np.array([tr._kf_t is not None for tr in tracks], dtype=bool)  # (M,)
            pos, pos_std = np.full((m, 2), np.nan), np.full(m, np.nan)
            if has_pos.any():
                known = [tracks[j] for j in np.flatnonzero(has_pos)]
                x, P = predict_positions(
                    np.array([tr._kf_x for tr in known]), np.array([tr._kf_P for tr in known]),
                    np.array([(t - cast(int, tr._kf_t)) / _NS_PER_S for tr in known]), cfg.accel_std_mps2,
                )
                pos[has_pos], pos_std[has_pos] = x[:, 0, :], np.sqrt(P[:, 0, 0])
            geo_d = np.linalg.norm(ground[:, None, :] - pos[None, :, :], axis=2)  # (K, M)
            radius = cfg.gate_m + np.hypot(sigma[:, None], pos_std[None, :])  # (K, M)
            geo_known = has_ground[:, None] & has_pos[None, :]
            with np.errstate(invalid="ignore"):
                near = geo_known & (geo_d <= radius)
                feasible &= ~geo_known | near
                cost += cfg.geometry_weight * np.where(geo_known, geo_d / radius, _UNKNOWN_COST)
            vouched = clearly_best(colour_d, REID_MARGIN) | (geo_known & (sigma < cfg.gate_m)[:, None])
        cost += UNCORROBORATED_COST * np.array([not corroborated(tr, cfg.confirm_min_support) for tr in tracks])[None, :]
        rows, cols = assign(cost, feasible & vouched, first=np.array([tr.state == "confirmed" for tr in tracks], dtype=bool))
        return rows, cols, colour_d, geo_d, near

    def _evict_candidate(self, t: int) -> bool:
        """Make room for a new candidate: drop the stalest candidate not seen at ``t``, if any."""
        stale = [tr for tr in self._tracks.values() if tr.state == "candidate" and tr.last_seen_ns < t]
        if not stale:
            return False
        victim = min(stale, key=lambda tr: (tr.last_seen_ns, tr.hits))
        del self._tracks[victim.id]
        self.stats["evicted_candidates"] += 1
        return True

    def _apply(self, tr: Track, camera: str, t: int, view: PersonView, views: FrameViews, r: int) -> None:
        """Record a view (row ``r`` of ``views``) matched to (or starting) ``tr``; confirm it when its time has come."""
        if t - tr.last_seen_ns > self._gap_ns:
            tr._streak_ns, tr._chances, tr._support = t, 1, 1
        tr.last_seen_ns = max(tr.last_seen_ns, t)
        tr.hits += 1
        below = self._cameras[camera].t
        tr.views[camera] = StampedView(t, view, (float(views.ground[r, 0]), float(views.ground[r, 1])), float(views.sigma[r]),
                                       (float(below[0]), float(below[1])))
        if views.has_colour[r]:
            tr._add_histogram(views.hists[r], views.amps[r])
        if tr.state == "candidate" and tr.last_seen_ns - tr._streak_ns >= self._confirm_ns and self._may_confirm(tr):
            tr.state, tr.confirmed_ns = "confirmed", t
            self.stats["confirmed"] += 1
            self._reidentify(tr, t)

    def _reidentify(self, tr: Track, t: int) -> None:
        """Give a just-confirmed track the id of the one remembered person it clearly is, if any."""
        self._forget_lost(t)
        others = [o for o in self._tracks.values() if o is not tr and o.state == "confirmed"]
        lost = remembered_as(tr, t, self._lost.values(), others, self.config)
        if lost is None:
            return
        del self._lost[lost.id]
        del self._tracks[tr.id]
        tr.id, tr.label = lost.id, lost.label
        self._tracks[tr.id] = tr
        self.stats["reidentified"] += 1

    def _forget_lost(self, now_ns: int) -> None:
        self._lost = {pid: lost for pid, lost in self._lost.items() if now_ns - lost.last_seen_ns <= self._reid_ns}

    def set_position(self, track_id: int, xy: NDArray | tuple[float, float], stamp_ns: int, std_m: float = 0.1) -> bool:
        """Feed back a better position (e.g. the GNN's) for a track, as a measurement of 1-sigma ``std_m``.

        Returns:
            False if no such track (it may just have been removed).
        """
        tr = self._tracks.get(track_id)
        xy = np.asarray(xy, dtype=np.float64).reshape(2)
        if tr is None or not np.isfinite(xy).all() or not (std_m > 0 and math.isfinite(std_m)):
            return False
        fuse_positions([tr], xy[None], np.array([float(std_m)]), int(stamp_ns), self.config.accel_std_mps2)
        return True

    def set_positions(self, track_ids: Sequence[int], xy: ArrayLike, stamps_ns: Sequence[int], std_m: float = 0.1) -> NDArray[np.bool_]:
        """``set_position`` for many tracks at once (one Kalman batch): ids (B,), xy (B, 2), stamps (B,).

        Returns:
            (B,) bool, False where there is no such track or the point is not finite.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if not (std_m > 0 and math.isfinite(std_m)):
            return np.zeros(len(xy), dtype=bool)
        tracks = [self._tracks.get(int(i)) for i in track_ids]
        ok = np.array([tr is not None for tr in tracks], dtype=bool) & np.isfinite(xy).all(axis=1)
        if ok.any():
            idx = np.flatnonzero(ok)
            fuse_positions([tracks[i] for i in idx], xy[idx], np.full(len(idx), float(std_m)),  # type: ignore[misc]
                            np.asarray(stamps_ns, dtype=np.int64)[idx], self.config.accel_std_mps2)
        return ok

    def prune(self, now_ns: int) -> list[Track]:
        """Remove tracks unseen for ``remove_after_s``, and the younger of two confirmed tracks that
        stood inside each other for ``MERGE_AFTER_S`` (``host.tracking.evidence``); return them."""
        merged = self._merge_coincident(now_ns)
        gone = [tr for tr in self._tracks.values() if now_ns - tr.last_seen_ns >= self._remove_ns]
        for tr in gone:
            del self._tracks[tr.id]
            self.stats["removed" if tr.state == "confirmed" else "dropped_candidates"] += 1
            n = min(tr._n_hist, self.config.history_q)
            if tr.state == "confirmed" and n > 0 and self._reid_ns > 0:
                self._lost[tr.id] = Lost(tr.id, tr.label, tr._amp[:n].copy(), tr.position, tr.last_seen_ns)
        while len(self._lost) > self.config.max_tracks:  # bounded whatever the input
            del self._lost[next(iter(self._lost))]
        self._forget_lost(now_ns)
        return merged + gone

    def _merge_coincident(self, now_ns: int) -> list[Track]:
        """The younger of two confirmed tracks closer than ``min_separation_m`` for ``MERGE_AFTER_S``, removed."""
        people = [tr for tr in self._tracks.values() if tr.state == "confirmed"]
        merged = coincident(people, now_ns, self.config.min_separation_m) if self.config.min_separation_m > 0 else []
        for tr in merged:
            del self._tracks[tr.id]
        self.stats["merged"] += len(merged)
        return merged

    def people(self, now_ns: int) -> list[Track]:
        """Confirmed tracks still alive at ``now_ns``, oldest first."""
        return [
            tr for tr in self._tracks.values()
            if tr.state == "confirmed" and now_ns - tr.last_seen_ns < self._remove_ns
        ]

    def view_sets(self, now_ns: int, freshness_s: float = 0.5) -> dict[int, dict[str, PersonView]]:
        """Set S of each confirmed person: its latest view per camera captured within ``freshness_s`` of now.

        People with no fresh view are left out.
        """
        if not (freshness_s > 0 and math.isfinite(freshness_s)):
            raise ValueError(f"view_sets: freshness_s must be a positive number of seconds, got {freshness_s!r}")
        fresh_ns = round(freshness_s * _NS_PER_S)
        sigmas = self.config.same_body_sigmas
        out: dict[int, dict[str, PersonView]] = {}
        for tr in self.people(now_ns):
            fresh = {cam: sv for cam, sv in tr.views.items() if now_ns - sv.stamp_ns <= fresh_ns}
            if len(fresh) > 1 and sigmas > 0:
                kept, left = set_s_of_one_body(tr, fresh, sigmas, self.config.same_body_across_m)
                self.stats["views_of_another_body"] += left
                fresh = {cam: fresh[cam] for cam in kept}
            if fresh:
                out[tr.id] = {cam: sv.view for cam, sv in fresh.items()}
        return out
