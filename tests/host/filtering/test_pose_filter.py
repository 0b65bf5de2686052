"""The temporal filter: pure Kalman steps and the per-person pose filter."""

from __future__ import annotations

import math
from typing import cast

import numpy as np
import pytest

from superbody.edge.angles import wrap_angle
from superbody.host.filtering.kalman import predict, update
from superbody.host.filtering.pose_filter import FilterConfig, PoseFilter

S = 1_000_000_000  # ns per second
DEG = math.pi / 180


@pytest.mark.parametrize(
    ("a", "wrapped"),
    [
        (0.0, 0.0),                      # identity
        (math.pi, math.pi),              # +pi stays
        (-math.pi, math.pi),             # -pi becomes +pi: the interval is (-pi, pi]
        (3 * math.pi / 2, -math.pi / 2),  # one turn down
        (-7 * math.pi / 2, math.pi / 2),  # two turns up
    ],
)
def test_wrap_angle(a, wrapped):
    assert wrap_angle(a) == pytest.approx(wrapped)


def test_predict_and_update_match_the_textbook_on_a_scalar():
    x, P = predict(np.array([1.0]), np.array([[2.0]]), np.array([[1.0]]), np.array([[0.5]]))
    assert x[0] == 1.0 and P[0, 0] == 2.5
    # Equal prior and measurement variances: halfway, half the variance.
    x, P = update(np.array([0.0]), np.array([[1.0]]), np.array([2.0]), np.array([[1.0]]), np.array([[1.0]]))
    assert x[0] == pytest.approx(1.0) and P[0, 0] == pytest.approx(0.5)


def test_update_handles_columns_sharing_a_covariance():
    # Two independent axes as the columns of x: same result as two separate updates.
    x = np.array([[0.0, 10.0], [1.0, -1.0]])  # (2, 2): rows (pos, vel), columns (x, y)
    P = np.array([[1.0, 0.2], [0.2, 0.5]])
    H, R = np.array([[1.0, 0.0]]), np.array([[0.3]])
    both, _ = update(x, P, np.array([[0.5, 9.0]]), H, R)
    for col, z in ((0, 0.5), (1, 9.0)):
        one, _ = update(x[:, col], P, np.array([z]), H, R)
        assert np.allclose(both[:, col], one)


def test_yaw_wraps_across_pi():
    f = PoseFilter()
    f.update(0, 0.0, 0.0, 170 * DEG)
    out = f.update(S // 10, 0.0, 0.0, -170 * DEG)
    # The innovation is +20 deg, not -340: the filter turns counter-clockwise through pi.
    assert out.yaw_rate > 0
    assert abs(wrap_angle(out.yaw - 170 * DEG)) < 20 * DEG
    assert -math.pi < out.yaw <= math.pi


def test_yaw_keeps_turning_through_pi():
    f = PoseFilter()
    for k in range(60):  # 4 s at 15 Hz turning at +1 rad/s, starting at 3 rad
        out = f.update(k * S // 15, 0.0, 0.0, float(wrap_angle(3.0 + k / 15)))
    assert out.yaw_rate == pytest.approx(1.0, abs=0.05)
    assert abs(wrap_angle(out.yaw - (3.0 + 59 / 15))) < 2 * DEG


@pytest.mark.parametrize(
    ("vx", "vy", "w"),
    [
        (0.0, 0.0, 0.0),    # standing still
        (1.2, -0.5, 0.0),   # walking diagonally
        (0.0, 1.0, -0.8),   # walking while turning clockwise
    ],
)
def test_converges_to_constant_velocity(vx, vy, w):
    rng = np.random.default_rng(0)
    f = PoseFilter()
    for k in range(75):  # 5 s at 15 Hz, noisy measurements
        t = k / 15
        out = f.update(round(t * S), 1 + vx * t + rng.normal(0, 0.05), -2 + vy * t + rng.normal(0, 0.05),
                       float(wrap_angle(0.5 + w * t + rng.normal(0, 3 * DEG))))
    assert (out.vx, out.vy) == pytest.approx((vx, vy), abs=0.15)
    assert out.yaw_rate == pytest.approx(w, abs=0.25)
    assert (out.x, out.y) == pytest.approx((1 + vx * t, -2 + vy * t), abs=0.1)
    assert out.cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(out.cov) > 0)
    # Filtered position is tighter than one measurement.
    assert out.cov[0, 0] < 0.1**2


def test_predict_to_extrapolates():
    f = PoseFilter()
    for k in range(30):
        f.update(k * S // 10, 0.5 * k / 10, 0.0, 0.0)
    ahead = f.predict_to(29 * S // 10 + S)
    assert ahead.x == pytest.approx(0.5 * 2.9 + 0.5, abs=0.05)
    assert ahead.cov[0, 0] > f.predict_to(0).cov[0, 0]  # uncertainty grows; earlier times give the state


def test_predict_to_needs_a_measurement():
    with pytest.raises(RuntimeError):
        PoseFilter().predict_to(0)


def test_disabled_passes_measurements_through_with_finite_difference_rates():
    f = PoseFilter(FilterConfig(enabled=False))
    first = f.update(0, 1.0, 2.0, 170 * DEG)
    assert (first.x, first.y, first.vx, first.vy, first.yaw_rate) == (1.0, 2.0, 0.0, 0.0, 0.0)
    out = f.update(S // 2, 1.5, 1.0, -170 * DEG)
    assert (out.x, out.y) == (1.5, 1.0) and out.yaw == pytest.approx(-170 * DEG)
    assert (out.vx, out.vy) == pytest.approx((1.0, -2.0))
    assert out.yaw_rate == pytest.approx(40 * DEG)  # +20 deg in 0.5 s, across pi
    c = FilterConfig()
    assert np.allclose(out.cov, np.diag([c.meas_std_xy_m**2, c.meas_std_xy_m**2, c.meas_std_yaw_rad**2]))  # the default sigmas
    assert f.predict_to(S).x == 1.5  # held, not extrapolated


def test_out_of_order_measurement_is_ignored():
    f = PoseFilter()
    f.update(S, 0.0, 0.0, 0.0)
    before = f.update(2 * S, 1.0, 0.0, 0.0)
    after = f.update(S + S // 2, 50.0, 50.0, 3.0)
    assert f.ignored == 1
    assert (after.stamp_ns, after.x, after.y) == (before.stamp_ns, before.x, before.y)


def test_long_gap_restarts():
    f = PoseFilter(FilterConfig(reset_after_s=1.0))
    f.update(0, 0.0, 0.0, 0.0)
    f.update(S // 10, 0.1, 0.0, 0.0)
    out = f.update(5 * S, 7.0, 7.0, 1.0)
    assert (out.x, out.y, out.yaw, out.vx) == (7.0, 7.0, 1.0, 0.0)


@pytest.mark.parametrize(
    ("args", "kwargs"),
    [
        ((0, math.nan, 0.0, 0.0), {}),                        # NaN x
        ((0, 0.0, math.inf, 0.0), {}),                        # infinite y
        ((0, 0.0, 0.0, math.nan), {}),                        # NaN yaw
        ((0, 0.0, 0.0, 0.0), {"meas_std": (0.1, 0.1)}),       # too few stds
        ((0, 0.0, 0.0, 0.0), {"meas_std": (0.1, 0.0, 0.1)}),  # zero std
        ((0, 0.0, 0.0, 0.0), {"meas_std": (0.1, 0.1, math.nan)}),  # NaN std
    ],
)
def test_rejects_bad_measurements(args, kwargs):
    with pytest.raises(ValueError):
        PoseFilter().update(*args, **kwargs)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("meas_std_xy_m", 0.0),          # must be positive
        ("meas_std_yaw_rad", 4.0),       # above pi
        ("accel_std_mps2", math.nan),    # not finite
        ("reset_after_s", -1.0),         # negative
        ("enabled", 1),                  # not a bool
        ("accel_std_mps2", "fast"),      # not a number
    ],
)
def test_config_is_validated(field, value):
    with pytest.raises(ValueError, match=field):
        FilterConfig(**{field: value})


def test_measurement_std_weights_the_update():
    sure, unsure = PoseFilter(), PoseFilter()
    for f in (sure, unsure):
        f.update(0, 0.0, 0.0, 0.0)
    a = sure.update(S // 10, 1.0, 0.0, 0.0, meas_std=(0.01, 0.01, 0.01))
    b = unsure.update(S // 10, 1.0, 0.0, 0.0, meas_std=(1.0, 1.0, 1.0))
    assert a.x > 0.9 and b.x < a.x


def _textbook_FQ(dt: float, c: FilterConfig) -> tuple[np.ndarray, np.ndarray]:
    """This filter's F and Q over dt seconds, built the textbook way (the reference for the batched code)."""
    from superbody.host.filtering.kalman import white_accel_noise

    F = np.eye(6)
    F[[0, 1, 2], [3, 4, 5]] = dt
    Q = np.zeros((6, 6))
    for i, sa in enumerate((c.accel_std_mps2, c.accel_std_mps2, c.yaw_accel_std_radps2)):
        Q[i::3, i::3] = white_accel_noise(dt, sa)
    return F, Q


def test_update_many_equals_one_update_per_filter():
    # Several people over time, with every path update_many must route right: the first
    # measurement, the batched predict + update, a late one (ignored), a gap (reset), own sigmas
    # and the default ones, yaw across pi.
    from superbody.host.filtering.pose_filter import update_many

    rng = np.random.default_rng(3)
    one, many = [PoseFilter() for _ in range(6)], [PoseFilter() for _ in range(6)]
    t = np.zeros(6, dtype=np.int64)
    for step in range(40):
        t += rng.integers(S // 60, S // 10, size=6)
        stamps = t.copy()
        stamps[step % 6] -= S if step % 7 == 3 else 0  # now and then a measurement older than the state
        stamps[(step + 2) % 6] += 3 * S if step == 20 else 0  # one gap past reset_after_s
        pose = np.column_stack([rng.normal(0, 2, 6), rng.normal(0, 2, 6), rng.uniform(-math.pi, math.pi, 6)])
        std = np.abs(rng.normal(0.2, 0.05, (6, 3)))
        std[step % 3] = np.nan  # the default sigma for one person
        expect = [f.update(int(s), *p, tuple(d) if np.isfinite(d).all() else None) for f, s, p, d in zip(one, stamps, pose, std)]
        got = update_many(many, stamps, pose, std)
        for e, g in zip(expect, got):
            assert g.stamp_ns == e.stamp_ns
            assert np.allclose([g.x, g.y, g.yaw, g.vx, g.vy, g.yaw_rate], [e.x, e.y, e.yaw, e.vx, e.vy, e.yaw_rate], atol=1e-9)
            assert np.allclose(g.cov, e.cov, atol=1e-12)
    assert [f.ignored for f in many] == [f.ignored for f in one] and sum(f.ignored for f in one) > 0


def test_update_many_rejects_bad_input_like_update():
    from superbody.host.filtering.pose_filter import update_many

    with pytest.raises(ValueError, match="x must be finite"):
        update_many([PoseFilter()], [0], np.array([[math.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="must match"):
        update_many([PoseFilter()], [0, 1], np.zeros((1, 3)))


def test_the_batched_step_is_the_textbook_six_state_filter():
    # _step writes the filter out per axis; here the same step with predict() and update() on
    # the full 6 x 6 matrices, for filters in mid-track (rates, cross terms within each axis).
    from superbody.edge.angles import wrap_angle
    from superbody.host.filtering.kalman import predict, update
    from superbody.host.filtering.pose_filter import _step

    rng = np.random.default_rng(5)
    plain = FilterConfig(walk_yaw_std_rad=0.0, outlier_sigma=0.0)  # the two additions off: the textbook filter
    filters = [PoseFilter(plain) for _ in range(5)]
    for f in filters:
        f.update(0, *rng.normal(0, 2, 2), rng.uniform(-math.pi, math.pi))
        for j in range(1, 6):  # build up rates and position-rate covariances
            f.update(j * S // 10, *rng.normal(0, 2, 2), rng.uniform(-math.pi, math.pi), tuple(np.abs(rng.normal(0.3, 0.1, 3))))
    before = [(f._t, f._x.copy(), f._P.copy()) for f in filters]
    t = np.array([S // 2 + k * S // 30 for k in range(5)], dtype=np.int64)
    pose = np.column_stack([rng.normal(0, 2, 5), rng.normal(0, 2, 5), rng.uniform(-3 * math.pi, 3 * math.pi, 5)])
    std = np.abs(rng.normal(0.2, 0.05, (5, 3)))
    got = _step(filters, t, pose, std)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    for k, (t0, x0, P0) in enumerate(before):
        c = filters[k].config
        x, P = predict(x0, P0, *_textbook_FQ((t[k] - t0) * 1e-9, c))
        x[2] = wrap_angle(x[2])
        z = np.array([pose[k, 0], pose[k, 1], x[2] + wrap_angle(wrap_angle(pose[k, 2]) - x[2])])
        x, P = update(x, P, z, H, np.diag(std[k] ** 2))
        x[2] = wrap_angle(x[2])
        g = got[k]
        assert np.allclose([g.x, g.y, g.yaw, g.vx, g.vy, g.yaw_rate], x, atol=1e-12)
        assert np.allclose(filters[k]._P, P, atol=1e-12)
        assert np.allclose(g.cov, P[:3, :3], atol=1e-12)


def test_predict_many_is_the_textbook_prediction_of_each_filter():
    # predict_many (and predict_to, which uses it) against predict() with this filter's F and Q,
    # for filters at different times; an earlier time gives the state, a disabled filter holds.
    from superbody.host.filtering.pose_filter import predict_many

    rng = np.random.default_rng(5)
    cfg = FilterConfig()
    filters = [PoseFilter(cfg) for _ in range(4)] + [PoseFilter(FilterConfig(enabled=False))]
    for f in filters:
        for k in range(int(rng.integers(3, 12))):
            f.update(k * S // 8 + int(rng.integers(0, S // 50)), *rng.normal(0, 1, 2), rng.uniform(-3, 3), (0.1, 0.1, 0.2))
    states = [(f.stamp_ns, f._x.copy(), f._P.copy()) for f in filters]
    want_t = [filters[0].stamp_ns + S // 3, filters[1].stamp_ns + 1, filters[2].stamp_ns - S, filters[3].stamp_ns, filters[4].stamp_ns + S]
    got = predict_many(filters, want_t)
    for i, (f, g) in enumerate(zip(filters, got)):
        t0, x0, P0 = states[i]
        assert (f.stamp_ns, f._x.tolist()) == (t0, x0.tolist())  # prediction leaves the state alone
        if i == 4:  # disabled: the last measurement, held, at the asked time
            assert g.stamp_ns == want_t[i] and (g.x, g.y, g.yaw) == (x0[0], x0[1], x0[2])
            continue
        x, P = predict(x0, P0, *_textbook_FQ(max(0, want_t[i] - t0) / S, cfg))
        assert g.stamp_ns == max(want_t[i], t0)
        assert np.allclose([g.x, g.y, g.vx, g.vy, g.yaw_rate], [x[0], x[1], x[3], x[4], x[5]], atol=1e-12)
        assert abs(wrap_angle(g.yaw - x[2])) < 1e-12 and np.allclose(g.cov, P[:3, :3], atol=1e-12)
        assert f.predict_to(want_t[i]).x == g.x
    with pytest.raises(RuntimeError, match="no measurement"):
        predict_many([filters[0], PoseFilter()], [0, 0])
    with pytest.raises(ValueError, match="must match"):
        predict_many(filters, [0])


def _walk(cfg: FilterConfig, yaw_measured: float, yaw_std_deg: float, seconds: float = 4.0, fps: float = 15.0) -> float:
    """A person walking along +x at 1 m/s, measured with a constant yaw: the filtered yaw at the end, degrees."""
    f = PoseFilter(cfg)
    for k in range(round(seconds * fps)):
        t = k / fps
        f.update(round(t * S), t, 0.0, yaw_measured, (0.05, 0.05, math.radians(yaw_std_deg)))
    return math.degrees(f.predict_to(cast(int, f.stamp_ns)).yaw)


@pytest.mark.parametrize("yaw_std_deg, lo, hi", [(90.0, 12.0, 30.0), (30.0, 33.0, 39.0)])
def test_walking_direction_pulls_a_measured_yaw_by_its_uncertainty_never_replacing_it(yaw_std_deg, lo, hi):
    # Walking along 0 deg, yaw measured at 40 deg. The filter takes the 15 measurements a second
    # as independent (information 15 / sigma^2 a second), the prior as one of 25 deg a second:
    # a poorly measured yaw (90 deg) is pulled about halfway, a fair one (30 deg) a few degrees.
    assert _walk(FilterConfig(walk_yaw_std_rad=0.0), math.radians(40), yaw_std_deg) == pytest.approx(40, abs=0.5)
    got = _walk(FilterConfig(), math.radians(40), yaw_std_deg)
    assert lo < got < hi
    # the frame rate does not change the prior's weight against measurements of the same information
    fast = _walk(FilterConfig(), math.radians(40), yaw_std_deg * math.sqrt(2), fps=30.0)
    assert fast == pytest.approx(got, abs=3)


def test_standing_still_gives_no_walking_prior():
    f = PoseFilter()
    for k in range(45):
        f.update(k * S // 15, 1.0, 2.0, math.radians(70), (0.05, 0.05, math.radians(30)))
    assert math.degrees(f.predict_to(f.stamp_ns).yaw) == pytest.approx(70, abs=0.5)


def test_an_unmeasured_yaw_turns_only_with_the_walk():
    # A person standing at 2 rad whose side then leaves every view: the position steps 0.15 m (the
    # torso's centre from one side's joints) and no yaw is measured. The step is a walk of 0.5 m/s
    # to the filter for a few frames; the walking prior then set the yaw turning at 10 deg/s, and
    # nothing measured stopped it. Now the turn stops with the walk.
    f = PoseFilter()
    for k in range(30):
        f.update(k * S // 15, 0.0, 0.0, 2.0, (0.05, 0.05, 0.1))
    for k in range(30, 60):
        p = f.update(k * S // 15, 0.15, 0.1, 0.0, (0.05, 0.05, math.inf))
    assert abs(p.yaw - 2.0) < math.radians(8) and p.yaw_rate == 0.0
    # A walker with no yaw measured is still turned to where they walk (the prior's whole use then).
    g = PoseFilter()
    for k in range(30):
        g.update(k * S // 15, 0.1 * k, 0.0, 2.0, (0.05, 0.05, 0.1))
    for k in range(30, 60):
        q = g.update(k * S // 15, 0.1 * k, 0.0, 0.0, (0.05, 0.05, math.inf))
    assert abs(q.yaw) < 1.0


@pytest.mark.parametrize("outlier_sigma, moved_max_m", [(3.0, 0.25), (0.0, None)])
def test_one_bad_measurement_does_not_move_a_track_far(outlier_sigma, moved_max_m):
    f = PoseFilter(FilterConfig(outlier_sigma=outlier_sigma, walk_yaw_std_rad=0.0))
    for k in range(30):  # standing at the origin, well measured
        f.update(k * S // 15, 0.0, 0.0, 0.0, (0.05, 0.05, 0.1))
    p = f.update(30 * S // 15, 2.0, 0.0, math.pi, (0.05, 0.05, 0.1))  # one view from somebody else, 2 m off, facing back
    if moved_max_m is None:
        assert p.x > 1.0  # the plain filter believes it
    else:
        assert p.x < moved_max_m and abs(p.yaw) < math.radians(60)
    for k in range(31, 60):  # but a real move, kept up, is followed within a second or two
        p = f.update(k * S // 15, 2.0, 0.0, 0.0, (0.05, 0.05, 0.1))
    assert p.x > 1.9


def test_a_yaw_std_of_inf_is_a_measurement_without_yaw():
    """An estimator that saw nothing to tell a yaw by reports it with an infinite sigma: the
    position is updated, the yaw goes on as predicted (a finite sigma, even 3 rad, taken 45 times
    a second, would turn the person). NaN in a row of ``update_many`` is that axis's default."""
    from superbody.host.filtering.pose_filter import update_many

    f, g = PoseFilter(), PoseFilter()
    for k in range(45):  # standing still (walking, the walking direction would pull the yaw)
        t, yaw, std = k * S // 30, (1.0 if k == 0 else 0.0), (0.05, 0.05, 0.1 if k == 0 else math.inf)
        f.update(t, 0.0, 0.0, yaw, std)
        (got,) = update_many([g], [t], np.array([[0.0, 0.0, yaw]]), np.array([std]))
    assert abs(got.yaw - 1.0) < 1e-6 and got.cov[2, 2] > 0.1**2 and np.allclose(got.cov, f.predict_to(t).cov)
    a, b = PoseFilter(), PoseFilter()
    c = FilterConfig()
    for k in range(5):
        pa = a.update(k * S // 10, 0.1 * k, 0.0, 0.2 * k, (c.meas_std_xy_m, 0.2, math.inf))
        (pb,) = update_many([b], [k * S // 10], np.array([[0.1 * k, 0.0, 0.2 * k]]), np.array([[math.nan, 0.2, math.inf]]))
        assert np.allclose([pa.x, pa.y, pa.yaw], [pb.x, pb.y, pb.yaw]) and np.allclose(pa.cov, pb.cov)
    with pytest.raises(ValueError, match="meas_std"):
        PoseFilter().update(0, 0.0, 0.0, 0.0, (math.inf, 0.1, 0.1))


def test_a_yaw_unmeasured_for_minutes_keeps_a_variance_a_pose_array_can_carry():
    """A person seen only from one side for minutes: with no yaw measured its variance grew
    without end (873,000 rad^2 after 100 s, past the PoseArray's limit of 1e6). An angle's
    variance is pi^2 at most."""
    from superbody.host.filtering.pose_filter import update_many
    from superbody.host.messages.pose_rules import _MAX_COV

    f = [PoseFilter(), PoseFilter()]
    update_many(f, [0, 0], np.array([[0.0, 0.0, 1.0], [1.0, 0.0, -1.0]]), np.full((2, 3), 0.1))
    for k in range(1, 1501):  # 150 s at 10 Hz, the second filter's yaw measured throughout
        got = update_many(f, [k * S // 10] * 2, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, -1.0]]), np.array([[0.05, 0.05, math.inf], [0.05, 0.05, 0.1]]))
    assert got[0].cov[2, 2] == pytest.approx(math.pi**2) and got[0].cov[2, 2] < _MAX_COV and abs(got[0].yaw - 1.0) < 1e-3
    assert got[1].cov[2, 2] < 0.1**2  # a measured yaw's variance is not touched
    assert np.all(np.linalg.eigvalsh(got[0].cov) >= 0)
