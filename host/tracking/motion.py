"""Each track's floor position over time: a constant-velocity Kalman filter per track, state
(x, y, vx, vy) with one 4 x 4 covariance, that the association gate follows.

It is fed the ground points of its views, each with its own 2 x 2 covariance: sure across its
camera's line of sight, unsure along it (``evidence.view_covariance``). Views from cameras that
look from different sides pin a track down from each side, as one camera's range alone cannot;
a filter that took each point as equally unsure in every direction (its range error) trailed a
person who set off walking by a quarter of a metre. The maths is ``host.filtering.kalman``'s
textbook ``predict`` and ``update``, batched over tracks.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from superbody.host.filtering.kalman import WALKING_SPEED_STD_MPS, continuous_accel_noise, predict, update

if TYPE_CHECKING:
    from superbody.host.tracking.track import Track

__all__ = ["predict_positions", "predict_tracks", "update_positions", "fuse_positions", "posterior"]

NS_PER_S = 1_000_000_000

_H = np.hstack([np.eye(2), np.zeros((2, 2))])  # a ground point measures the position


def predict_positions(x: NDArray, P: NDArray, dt: NDArray, accel_std_mps2: float) -> tuple[NDArray, NDArray]:
    """Constant-velocity prediction of B position filters, each ``dt`` (B,) seconds ahead.

    Args:
        x: (B, 2, 2) states, rows (position, velocity), columns (x, y).
        P: (B, 4, 4) covariances of the states read row by row: (x, y, vx, vy).

    Returns:
        ``(x, P)`` predicted, same shapes.
    """
    dt = np.asarray(dt, dtype=np.float64)
    F = np.tile(np.eye(4), (len(dt), 1, 1))
    F[:, 0, 2] = F[:, 1, 3] = dt
    Q = np.kron(continuous_accel_noise(dt, accel_std_mps2**2), np.eye(2))  # (B, 4, 4): each axis alike, independent
    x4, P = predict(x.reshape(-1, 4, 1), P, F, Q)
    return x4.reshape(-1, 2, 2), P


def update_positions(x: NDArray, P: NDArray, z: NDArray, R: NDArray) -> tuple[NDArray, NDArray]:
    """Position measurements of B filters.

    Args:
        x: (B, 2, 2) states; P: (B, 4, 4) covariances; z: (B, 2) measured (x, y); R: (B, 2, 2) their covariances.
    """
    x4, P = update(x.reshape(-1, 4, 1), P, np.asarray(z, dtype=np.float64)[:, :, None], _H, R)
    return x4.reshape(-1, 2, 2), P


def predict_tracks(tracks: list[Track], t_ns: int | NDArray, accel_std_mps2: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The M tracks' positions predicted to ``t_ns`` (one time, or (M,) one per track), in one batch.

    Returns:
        ``(xy, cov)``: (M, 2) positions and (M, 2, 2) their covariances, m^2; NaN for a track that
        has no position yet.
    """
    t = np.broadcast_to(np.asarray(t_ns, dtype=np.int64), (len(tracks),))
    xy, cov = np.full((len(tracks), 2), np.nan), np.full((len(tracks), 2, 2), np.nan)
    placed = [j for j, tr in enumerate(tracks) if tr.motion is not None]
    if placed:
        states = [cast(tuple, tracks[j].motion) for j in placed]
        x, P = predict_positions(np.array([st[0] for st in states]), np.array([st[1] for st in states]),
                                 (t[placed] - np.array([st[2] for st in states])) / NS_PER_S, accel_std_mps2)
        xy[placed], cov[placed] = x[:, 0, :], P[:, :2, :2]
    return xy, cov


def fuse_positions(tracks: list[Track], xy: NDArray, R: NDArray, t_ns: int | NDArray, accel_std_mps2: float) -> None:
    """Kalman-update the positions of ``tracks`` with floor points (B, 2) of covariances ``R``
    (B, 2, 2), seen at ``t_ns`` (one time, or (B,) one per track)."""
    stamps = [int(t_ns)] * len(tracks) if np.ndim(t_ns) == 0 else [int(v) for v in cast("NDArray", t_ns)]  # (B,)
    rows: list[int] = []  # tracks with a state: predicted, then updated in one batch
    for j, tr in enumerate(tracks):
        if tr.motion is None:  # first point: the velocity is unknown
            P = np.zeros((4, 4))
            P[:2, :2], P[2:, 2:] = R[j], WALKING_SPEED_STD_MPS**2 * np.eye(2)
            tr.set_motion(np.vstack([xy[j], np.zeros(2)]), P, stamps[j])
        else:
            rows.append(j)
    if not rows:
        return
    old = [cast(tuple, tracks[j].motion) for j in rows]
    if len(rows) < len(tracks):
        xy, R = xy[rows], R[rows]
    t_old = [stamps[j] for j in rows]
    x = np.array([m[0] for m in old])  # (B, 2, 2)
    P = np.array([m[1] for m in old])  # (B, 4, 4)
    dt = np.array([t - m[2] for t, m in zip(t_old, old, strict=True)], dtype=np.float64) / NS_PER_S  # (B,)
    x, P = predict_positions(x, P, np.maximum(dt, 0.0), accel_std_mps2)
    # A point older than the state (another camera's frame came late) is applied at the state's
    # time, with the distance the person may have walked since as extra noise.
    R = R + ((WALKING_SPEED_STD_MPS * np.minimum(dt, 0.0)) ** 2)[:, None, None] * np.eye(2)  # (B, 2, 2)
    x, P = update_positions(x, P, xy, R)
    for j, (i, m) in enumerate(zip(rows, old, strict=True)):
        tracks[i].set_motion(x[j], P[j], max(m[2], t_old[j]))


def posterior(xy: NDArray, cov: NDArray, z: NDArray, R: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """M positions (M, 2) of covariances ``cov`` (M, 2, 2), each updated with up to G floor points
    ``z`` (M, G, 2) of covariances ``R`` (M, G, 2, 2) (NaN rows: no point), in information form.

    Returns:
        ``(xy, cov)`` after the points, same shapes; a NaN position stays NaN.
    """
    has = np.isfinite(z).all(axis=2) & np.isfinite(R).all(axis=(2, 3))  # (M, G)
    placed = np.isfinite(xy).all(axis=1) & np.isfinite(cov).all(axis=(1, 2))  # (M,)
    out_xy, out_cov = xy.copy(), cov.copy()
    rows = np.flatnonzero(placed & has.any(axis=1))
    if not len(rows):
        return out_xy, out_cov
    eye = np.eye(2)
    Ri = np.where(has[rows][..., None, None], np.linalg.inv(np.where(has[rows][..., None, None], R[rows], eye)), 0.0)  # (B, G, 2, 2)
    Pi = np.linalg.inv(cov[rows])  # (B, 2, 2)
    info = Pi + Ri.sum(axis=1)
    vec = (Pi @ xy[rows][..., None])[..., 0] + (Ri @ np.where(has[rows][..., None], z[rows], 0.0)[..., None])[..., 0].sum(axis=1)
    out_cov[rows] = np.linalg.inv(info)
    out_xy[rows] = (out_cov[rows] @ vec[..., None])[..., 0]
    return out_xy, out_cov
