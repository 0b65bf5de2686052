"""One instant's frames associated with the tracks at once: the views of one body found in the solve.

An instant is every camera's frame up to one camera's next (``host.aggregator``): the host's
timeline releases them in capture order, and the views in them are the people as the cameras saw
them together. Each frame's views are assigned to the tracks (``association.associate``), first
against the tracks' predictions, then against each track as the instant's other frames place it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from superbody.host.filtering.kalman import WALKING_SPEED_STD_MPS
from superbody.host.tracking.association import associate
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import view_covariance
from superbody.host.tracking.measure import FrameViews
from superbody.host.tracking.motion import NS_PER_S, posterior, predict_tracks
from superbody.host.tracking.track import Track

__all__ = ["associate_instant", "subset"]

# At most this many solves of an instant's association (the first against the predictions).
_PASSES = 3


def subset(views: FrameViews, rows: NDArray) -> FrameViews:
    """The views of ``rows`` of a frame (``n_joints`` and ``camera_xy`` are the frame's)."""
    v = views
    return FrameViews(v.idx[rows], v.n_joints, v.ground[rows], v.sigma[rows], v.has_ground[rows], v.hists[rows], v.has_colour[rows],
                      v.amps[rows], v.camera_xy)


def associate_instant(stamps: dict[int, int], views: dict[int, FrameViews], tracks: list[Track], cfg: TrackerConfig) -> dict[int, tuple]:
    """``association.associate`` of each frame's views, all frames of the instant jointly.

    First each frame against the tracks' predictions; then, up to ``_PASSES`` times, each frame
    again against each track as the other frames' views matched to it place it now (their
    ground points fused into its prediction: ``motion.posterior``), until nothing changes. A view
    must so agree with where the instant's other cameras see the person, not only with where
    they were heading: the views of one body are found in the solve, not checked after it.
    """
    frames = [f for f, v in views.items() if len(v.idx)]
    if len(frames) < 2 or not tracks or not cfg.use_geometry:
        return {f: associate(stamps[f], tracks, views[f], cfg) for f in frames}
    m = len(tracks)
    priors = {f: predict_tracks(tracks, stamps[f], cfg.accel_std_mps2) for f in frames}  # predicted once, for every pass
    solved = {f: associate(stamps[f], tracks, views[f], cfg, prior=priors[f]) for f in frames}
    covs = {f: view_covariance(views[f].ground, views[f].sigma, views[f].camera_xy, cfg.same_body_across_m) for f in frames}
    # another frame's point, seen up to a frame period earlier or later: the walk since as extra noise
    t = np.array([stamps[f] for f in frames], dtype=np.float64) / NS_PER_S
    walk = (WALKING_SPEED_STD_MPS * (t[None, :] - t[:, None])) ** 2  # (F, F) variance added to frame h's point seen from frame g
    for _ in range(_PASSES - 1):
        z, R = np.full((len(frames), m, 2), np.nan), np.full((len(frames), m, 2, 2), np.nan)  # each frame's point of each track
        for g, f in enumerate(frames):
            rows, cols = solved[f][:2]
            a, b, c = (x[rows] for x in covs[f])
            z[g, cols], R[g, cols] = views[f].ground[rows], np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
        new = {}
        for g, f in enumerate(frames):
            others = np.arange(len(frames)) != g
            Rf = R[others] + walk[g, others][:, None, None, None] * np.eye(2)
            prior = posterior(*priors[f], z[others].transpose(1, 0, 2), Rf.transpose(1, 0, 2, 3))
            new[f] = associate(stamps[f], tracks, views[f], cfg, prior=prior)
        same = all(np.array_equal(new[f][0], solved[f][0]) and np.array_equal(new[f][1], solved[f][1]) for f in frames)
        solved = new
        if same:
            break
    return solved
