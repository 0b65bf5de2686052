"""The temporal filter: a constant-velocity Kalman filter on each person's (x, y, yaw).

``PoseFilter`` holds one person's state; the maths is ``host.filtering.kalman``'s per-axis
constant-velocity step (the three axes never mix), run for a batch of people at once.

State: (x, y, yaw, vx, vy, yaw_rate); yaw is kept wrapped to (-pi, pi] and each yaw measurement
is unwrapped next to the state first, so a person turning through +-pi gives a small innovation.
Process noise: piecewise-constant white acceleration (Bar-Shalom), per axis

    Q = sigma_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]

Beyond the plain filter (each can be turned off in ``FilterConfig``):

- **Walking direction as a yaw prior.** People mostly face where they walk: in both of the
  paper's recordings torso yaw and walking direction differ by 17-20 degrees on average while
  the person moves. So while a track moves faster than ``walk_min_speed_mps``, the direction of
  its velocity is a second, weak measurement of its yaw, of variance ``walk_yaw_std_rad``^2 (the
  spread of yaw about the walking direction) plus the velocity direction's own (speed variance
  over speed squared). That spread is one fact about a walk, not one per frame: the prior counts
  as independent once per ``walk_prior_time_s``, so at a frame interval dt its variance is
  multiplied by ``walk_prior_time_s / dt``. A prior weighted by its uncertainty, never a
  replacement: a person who walks sideways or backwards is still measured by the views. A yaw
  no view measures (``meas_std`` yaw inf) turns only with the walk: once the prior no longer
  applies, its rate is 0.
- **No single measurement moves a track far.** A measurement more than ``outlier_sigma``
  standard deviations of its innovation from the prediction (one bad view: a 180-degree yaw
  flip, a position from the wrong person) counts with its variance multiplied by d / k (d its
  distance in standard deviations, k = ``outlier_sigma``; Huber's weight): its pull on the state
  is bounded, while a change that persists still wins over a few frames.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.host.filtering.kalman import WALKING_SPEED_STD_MPS, AxisCov, cv_predict, cv_update

__all__ = ["FilterConfig", "FilteredPose", "PoseFilter", "update_many", "predict_many"]

_NS = 1e-9
_AX = np.arange(3)  # state indices of x, y, yaw
_RATE = _AX + 3  # and of their rates


def _check(name: str, value: float, lo: float, hi: float, lo_open: bool = True) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not (ok and (lo < value if lo_open else lo <= value) and value <= hi):
        raise ValueError(f"FilterConfig.{name} must be in {'(' if lo_open else '['}{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class FilterConfig:
    """Noise model of a walking person and the filter's switches.

    Attributes:
        enabled: False passes measurements through (per-frame output, finite-difference rates).
        meas_std_xy_m: default 1-sigma of a position measurement, metres: for an estimator that
            reports none (geometry on a site with no model; ``AnalyticEstimator`` with a
            calibration reports its own). 0.03, geometry's error with two or more cameras: until
            December 2026 it was 0.1, and the filter lagged behind people shuffling in a
            simulated crowd (scenes d and k, 15 s, seeds 1-3: position p90 28-82 mm against
            15-69 per frame; at 0.03 17-63 mm) and made a real four-person recording worse
            than per-frame output. dev.json's live geometry (225 samples, 1-3 cameras) went from
            70.0 / 76.0 mm, 8.26 deg to 68.3 / 75.5 mm, 8.14 deg with both defaults changed.
        meas_std_yaw_rad: default 1-sigma of a yaw measurement, radians: 4 deg (was 10), as above.
        accel_std_mps2: 1-sigma of a person's acceleration (starting, stopping), m/s^2. Larger
            than a walk's own (about 0.5 m/s^2 over 0.2 s on dev.json's tracker): 3 had the least
            position error of 1.5, 2, 2.5, 3, 4 and 6 with the shipped hybrid on eight simulated
            30 s recordings (exact truth; ``python benchmarks/filter_tuning.py``), and it also
            lowers the live error on dev.json's spatial cross-validation (models/MODEL_CARD.md).
            A likely reason: successive estimates share views (set S keeps each camera's latest
            one), so their errors are not independent, and a filter that takes them as
            independent trusts its past too much and lags.
        yaw_accel_std_radps2: 1-sigma of torso angular acceleration, rad/s^2.
        init_speed_std_mps: 1-sigma of the unknown speed at the first measurement, m/s.
        init_yaw_rate_std_radps: 1-sigma of the unknown yaw rate at the first measurement.
        reset_after_s: a gap longer than this between measurements restarts the filter.
        walk_yaw_std_rad: 1-sigma of torso yaw about the walking direction while walking (module
            docstring: 17-20 deg mean absolute difference in both recordings, about 23 deg as a
            Gaussian's sigma; 25 deg); 0 turns the walking prior off.
        walk_min_speed_mps: the walking prior applies above this estimated speed.
        walk_prior_time_s: the walking prior counts as independent once per this long.
        outlier_sigma: measurements beyond this many innovation sigmas are down-weighted
            (module docstring); 0 turns it off.
    """

    enabled: bool = True
    meas_std_xy_m: float = 0.03
    meas_std_yaw_rad: float = math.radians(4.0)
    accel_std_mps2: float = 3.0
    yaw_accel_std_radps2: float = 5.0
    init_speed_std_mps: float = WALKING_SPEED_STD_MPS
    init_yaw_rate_std_radps: float = 2.0
    reset_after_s: float = 2.0
    walk_yaw_std_rad: float = math.radians(25.0)
    walk_min_speed_mps: float = 0.3
    walk_prior_time_s: float = 1.0
    outlier_sigma: float = 3.0

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"FilterConfig.enabled must be true or false, got {self.enabled!r}")
        _check("meas_std_xy_m", self.meas_std_xy_m, 0.0, 10.0)
        _check("meas_std_yaw_rad", self.meas_std_yaw_rad, 0.0, math.pi)
        _check("accel_std_mps2", self.accel_std_mps2, 0.0, 100.0)
        _check("yaw_accel_std_radps2", self.yaw_accel_std_radps2, 0.0, 1000.0)
        _check("init_speed_std_mps", self.init_speed_std_mps, 0.0, 100.0)
        _check("init_yaw_rate_std_radps", self.init_yaw_rate_std_radps, 0.0, 100.0)
        _check("reset_after_s", self.reset_after_s, 0.0, 3600.0)
        _check("walk_yaw_std_rad", self.walk_yaw_std_rad, 0.0, math.pi, lo_open=False)
        _check("walk_min_speed_mps", self.walk_min_speed_mps, 0.0, 10.0)
        _check("walk_prior_time_s", self.walk_prior_time_s, 0.0, 60.0)
        _check("outlier_sigma", self.outlier_sigma, 0.0, 100.0, lo_open=False)


@dataclass(frozen=True, eq=False)
class FilteredPose:
    """One person's filtered pose at one time.

    Attributes:
        stamp_ns: the time it holds for, UNIX nanoseconds.
        x, y: floor position, metres (REP-103).
        yaw: torso yaw, radians in (-pi, pi].
        vx, vy: velocity, m/s.
        yaw_rate: rad/s, counter-clockwise positive.
        cov: (3, 3) covariance of (x, y, yaw).
    """

    stamp_ns: int
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    cov: NDArray[np.float64]


# State layout: (x, y, yaw, vx, vy, yaw_rate); position i's velocity is at i + 3.


class PoseFilter:
    """Constant-velocity Kalman filter on one person's (x, y, yaw), fed with time stamps.

    Measurements older than the state are ignored (counted in ``ignored``); a gap longer than
    ``config.reset_after_s`` restarts the filter from the new measurement.
    """

    def __init__(self, config: FilterConfig | None = None) -> None:
        self.config = config or FilterConfig()
        self.ignored = 0
        self.reset()

    def reset(self) -> None:
        """Forget the state; the next measurement starts afresh."""
        self._t: int | None = None
        self._x = np.zeros(6)  # (6,) state
        self._P = np.eye(6)  # (6, 6) covariance

    @property
    def stamp_ns(self) -> int | None:
        """Time of the state, or None before the first measurement."""
        return self._t

    def update(self, t_ns: int, x: float, y: float, yaw: float, meas_std: tuple[float, float, float] | None = None) -> FilteredPose:
        """Add one measurement and return the filtered pose at ``t_ns``.

        Args:
            t_ns: capture time, UNIX nanoseconds.
            x, y: measured floor position, metres.
            yaw: measured torso yaw, radians (any range; it is wrapped).
            meas_std: (std_x m, std_y m, std_yaw rad) of this measurement; the config's by default.
                A yaw std of inf: the measurement has no yaw (the estimator had nothing to see it
                by), and the filter's yaw goes on as predicted.

        Raises:
            ValueError: a non-finite input or a non-positive std (inf allowed for the yaw only).
        """
        for name, v in (("x", x), ("y", y), ("yaw", yaw)):
            if not math.isfinite(v):
                raise ValueError(f"PoseFilter.update: {name} must be finite, got {v!r}")
        if meas_std is None:
            c = self.config
            std: tuple[float, ...] = (c.meas_std_xy_m, c.meas_std_xy_m, c.meas_std_yaw_rad)
        else:
            std = tuple(float(s) for s in meas_std)
            if len(std) != 3 or not all(math.isfinite(s) and s > 0 for s in std[:2]) or not std[2] > 0:
                raise ValueError(f"PoseFilter.update: meas_std must be 3 positive stds (x m, y m, yaw rad; finite, "
                                 f"but a yaw std may be inf), got {meas_std!r}")
        t_ns = int(t_ns)
        yaw = float(wrap_angle(float(yaw)))
        no_yaw = math.isinf(std[2])
        if self._t is not None and t_ns < self._t:
            self.ignored += 1
            return self._pose(self._t, self._x, self._P)
        # Starting (or passing through) without a yaw: the yaw is unknown, pi^2 its variance.
        R = np.diag(np.square((*std[:2], math.pi if no_yaw else std[2])))  # (3, 3)
        if self._t is None or (t_ns - self._t) * _NS > self.config.reset_after_s:
            return self._start(t_ns, x, y, yaw, R)
        if not self.config.enabled:
            return self._pass_through(t_ns, x, y, float(self._x[2]) if no_yaw else yaw, R)
        return _step([self], np.array([t_ns]), np.array([[x, y, yaw]]), np.array([std]))[0]

    def predict_to(self, t_ns: int) -> FilteredPose:
        """The pose predicted at ``t_ns`` (the state's own time if ``t_ns`` is earlier).

        With the filter disabled this is the last measurement, held.

        Raises:
            RuntimeError: no measurement yet.
        """
        if self._t is None:
            raise RuntimeError("PoseFilter.predict_to: no measurement yet")
        return predict_many([self], [t_ns])[0]

    def _start(self, t_ns: int, x: float, y: float, yaw: float, R: NDArray) -> FilteredPose:
        c = self.config
        self._t = t_ns
        self._x = np.array([x, y, yaw, 0.0, 0.0, 0.0])
        self._P = np.zeros((6, 6))
        self._P[:3, :3] = R
        self._P[3:, 3:] = np.diag([c.init_speed_std_mps**2, c.init_speed_std_mps**2, c.init_yaw_rate_std_radps**2])
        if not c.enabled:
            self._P[3:, 3:] = 0.0
        return self._pose(t_ns, self._x, self._P)

    def _pass_through(self, t_ns: int, x: float, y: float, yaw: float, R: NDArray) -> FilteredPose:
        assert self._t is not None  # update() starts a filter without a state instead
        dt = (t_ns - self._t) * _NS
        old = self._x
        rates = old[3:]  # a repeated stamp keeps the previous rates
        if dt > 0:
            # Finite differences; the yaw difference wrapped, so 170 -> -170 deg is +20 deg.
            rates = np.array([(x - old[0]) / dt, (y - old[1]) / dt, wrap_angle(yaw - old[2]) / dt])
        self._t = t_ns
        self._x = np.concatenate([[x, y, yaw], rates])
        self._P = np.zeros((6, 6))
        self._P[:3, :3] = R
        return self._pose(t_ns, self._x, self._P)

    @staticmethod
    def _pose(t_ns: int, xs: NDArray, P: NDArray) -> FilteredPose:
        return FilteredPose(
            stamp_ns=t_ns, x=float(xs[0]), y=float(xs[1]), yaw=float(xs[2]),
            vx=float(xs[3]), vy=float(xs[4]), yaw_rate=float(xs[5]), cov=P[:3, :3].copy(),
        )


def update_many(
    filters: Sequence[PoseFilter], t_ns: Sequence[int], pose: NDArray, meas_std: NDArray | None = None,
) -> list[FilteredPose]:
    """``filters[i].update(t_ns[i], *pose[i], meas_std[i])`` for every i, the common case in one pass.

    A host step updates every person it estimated: stacking the filters that take the plain
    predict + update path (enabled, a state, a measurement neither older than it nor after a
    reset gap) makes that one batch of 6 x 6 products instead of one small batch per person.
    The others (first measurement, reset, late, pass-through, bad input) go through
    ``PoseFilter.update`` one by one, which also raises on bad input exactly as it does.

    Args:
        filters: B filters (distinct).
        t_ns: (B,) capture times, UNIX nanoseconds.
        pose: (B, 3) measured (x, y, yaw).
        meas_std: (B, 3) 1-sigma per measurement; NaN in an axis (or None for all) means the
            filter's configured default for that axis; a yaw of inf, no yaw (``PoseFilter.update``);
            a row with any other value that is not a finite positive number, the defaults for
            the whole row.

    Returns:
        The B filtered poses, in order.
    """
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    B = len(filters)
    if len(pose) != B or len(t_ns) != B:
        raise ValueError(f"update_many: {B} filters, {len(t_ns)} stamps and {len(pose)} poses must match")
    defaults = np.array([(f.config.meas_std_xy_m, f.config.meas_std_xy_m, f.config.meas_std_yaw_rad) for f in filters]).reshape(B, 3)
    ms = defaults if meas_std is None else np.asarray(meas_std, dtype=np.float64).reshape(B, 3)
    ms = np.where(np.isnan(ms), defaults, ms)
    good = cast("NDArray[np.bool_]", (np.isfinite(ms[:, :2]) & (ms[:, :2] > 0)).all(axis=1) & (ms[:, 2] > 0))  # (B,) rows that are a sigma
    ms[~good] = defaults[~good]
    finite = cast("NDArray[np.bool_]", np.isfinite(pose).all(axis=1)).tolist()
    out: list[FilteredPose | None] = [None] * B
    batch: list[int] = []
    for i, f in enumerate(filters):
        t = int(t_ns[i])
        if f.config.enabled and finite[i] and f._t is not None and f._t <= t and (t - f._t) * _NS <= f.config.reset_after_s:
            batch.append(i)
        else:
            out[i] = f.update(t, float(pose[i, 0]), float(pose[i, 1]), float(pose[i, 2]), cast("tuple[float, float, float]", tuple(map(float, ms[i]))))
    if batch:
        fs = [filters[i] for i in batch]
        for i, fp in zip(batch, _step(fs, np.array([int(t_ns[i]) for i in batch], dtype=np.int64), pose[batch], ms[batch])):
            out[i] = fp
    return out  # type: ignore[return-value]


def predict_many(filters: Sequence[PoseFilter], t_ns: Sequence[int]) -> list[FilteredPose]:
    """``filters[i].predict_to(t_ns[i])`` for every i, the enabled ones in one batch.

    Raises:
        RuntimeError: a filter has no measurement yet.
    """
    if len(filters) != len(t_ns):
        raise ValueError(f"predict_many: {len(filters)} filters and {len(t_ns)} stamps must match")
    if any(f._t is None for f in filters):
        raise RuntimeError("predict_many: a filter has no measurement yet")
    t = [max(int(ti), cast(int, f._t)) for f, ti in zip(filters, t_ns)]  # every _t is set (checked above)
    batch = [i for i, f in enumerate(filters) if f.config.enabled and t[i] > cast(int, f._t)]
    out: list[FilteredPose | None] = [None] * len(filters)
    if batch:
        x, P = _predict_many([filters[i] for i in batch], np.array([t[i] for i in batch], dtype=np.int64))
        for k, i in enumerate(batch):
            out[i] = filters[i]._pose(t[i], x[k, :, 0], P[k])
    # The rest are held (disabled) or already at that time.
    return [p if p is not None else f._pose(ti, f._x, f._P) for p, f, ti in zip(out, filters, t)]


def _axes(filters: Sequence[PoseFilter]) -> tuple[NDArray, NDArray, AxisCov, NDArray]:
    """The filters' states as axes: positions (n, 3), rates (n, 3), their 2 x 2 covariances
    (n, 3) each, and the acceleration variances (n, 3)."""
    X = np.stack([f._x for f in filters])  # (n, 6)
    P = np.stack([f._P for f in filters])  # (n, 6, 6)
    q = np.square([(f.config.accel_std_mps2, f.config.accel_std_mps2, f.config.yaw_accel_std_radps2) for f in filters])  # (n, 3)
    return X[:, :3], X[:, 3:], AxisCov(P[:, _AX, _AX], P[:, _AX, _RATE], P[:, _RATE, _AX], P[:, _RATE, _RATE]), q


def _packed(pos: NDArray, rate: NDArray, cov: AxisCov) -> tuple[NDArray, NDArray]:
    """Axes back to states (n, 6) and 6 x 6 covariances (n, 6, 6) with no cross-axis terms."""
    P = np.zeros((len(pos), 6, 6))
    P[:, _AX, _AX], P[:, _AX, _RATE], P[:, _RATE, _AX], P[:, _RATE, _RATE] = cov
    return np.concatenate([pos, rate], axis=1), P


def _predicted(filters: Sequence[PoseFilter], t_ns: NDArray) -> tuple[NDArray, NDArray, AxisCov]:
    """Each filter's axes predicted to its time in ``t_ns`` (n,), the yaw wrapped: positions and
    rates (n, 3), covariances (n, 3) each."""
    dt = ((np.asarray(t_ns, dtype=np.int64) - np.array([f._t for f in filters], dtype=np.int64)) * _NS)[:, None]  # (n, 1)
    pos, rate, cov, q = _axes(filters)
    pos, rate, cov = cv_predict(pos, rate, cov, dt, q)
    pos[:, 2] = wrap_angle(pos[:, 2])
    return pos, rate, cov


def _predict_many(filters: Sequence[PoseFilter], t_ns: NDArray) -> tuple[NDArray, NDArray]:
    """Each filter's state predicted to its time in ``t_ns`` (n,): x (n, 6, 1), P (n, 6, 6)."""
    x, P = _packed(*_predicted(filters, t_ns))
    return x[:, :, None], P


# A yaw measurement's std (rad) standing for "no yaw": its Kalman gain is below 1e-10.
_NO_YAW_STD = 1e6
_MAX_YAW_VAR = math.pi**2


def _step(filters: Sequence[PoseFilter], t_ns: NDArray, pose: NDArray, std: NDArray) -> list[FilteredPose]:
    """The plain predict + update of n filters with a state not newer than ``t_ns`` (n,), in one
    batch: measurements ``pose`` (n, 3) of 1-sigma ``std`` (n, 3). Sets and returns their states.

    The three axes never mix: F and Q act on each (position, rate) pair alone, H reads the
    positions and R is diagonal, so a covariance that starts with no cross-axis terms (every path
    of ``PoseFilter`` starts one so) keeps none, and the 6 x 6 filter is three 2 x 2 filters:
    ``kalman.cv_predict`` and ``kalman.cv_update`` on (n, 3) axes. Same numbers as the textbook
    6 x 6 form (tests/host/filtering/test_pose_filter.py and test_kalman.py).
    """
    dt = (np.asarray(t_ns, dtype=np.int64) - np.array([f._t for f in filters], dtype=np.int64)) * _NS  # (n,)
    pos, rate, cov = _predicted(filters, t_ns)
    # Update with z = the measured positions, the yaw unwrapped next to the predicted yaw (the
    # innovation stays in (-pi, pi])
    z = np.column_stack([pose[:, 0], pose[:, 1], pos[:, 2] + wrap_angle(wrap_angle(pose[:, 2]) - pos[:, 2])])  # (n, 3)
    gate = np.array([f.config.outlier_sigma for f in filters])[:, None]  # (n, 1)
    R = np.square(np.where(np.isinf(std), _NO_YAW_STD, std))  # no yaw: a variance that moves nothing
    pos, rate, cov = cv_update(pos, rate, cov, z, _huber(R, z - pos, cov.p00, gate))
    pos, rate, cov, walking = _walking_prior(filters, pos, rate, cov, dt)
    # A yaw no view measures turns only with the walk: where the prior no longer applies either,
    # nothing measures a turn, and a rate the prior set (a position that stepped 0.15 m, a person
    # whose side left every view, is a walk of 0.5 m/s to the filter for a few frames) would turn
    # a person standing still for as long as nothing is measured (10 deg/s: test_aggregator.py).
    # (rate and cov are this step's own arrays: cv_update and _walking_prior return new ones.)
    still = np.isinf(std[:, 2]) & ~walking
    rate[still, 2] = 0.0
    cov.p01[still, 2] = cov.p10[still, 2] = 0.0
    pos[:, 2] = wrap_angle(pos[:, 2])
    # Without yaw measurements the yaw's variance would grow without end (past the PoseArray's
    # limit within two minutes); an angle's is pi^2 at most: the yaw axis's block is scaled down.
    scale = np.ones_like(cov.p00)  # (n, 3)
    scale[:, 2] = np.minimum(1.0, _MAX_YAW_VAR / cov.p00[:, 2])
    cov = AxisCov(*(block * scale for block in cov))  # new arrays: no block is scaled twice through an alias
    X, P = _packed(pos, rate, cov)
    out = []
    for k, f in enumerate(filters):
        f._t, f._x, f._P = int(t_ns[k]), X[k], P[k]
        out.append(f._pose(f._t, f._x, f._P))
    return out


def _huber(R: NDArray, innovation: NDArray, p00: NDArray, k: NDArray) -> NDArray:
    """Measurement variances (n, 3), each multiplied by d / k where its innovation lies d > k
    standard deviations (of the innovation, p00 + R) from the prediction; k <= 0: unchanged."""
    d = np.abs(innovation) / np.sqrt(p00 + R)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((k > 0) & (d > k), R * d / k, R)


def _walking_prior(filters: Sequence[PoseFilter], pos: NDArray, rate: NDArray, cov: AxisCov,
                   dt: NDArray) -> tuple[NDArray, NDArray, AxisCov, NDArray]:
    """The yaw of each moving filter updated with its walking direction (module docstring), and
    (n,) which filters walk (faster than ``walk_min_speed_mps``, the prior on)."""
    c = [f.config for f in filters]
    sigma = np.array([x.walk_yaw_std_rad for x in c])
    speed = np.hypot(rate[:, 0], rate[:, 1])  # (n,)
    walking = (sigma > 0) & (speed > np.array([x.walk_min_speed_mps for x in c]))
    moving = walking & (dt > 0)
    if not moving.any():
        return pos, rate, cov, walking
    i = np.flatnonzero(moving)
    heading = np.arctan2(rate[i, 1], rate[i, 0])
    # the heading's own variance: the speed's variance across the direction, over speed^2
    var_dir = 0.5 * (cov.p11[i, 0] + cov.p11[i, 1]) / np.square(speed[i])
    scale = np.array([c[j].walk_prior_time_s for j in i]) / dt[i]
    R = np.square(sigma[i]) * np.maximum(scale, 1.0) + var_dir
    z = pos[i, 2] + wrap_angle(heading - pos[i, 2])  # unwrapped next to the yaw
    yaw_cov = AxisCov(*(f[i, 2] for f in cov))
    p, r, yc = cv_update(pos[i, 2], rate[i, 2], yaw_cov, z, R)
    pos, rate = pos.copy(), rate.copy()
    pos[i, 2], rate[i, 2] = p, r
    fields = [f.copy() for f in cov]
    for f, new in zip(fields, yc, strict=True):
        f[i, 2] = new
    return pos, rate, AxisCov(*fields), walking
