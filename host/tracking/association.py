"""Matching views to tracks: joint assignment on a cost matrix and the colour distance between a
view's histogram and a track's history (median Bhattacharyya distance, the paper's rule)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components

from superbody.edge.colour import bhattacharyya_matrix

__all__ = ["Match", "FrameViews", "assign", "clearly_best", "median_colour_distance", "duplicate_views", "DUPLICATE_SPREAD"]

# Two skeletons of one frame whose shared joints lie on average within this fraction of the
# skeleton's height of each other are one detection: people standing side by side are a body
# width apart (about a quarter of their height), a detector's double report or a replayed copy
# a few pixels.
DUPLICATE_SPREAD = 0.1
# Fewer shared joints than this cannot tell a copy from a neighbour.
_MIN_SHARED_JOINTS = 5
# A skeleton's height in pixels is at least this (a few joints close together say little).
_MIN_HEIGHT_PX = 20.0


@dataclass(frozen=True)
class Match:
    """What became of one view of an observation.

    Attributes:
        view_index: index of the view in ``Observation.people``.
        track_id: the track it went to, or None when it was ignored.
        status: "matched" to an existing track, "created" a new candidate, or "ignored":
            fewer than ``min_joints`` joints; or unmatched and unfit to start a candidate
            (fewer than ``min_joints_new`` joints, no ground point surer than ``gate_m``,
            standing where an unseen track stands, or with neither a colour nor a ground
            point); ``Tracker.stats`` counts each reason.
        colour_distance: median Bhattacharyya distance to the track's history (NaN if unknown
            or new).
        ground_distance_m: distance from its ground point to the track's predicted position
            (NaN if unknown or new).
    """

    view_index: int
    track_id: int | None
    status: Literal["matched", "created", "ignored"]
    colour_distance: float = math.nan
    ground_distance_m: float = math.nan


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


def assign(cost: NDArray, feasible: NDArray, first: NDArray | None = None) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Joint assignment of rows to columns: the most feasible pairs, then the least total cost.

    Args:
        cost: (N, M) cost of each pair.
        feasible: (N, M) bool, False for pairs that must not be matched.
        first: (M,) bool: these columns are assigned first, the others then take the rows left.

    Returns:
        ``(rows, cols)``: matched index pairs, each (K,), all feasible.
    """
    cost = np.asarray(cost, dtype=np.float64)
    feasible = np.asarray(feasible, dtype=bool)
    if first is not None:
        a, b = np.flatnonzero(first), np.flatnonzero(~np.asarray(first, dtype=bool))
        rows, cols = assign(cost[:, a], feasible[:, a])
        left = np.setdiff1d(np.arange(len(cost)), rows)
        r2, c2 = assign(cost[np.ix_(left, b)], feasible[np.ix_(left, b)])
        return np.concatenate([rows, left[r2]]).astype(np.intp), np.concatenate([a[cols], b[c2]]).astype(np.intp)
    if cost.size == 0 or not feasible.any():
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    # Any forbidden pair costs more than all feasible pairs together, so the solver first
    # maximises the number of feasible matches, then minimises their cost.
    big = 1.0 + np.abs(cost[feasible]).sum()
    rows, cols = linear_sum_assignment(np.where(feasible, cost, big))
    keep = feasible[rows, cols]
    return rows[keep], cols[keep]


def _amplitudes(hists: NDArray) -> NDArray[np.float64]:
    """Histograms (N, B) as unit vectors sqrt(h) / |sqrt(h)| (zeros for an empty one).

    The dot product of two is their Bhattacharyya coefficient, exactly as in
    ``edge.colour.bhattacharyya_matrix``; the tracker keeps its history in this form so that
    each frame costs one matrix product instead of re-rooting every stored histogram.
    """
    a = np.sqrt(np.maximum(hists, 0.0))
    norm = np.linalg.norm(a, axis=1, keepdims=True)
    return a / np.where(norm > 0, norm, 1.0)


def _median_over_history(d: NDArray, counts: NDArray) -> NDArray[np.float64]:
    """Median over each track's used history rows: (N, M, Q) distances, (M,) counts -> (N, M), NaN for count 0."""
    q, m = d.shape[2], d.shape[1]
    d[:, np.arange(q)[None, :] >= counts[:, None]] = np.inf  # unused rows sort last
    d.sort(axis=2)
    cols = np.arange(m)
    lo, hi = np.maximum(counts - 1, 0) // 2, counts // 2  # (M,) the middle ranks
    return 0.5 * (d[:, cols, lo] + np.where(counts > 0, d[:, cols, np.minimum(hi, q - 1)], np.nan))


def clearly_best(colour_d: NDArray, margin: float) -> NDArray[np.bool_]:
    """(K, M) whether each of M tracks is the one a view's colours clearly point to.

    Clearly: its colour distance (``colour_d``, (K, M), NaN where unknown) is the view's
    smallest and every other track's is at least ``margin`` larger. Identical clothing points
    to nobody; a lone track is pointed to whenever its distance is known.
    """
    d = np.where(np.isnan(colour_d), np.inf, colour_d)
    if d.shape[1] < 2:
        return np.isfinite(d)
    two = np.partition(d, 1, axis=1)[:, :2]  # (K, 2) the nearest and the next
    with np.errstate(invalid="ignore"):  # inf - inf: a view without colour points to nobody
        return np.isfinite(d) & (d <= two[:, :1]) & (two[:, 1:] - two[:, :1] >= margin)


def median_colour_distance(hists: NDArray, history: NDArray, counts: NDArray) -> NDArray[np.float64]:
    """Median Bhattacharyya distance of each view to each track's histogram history.

    Args:
        hists: (N, B) view histograms.
        history: (M, Q, B) each track's histograms; rows at or past its count are unused.
        counts: (M,) used rows per track (<= Q).

    Returns:
        (N, M) distances; NaN where the view's histogram or the track's history is empty.
    """
    n, m = len(hists), len(history)
    if n == 0 or m == 0:
        return np.zeros((n, m))
    hists = np.asarray(hists).reshape(n, -1)
    q = history.shape[1]
    d = bhattacharyya_matrix(hists, history.reshape(m * q, -1)).reshape(n, m, q)  # (N, M, Q)
    med = _median_over_history(d, np.asarray(counts))
    med[~(hists.sum(axis=1) > 0)] = np.nan
    return med


def duplicate_views(keypoints: NDArray, n_joints: NDArray) -> NDArray[np.bool_]:
    """Which of one frame's K skeletons repeat another: the same person reported more than once.

    Two skeletons are close when they share at least ``_MIN_SHARED_JOINTS`` detected joints and
    those joints lie, on average, within ``DUPLICATE_SPREAD`` of the taller one's height (the
    vertical extent of its joints) of each other. Closeness links skeletons into groups
    (transitively: a chain of copies a few pixels apart is one group however long it is); each
    group keeps the skeleton with the most detected joints (ties: the first in the frame).
    People side by side are a body width apart and never link.

    Args:
        keypoints: (K, 17, 2) pixel coordinates, NaN for joints not detected.
        n_joints: (K,) detected joints of each.

    Returns:
        (K,) True for the copies.
    """
    k = len(keypoints)
    if k < 2:
        return np.zeros(k, dtype=bool)
    vis = np.isfinite(keypoints).all(axis=2)  # (K, 17)
    v = np.where(vis, keypoints[:, :, 1], np.nan)
    with np.errstate(invalid="ignore"):
        height = np.maximum(np.nanmax(v, axis=1) - np.nanmin(v, axis=1), _MIN_HEIGHT_PX)  # (K,)
    shared = vis[:, None, :] & vis[None, :, :]  # (K, K, 17)
    d = np.linalg.norm(np.where(shared[..., None], keypoints[:, None] - keypoints[None, :], 0.0), axis=3)  # (K, K, 17)
    n_shared = shared.sum(axis=2)  # (K, K)
    mean_d = d.sum(axis=2) / np.maximum(n_shared, 1)  # (K, K)
    close = (n_shared >= _MIN_SHARED_JOINTS) & (mean_d <= DUPLICATE_SPREAD * np.maximum(height[:, None], height[None, :]))
    _, group = connected_components(close, directed=False)  # (K,) group of each skeleton
    best: dict[int, int] = {}
    for i in np.argsort(-np.asarray(n_joints), kind="stable").tolist():
        best.setdefault(int(group[i]), i)
    keep = np.zeros(k, dtype=bool)
    keep[list(best.values())] = True
    return ~keep
