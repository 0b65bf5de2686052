"""Matching views to tracks: joint assignment on a cost matrix (a negative log likelihood of each
view under each track: ``associate``) and the colour distance between a view's histogram and a
track's history (median Bhattacharyya distance, the paper's rule)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from superbody.edge.colour import bhattacharyya_matrix
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import sigmas_from
from superbody.host.tracking.motion import predict_tracks
from superbody.host.tracking.track import BINS, Track

if TYPE_CHECKING:
    from superbody.host.tracking.measure import FrameViews

__all__ = ["Match", "associate", "assign", "amplitudes", "clearly_best", "median_colour_distance", "median_over_history"]

# A view or a track without a place costs what a true match's place costs on average: half the
# expected squared sigmas of a 2-D Gaussian, and no spread.
_UNKNOWN_PLACE_COST = 1.0


@dataclass(frozen=True)
class Match:
    """What became of one view of an observation.

    Attributes:
        view_index: index of the view in ``Observation.people``.
        track_id: the track it went to, or None when it was ignored.
        status: "matched" to an existing track, "created" a new candidate, or "ignored":
            fewer than ``min_joints`` joints; or unmatched and unfit to start a candidate
            (with geometry, no ground point surer than ``gate_m``,
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


def amplitudes(hists: NDArray) -> NDArray[np.float64]:
    """Histograms (N, B) as unit vectors sqrt(h) / |sqrt(h)| (zeros for an empty one).

    The dot product of two is their Bhattacharyya coefficient, exactly as in
    ``edge.colour.bhattacharyya_matrix``; the tracker keeps its history in this form so that
    each frame costs one matrix product instead of re-rooting every stored histogram.
    """
    a = np.sqrt(np.maximum(hists, 0.0))
    norm = np.linalg.norm(a, axis=1, keepdims=True)
    return a / np.where(norm > 0, norm, 1.0)


def median_over_history(d: NDArray, counts: NDArray) -> NDArray[np.float64]:
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
    med = median_over_history(d, np.asarray(counts))
    med[~(hists.sum(axis=1) > 0)] = np.nan
    return med


def associate(t: int, tracks: list[Track], views: FrameViews, cfg: TrackerConfig,
              prior: tuple[NDArray, NDArray] | None = None) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Cost, feasibility and joint assignment of a frame's K views to M tracks at time ``t``.

    The cost of a pair, in units of a negative log likelihood, is the sum of three terms:

    - colour: the colour distance over ``d_max`` (the paper's rule: feasible below it);
      ``unknown_colour_cost`` where either has no colours;
    - place (with ``use_geometry``): ``s^2 / 2 + log(det C / det V) / 2``,
      ``s`` the combined sigmas between the view's ground point and the track's prediction
      (``evidence.sigmas_from``: the view sure across its camera's line of sight and unsure along
      it, the prediction's sigma added), C that combined covariance and V the view's own. The
      second part is how much a prediction's vagueness spreads its chance over the floor: a vague
      track explains any one view less well, where a distance over a gate that widens with the
      track's sigma made it the cheaper match (a candidate born beside a person from a detector's
      second skeleton took the person's next views; scene k, seed 23). ``_UNKNOWN_PLACE_COST``
      where either has no place;
    - detection: minus the log of the share of its chances the track was reported in since its
      steady matches began (``Track.support``; a person: 0), as a detection probability weighs a
      likelihood: a candidate that the cameras which clearly see its spot do not report (built
      from a detector's false positives) pays for every view it takes (scene l, seed 19: such a
      candidate beside a person who stopped at once took their views, while the person's
      prediction ran on).

    Feasible: the colour distance below ``d_max`` where known; with ``use_geometry``, the ground
    point within ``gate_m`` plus the view's and the prediction's sigma of the prediction, and where
    one body could stand, within ``same_body_sigmas`` of it (set S's test). A pair is feasible only
    if a cue vouches for it: colours that point to that track (``clearly_best``) or a ground point
    surer than ``gate_m``. All tracks, people and candidates, are assigned at once (``assign``):
    the one-body test keeps a person whose own view is missing from taking a neighbour's.

    Args:
        views: the frame's views (``host.tracking.measure``).
        prior: each track's position (M, 2) and covariance (M, 2, 2) at ``t``, where more is known
            than its prediction (the other cameras' views of the same instant: ``Tracker.update_instant``);
            None: the tracks' predictions.

    Returns:
        ``(rows, cols, colour_d, geo_d, near, body)``: matched view and track indices, the (K, M)
        colour and ground distances (NaN where unknown), (K, M) whether each view's ground point
        lies inside each track's gate, and (K, M) whether it also lies where that track's body
        could stand (the one-body test; vouched for or not); both all False without geometry.
    """
    amps, has_colour, ground, sigma, has_ground = views.amps, views.has_colour, views.ground, views.sigma, views.has_ground
    k, m = len(amps), len(tracks)
    geo_d = np.full((k, m), np.nan)
    near = np.zeros((k, m), dtype=bool)
    body = near
    if m == 0:
        return np.empty(0, np.intp), np.empty(0, np.intp), np.full((k, 0), np.nan), geo_d, near, body
    q = cfg.history_q
    rows_of = [tr.colour_rows for tr in tracks]
    history = np.array([a for a, _ in rows_of]).reshape(m * q, BINS)  # (M*Q, B)
    counts = np.array([n for _, n in rows_of])  # (M,)
    # d = sqrt(1 - BC), BC the dot product of amplitudes (see amplitudes)
    d = np.sqrt(np.clip(1.0 - amps @ history.T, 0.0, 1.0)).reshape(k, m, q)  # (K, M, Q)
    colour_d = median_over_history(d, counts)  # (K, M)
    colour_d[~has_colour] = np.nan
    colour_known = ~np.isnan(colour_d)
    with np.errstate(invalid="ignore"):
        feasible = ~colour_known | (colour_d < cfg.d_max)  # (K, M)
    cost = np.where(colour_known, colour_d / cfg.d_max, cfg.unknown_colour_cost)
    vouched = colour_known
    if cfg.use_geometry:
        pos, pos_cov = predict_tracks(tracks, t, cfg.accel_std_mps2) if prior is None else prior  # (M, 2), (M, 2, 2)
        has_pos, pos_std = ~np.isnan(pos[:, 0]), np.sqrt(0.5 * (pos_cov[:, 0, 0] + pos_cov[:, 1, 1]))
        geo_d = np.linalg.norm(ground[:, None, :] - pos[None, :, :], axis=2)  # (K, M)
        radius = cfg.gate_m + np.hypot(sigma[:, None], pos_std[None, :])  # (K, M)
        geo_known = has_ground[:, None] & has_pos[None, :]
        with np.errstate(invalid="ignore"):
            near = geo_known & (geo_d <= radius)
            body = near
            sig, spread = sigmas_from(ground, sigma, views.camera_xy, pos, pos_cov, cfg.same_body_across_m)
            if cfg.same_body_sigmas > 0:  # and where one body could stand: the set S test, per view
                body = near & (sig <= cfg.same_body_sigmas)
            feasible &= ~geo_known | body
            cost += np.where(geo_known, 0.5 * sig**2 + spread, _UNKNOWN_PLACE_COST)
        vouched = clearly_best(colour_d, cfg.colour_margin) | (geo_known & (sigma < cfg.gate_m)[:, None])
    cost -= np.log(np.array([tr.support for tr in tracks]))[None, :]
    rows, cols = assign(cost, feasible & vouched)
    return rows, cols, colour_d, geo_d, near, body
