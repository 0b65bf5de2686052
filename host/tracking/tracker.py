"""The tracker: people from the observations of all cameras of a site.

The paper's tracker matches each detected person to a known one when the median Bhattacharyya
distance between its hue-saturation histogram and that person's last Q histograms is below
d_max; unmatched detections start candidates, a candidate matched for 2 s becomes a person, and
a person unseen for 2 s is removed. ``Tracker.update_instant`` runs one instant's camera frames
(``update``: one frame) through its stages, each a module of its own:

1. measure (``host.tracking.measure``): each frame's views with enough joints, one per person
   (a detector's double report, a flood of copies: one view), their ground points
   (``host.tracking.ground``) and colours;
2. associate (``host.tracking.instant``): all the instant's views with the tracks at once, each
   frame's by joint assignment (``host.tracking.association``) on colour plus the negative log
   likelihood of the view's ground point under where the track stands (``host.tracking.motion``:
   a constant-velocity Kalman filter per track, and the instant's other views of it) and of the
   track being reported at all, gated where one body could stand, a cue vouching for each pair;
3. evidence (``host.tracking.evidence``): each candidate's chance to be seen by each camera, and
   whether it was;
4. record the matched views, and start candidates from the rest, one per body the instant's
   cameras agree on (``host.tracking.lifecycle``: the birth vetoes, then the confirmation rules,
   re-identification: ``host.tracking.reid``);
5. fuse the views' ground points into their tracks' positions.

Frames come from the host's timeline (``host.timeline``), which admits each frame once and
releases them in capture order across all cameras; everything runs on capture stamps.
``prune`` removes the merged and the unseen. For each confirmed person, ``view_sets`` gives the
paper's set S: its latest view per camera, if fresh, and of one body (``evidence.one_body``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.tracking.association import Match, associate
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import clearly_sees, off_track, set_s_of_one_body, view_covariance
from superbody.host.tracking.instant import associate_instant, subset
from superbody.host.tracking.lifecycle import Lifecycle, Newcomer
from superbody.host.tracking.measure import FrameViews, measure
from superbody.host.tracking.motion import NS_PER_S, fuse_positions
from superbody.host.tracking.track import StampedView, Track

__all__ = ["Tracker"]

_STATS = (
    "observations", "views", "wrong_site", "unknown_camera", "too_few_joints", "track_cap", "evicted_candidates",
    "no_ground_point", "no_signature", "unplaced_new", "suppressed", "duplicate_views", "matched", "new_candidates", "confirmed", "removed",
    "dropped_candidates", "reidentified", "merged", "views_of_another_body",
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
        self.stats: dict[str, int] = dict.fromkeys(_STATS, 0)
        self._cameras = {c.id: c for c in site.cameras}
        self._life = Lifecycle(self.config, self.stats, id_prefix)

    @property
    def tracks(self) -> list[Track]:
        """All tracks, candidates included, oldest first."""
        return list(self._life.tracks.values())

    def track(self, track_id: int) -> Track | None:
        return self._life.tracks.get(track_id)

    def update(self, obs: Observation) -> list[Match]:
        """One camera frame on its own: ``update_instant([obs])``'s matches."""
        return self.update_instant([obs])[0]

    def update_instant(self, frames: Sequence[Observation]) -> list[list[Match]]:
        """Match one instant's camera frames (at most one per camera, in capture order) to tracks:
        the stages of the module docstring, in order. Removal is ``prune``'s.

        Returns:
            For each frame, one ``Match`` per view of its ``people``, in order; empty for a frame
            that is not the site's (``stats`` counts "wrong_site" and "unknown_camera").
        """
        st, out = self.stats, [list[Match]() for _ in frames]
        ours = []
        for f, obs in enumerate(frames):
            st["observations"] += 1
            if obs.site != self.site.name or obs.camera not in self._cameras:
                st["wrong_site" if obs.site != self.site.name else "unknown_camera"] += 1
            else:
                st["views"] += len(obs.people)
                ours.append(f)
        if not ours:
            return out
        t0 = min(int(frames[f].stamp_ns) for f in ours)
        tracks = [tr for tr in self._life.tracks.values() if t0 - tr.last_seen_ns < self._life.remove_ns]
        views = {f: measure(frames[f], self._cameras[frames[f].camera], self.config, st) for f in ours if frames[f].people}
        solved = associate_instant({f: int(frames[f].stamp_ns) for f in views}, views, tracks, self.config)
        newborn: list[Track] = []
        for f in ours:
            obs, t, v = frames[f], int(frames[f].stamp_ns), views.get(f)
            if v is None or not len(v.idx):
                self._count_chances(obs.camera, tracks, np.empty(0, np.intp))  # a frame that sees nobody is evidence too
                out[f] = [Match(i, None, "ignored") for i in range(len(obs.people))]
                continue
            rows, cols, colour_d, geo_d, near, body = solved[f]
            left = np.ones(len(v.idx), dtype=bool)  # the views no track took
            left[rows] = False
            self._count_chances(obs.camera, tracks, cols, glimpsed=np.asarray(body[left].any(axis=0)))
            taken = [(tracks[c], int(r), Match(int(v.idx[r]), tracks[c].id, "matched", float(colour_d[r, c]), float(geo_d[r, c])))
                     for r, c in zip(rows, cols, strict=True)]
            st["matched"] += len(taken)
            for tr, r, _ in taken:  # recorded before any birth: a candidate seen now is not the stalest to evict
                self._record(tr, obs, t, v, r)
            born = self._births(t, v, tracks, left, cols, near, newborn)
            for tr, r, m in born:
                self._record(tr, obs, t, v, r)
                st["matched"] += m.status == "matched"
            taken += born
            out[f] = [Match(i, None, "ignored") for i in range(len(obs.people))]  # but the views taken:
            for _, _, m in taken:
                out[f][m.view_index] = m
            self._fuse([(tr, r) for tr, r, _ in taken], v, t)
        return out

    def _births(self, t: int, views: FrameViews, tracks: list[Track], left: NDArray, cols: NDArray, near: NDArray,
                newborn: list[Track]) -> list[tuple[Track, int, Match]]:
        """The views no track took (``left``): each joins a candidate this instant's earlier frames
        started where it matches one (``association.associate``), else starts one where the birth
        rules allow (``newborn`` gets it); (track, view row, match) for each."""
        unseen = np.ones(len(tracks), dtype=bool)  # tracks this frame did not see
        unseen[cols] = False
        out: list[tuple[Track, int, Match]] = []
        rest = np.flatnonzero(left)
        if newborn and len(rest):
            rows, cols_new = associate(t, newborn, subset(views, rest), self.config)[:2]
            out += [(newborn[c], int(r), Match(int(views.idx[r]), newborn[c].id, "matched")) for r, c in zip(rest[rows], cols_new, strict=True)]
            rest = np.setdiff1d(rest, rest[rows])
        for r in rest:
            i = int(views.idx[r])
            newcomer = Newcomer(bool(views.has_colour[r]), bool(views.has_ground[r]), float(views.sigma[r]),
                                bool((near[r] & unseen).any()))
            tr = self._life.birth(newcomer, t)
            if tr is not None:
                newborn.append(tr)
                out.append((tr, int(r), Match(i, tr.id, "created")))
        return out

    def _count_chances(self, camera: str, tracks: list[Track], cols: NDArray, glimpsed: NDArray | None = None) -> None:
        """Each placed candidate's chance to be seen in this frame, and whether it was (``host.tracking.evidence``);
        no chance where a view no track took could be it (``glimpsed``, (M,))."""
        idx = [j for j, tr in enumerate(tracks) if tr.state == "candidate" and tr.motion is not None]
        if not idx:
            return
        seen = clearly_sees(self._cameras[camera], np.array([tracks[j].position for j in idx]), self.config.edge_margin, self.site.obstacles)
        if glimpsed is not None:
            seen &= ~glimpsed[idx]
        matched = set(cols.tolist())
        for j, s in zip(idx, seen, strict=True):
            tracks[j].count_chance(hit=j in matched, seen=bool(s))

    def _record(self, tr: Track, obs: Observation, t: int, views: FrameViews, r: int) -> None:
        """Record a view (row ``r`` of ``views``) matched to (or starting) ``tr``; confirm it when its time has come."""
        if t - tr.last_seen_ns > self._life.gap_ns:
            tr.restart_streak(t)
        tr.last_seen_ns = max(tr.last_seen_ns, t)
        tr.hits += 1
        below = self._cameras[obs.camera].t
        tr.views[obs.camera] = StampedView(t, obs.people[int(views.idx[r])], (float(views.ground[r, 0]), float(views.ground[r, 1])),
                                           float(views.sigma[r]), (float(below[0]), float(below[1])))
        if views.has_colour[r]:
            tr.add_colour(views.hists[r], views.amps[r])
        self._life.confirm_if_due(tr, t)

    def _fuse(self, fused: list[tuple[Track, int]], views: FrameViews, t: int) -> None:
        """The ground points of the views applied to their tracks' position filters."""
        fused = [(tr, r) for tr, r in fused if views.has_ground[r]]
        if fused:
            rs = np.array([r for _, r in fused])
            a, b, c = view_covariance(views.ground[rs], views.sigma[rs], views.camera_xy, self.config.same_body_across_m)
            R = np.stack([np.stack([a, b], axis=1), np.stack([b, c], axis=1)], axis=1)  # (B, 2, 2)
            fuse_positions([tr for tr, _ in fused], views.ground[rs], R, t, self.config.accel_std_mps2)

    def off_track(self, track_ids: Sequence[int], xy: ArrayLike, stamps_ns: Sequence[int], cov: NDArray) -> tuple[NDArray[np.bool_], NDArray, NDArray]:
        """Which points (B, 2) of covariance ``cov`` (B, 2, 2) lie where one body could not stand
        (``evidence.off_track``), and the tracks' predictions (B, 2) and covariances (B, 2, 2)."""
        return off_track([self._life.tracks.get(int(i)) for i in track_ids], xy, stamps_ns, cov, self.config)

    def prune(self, now_ns: int) -> list[Track]:
        """Remove tracks unseen for ``remove_after_s``, and the younger of two confirmed tracks that
        are one person (``host.tracking.merge``); return them."""
        return self._life.prune(now_ns)

    def people(self, now_ns: int) -> list[Track]:
        """Confirmed tracks still alive at ``now_ns``, oldest first."""
        return [
            tr for tr in self._life.tracks.values()
            if tr.state == "confirmed" and now_ns - tr.last_seen_ns < self._life.remove_ns
        ]

    def view_sets(self, now_ns: int, freshness_s: float = 0.5) -> dict[int, dict[str, PersonView]]:
        """Set S of each confirmed person: its latest view per camera captured within ``freshness_s`` of now.

        People with no fresh view are left out.
        """
        if not (freshness_s > 0 and math.isfinite(freshness_s)):
            raise ValueError(f"view_sets: freshness_s must be a positive number of seconds, got {freshness_s!r}")
        fresh_ns = round(freshness_s * NS_PER_S)
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
