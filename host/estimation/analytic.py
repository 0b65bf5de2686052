"""The analytic estimator: torso pose from geometry alone, no learning.

The baseline every learned model is compared against, and the host's fallback when no model
fits the site. For one person's views:

1. each joint seen by two or more cameras is triangulated (the point closest to all its rays);
   a joint seen by one camera is put where its ray reaches the joint's typical height
   (edge.body.TYPICAL_HEIGHT_M);
2. position: the mean of the torso joints (shoulders, hips) on the floor, or of all joints if
   no torso joint was seen, leaving out joints one camera placed on a ray that grazes their
   plane (``MAX_PLACEMENT_STD_M``) unless nothing else is left. From one camera, the floor
   point of the view's surest body part instead (``host.tracking.ground``, where the tracker
   places the same view): a person seen through a doorway by a camera 1 m up showed their
   shoulders and ankles; the shoulders, 0.4 m above the camera, put them 0.6-1.4 m off along its
   line of sight, the ankles within 0.2 m (scene m, seed 1). Likewise where no torso joint is
   triangulated (cameras that each saw other joints: one the left shoulder and hip, another the
   right ones): the views' floor points, weighted by their inverse variances, rather than the
   mean of joints each put at its typical height along one camera's ray, which mixed the
   cameras' range errors (scene m, seed 1: 2-view sets 204 -> 142 mm off at the median);
3. yaw: perpendicular to the left-right shoulder and hip lines (pointing to the body's front),
   averaged as vectors; with neither pair, from the nose against the ears/eyes; else 0. Each
   line's two ends come from the same cameras, those that saw both (``pair_points``): a shoulder
   triangulated from two cameras joined to its partner put at the typical height along one
   camera's ray mixes a small error with a large one, and the line between them turns (on
   dev.json, two-camera yaw 16.8 -> 10.3 deg MAE; from one camera the two ends' depth errors
   are alike and the line keeps its direction). A line with an end on a ray that grazes its
   plane (``MAX_PLACEMENT_STD_M``, as for the position) gives no direction: from a camera 1 m
   up, the hips' rays meet their 0.91-m plane at a slope where a pixel of noise moves an end by
   decimetres, so the two hips' points, metres long apart, turned the line anywhere and
   outweighed the shoulders' (scene m, seed 1: a person in the hallway seen through the door).
   Where one camera alone saw a line, its offsets across that camera's line of sight come from
   pixels and are sure, and along it from the ends' typical heights and are not: the yaw is the
   one at which lines of an adult's width best explain every line's offsets, the triangulated
   ones as sure both ways (``_fitted_facing``; dev.json per frame, one camera: 24.8 -> 20.2 deg
   MAE; two cameras, where one saw a line alone: 9.4-9.9 -> 3.6-4.7).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from superbody.edge import body
from superbody.edge.camera import Camera, intersect_plane, pixel_to_ray
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.host.estimation.estimator import Estimates
from superbody.host.tracking.ground import JOINT_PIXEL_STD, MAX_RANGE_M, ground_point, ground_points, torso_range

__all__ = ["AnalyticEstimator", "GeometrySigmas", "triangulate", "joints_3d", "pair_points", "YAW_STD_NO_CUE", "NO_CUE", "HEAD", "PAIR",
           "HEIGHT_STD_M", "MAX_PLACEMENT_STD_M"]

# The 1-sigma (rad) of a yaw from nothing: no shoulder or hip pair, no nose with an eye or ear
# (one side of a person cut off at an image edge, legs alone). The yaw is then 0 by convention and
# says nothing: inf tells the temporal filter to keep the person's yaw as predicted
# (``PoseFilter.update``). A finite sigma, however large, would not do: 45 views a second of yaw 0
# at 3 rad turned a person standing still by 100 deg in 1.5 s.
YAW_STD_NO_CUE = math.inf
# What a yaw came from (``AnalyticEstimator.estimate_with_cues``).
NO_CUE, HEAD, PAIR = 0, 1, 2

_HEIGHTS = np.asarray(body.TYPICAL_HEIGHT_M)
# How much a joint's height varies between people and poses (host.tracking.ground's shoulders),
# 1-sigma metres. A joint one camera placed at its typical height is unsure along that camera's
# ray by HEIGHT_STD_M over the ray's slope towards the plane. The torso's centre leaves out the
# joints unsure by more than MAX_PLACEMENT_STD_M: from a camera at hip height (1 m), a tall
# person's hips (0.95-1.0 m up) lie on rays that meet the 0.91-m plane 5-20 m away. It keeps the
# others, though a short person's hips come too close and shoulders too far: their mean cancels.
# On dev.json (cameras about 2 m up) no joint is that unsure, at 1 m as at 3 m: the figures
# are the same (``superbody eval ... --estimator analytic``).
HEIGHT_STD_M = 0.10
MAX_PLACEMENT_STD_M = 3.0
_ANGLES = np.radians(np.arange(360.0))  # candidate yaws, 1 deg apart
_COS, _SIN = np.cos(_ANGLES), np.sin(_ANGLES)
_PAIRS = ((body.LEFT_SHOULDER, body.RIGHT_SHOULDER), (body.LEFT_HIP, body.RIGHT_HIP))
_HEAD = (1, 2, 3, 4)  # eyes and ears
_SHOULDERS, _HIPS = _PAIRS


def triangulate(origins: NDArray, directions: NDArray) -> NDArray[np.float64]:
    """The point closest (least squares) to several rays.

    Args:
        origins: (K, 3) ray origins.
        directions: (K, 3) unit directions.

    Returns:
        (3,) point minimising the sum of squared distances to the rays.
    """
    # sum_k (I - d_k d_k^T) p = sum_k (I - d_k d_k^T) o_k
    P = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]  # (K, 3, 3)
    A = P.sum(0)
    b = (P @ origins[:, :, None]).sum(0)[:, 0]
    return np.linalg.lstsq(A, b, rcond=None)[0]


def joints_3d(views: Mapping[str, PersonView], site: Site, joints: Sequence[int] | None = None) -> NDArray[np.float64]:
    """(17, 3) world joints of one person from its views; NaN rows for joints no camera saw
    (and for those not in ``joints``, when given)."""
    return _joints_3d(views, site, joints)[0]


def _joints_3d(views: Mapping[str, PersonView], site: Site, joints: Sequence[int] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``joints_3d``, and (17,) how far each joint may lie from its point on the floor, 1-sigma
    metres, from its typical height's spread: 0 for a triangulated joint, NaN where unseen."""
    rays: list[list[tuple[NDArray, NDArray]]] = [[] for _ in range(body.NUM_KEYPOINTS)]
    only = None if joints is None else np.isin(np.arange(body.NUM_KEYPOINTS), joints)
    for cam_id, view in views.items():
        cam = site.camera(cam_id)
        vis = np.flatnonzero(view.visible if only is None else view.visible & only)
        if len(vis) == 0:
            continue
        origin, dirs = pixel_to_ray(view.keypoints[vis, :2].astype(np.float64), cam)
        for k, d in zip(vis, dirs):
            rays[k].append((origin, d))
    out = np.full((body.NUM_KEYPOINTS, 3), np.nan)
    sigma = np.full(body.NUM_KEYPOINTS, np.nan)
    for j, rs in enumerate(rays):
        if len(rs) >= 2:
            o = np.array([r[0] for r in rs])
            d = np.array([r[1] for r in rs])
            # Nearly parallel rays triangulate badly: fall back to the typical height then.
            if np.linalg.norm(np.cross(d[0], d[1:]), axis=1).max() > 0.05:
                out[j], sigma[j] = triangulate(o, d), 0.0
                continue
        if rs:
            o = np.array([r[0] for r in rs])
            pts, ok = intersect_plane(o, np.array([r[1] for r in rs]), _HEIGHTS[j])
            if ok.any():
                out[j] = pts[ok].mean(0)
                # A height off by HEIGHT_STD_M moves the point along the ray by that much over
                # the ray's slope towards the plane: metres where the ray grazes it. (Nearly
                # parallel rays share that error: the same joint's height.)
                r = np.hypot(*(pts[ok, :2] - o[ok, :2]).T)
                dh = np.abs(o[ok, 2] - _HEIGHTS[j])
                sigma[j] = float(np.mean(HEIGHT_STD_M * r / np.maximum(dh, 1e-6)))
    return out, sigma


def pair_points(views: Mapping[str, PersonView], site: Site, left: int, right: int,
                joints: tuple[NDArray, NDArray] | None = None) -> tuple[NDArray, NDArray] | None:
    """World points of a left/right joint pair from the cameras that saw both, or None (no camera
    saw both, or an end lies on a ray that grazes its plane: ``MAX_PLACEMENT_STD_M``).

    ``joints`` (``_joints_3d`` of all ``views``: points and sigmas) is reused when every view saw both.
    """
    both = {c: v for c, v in views.items() if v.visible[left] and v.visible[right]}
    if not both:
        return None
    j, sigma = joints if joints is not None and len(both) == len(views) else _joints_3d(both, site, (left, right))
    if np.isnan(j[left, 0]) or np.isnan(j[right, 0]) or max(sigma[left], sigma[right]) > MAX_PLACEMENT_STD_M:
        return None
    return j[left], j[right]


def _fitted_facing(lines: Sequence[tuple[tuple[NDArray, NDArray], tuple[int, int], list[str]]], views: Mapping[str, PersonView],
                   site: Site) -> NDArray[np.float64] | None:
    """(2,) the facing (a direction) of a torso from its shoulder and hip lines (``pair_points``' ends,
    the pair, and the cameras that saw both ends), where some line was seen by one camera alone: each
    end then at its typical height along that camera's rays. None where such a camera has no line of
    sight to fit along (below).

    Across a camera's line of sight a line's offset comes from pixels and is sure; along it it
    comes from where each end's ray meets its typical height, so a pixel of noise, or an end a
    few centimetres higher than its partner, moves it by the ray's slope times that (on dev.json's
    single views, 0.14 m 1-sigma against 0.04 across). Taken as they are, the two offsets turned
    a line seen side-on, whose offset across is nearly 0, anywhere the depth's noise sent it.
    Here the facing is the one at which lines of an adult's width (``body.WIDTH_RANGE_M``) best
    explain every line's offsets, each by its own sigma: side-on, the offsets across say how
    far the torso is turned and the depths only which way; facing the camera or away, the
    depths' noise is what is left. A line two cameras or more triangulated is as sure along as
    across (the pixels' sigma at its range, both ways). Widths are measured against the torso's
    length where the one camera's view shows both (``_torso_range``): a tall person's lines, put
    at a typical height along the rays, come out too far and too wide, and both by the same
    factor. Lines whose offsets fit such widths (no noise) keep their direction. The sigmas are
    the pixels' alone (the ground levels' detector noise), which make the offset along 3-10 times
    less sure than across from 2-6 m; a lean added to them changed dev.json's figures by 0.1 deg.
    A person under a camera that saw a line alone (within 0.1 m of its foot) has no line of sight
    along the floor: None (the lines as placed).
    """
    cost = np.zeros(len(_COS))
    alone = {cams[0] for _, _, cams in lines if len(cams) == 1}
    frames = {}
    for cam_id in alone:  # each such camera's line of sight, and its scale to a typical torso
        cam = site.camera(cam_id)
        d = np.mean([0.5 * (left[:2] + right[:2]) for (left, right), _, cams in lines if cams == [cam_id]], axis=0) - cam.t[:2]
        r = float(np.hypot(*d))
        if r < 0.1:
            return None
        torso_r = _torso_range(views[cam_id], cam)
        frames[cam_id] = (cam, d / r, r, torso_r / r if 0.0 < torso_r <= MAX_RANGE_M else 1.0)
    ref: tuple[NDArray, NDArray] | None = None  # the first line's frame: along, across its line of sight
    for (left, right), pair, cams in lines:
        lr = left[:2] - right[:2]
        if len(cams) == 1:
            cam, d, r, scale = frames[cams[0]]
            lr = lr * scale
            dh = max(abs(float(cam.t[2] - 0.5 * (left[2] + right[2]))), 1e-6)
            dtheta = JOINT_PIXEL_STD / (0.5 * (cam.fx + cam.fy))
            var_across = 2.0 * (dtheta * r) ** 2
            var_along = 2.0 * (dtheta * (r * r + dh * dh) / dh) ** 2
        else:  # triangulated: the pixels' sigma at its range, both ways (so any frame will do: its first camera's)
            cam = site.camera(cams[0])
            mid = 0.5 * (left[:2] + right[:2])
            r = max(float(np.mean([np.hypot(*(mid - site.camera(k).t[:2])) for k in cams])), 0.1)
            d = (mid - cam.t[:2]) / max(float(np.hypot(*(mid - cam.t[:2]))), 1e-6)
            var_across = var_along = 2.0 * (JOINT_PIXEL_STD / (0.5 * (cam.fx + cam.fy)) * r) ** 2
        p = np.array([-d[1], d[0]])  # across the line of sight, to the camera's left
        # The line at angle a in the first line's frame (across its line of sight, along it) is
        # at a - (this frame's bearing - the first's) in this one; there, with width w,
        # across = w cos a, along = -w sin a. For each a the best w in the range (the least
        # squares' w, clipped), then the best a for all lines.
        if ref is None:
            ref = d, p
        turn = math.atan2(float(d @ ref[1]), float(d @ ref[0]))  # this frame's bearing less the first's
        c, s = (_COS, _SIN) if turn == 0.0 else (np.cos(_ANGLES - turn), np.sin(_ANGLES - turn))
        across, along = float(lr @ p), float(lr @ d)
        w = np.clip((across * c / var_across - along * s / var_along) / (c * c / var_across + s * s / var_along), *body.WIDTH_RANGE_M[pair])
        cost += (across - w * c) ** 2 / var_across + (along + w * s) ** 2 / var_along
    assert ref is not None  # lines is never empty
    k = int(np.argmin(cost))
    lr = _COS[k] * ref[1] - _SIN[k] * ref[0]  # the left-to-right direction in the world
    return np.array([lr[1], -lr[0]])


def _torso_range(view: PersonView, cam: Camera) -> float:
    """Horizontal range (m) at which the shoulders' ray (their visible ones' mean pixel) passes a
    typical torso's length above the hips' (``host.tracking.ground.torso_range``, its torso
    level); NaN without both, 0 or less where the rays do not part upwards."""
    mean_px = [np.nanmean(view.keypoints[list(j), :2], axis=0) for j in (_SHOULDERS, _HIPS) if view.visible[list(j)].any()]
    if len(mean_px) < 2:
        return math.nan
    shoulders, hips = pixel_to_ray(np.array(mean_px, dtype=np.float64), cam)[1]
    return float(torso_range(hips[None], shoulders[None])[0])


class GeometrySigmas(Protocol):
    """Where the geometry's 1-sigmas come from: ``host.estimation.hybrid.HybridCalibration``
    (measured per camera count on real data, or on simulation of the site)."""

    def analytic_sigmas(self, cameras: NDArray, pair: NDArray) -> NDArray[np.float64]:
        """(B, 3) 1-sigma (m, m, rad) for camera counts (B,) and shoulder-or-hip-pair flags (B,)."""
        ...


class AnalyticEstimator:
    """Torso pose from per-view geometry; implements the host's ``Estimator`` protocol.

    Args:
        site: the site (camera models).
        sigmas: the geometry's measured 1-sigmas, reported with each pose
            (``estimate_detailed``) so that the temporal filter weighs a pose as it deserves;
            None: no sigmas (the filter then uses its defaults, ``FilterConfig.meas_std_xy_m``
            and ``meas_std_yaw_rad``), but for the position from one view (below).
    """

    def __init__(self, site: Site, sigmas: GeometrySigmas | None = None):
        self.site = site
        self.sigmas = sigmas

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates:
        """Poses, their 1-sigmas (NaN without ``sigmas``: the filter's defaults) and the source
        "analytic". A yaw from no cue at all has ``YAW_STD_NO_CUE`` either way, and a position
        from one view is no surer than its ground point (``host.tracking.ground``'s sigma, per
        axis): the calibration's sigma is per camera count, and a box's bottom edge from a view
        of two wrists and a knee is not the ankles of a whole one (scene g, seed 1: such a pose,
        reported at 0.13 m, 0.6 m off, pulled the person's track off them). A position from
        several views' ground points (no torso joint triangulated) keeps the calibration's sigma
        for its camera count, or none: reported at their mean's (0.15-0.3 m) where the filter's
        default is 0.03 m, such poses moved the filter and the tracker so that scene m's yaw p90
        went 23.6 -> 49.4 deg (``analytic``, seed 1, 45 s). Without ``sigmas`` a yaw from the
        head (the nose against the eyes and ears, each put at its height along one camera's ray)
        says nothing either: the filter's default (4 deg) is a pair's error, and a head's yaw from
        5-6 m and a camera 1 m up is 47 deg off at the median (scene m, seed 1; 29 on dev.json's
        22 such samples), so it turned people seen through a doorway (m's ``analytic`` yaw p90
        28.3 -> 15.8 deg). A calibration gives it its own sigma (the no-pair one)."""
        pose, cue, place_std = self._estimate(view_sets)
        if self.sigmas is None:
            std = np.full(pose.shape, np.nan)
        else:
            std = self.sigmas.analytic_sigmas(np.array([len(v) for v in view_sets], dtype=np.int64), cue == PAIR).reshape(pose.shape)
        std[:, :2] = np.fmax(std[:, :2], place_std[:, None])  # one view: no surer than its ground point
        std[(cue == NO_CUE) | ((cue == HEAD) & (self.sigmas is None)), 2] = YAW_STD_NO_CUE  # says nothing (above)
        return Estimates(pose, std, ("analytic",) * len(pose))

    def estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> NDArray[np.float64]:
        """(B, 3) x, y, yaw for each person's views."""
        return self.estimate_with_pairs(view_sets)[0]

    def estimate_with_pairs(self, view_sets: Sequence[Mapping[str, PersonView]]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(B, 3) poses, and (B,) whether each yaw came from a shoulder or hip pair (the
        reliable case; otherwise it came from the head, or is 0 for lack of anything)."""
        pose, cue = self.estimate_with_cues(view_sets)
        return pose, cue == PAIR

    def estimate_with_cues(self, view_sets: Sequence[Mapping[str, PersonView]]) -> tuple[NDArray[np.float64], NDArray[np.int8]]:
        """(B, 3) poses, and (B,) what each yaw came from: ``PAIR``, ``HEAD`` or ``NO_CUE``."""
        pose, cue, _ = self._estimate(view_sets)
        return pose, cue

    def _estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> tuple[NDArray[np.float64], NDArray[np.int8], NDArray[np.float64]]:
        """Poses, cues, and each one-view position's ground-point sigma (NaN for the others)."""
        n = len(view_sets)
        out, cue = np.zeros((n, 3)), np.zeros(n, np.int8)
        ground, place_std = np.full((n, 2), np.nan), np.full(n, np.nan)
        by_camera: dict[str, list[int]] = {}  # the one-view sets, by their camera: one ground_points call each
        for i, views in enumerate(view_sets):
            if len(views) == 1:
                by_camera.setdefault(next(iter(views)), []).append(i)
        for cam_id, idx in by_camera.items():
            seen = [view_sets[i][cam_id] for i in idx]
            ground[idx], place_std[idx], _ = ground_points(np.array([v.keypoints for v in seen]), self.site.camera(cam_id))
        for i, views in enumerate(view_sets):
            out[i], cue[i] = self._one(views, ground[i])
        return out, cue, place_std

    def _one(self, views: Mapping[str, PersonView], ground: NDArray[np.float64]) -> tuple[NDArray[np.float64], int]:
        """One person's pose and cue; ``ground`` (2,): the floor point of their one view (NaN: none, or more views)."""
        j, sigma = _joints_3d(views, self.site)
        seen = ~np.isnan(j[:, 0])
        if not seen.any():
            return np.array([np.nan, np.nan, 0.0]), NO_CUE
        torso = np.array([t for t in body.TORSO if seen[t]] or np.flatnonzero(seen))
        if np.isfinite(ground).all():  # one view: its surest body part (module docstring)
            centre = ground
        elif not (sigma[torso] == 0).any() and np.isfinite(fused := self._fused_ground(views)).all():
            centre = fused  # no torso joint triangulated: the views' ground points
        else:
            sure = torso[sigma[torso] <= MAX_PLACEMENT_STD_M]  # a ray that grazes its plane places nothing
            centre = j[sure if len(sure) else torso[[np.argmin(sigma[torso])]], :2].mean(0)
        facing = np.zeros(2)
        lines: dict[tuple[int, int], tuple[tuple[NDArray, NDArray], list[str]]] = {}  # pair -> (ends, the cameras that saw both)
        for pair in _PAIRS:
            if (ends := pair_points(views, self.site, *pair, (j, sigma))) is not None:
                lines[pair] = ends, [c for c, v in views.items() if v.visible[pair[0]] and v.visible[pair[1]]]
        fitted = None
        if any(len(seen_by) == 1 for _, seen_by in lines.values()):  # a line one camera placed: fit them together (``_fitted_facing``)
            fitted = _fitted_facing([(ends, pair, seen_by) for pair, (ends, seen_by) in lines.items()], views, self.site)
        if fitted is not None:
            facing = fitted
        else:  # the lines as placed
            for ends, _ in lines.values():
                lr = ends[0][:2] - ends[1][:2]
                facing += np.array([lr[1], -lr[0]])  # the left-to-right vector turned -90 degrees
        cue = PAIR if facing.any() else NO_CUE
        if cue == NO_CUE and seen[body.NOSE]:
            head = [h for h in _HEAD if seen[h]]
            if head:
                facing = j[body.NOSE, :2] - j[head, :2].mean(0)
                cue = HEAD if facing.any() else NO_CUE
        yaw = math.atan2(facing[1], facing[0]) if facing.any() else 0.0
        return np.array([centre[0], centre[1], yaw]), cue

    def _fused_ground(self, views: Mapping[str, PersonView]) -> NDArray[np.float64]:
        """(2,) the views' ground points (``host.tracking.ground``) weighted by their inverse
        variances; NaN where no view gives one."""
        points = [p for cam_id, v in views.items() if (p := ground_point(v, self.site.camera(cam_id))) is not None]
        if not points:
            return np.full(2, np.nan)
        w = np.array([1.0 / std**2 for _, std in points])
        return np.asarray(w @ np.array([xy for xy, _ in points]) / w.sum(), dtype=np.float64)
