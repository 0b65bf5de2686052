"""The Kalman filter, once: pure functions in textbook notation, used by the pose filter and the
tracker's position filter alike.

- ``predict`` and ``update`` are the general form (any n, leading batch dimensions broadcast),
  each equation in a comment above its line;
- ``cv_predict`` and ``cv_update`` are the pose filter's step: independent axes, each a
  constant-velocity (position, rate) pair that measures its position, written out per element
  on the 2 x 2 covariance ``AxisCov`` so that a batch of B filters of A axes is a handful of
  array operations instead of B small matrix products and solves. (The tracker's position
  filter measures x and y together, with a covariance that ties them, so it runs the general
  form.) They give the numbers of
  ``predict`` / ``update`` with the block-diagonal F, Q, H = [1, 0] per axis and a diagonal R
  (tests/host/filtering/test_kalman.py checks them against the textbook 6 x 6 form).

Process noise: piecewise-constant white acceleration (Bar-Shalom), per axis

    Q = sigma_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["WALKING_SPEED_STD_MPS", "predict", "update", "white_accel_noise", "continuous_accel_noise", "AxisCov", "cv_predict", "cv_update"]

# How fast a person first seen may be walking, 1-sigma, m/s (people walk at 1.2-1.4 m/s): the
# speed both the tracks' position filters and the host's pose filter start from.
WALKING_SPEED_STD_MPS = 1.0


def _T(a: NDArray) -> NDArray:
    """Transpose of the last two axes (a batch of matrices stays a batch)."""
    return np.swapaxes(a, -1, -2)


def predict(x: NDArray, P: NDArray, F: NDArray, Q: NDArray) -> tuple[NDArray, NDArray]:
    """Kalman prediction.

    Leading batch dimensions (B, ...) broadcast: a batch of filters runs in one call.

    Args:
        x: state, (n,) or (n, k), or batched (B, n, k).
        P: covariance, (n, n) or (B, n, n).
        F: state transition, (n, n) or (B, n, n).
        Q: process noise, (n, n) or (B, n, n).

    Returns:
        ``(x, P)`` predicted.
    """
    # x = F x
    x = F @ x
    # P = F P F^T + Q
    P = F @ P @ _T(F) + Q
    return x, P


def update(x: NDArray, P: NDArray, z: NDArray, H: NDArray, R: NDArray) -> tuple[NDArray, NDArray]:
    """Kalman measurement update (Joseph form, which keeps P symmetric positive definite).

    Leading batch dimensions (B, ...) broadcast, as in ``predict``.

    Args:
        x: state, (n,) or (n, k), or batched (B, n, k).
        P: covariance, (n, n) or (B, n, n).
        z: measurement, (m,) or (m, k), or batched (B, m, k).
        H: measurement matrix, (m, n) or (B, m, n).
        R: measurement noise, (m, m) or (B, m, m).

    Returns:
        ``(x, P)`` updated.
    """
    # y = z - H x
    y = z - H @ x
    # S = H P H^T + R
    S = H @ P @ _T(H) + R
    # K = P H^T S^-1   (solved as K^T = S^-T (P H^T)^T)
    K = _T(np.linalg.solve(_T(S), _T(P @ _T(H))))
    # x = x + K y
    x = x + K @ y
    # P = (I - K H) P (I - K H)^T + K R K^T
    I_KH = np.eye(P.shape[-1]) - K @ H
    P = I_KH @ P @ _T(I_KH) + K @ R @ _T(K)
    return x, P


def white_accel_noise(dt: float | NDArray, sigma_a: float) -> NDArray[np.float64]:
    """Process noise of one (position, velocity) axis over ``dt`` seconds.

    Returns:
        (2, 2), or (B, 2, 2) for ``dt`` of shape (B,).
    """
    dt = np.asarray(dt, dtype=np.float64)
    g = np.stack([0.5 * dt * dt, dt], axis=-1)  # (..., 2)
    # Q = sigma_a^2 g g^T = sigma_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]
    return sigma_a * sigma_a * g[..., :, None] * g[..., None, :]


def continuous_accel_noise(dt: float | NDArray, q: float) -> NDArray[np.float64]:
    """Process noise of one (position, velocity) axis over ``dt`` seconds under continuous white
    acceleration of spectral density ``q`` (m^2/s^3): the velocity wanders by ``sqrt(q dt)``.

    Unlike ``white_accel_noise`` (one random acceleration held over each step), two steps of dt/2
    add up to one of dt: a filter updated by many cameras' frames is no stiffer than one updated
    by a single camera's.

    A negative ``dt`` (back in time: a late camera's frame) grows the uncertainty alike, by ``|dt|``.

    Returns:
        (2, 2), or (B, 2, 2) for ``dt`` of shape (B,).
    """
    dt = np.asarray(dt, dtype=np.float64)[..., None, None]
    a = np.abs(dt)
    # Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]] (|dt| for the variances, dt's sign on the cross term)
    return q * np.concatenate([np.concatenate([a**3 / 3, dt * a / 2], axis=-1), np.concatenate([dt * a / 2, a], axis=-1)], axis=-2)


class AxisCov(NamedTuple):
    """The 2 x 2 covariance [[p00, p01], [p10, p11]] of (position, rate) axes, element-wise:
    each field one array of any (broadcast) shape, one entry per filter and axis."""

    p00: NDArray
    p01: NDArray
    p10: NDArray
    p11: NDArray


def cv_predict(pos: NDArray, rate: NDArray, P: AxisCov, dt: NDArray, q: NDArray | float) -> tuple[NDArray, NDArray, AxisCov]:
    """``predict`` of constant-velocity axes, F = [[1, dt], [0, 1]] and the white-acceleration Q.

    Args:
        pos, rate: positions and rates, any (broadcast) shape, e.g. (B, A).
        P: their covariances (``AxisCov``), broadcast against ``pos``.
        dt: seconds ahead, broadcast against ``pos`` (e.g. (B, 1)).
        q: acceleration variances sigma_a^2, broadcast (e.g. (B, A) or a number).

    Returns:
        ``(pos, rate, P)`` predicted.
    """
    dt2 = dt * dt
    # x = F x: position += dt * rate
    pos = pos + dt * rate
    # P = F P F^T + Q, Q = q [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]
    p00, p01, p10, p11 = P
    P = AxisCov(p00 + dt * (p01 + p10) + dt2 * p11 + q * dt2 * dt2 / 4, p01 + dt * p11 + q * dt2 * dt / 2,
                p10 + dt * p11 + q * dt2 * dt / 2, p11 + q * dt2)
    return pos, rate, P


def cv_update(pos: NDArray, rate: NDArray, P: AxisCov, z: NDArray, R: NDArray) -> tuple[NDArray, NDArray, AxisCov]:
    """``update`` of constant-velocity axes that measure their position (H = [1, 0]), Joseph form.

    Args:
        pos, rate: states, any (broadcast) shape.
        P: their covariances (``AxisCov``).
        z: measured positions, shape of ``pos``.
        R: measurement variances, broadcast against ``P``'s fields.

    Returns:
        ``(pos, rate, P)`` updated.
    """
    p00, p01, p10, p11 = P
    # S = H P H^T + R
    S = p00 + R
    # K = P H^T S^-1 = (p00, p10) / S
    k0, k1 = p00 / S, p10 / S
    # y = z - H x;  x = x + K y
    y = z - pos
    pos, rate = pos + k0 * y, rate + k1 * y
    # P = (I - K H) P (I - K H)^T + K R K^T, with I - K H = [[1 - k0, 0], [-k1, 1]]
    a = 1.0 - k0
    P = AxisCov(a * a * p00 + k0 * k0 * R, a * (p01 - k1 * p00) + k0 * k1 * R, a * (p10 - k1 * p00) + k0 * k1 * R,
                k1 * k1 * p00 - k1 * (p01 + p10) + p11 + k1 * k1 * R)
    return pos, rate, P
