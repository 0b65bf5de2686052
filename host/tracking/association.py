"""Matching views to tracks: joint assignment on a cost matrix and the colour distance between a
view's histogram and a track's history (median Bhattacharyya distance, the paper's rule)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from superbody.edge.colour import bhattacharyya_matrix

__all__ = ["Match", "assign", "median_colour_distance"]


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


def assign(cost: NDArray, feasible: NDArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Joint assignment of rows to columns: the most feasible pairs, then the least total cost.

    Args:
        cost: (N, M) cost of each pair.
        feasible: (N, M) bool, False for pairs that must not be matched.

    Returns:
        ``(rows, cols)``: matched index pairs, each (K,), all feasible.
    """
    cost = np.asarray(cost, dtype=np.float64)
    feasible = np.asarray(feasible, dtype=bool)
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
