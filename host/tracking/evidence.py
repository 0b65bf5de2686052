"""Whether a candidate is a person: the evidence the tracker weighs before it confirms one.

The paper confirms a candidate after 2 s of matches. A detector's false positives pass that
test: a coat on a stand that one camera reports in most frames, random partial skeletons that
keep landing inside a candidate's gate. Two physical facts tell them from people:

- **A person is seen by every camera that clearly sees where they stand** (negative evidence).
  Each frame of a camera that clearly sees a candidate's position (``clearly_sees``: the torso
  centre, 1.17 m up, inside the image less ``TrackerConfig.edge_margin`` of its size on each side, in front
  of the camera, within the detector's range, no obstacle of the site in between) is a chance
  to see it; a candidate is
  confirmed only if at least ``TrackerConfig.confirm_min_support`` of its chances since its
  steady matches began were matches. A person in full view of three cameras is matched in most
  of their frames; the coat, reported by one of the three cameras that see its spot, in at most
  a third of them. A camera that sees the spot only near its image edge (where a detector may
  miss a person cut in half) gives no chance, so people cut off at the edges are not penalised.
  Nor does a frame in which the camera reported someone it could not place well enough to match
  but who could be the candidate (a view no track took, within ``same_body_sigmas`` of its
  position: a glimpse): a person half hidden behind another shows a head and a shoulder, 3-4
  joints whose ground point is unsure by 1-2 m. Counted as misses, such frames kept a person
  that a fourth camera did not see at all from being confirmed for 3 s (scene k, seed 40). The
  coat of the first point is still a miss in every frame where the camera sees nothing there.
- **Two people cannot stand inside each other.** A candidate whose position lies within
  ``TrackerConfig.min_separation_m`` of a confirmed person's is that person seen again (a
  detector's second, partial skeleton of them, another camera's odd colours), not a newcomer:
  it is not confirmed. Two confirmed tracks that stay that close (or whose views each fit the
  other's position) for ``TrackerConfig.merge_after_s``, and that no camera saw in one frame
  (``merge.seen_together``: two detections in one frame are two bodies), are one person whose
  views went to two tracks: the younger is removed (``host.tracking.merge``). Torsos are about
  0.25 m deep and 0.4 m wide, so centres closer than 0.3 m are one body; people standing shoulder to shoulder, or
  hugging, stay further apart than that.
- **A person's views show one body.** Each camera's latest view of a person (set S) was matched
  to them on its own; in a crowd a camera's view of a neighbour (or of a coat on a stand) can join
  a track, and a track built from two bodies' views stands between them, where it keeps drawing
  views of both. Before set S is used (``one_body``), each of its views must put the person within
  ``TrackerConfig.same_body_sigmas`` of the point the others agree on. A view's ground point
  (``host.tracking.ground``) is unsure along its camera's line of sight, where the range comes from
  a body part's assumed height (0.2-0.3 m from a camera at 1 m), and sure across it, where the
  bearing comes from pixels (``TrackerConfig.same_body_across_m``): a view of someone 0.35 m to the
  side is told from a range error. The worst view is left out (ties: the one farthest from the
  track's position, then the one with fewest joints) until the rest agree, and those left out
  wait for their cameras' next frames. The same test, against the track's predicted position
  (``sigmas_from``), decides which tracks a view may be matched to at all: a person whose own view
  is missing from a camera's frame (hidden behind someone) otherwise took a neighbour's view
  inside their 1 m gate, 6 sigmas off, and starved the neighbour's candidate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from superbody.edge.body import LEFT_HIP, LEFT_SHOULDER, TYPICAL_HEIGHT_M
from superbody.edge.camera import Camera
from superbody.edge.floor import visible
from superbody.edge.site import Obstacle
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.motion import predict_tracks
from superbody.host.tracking.track import StampedView, Track

__all__ = ["TORSO_CENTRE_M", "clearly_sees", "corroborated", "too_close", "off_track", "one_body", "set_s_of_one_body", "sigmas_from", "squared_sigmas", "view_covariance"]

# Height of a standing adult's torso centre: midway between the hips and the shoulders (edge.body).
TORSO_CENTRE_M = 0.5 * (TYPICAL_HEIGHT_M[LEFT_HIP] + TYPICAL_HEIGHT_M[LEFT_SHOULDER])


def clearly_sees(cam: Camera, xy: NDArray, margin: float, obstacles: Sequence[Obstacle] = ()) -> NDArray[np.bool_]:
    """(N,) whether the camera clearly sees a person standing at each floor point (N, 2).

    Clearly: their torso centre projects inside the image less ``margin`` (a share of its width
    and height: ``TrackerConfig.edge_margin``) on each side,
    in front of the camera, within ``edge.floor.detectable_range_m``, and no obstacle of the
    site (a shelf, a pillar) stands between the camera and it (``edge.floor.visible``). Other
    people are not modelled.
    """
    return visible(cam, xy, (TORSO_CENTRE_M,), margin, obstacles=obstacles)


def corroborated(tr: Track, min_support: float) -> bool:
    """Whether the cameras that clearly see where a candidate stands matched it in ``min_support``
    of their frames since its steady matches began (the evidence rule; a person is corroborated)."""
    return tr.corroborated(min_support)


def too_close(xy: NDArray, others: Sequence[NDArray] | NDArray, min_separation_m: float) -> NDArray[np.bool_]:
    """(N,) whether each point (N, 2) lies within ``min_separation_m`` of any of ``others`` (M, 2)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    o = np.asarray(others, dtype=np.float64).reshape(-1, 2)
    if not len(xy) or not len(o):
        return np.zeros(len(xy), dtype=bool)
    return np.asarray((np.linalg.norm(xy[:, None, :] - o[None, :, :], axis=2) < min_separation_m).any(axis=1), dtype=bool)


def off_track(tracks: Sequence[Track | None], xy: ArrayLike, stamps_ns: Sequence[int], cov: NDArray, cfg: TrackerConfig) -> tuple[NDArray[np.bool_], NDArray, NDArray]:
    """Whether each point (B, 2), of covariance ``cov`` (B, 2, 2), lies where one body could not
    stand: beyond ``same_body_sigmas`` combined 1-sigmas of its track's prediction at its stamp, as
    a view is refused (False where there is no track or position, or the test is off); and those
    predictions (B, 2) with their covariances (B, 2, 2), NaN where unknown."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    pred, pcov = np.full((len(xy), 2), np.nan), np.full((len(xy), 2, 2), np.nan)
    sigmas = cfg.same_body_sigmas
    idx = np.array([j for j, tr in enumerate(tracks) if tr is not None], dtype=np.intp)
    if sigmas <= 0 or not len(idx):  # the test is off, or no track: nothing to refuse
        return np.zeros(len(xy), dtype=bool), pred, pcov
    pred[idx], pcov[idx] = predict_tracks([tracks[j] for j in idx], np.asarray(stamps_ns, dtype=np.int64)[idx], cfg.accel_std_mps2)  # type: ignore[misc]
    g, C = xy - pred, pcov + cov
    with np.errstate(invalid="ignore"):  # NaN: nothing to refuse
        return squared_sigmas(g[:, 0], g[:, 1], C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]) > sigmas**2, pred, pcov


def one_body(views: dict[str, StampedView], near_xy: NDArray | None, sigmas: float, across_m: float = math.inf) -> list[str]:
    """The cameras whose views of one person agree on where they stand (module docstring).

    A view's ground point is unsure along its camera's line of sight (its ``ground_std_m``: the
    range comes from a body part's assumed height) and sure across it (``across_m``: the bearing
    comes from the pixels). Each view is tested against the point the other views agree on (their
    inverse-covariance-weighted mean): its Mahalanobis distance must be within ``sigmas``. The
    worst view beyond that is left out, then the test is run again on the rest.

    Args:
        views: set S, camera id -> its view with its ground point.
        near_xy: (2,) the track's position, to break ties; None: the views with most joints win.
        sigmas: how many combined 1-sigmas a view may lie from the others' point.
        across_m: a ground point's 1-sigma across the line of sight (capped at its own
            ``ground_std_m``); views without ``camera_xy`` are equally unsure in every direction.

    Returns:
        The camera ids kept, in ``views``' order. A view with no ground point agrees with all.
    """
    cams = list(views)
    if len(cams) < 2:
        return cams
    sv = [views[c] for c in cams]
    xy = np.array([v.ground_xy for v in sv], dtype=np.float64)  # (V, 2)
    std = np.array([v.ground_std_m for v in sv], dtype=np.float64)  # (V,)
    placed = np.isfinite(xy).all(axis=1) & (std > 0) & np.isfinite(std)  # (V,)
    if placed.sum() < 2:
        return cams
    a, b, c = view_covariance(xy, std, np.array([v.camera_xy for v in sv], dtype=np.float64), across_m)
    with np.errstate(all="ignore"):  # rows of views not placed are NaN, and never used
        det = a * c - b * b
        ia, ib, ic = c / det, -b / det, a / det  # the inverse: each view's information
        bx, by = ia * xy[:, 0] + ib * xy[:, 1], ib * xy[:, 0] + ic * xy[:, 1]  # information times point
    keep = placed.copy()
    far = np.hypot(*(xy - near_xy).T) if near_xy is not None else np.zeros(len(cams))
    joints = np.array([v.view.num_visible for v in sv])
    while keep.sum() >= 2:
        k = np.flatnonzero(keep)
        # For each kept view, the others' information (all kept, less it), their point and covariance.
        oa, ob, oc = ia[k].sum() - ia[k], ib[k].sum() - ib[k], ic[k].sum() - ic[k]
        odet = oa * oc - ob * ob
        ca, cb, cc = oc / odet, -ob / odet, oa / odet
        rx, ry = bx[k].sum() - bx[k], by[k].sum() - by[k]
        gx, gy = xy[k, 0] - (ca * rx + cb * ry), xy[k, 1] - (cb * rx + cc * ry)
        ma, mb, mc = a[k] + ca, b[k] + cb, c[k] + cc  # the gap's covariance
        d2 = squared_sigmas(gx, gy, ma, mb, mc)  # (K,)
        if not (d2 > sigmas**2).any():
            break
        # The worst goes (two views are equally far from each other; ties: the one farthest from
        # the track, then the one with fewest joints).
        order = np.lexsort((joints[k], -np.nan_to_num(far[k]), -np.round(d2, 6)))
        keep[k[order[0]]] = False
    return [cam for cam, kept, p in zip(cams, keep, placed, strict=True) if kept or not p]


def squared_sigmas(gx: NDArray, gy: NDArray, a: NDArray, b: NDArray, c: NDArray) -> NDArray[np.float64]:
    """The squared Mahalanobis distance of gaps (gx, gy) under covariances ``[[a, b], [b, c]]``
    (all arrays broadcast): ``g^T C^-1 g``, the 2 x 2 inverse written out."""
    return np.asarray((c * gx * gx - 2 * b * gx * gy + a * gy * gy) / (a * c - b * b), dtype=np.float64)


def view_covariance(xy: NDArray, std: NDArray, camera_xy: NDArray, across_m: float) -> tuple[NDArray, NDArray, NDArray]:
    """Each ground point's covariance ``[[a, b], [b, c]]`` (three (V,) arrays): ``std`` (V,) along its
    camera's line of sight (from ``camera_xy``, (V, 2) or (2,)), ``across_m`` across it (capped at
    ``std``). A point without a camera point (NaN) is unsure alike in every direction; NaN rows
    (no ground point) stay NaN."""
    u = xy - camera_xy  # (V, 2) lines of sight
    norm = np.hypot(u[:, 0], u[:, 1])
    aimed = norm > 0
    with np.errstate(all="ignore"):
        u = np.where(aimed[:, None], u / np.where(aimed, norm, 1.0)[:, None], 0.0)
        across2 = np.where(aimed, np.minimum(across_m, std), std) ** 2
        extra = std**2 - across2  # along minus across
        return across2 + extra * u[:, 0] ** 2, extra * u[:, 0] * u[:, 1], across2 + extra * u[:, 1] ** 2


def sigmas_from(ground: NDArray, std: NDArray, camera_xy: NDArray, xy: NDArray, cov: NDArray,
                across_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(K, M) how many combined 1-sigmas each of K ground points lies from each of M
    predicted positions: the views' error as in ``one_body`` (``view_covariance``) plus each
    prediction's (``cov``). NaN where a point or a prediction is unknown.

    Args:
        ground: (K, 2) ground points; std: (K,) their 1-sigma; camera_xy: (2,) the camera's floor
            point, or (K, 2) each point's camera's.
        xy: (M, 2) predicted positions; cov: (M, 2, 2) their covariances, m^2.

    Returns:
        ``(sigmas, spread)``, both (K, M): the sigmas, and ``0.5 log(det C / det V)``, C the
        combined covariance and V the view's own: how much a prediction's vagueness spreads the
        chance of a view over the floor (0 for a sure prediction). Half the squared sigmas plus
        the spread is the negative log likelihood of the view given the prediction, less a term
        of the view alone.
    """
    a0, b0, c0 = view_covariance(ground, std, np.asarray(camera_xy, dtype=np.float64), across_m)  # (K,)
    a, b, c = a0[:, None] + cov[None, :, 0, 0], b0[:, None] + cov[None, :, 0, 1], c0[:, None] + cov[None, :, 1, 1]  # (K, M)
    g = ground[:, None, :] - xy[None, :, :]  # (K, M, 2)
    with np.errstate(all="ignore"):
        det = a * c - b * b
        m = np.sqrt(squared_sigmas(g[..., 0], g[..., 1], a, b, c))
        return m, 0.5 * np.log(det / (a0 * c0 - b0 * b0)[:, None])


def set_s_of_one_body(tr: Track, fresh: dict[str, StampedView], sigmas: float, across_m: float) -> tuple[list[str], int]:
    """``one_body`` of a track's fresh views, checked once per set (the track keeps the last one:
    the host asks every step, and a person's set changes only when a camera sees them again).

    Returns:
        The cameras kept, and how many views this call newly left out (0 for a set checked before).
    """
    key = tuple((cam, sv.stamp_ns) for cam, sv in fresh.items())
    if tr.checked_set is not None and tr.checked_set[0] == key:
        return tr.checked_set[1], 0
    kept = one_body(fresh, tr.position, sigmas, across_m)
    tr.checked_set = key, kept
    return kept, len(fresh) - len(kept)
