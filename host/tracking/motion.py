"""Each track's floor position over time: a constant-velocity Kalman filter per track (x and y
axes, one covariance shared by both), fed with the ground points of its views, that the
association gate follows. The maths is ``host.filtering.kalman``'s per-axis step."""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from superbody.host.filtering.kalman import AxisCov, cv_predict, cv_update

if TYPE_CHECKING:
    from superbody.host.tracking.track import Track

__all__ = ["predict_positions", "predict_tracks", "update_positions", "fuse_positions", "INIT_SPEED_STD"]

NS_PER_S = 1_000_000_000

# Speed we assume for a track whose velocity is not yet known (1-sigma, m/s).
INIT_SPEED_STD = 1.0


def _axis_cov(P: NDArray) -> AxisCov:
    """(B, 2, 2) covariances shared by the x and y columns -> ``AxisCov`` of (B, 1) fields."""
    return AxisCov(P[:, 0, 0, None], P[:, 0, 1, None], P[:, 1, 0, None], P[:, 1, 1, None])


def _packed(pos: NDArray, rate: NDArray, P: AxisCov) -> tuple[NDArray, NDArray]:
    x = np.stack([pos, rate], axis=1)  # (B, 2, 2)
    return x, np.stack([np.concatenate(P[:2], axis=1), np.concatenate(P[2:], axis=1)], axis=1)


def predict_positions(x: NDArray, P: NDArray, dt: NDArray, accel_std_mps2: float) -> tuple[NDArray, NDArray]:
    """Constant-velocity prediction of B position filters, each ``dt`` (B,) seconds ahead.

    Args:
        x: (B, 2, 2) states, rows (position, velocity), columns (x, y).
        P: (B, 2, 2) covariances, shared by the x and y columns.

    Returns:
        ``(x, P)`` predicted, same shapes.
    """
    dt = np.asarray(dt, dtype=np.float64)[:, None]  # (B, 1)
    pos, rate, cov = cv_predict(x[:, 0], x[:, 1], _axis_cov(P), dt, accel_std_mps2 * accel_std_mps2)
    return _packed(pos, rate, cov)


def update_positions(x: NDArray, P: NDArray, z: NDArray, R: NDArray) -> tuple[NDArray, NDArray]:
    """Position measurements (H = [1, 0], both columns) of B filters.

    Args:
        x: (B, 2, 2) states; P: (B, 2, 2) covariances; z: (B, 2) measured (x, y); R: (B,) variances.
    """
    pos, rate, cov = cv_update(x[:, 0], x[:, 1], _axis_cov(P), z, np.asarray(R, dtype=np.float64)[:, None])
    return _packed(pos, rate, cov)


def predict_tracks(tracks: list[Track], t_ns: int | NDArray, accel_std_mps2: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The M tracks' positions predicted to ``t_ns`` (one time, or (M,) one per track), in one batch.

    Returns:
        ``(xy, var)``: (M, 2) positions and (M,) their variance per axis, m^2; NaN for a track
        that has no position yet.
    """
    t = np.broadcast_to(np.asarray(t_ns, dtype=np.int64), (len(tracks),))
    xy, var = np.full((len(tracks), 2), np.nan), np.full(len(tracks), np.nan)
    placed = [j for j, tr in enumerate(tracks) if tr.motion is not None]
    if placed:
        states = [cast(tuple, tracks[j].motion) for j in placed]
        x, P = predict_positions(np.array([st[0] for st in states]), np.array([st[1] for st in states]),
                                 (t[placed] - np.array([st[2] for st in states])) / NS_PER_S, accel_std_mps2)
        xy[placed], var[placed] = x[:, 0, :], P[:, 0, 0]
    return xy, var


def fuse_positions(tracks: list[Track], xy: NDArray, sigma: NDArray, t_ns: int | NDArray, accel_std_mps2: float) -> None:
    """Kalman-update the positions of ``tracks`` with floor points (B, 2) of 1-sigma (B,), seen
    at ``t_ns`` (one time, or (B,) one per track)."""
    stamps = [int(t_ns)] * len(tracks) if np.ndim(t_ns) == 0 else [int(v) for v in cast("NDArray", t_ns)]  # (B,)
    rows: list[int] = []  # tracks with a state: predicted, then updated in one batch
    for j, tr in enumerate(tracks):
        if tr.motion is None:  # first point: the velocity is unknown
            tr.set_motion(np.vstack([xy[j], np.zeros(2)]), np.diag([sigma[j] ** 2, INIT_SPEED_STD**2]), stamps[j])
        else:
            rows.append(j)
    if not rows:
        return
    old = [cast(tuple, tracks[j].motion) for j in rows]
    if len(rows) < len(tracks):
        xy, sigma = xy[rows], sigma[rows]
    t_old = [stamps[j] for j in rows]
    x = np.array([m[0] for m in old])  # (B, 2, 2)
    P = np.array([m[1] for m in old])  # (B, 2, 2)
    dt = np.array([t - m[2] for t, m in zip(t_old, old, strict=True)], dtype=np.float64) / NS_PER_S  # (B,)
    x, P = predict_positions(x, P, np.maximum(dt, 0.0), accel_std_mps2)
    # A point older than the state (another camera's frame came late) is applied at the state's
    # time, with the distance the person may have walked since as extra noise.
    R = sigma**2 + (INIT_SPEED_STD * np.minimum(dt, 0.0)) ** 2  # (B,)
    x, P = update_positions(x, P, xy, R)
    for j, (i, m) in enumerate(zip(rows, old, strict=True)):
        tracks[i].set_motion(x[j], P[j], max(m[2], t_old[j]))
