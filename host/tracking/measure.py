"""The measure stage: one camera frame's usable views, with their ground points and colours.

A view is used when it shows at least ``TrackerConfig.min_joints`` joints; one person is one
detection (``duplicate_views``: skeletons of one frame whose shared joints nearly coincide, a
detector's double report or a flood of replayed copies, are one view, the one with the most
joints); its ground point and 1-sigma come from ``host.tracking.ground``, its colour signature
from its hue-saturation histogram, kept as amplitudes (``association.amplitudes``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from superbody.edge.camera import Camera
from superbody.edge.messages.observation import Observation
from superbody.host.tracking.association import amplitudes
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.ground import ground_points
from superbody.host.tracking.track import BINS

__all__ = ["FrameViews", "measure", "duplicate_views"]




class FrameViews(NamedTuple):
    """One frame's usable views (K of its N people), as ``Tracker._measure`` finds them."""

    idx: NDArray[np.intp]  # (K,) indices into the frame's people
    n_joints: NDArray[np.intp]  # (N,) detected joints of every person of the frame
    ground: NDArray[np.float64]  # (K, 2) ground points
    sigma: NDArray[np.float64]  # (K,) their 1-sigma, NaN: none
    has_ground: NDArray[np.bool_]  # (K,)
    hists: NDArray[np.float32]  # (K, B) flattened histograms
    has_colour: NDArray[np.bool_]  # (K,) False for an empty histogram
    amps: NDArray[np.float64]  # (K, B) their amplitudes (association.py)
    camera_xy: NDArray[np.float64]  # (2,) the camera's floor point: each ground point's line of sight



def measure(obs: Observation, camera: Camera, cfg: TrackerConfig, stats: dict[str, int]) -> FrameViews:
    """The frame's views with enough joints, and their ground points and colours (counting
    ``too_few_joints``, ``duplicate_views`` and ``no_ground_point`` in ``stats``)."""
    n = len(obs.people)
    kps = np.array([p.keypoints for p in obs.people]).reshape(n, -1, 3)  # (N, 17, 3)
    n_joints = (~np.isnan(kps[:, :, 0])).sum(axis=1)  # (N,)
    enough = n_joints >= cfg.min_joints
    stats["too_few_joints"] += int(n - enough.sum())
    idx = np.flatnonzero(enough)  # (K,) the views we use
    copies = duplicate_views(kps[idx, :, :2], n_joints[idx], cfg.duplicate_spread, cfg.duplicate_min_joints)  # one person reported twice, or a flood of copies
    stats["duplicate_views"] += int(copies.sum())
    idx = idx[~copies]
    if not len(idx):
        return FrameViews(idx, n_joints, np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool), np.zeros((0, BINS), np.float32),
                          np.zeros(0, bool), np.zeros((0, BINS)), camera.t[:2].copy())
    ground, sigma, _ = ground_points(kps[idx], camera)  # (K, 2), (K,)
    has_ground = ~np.isnan(sigma)  # (K,)
    stats["no_ground_point"] += int((~has_ground).sum())
    hists = np.array([obs.people[i].histogram.reshape(-1) for i in idx])  # (K, B)
    return FrameViews(idx, n_joints, ground, sigma, has_ground, hists, hists.sum(axis=1) > 0, amplitudes(hists), camera.t[:2].copy())


def duplicate_views(keypoints: NDArray, n_joints: NDArray, spread: float, min_shared: int) -> NDArray[np.bool_]:
    """Which of one frame's K skeletons repeat another: the same person reported more than once.

    Two skeletons are close when they share at least ``min_shared`` detected joints and
    those joints lie, on average, within ``spread`` (``TrackerConfig.duplicate_spread``) of the taller one's height (the
    vertical extent of its joints) of each other. Closeness links skeletons into groups
    (transitively: a chain of copies a few pixels apart is one group however long it is); each
    group keeps the skeleton with the most detected joints (ties: the first in the frame).
    People side by side are a body width apart and never link.

    Args:
        keypoints: (K, 17, 2) pixel coordinates, NaN for joints not detected.
        n_joints: (K,) detected joints of each.
        spread: how close, as a share of the taller skeleton's height (``TrackerConfig.duplicate_spread``).
        min_shared: the fewest shared joints that can tell a copy from a neighbour
            (``TrackerConfig.duplicate_min_joints``).

    Returns:
        (K,) True for the copies.
    """
    k = len(keypoints)
    if k < 2:
        return np.zeros(k, dtype=bool)
    vis = np.isfinite(keypoints).all(axis=2)  # (K, 17)
    v = np.where(vis, keypoints[:, :, 1], np.nan)
    height = np.fmax.reduce(v, axis=1) - np.fmin.reduce(v, axis=1)  # (K,) NaN for a skeleton without joints
    shared = vis[:, None, :] & vis[None, :, :]  # (K, K, 17)
    d = np.linalg.norm(np.where(shared[..., None], keypoints[:, None] - keypoints[None, :], 0.0), axis=3)  # (K, K, 17)
    n_shared = shared.sum(axis=2)  # (K, K)
    mean_d = d.sum(axis=2) / np.maximum(n_shared, 1)  # (K, K)
    close = (n_shared >= min_shared) & (mean_d <= spread * np.maximum(height[:, None], height[None, :]))
    _, group = connected_components(close, directed=False)  # (K,) group of each skeleton
    best: dict[int, int] = {}
    for i in np.argsort(-np.asarray(n_joints), kind="stable").tolist():
        best.setdefault(int(group[i]), i)
    keep = np.zeros(k, dtype=bool)
    keep[list(best.values())] = True
    return ~keep
