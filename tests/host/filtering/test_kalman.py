"""The one Kalman implementation: the per-axis constant-velocity step against the textbook 6 x 6 form."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.host.filtering.kalman import AxisCov, continuous_accel_noise, cv_predict, cv_update, predict, update, white_accel_noise


def _six_state(rng: np.random.Generator, B: int) -> tuple[np.ndarray, np.ndarray]:
    """B states (x, y, yaw, vx, vy, yaw_rate) with covariances coupling each position and its rate only."""
    x = rng.normal(size=(B, 6))
    P = np.zeros((B, 6, 6))
    for i in range(3):
        A = rng.normal(size=(B, 2, 2))
        P[:, i::3, i::3] = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(2)
    return x, P


def _axes(x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, AxisCov]:
    a, r = np.arange(3), np.arange(3) + 3
    return x[:, :3], x[:, 3:], AxisCov(P[:, a, a], P[:, a, r], P[:, r, a], P[:, r, r])


def _six(pos: np.ndarray, rate: np.ndarray, cov: AxisCov) -> tuple[np.ndarray, np.ndarray]:
    a, r = np.arange(3), np.arange(3) + 3
    P = np.zeros((len(pos), 6, 6))
    P[:, a, a], P[:, a, r], P[:, r, a], P[:, r, r] = cov
    return np.concatenate([pos, rate], axis=1), P


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_per_axis_step_is_the_textbook_six_state_filter(seed: int) -> None:
    rng = np.random.default_rng(seed)
    B = 6
    x, P = _six_state(rng, B)
    dt = rng.uniform(0.0, 1.5, B)
    sig = rng.uniform(0.5, 4.0, (B, 3))  # acceleration std per axis
    # Textbook: F = [[I, dt I], [0, I]], Q per axis from white_accel_noise, H = [I, 0], R diagonal.
    F = np.broadcast_to(np.eye(6), (B, 6, 6)).copy()
    F[:, [0, 1, 2], [3, 4, 5]] = dt[:, None]
    Q = np.zeros((B, 6, 6))
    for i in range(3):
        Q[:, i::3, i::3] = sig[:, i, None, None] ** 2 * white_accel_noise(dt, 1.0)
    xe, Pe = predict(x[:, :, None], P, F, Q)
    pos, rate, cov = cv_predict(*_axes(x, P), dt[:, None], sig**2)
    xg, Pg = _six(pos, rate, cov)
    assert np.allclose(xg, xe[:, :, 0], atol=1e-12) and np.allclose(Pg, Pe, atol=1e-12)

    z, R = rng.normal(size=(B, 3)), rng.uniform(0.01, 1.0, (B, 3))
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    Rm = np.zeros((B, 3, 3))
    Rm[:, [0, 1, 2], [0, 1, 2]] = R
    xe, Pe = update(xe, Pe, z[:, :, None], H, Rm)
    pos, rate, cov = cv_update(pos, rate, cov, z, R)
    xg, Pg = _six(pos, rate, cov)
    assert np.allclose(xg, xe[:, :, 0], atol=1e-12) and np.allclose(Pg, Pe, atol=1e-12)


def test_update_moves_towards_the_measurement_by_the_gain() -> None:
    pos, rate, cov = cv_update(np.array([0.0]), np.array([0.0]), AxisCov(*(np.array([v]) for v in (1.0, 0.0, 0.0, 1.0))),
                               np.array([1.0]), np.array([1.0]))
    assert pos[0] == pytest.approx(0.5) and cov.p00[0] == pytest.approx(0.5) and rate[0] == 0.0


def test_continuous_acceleration_noise_does_not_depend_on_how_often_the_filter_steps() -> None:
    # One second in one step, or in 75 (five cameras at 15 fps each): the same prediction covariance.
    # The piecewise-constant model (white_accel_noise) makes the second 75 times stiffer in velocity.
    F = lambda dt: np.array([[1.0, dt], [0.0, 1.0]])  # noqa: E731
    P0 = np.diag([0.01, 0.04])
    for noise, same in ((lambda dt: continuous_accel_noise(dt, 4.0), True), (lambda dt: white_accel_noise(dt, 2.0), False)):
        once = predict(np.zeros(2), P0, F(1.0), noise(1.0))[1]
        P = P0
        for _ in range(75):
            P = predict(np.zeros(2), P, F(1 / 75), noise(1 / 75))[1]
        assert np.allclose(P, once) == same
    assert np.isclose(continuous_accel_noise(1.0, 4.0)[1, 1], 4.0)  # the velocity wanders by sqrt(q) a second
    assert continuous_accel_noise(np.array([0.1, 0.2]), 4.0).shape == (2, 2, 2)
    back = continuous_accel_noise(-0.5, 4.0)  # back in time (a late frame): as uncertain, the cross term turned
    assert np.allclose(np.diag(back), np.diag(continuous_accel_noise(0.5, 4.0))) and back[0, 1] < 0
    assert np.all(np.linalg.eigvalsh(back) >= 0)
