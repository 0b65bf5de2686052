"""The tracker: people from the observations of all cameras of a site.

The paper's tracker matches each detected person to a known one when the median Bhattacharyya
distance between its hue-saturation histogram and that person's last Q histograms is below
d_max; unmatched detections start candidates, a candidate matched for 2 s becomes a person,
and a person unseen for 2 s is removed. This one adds:

- a geometric gate: a view also needs its ground point (host.ground) within
  ``gate_m + sigma`` of the person's predicted position, sigma combining the ground point's and
  the prediction's uncertainty; a small constant-velocity Kalman filter per track (host.filter's
  ``predict``/``update``) makes the gate follow a walking person;
- joint assignment: all people of one camera frame go to tracks at once
  (``scipy.optimize.linear_sum_assignment``) on colour plus normalised geometric distance,
  infeasible pairs forbidden, so one greedy choice cannot steal another view's only match;
- care in starting people: a view starts a candidate only if it shows enough joints
  (``min_joints_new``), is placed on the floor (a ground point surer than ``gate_m``, 1 sigma)
  and does not stand inside the gate of a track that this frame did not see. Views that fail
  are usually a known person under another camera's light, or a partial view whose box puts
  them metres away; starting a candidate from them breeds duplicates that later split a
  person's views between two ids. (The ground rule applies only with ``use_geometry``.)
- time from the messages: everything runs on capture stamps and an injected ``now_ns``. A
  camera's frames are admitted in order (``Tracker.admit``): a frame older than the newest one
  admitted from that camera is "late", one with the same stamp or sequence number a
  "duplicate", one whose sequence number goes back without the camera having restarted
  "seq_backwards" (a node restart is recognised: see ``restart_gap_s``), one older than
  ``remove_after_s`` "stale". The ordering reference of a
  camera is its newest admitted stamp capped at the host's clock when it was admitted, so a
  frame stamped in the future (a skewed clock, a hostile peer) cannot make that camera's real
  frames "late";
- a cap on tracks (``max_tracks``, at most what a PoseArray may carry): confirmed people are
  never evicted for newcomers; when the tracker is full, a view that would start a candidate
  replaces the stalest candidate not seen in this frame, or, if there is none, is ignored
  (counted as ``track_cap``). A flood of fake people therefore costs candidates, never the
  output nor the people already tracked.

- re-identification: a removed person is remembered for ``reid_window_s`` (colour history,
  last position). When a candidate is confirmed and its colours match exactly one remembered
  person (median Bhattacharyya distance between the two histories below ``reid_d_max``, the
  next remembered person and every person present at least ``_REID_MARGIN`` further) who could
  have walked to where it stands, it takes that person's id back. (Measured in the demo's
  apartment: the same person after a gap 0.07-0.53, different people 0.71-0.91.) Without it, a person who stands where no working camera sees
  them (a camera died, a corner) for more than ``remove_after_s`` comes back as someone new:
  a new id and an identity switch for every subscriber.

For each confirmed person, ``view_sets`` gives the paper's set S: its latest view per camera,
if fresh, for the GNN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final, Literal, NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.colour import HIST_BINS, bhattacharyya_matrix
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.filter import joseph_position_update
from superbody.host.ground import ground_points
from superbody.host.pose import MAX_PEOPLE

__all__ = [
    "TrackerConfig",
    "Track",
    "StampedView",
    "Match",
    "Tracker",
    "assign",
    "median_colour_distance",
    "DROP_REASONS",
]

_NS_PER_S = 1_000_000_000
_BINS = HIST_BINS[0] * HIST_BINS[1]
# A cue we cannot compute (empty histogram, no ground point) costs this much, normalised.
_UNKNOWN_COST = 0.5
# Candidates cost a little more than confirmed people, so a duplicate candidate of a person
# does not steal that person's views when both fit.
_CANDIDATE_COST = 0.1
# Re-identification needs the best remembered person this much closer in colour than the next.
_REID_MARGIN = 0.1
# Speed we assume for a track whose velocity is not yet known (1-sigma, m/s).
_INIT_SPEED_STD = 1.0


def _check(name: str, value: object, lo: float, hi: float, *, lo_open: bool = False, integer: bool = False) -> None:
    kind = int if integer else (int, float)
    ok = isinstance(value, kind) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (lo < value if lo_open else lo <= value) and value <= hi
    if not ok:
        what = "an integer" if integer else "a number"
        raise ValueError(f"TrackerConfig.{name} must be {what} in {'(' if lo_open else '['}{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's parameters; defaults are the paper's values where it gives one.

    Attributes:
        confirm_after_s: a candidate becomes a person after matches spanning this long.
        remove_after_s: a track unseen this long is removed (a person) or dropped (a candidate).
        d_max: a view matches a track only if the median Bhattacharyya distance between its
            histogram and the track's last ``history_q`` histograms is below this.
        history_q: histograms kept per track (Q).
        gate_m: a view matches a track only if its ground point lies within
            ``gate_m + sigma`` of the track's predicted position.
        use_geometry: False turns the gate and the geometric cost off (the paper's tracker).
        min_joints: views with fewer visible joints are ignored.
        min_joints_new: a view needs at least this many visible joints to start a candidate
            (and, with ``use_geometry``, a ground point whose 1-sigma is under ``gate_m``);
            poorer ones (a head and a hand at the image's edge) may only match existing
            tracks: their colours come from a few pixels and their ground points from a box,
            and a candidate started from them is usually a duplicate of someone.
        confirm_max_gap_s: a candidate unseen longer than this restarts its confirmation clock,
            so "2 s of matches" means 2 s of steady matches.
        geometry_weight: weight of the normalised ground distance against the normalised
            colour distance in the assignment cost.
        accel_std_mps2: 1-sigma acceleration of a walking person, for the position prediction.
        max_tracks: at most this many tracks, candidates included (see the module docstring
            for the policy when full); at most ``host.pose.MAX_PEOPLE`` so every PoseArray
            can be published.
        reid_window_s: a removed person is remembered this long for re-identification
            (0 turns re-identification off).
        reid_d_max: a new person is re-identified as a remembered one only if the median
            Bhattacharyya distance between their colour histories is below this.
        reid_speed_mps: ... and if the remembered person, walking at this speed, could have
            reached (within ``gate_m``) where the new one stands.
        restart_gap_s: a camera whose sequence number goes back is taken as restarted (its
            frames are admitted again) after this long without frames from it, when the frame
            after a refused one continues the new count, or after ``Tracker.reset_camera``;
            otherwise such frames are dropped as "seq_backwards". A forged frame with a high
            sequence number therefore costs a camera one real frame, never its view.
    """

    confirm_after_s: float = 2.0
    remove_after_s: float = 2.0
    d_max: float = 0.65
    history_q: int = 10
    gate_m: float = 1.0
    use_geometry: bool = True
    min_joints: int = 3
    min_joints_new: int = 6
    confirm_max_gap_s: float = 1.0
    geometry_weight: float = 1.0
    accel_std_mps2: float = 2.0
    max_tracks: int = 64
    reid_window_s: float = 30.0
    reid_d_max: float = 0.6
    reid_speed_mps: float = 1.5
    restart_gap_s: float = 1.0

    def __post_init__(self) -> None:
        _check("confirm_after_s", self.confirm_after_s, 0.0, 600.0)
        _check("remove_after_s", self.remove_after_s, 0.0, 600.0, lo_open=True)
        _check("d_max", self.d_max, 0.0, 1.0, lo_open=True)
        _check("history_q", self.history_q, 1, 1000, integer=True)
        _check("gate_m", self.gate_m, 0.0, 100.0, lo_open=True)
        if not isinstance(self.use_geometry, bool):
            raise ValueError(f"TrackerConfig.use_geometry must be true or false, got {self.use_geometry!r}")
        _check("min_joints", self.min_joints, 0, NUM_KEYPOINTS, integer=True)
        _check("min_joints_new", self.min_joints_new, 0, NUM_KEYPOINTS, integer=True)
        _check("confirm_max_gap_s", self.confirm_max_gap_s, 0.0, 600.0, lo_open=True)
        _check("geometry_weight", self.geometry_weight, 0.0, 100.0)
        _check("accel_std_mps2", self.accel_std_mps2, 0.0, 100.0, lo_open=True)
        _check("max_tracks", self.max_tracks, 1, MAX_PEOPLE, integer=True)
        _check("reid_window_s", self.reid_window_s, 0.0, 3600.0)
        _check("reid_d_max", self.reid_d_max, 0.0, 1.0, lo_open=True)
        _check("reid_speed_mps", self.reid_speed_mps, 0.0, 100.0)
        _check("restart_gap_s", self.restart_gap_s, 0.0, 600.0)


class _Order(NamedTuple):
    """A camera's frame order: the reference a next frame must not be older than, and its newest frame."""

    ref_ns: int  # newest admitted stamp, capped at the host's clock when it was admitted
    stamp_ns: int  # stamp of the newest admitted frame
    seq: int  # its sequence number
    back_seq: int | None = None  # the last frame refused as seq_backwards since: its seq ...
    back_ns: int = 0  # ... and stamp


class _Lost(NamedTuple):
    """A removed person, remembered for re-identification."""

    id: int
    label: str
    amp: NDArray[np.float64]  # (n, B) their last histograms as amplitudes
    position: NDArray[np.float64] | None  # (2,) last estimated floor position
    last_seen_ns: int


class StampedView(NamedTuple):
    """A view and the capture time of its frame (UNIX ns)."""

    stamp_ns: int
    view: PersonView


@dataclass(eq=False)
class Track:
    """One tracked person (or candidate).

    Attributes:
        id: integer id, unique within its tracker; it returns only to the person it was
            given to (re-identification), never to anyone else.
        label: ``id_prefix`` + id, for people reading logs and displays.
        state: "candidate" until confirmed, then "confirmed".
        first_seen_ns: capture time of the view that started it.
        last_seen_ns: latest capture time of a view matched to it.
        confirmed_ns: capture time of the match that confirmed it, or None.
        views: latest matched view per camera id, with its stamp.
        hits: number of views matched to it, the first included.
    """

    id: int
    label: str
    state: Literal["candidate", "confirmed"]
    first_seen_ns: int
    last_seen_ns: int
    history_q: int
    confirmed_ns: int | None = None
    views: dict[str, StampedView] = field(default_factory=dict)
    hits: int = 0
    _hist: NDArray[np.float32] = field(init=False, repr=False)  # (Q, B) ring buffer of histograms
    _amp: NDArray[np.float64] = field(init=False, repr=False)  # (Q, B) the same as amplitudes
    _n_hist: int = field(default=0, init=False, repr=False)
    _streak_ns: int = field(default=0, init=False, repr=False)  # start of the steady matches
    _kf_t: int | None = field(default=None, init=False, repr=False)  # time of the position state
    _kf_x: NDArray[np.float64] = field(init=False, repr=False)  # (2, 2): rows (pos, vel), columns (x, y)
    _kf_P: NDArray[np.float64] = field(init=False, repr=False)  # (2, 2) shared by both columns

    def __post_init__(self) -> None:
        self._hist = np.zeros((self.history_q, _BINS), dtype=np.float32)
        self._amp = np.zeros((self.history_q, _BINS))
        self._streak_ns = self.first_seen_ns
        self._kf_x = np.zeros((2, 2))
        self._kf_P = np.eye(2)

    @property
    def histograms(self) -> NDArray[np.float32]:
        """The last (up to Q) non-empty histograms matched, oldest first, shape (n, 16, 8)."""
        n, q = self._n_hist, self.history_q
        order = np.arange(n - min(n, q), n) % q
        return self._hist[order].reshape(-1, *HIST_BINS)

    @property
    def position(self) -> NDArray[np.float64] | None:
        """Estimated floor position (2,) in metres at ``position_stamp_ns``, or None if unknown."""
        return None if self._kf_t is None else self._kf_x[0].copy()

    @property
    def velocity(self) -> NDArray[np.float64] | None:
        """Estimated floor velocity (2,) in m/s, or None if the position is unknown."""
        return None if self._kf_t is None else self._kf_x[1].copy()

    @property
    def position_std(self) -> float:
        """1-sigma of the position estimate per axis, metres (NaN if unknown)."""
        return math.nan if self._kf_t is None else math.sqrt(self._kf_P[0, 0])

    @property
    def position_stamp_ns(self) -> int | None:
        return self._kf_t

    def predict_position(self, t_ns: int, accel_std_mps2: float = 2.0) -> tuple[NDArray[np.float64], float] | None:
        """Predicted floor position (2,) at ``t_ns`` and its 1-sigma per axis, or None if unknown."""
        if self._kf_t is None:
            return None
        x, P = _predict_positions(self._kf_x[None], self._kf_P[None], np.array([(t_ns - self._kf_t) / _NS_PER_S]), accel_std_mps2)
        return x[0, 0], math.sqrt(P[0, 0, 0])

    def _add_histogram(self, h: NDArray, amp: NDArray) -> None:
        slot = self._n_hist % self.history_q
        self._hist[slot], self._amp[slot] = h.reshape(-1), amp
        self._n_hist += 1


def _predict_positions(x: NDArray, P: NDArray, dt: NDArray, accel_std_mps2: float) -> tuple[NDArray, NDArray]:
    """Constant-velocity prediction of B position filters, each ``dt`` (B,) seconds ahead.

    ``host.filter.predict`` with F = [[1, dt], [0, 1]] and the white-acceleration Q, written out
    per element: the same numbers, without a batch of 2 x 2 matrix products per call.

    Args:
        x: (B, 2, 2) states, rows (position, velocity), columns (x, y).
        P: (B, 2, 2) covariances, shared by the x and y columns.
    """
    dt = np.asarray(dt, dtype=np.float64)[:, None]  # (B, 1)
    # x = F x: position += dt * velocity
    x = x.copy()
    x[:, 0] += dt * x[:, 1]
    # P = F P F^T + Q: F P adds dt x row 1 to row 0, then (F P) F^T dt x column 1 to column 0
    P = P.copy()
    P[:, 0] += dt * P[:, 1]
    P[:, :, 0] += dt * P[:, :, 1]
    # Q = q g g^T, g = (dt^2 / 2, dt): q [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]
    g = np.concatenate([0.5 * dt * dt, dt], axis=1) * accel_std_mps2  # (B, 2)
    P += g[:, :, None] * g[:, None, :]
    return x, P


def _update_positions(x: NDArray, P: NDArray, z: NDArray, R: NDArray) -> tuple[NDArray, NDArray]:
    """``host.filter.update`` with H = [1, 0] (a position measured, both columns), per element.

    Args:
        x: (B, 2, 2) states; P: (B, 2, 2) covariances; z: (B, 2) measured (x, y); R: (B,) variances.
    """
    k0, k1, *n = joseph_position_update(P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1], R)  # (B,) each
    # x = x + K (z - H x)
    y = z - x[:, 0]  # (B, 2)
    x = np.stack([x[:, 0] + k0[:, None] * y, x[:, 1] + k1[:, None] * y], axis=1)  # (B, 2, 2)
    return x, np.stack(n, axis=1).reshape(-1, 2, 2)


def _fuse_positions(tracks: list[Track], xy: NDArray, sigma: NDArray, t_ns: int | NDArray, accel_std_mps2: float) -> None:
    """Kalman-update the positions of ``tracks`` with floor points (B, 2) of 1-sigma (B,), seen
    at ``t_ns`` (one time, or (B,) one per track)."""
    stamps = [int(t_ns)] * len(tracks) if np.ndim(t_ns) == 0 else [int(v) for v in t_ns]  # (B,)
    rows: list[int] = []  # tracks with a state: predicted, then updated in one batch
    for j, tr in enumerate(tracks):
        if tr._kf_t is None:  # first point: the velocity is unknown
            tr._kf_t = stamps[j]
            tr._kf_x = np.vstack([xy[j], np.zeros(2)])
            tr._kf_P = np.diag([sigma[j] ** 2, _INIT_SPEED_STD**2])
        else:
            rows.append(j)
    if not rows:
        return
    old = [tracks[j] for j in rows]
    if len(rows) < len(tracks):
        xy, sigma = xy[rows], sigma[rows]
    t_old = [stamps[j] for j in rows]
    x = np.array([tr._kf_x for tr in old])  # (B, 2, 2)
    P = np.array([tr._kf_P for tr in old])  # (B, 2, 2)
    dt = np.array([t - tr._kf_t for t, tr in zip(t_old, old)], dtype=np.float64) / _NS_PER_S  # (B,)
    x, P = _predict_positions(x, P, np.maximum(dt, 0.0), accel_std_mps2)
    # A point older than the state (another camera's frame came late) is applied at the state's
    # time, with the distance the person may have walked since as extra noise.
    R = sigma**2 + (_INIT_SPEED_STD * np.minimum(dt, 0.0)) ** 2  # (B,)
    x, P = _update_positions(x, P, xy, R)
    for j, tr in enumerate(old):
        tr._kf_x, tr._kf_P, tr._kf_t = x[j], P[j], max(tr._kf_t, t_old[j])


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


# Why ``Tracker.admit`` refuses a frame, in the order checked.
DROP_REASONS: Final[tuple[str, ...]] = ("wrong_site", "unknown_camera", "stale", "late", "duplicate", "seq_backwards")

_STATS = (
    "observations", "views", "late_dropped", "duplicate_dropped", "stale_dropped", "seq_backwards_dropped", "wrong_site",
    "unknown_camera", "too_few_joints", "track_cap", "evicted_candidates", "too_few_joints_new", "no_ground_point", "no_signature",
    "unplaced_new", "suppressed", "matched", "new_candidates", "confirmed", "removed", "dropped_candidates", "reidentified",
)


class Tracker:
    """People from the observations of one site's cameras.

    Args:
        site: the site; observations from other sites or unknown cameras are dropped.
        config: parameters (the paper's by default).
        id_prefix: prepended to ids in ``Track.label``.

    Attributes:
        stats: counters, e.g. ``late_dropped``, ``too_few_joints``, ``new_candidates``,
            ``confirmed``, ``removed``.
    """

    def __init__(self, site: Site, config: TrackerConfig | None = None, id_prefix: str = "") -> None:
        self.site = site
        self.config = config or TrackerConfig()
        self.id_prefix = id_prefix
        self.stats: dict[str, int] = dict.fromkeys(_STATS, 0)
        self._cameras = {c.id: c for c in site.cameras}
        self._tracks: dict[int, Track] = {}
        self._lost: dict[int, _Lost] = {}  # removed people, oldest first, for re-identification
        self._next_id = 1
        self._order: dict[str, _Order] = {}  # per camera: what its next frame is judged against
        c = self.config
        self._confirm_ns = round(c.confirm_after_s * _NS_PER_S)
        self._remove_ns = round(c.remove_after_s * _NS_PER_S)
        self._gap_ns = round(c.confirm_max_gap_s * _NS_PER_S)
        self._restart_ns = round(c.restart_gap_s * _NS_PER_S)
        self._reid_ns = round(c.reid_window_s * _NS_PER_S)

    @property
    def tracks(self) -> list[Track]:
        """All tracks, candidates included, oldest first."""
        return list(self._tracks.values())

    def track(self, track_id: int) -> Track | None:
        return self._tracks.get(track_id)

    def admit(self, obs: Observation, now_ns: int | None = None) -> str | None:
        """Why ``update`` would drop this frame (one of ``DROP_REASONS``), or None if it would use it.

        Changes nothing; ``now_ns`` as in ``update``.
        """
        t = int(obs.stamp_ns)
        now = t if now_ns is None else int(now_ns)
        if obs.site != self.site.name:
            return "wrong_site"
        if obs.camera not in self._cameras:
            return "unknown_camera"
        if now - t >= self._remove_ns:
            return "stale"
        o = self._order.get(obs.camera)
        if o is None:
            return None
        if t == o.stamp_ns or obs.seq == o.seq:
            return "duplicate"
        if t < o.ref_ns:
            return "late"
        restarted = t - o.stamp_ns >= self._restart_ns or (o.back_seq is not None and obs.seq == o.back_seq + 1 and t > o.back_ns)
        if obs.seq < o.seq and not restarted:
            return "seq_backwards"
        return None

    def reset_camera(self, camera: str) -> None:
        """Forget a camera's frame order, e.g. when its node restarted (its liveliness token came back)."""
        self._order.pop(camera, None)

    def update(self, obs: Observation, now_ns: int | None = None) -> list[Match]:
        """Match one camera frame's people to tracks.

        Args:
            obs: one frame of one camera.
            now_ns: the host's clock (UNIX ns); the frame's stamp by default. A frame already
                older than ``remove_after_s`` could keep nobody alive and is dropped.

        Returns:
            One ``Match`` per view of ``obs.people``, in order; empty when the frame was dropped
            (``admit`` says why; ``stats`` counts each reason).
        """
        st, cfg = self.stats, self.config
        t = int(obs.stamp_ns)
        now = t if now_ns is None else int(now_ns)
        st["observations"] += 1
        reason = self.admit(obs, now)
        if reason is not None:
            st[reason if reason in ("wrong_site", "unknown_camera") else f"{reason}_dropped"] += 1
            if reason == "seq_backwards":  # remembered: if the next frame follows it, the node restarted
                self._order[obs.camera] = self._order[obs.camera]._replace(back_seq=int(obs.seq), back_ns=t)
            return []
        cam = self._cameras[obs.camera]
        # The stamp orders this camera's next frames, capped at the host's clock: a frame from
        # the future is used, but cannot make the camera's real frames look late.
        prev, ref = self._order.get(obs.camera), min(t, now)
        self._order[obs.camera] = _Order(ref if prev is None else max(prev.ref_ns, ref), t, int(obs.seq))
        n = len(obs.people)
        st["views"] += n
        if n == 0:
            return []

        kps = np.array([p.keypoints for p in obs.people])  # (N, 17, 3)
        n_joints = (~np.isnan(kps[:, :, 0])).sum(axis=1)  # (N,)
        enough = n_joints >= cfg.min_joints
        st["too_few_joints"] += int(n - enough.sum())
        idx = np.flatnonzero(enough)  # (K,) the views we use
        if len(idx) == 0:
            return [Match(i, None, "ignored") for i in range(n)]
        matches: list[Match | None] = [None] * n  # the views left None at the end were ignored
        bboxes = np.array([obs.people[i].bbox for i in idx])  # (K, 4)
        ground, sigma, _ = ground_points(kps[idx], bboxes, cam)  # (K, 2), (K,)
        has_ground = ~np.isnan(sigma)  # (K,)
        st["no_ground_point"] += int((~has_ground).sum())
        hists = np.array([obs.people[i].histogram.reshape(-1) for i in idx])  # (K, B)
        has_colour = hists.sum(axis=1) > 0  # (K,)
        amps = _amplitudes(hists)  # (K, B)

        tracks = [tr for tr in self._tracks.values() if t - tr.last_seen_ns < self._remove_ns]
        rows, cols, colour_d, geo_d, near = self._associate(t, tracks, amps, has_colour, ground, sigma, has_ground)

        fused: list[tuple[Track, int]] = []  # (track, row) pairs whose ground point updates the track
        for r, c in zip(rows, cols):
            tr, i = tracks[c], int(idx[r])
            self._apply(tr, obs.camera, t, obs.people[i], hists[r], amps[r], has_colour[r])
            fused.append((tr, r))
            matches[i] = Match(i, tr.id, "matched", float(colour_d[r, c]), float(geo_d[r, c]))
            st["matched"] += 1
        taken = np.zeros(len(idx), dtype=bool)
        taken[rows] = True
        # A track this frame did not see, standing where an unmatched view stands: the view is
        # that person in another camera's light (or a partial view's odd colours), not a
        # newcomer. Starting a candidate there would breed a duplicate of them. (A newcomer
        # beside someone is still started by any camera that sees both in one frame.)
        lonely = np.ones(len(tracks), dtype=bool)
        lonely[cols] = False
        for r in np.flatnonzero(~taken):
            i = int(idx[r])
            if not (has_colour[r] or (has_ground[r] and cfg.use_geometry)):
                st["no_signature"] += 1  # nothing to ever match it on again
                continue
            if n_joints[i] < cfg.min_joints_new:
                st["too_few_joints_new"] += 1
                continue
            if cfg.use_geometry and not sigma[r] < cfg.gate_m:  # no ground point, or one less sure than the gate
                st["unplaced_new"] += 1
                continue
            if (near[r] & lonely).any():
                st["suppressed"] += 1
                continue
            if len(self._tracks) >= cfg.max_tracks and not self._evict_candidate(t):
                st["track_cap"] += 1
                continue
            tr = Track(self._next_id, f"{self.id_prefix}{self._next_id}", "candidate", t, t, cfg.history_q)
            self._next_id += 1
            self._tracks[tr.id] = tr
            st["new_candidates"] += 1
            self._apply(tr, obs.camera, t, obs.people[i], hists[r], amps[r], has_colour[r])
            fused.append((tr, r))
            matches[i] = Match(i, tr.id, "created")
        fused = [(tr, r) for tr, r in fused if has_ground[r]]
        if fused:
            rs = np.array([r for _, r in fused])
            _fuse_positions([tr for tr, _ in fused], ground[rs], sigma[rs], t, cfg.accel_std_mps2)
        return [Match(i, None, "ignored") if m is None else m for i, m in enumerate(matches)]

    def _associate(
        self, t: int, tracks: list[Track], amps: NDArray, has_colour: NDArray,
        ground: NDArray, sigma: NDArray, has_ground: NDArray,
    ) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """Cost, feasibility and joint assignment of K views to M tracks at time ``t``.

        Args:
            amps: (K, B) the views' histogram amplitudes; has_colour (K,) False for empty ones.
            ground, sigma, has_ground: (K, 2), (K,), (K,) the views' ground points.

        Returns:
            ``(rows, cols, colour_d, geo_d, near)``: matched view and track indices, the (K, M)
            colour and ground distances (NaN where unknown), and (K, M) whether each view's
            ground point lies inside each track's gate (all False without geometry).
        """
        cfg = self.config
        k, m = len(amps), len(tracks)
        geo_d = np.full((k, m), np.nan)
        near = np.zeros((k, m), dtype=bool)
        if m == 0:
            return np.empty(0, np.intp), np.empty(0, np.intp), np.full((k, 0), np.nan), geo_d, near
        q = cfg.history_q
        history = np.array([tr._amp for tr in tracks]).reshape(m * q, _BINS)  # (M*Q, B)
        counts = np.array([min(tr._n_hist, q) for tr in tracks])  # (M,)
        # d = sqrt(1 - BC), BC the dot product of amplitudes (see _amplitudes)
        d = np.sqrt(np.clip(1.0 - amps @ history.T, 0.0, 1.0)).reshape(k, m, q)  # (K, M, Q)
        colour_d = _median_over_history(d, counts)  # (K, M)
        colour_d[~has_colour] = np.nan
        colour_known = ~np.isnan(colour_d)
        with np.errstate(invalid="ignore"):
            feasible = ~colour_known | (colour_d < cfg.d_max)  # (K, M)
        cost = np.where(colour_known, colour_d / cfg.d_max, _UNKNOWN_COST)
        cost += np.array([_CANDIDATE_COST if tr.state == "candidate" else 0.0 for tr in tracks])[None, :]
        vouched = colour_known
        if cfg.use_geometry:
            has_pos = np.array([tr._kf_t is not None for tr in tracks], dtype=bool)  # (M,)
            pos, pos_std = np.full((m, 2), np.nan), np.full(m, np.nan)
            if has_pos.any():
                known = [tracks[j] for j in np.flatnonzero(has_pos)]
                x, P = _predict_positions(
                    np.array([tr._kf_x for tr in known]), np.array([tr._kf_P for tr in known]),
                    np.array([(t - tr._kf_t) / _NS_PER_S for tr in known]), cfg.accel_std_mps2,
                )
                pos[has_pos], pos_std[has_pos] = x[:, 0, :], np.sqrt(P[:, 0, 0])
            geo_d = np.linalg.norm(ground[:, None, :] - pos[None, :, :], axis=2)  # (K, M)
            radius = cfg.gate_m + np.hypot(sigma[:, None], pos_std[None, :])  # (K, M)
            geo_known = has_ground[:, None] & has_pos[None, :]
            with np.errstate(invalid="ignore"):
                near = geo_known & (geo_d <= radius)
                feasible &= ~geo_known | near
                cost += cfg.geometry_weight * np.where(geo_known, geo_d / radius, _UNKNOWN_COST)
            vouched = vouched | geo_known
        rows, cols = assign(cost, feasible & vouched)  # at least one cue must vouch for a pair
        return rows, cols, colour_d, geo_d, near

    def _evict_candidate(self, t: int) -> bool:
        """Make room for a new candidate: drop the stalest candidate not seen at ``t``, if any."""
        stale = [tr for tr in self._tracks.values() if tr.state == "candidate" and tr.last_seen_ns < t]
        if not stale:
            return False
        victim = min(stale, key=lambda tr: (tr.last_seen_ns, tr.hits))
        del self._tracks[victim.id]
        self.stats["evicted_candidates"] += 1
        return True

    def _apply(self, tr: Track, camera: str, t: int, view: PersonView, hist: NDArray, amp: NDArray, has_colour: bool) -> None:
        """Record a view matched to (or starting) ``tr``; confirm it when its time has come."""
        if t - tr.last_seen_ns > self._gap_ns:
            tr._streak_ns = t
        tr.last_seen_ns = max(tr.last_seen_ns, t)
        tr.hits += 1
        tr.views[camera] = StampedView(t, view)
        if has_colour:
            tr._add_histogram(hist, amp)
        if tr.state == "candidate" and tr.last_seen_ns - tr._streak_ns >= self._confirm_ns:
            tr.state, tr.confirmed_ns = "confirmed", t
            self.stats["confirmed"] += 1
            self._reidentify(tr, t)

    def _reidentify(self, tr: Track, t: int) -> None:
        """Give a just-confirmed track the id of the one remembered person it clearly is, if any."""
        cfg = self.config
        self._forget_lost(t)
        n = min(tr._n_hist, cfg.history_q)
        if not self._lost or n == 0:
            return
        mine = tr._amp[:n]  # (n, B): the ring buffer's used rows
        pos = tr.position
        scored: list[tuple[float, int]] = []
        for lost in self._lost.values():
            if pos is not None and lost.position is not None:
                reach = cfg.gate_m + cfg.reid_speed_mps * (t - lost.last_seen_ns) / _NS_PER_S
                if np.linalg.norm(pos - lost.position) > reach:
                    continue
            # d = sqrt(1 - BC) for every pair of histories; the median is robust to odd views
            d = np.sqrt(np.clip(1.0 - mine @ lost.amp.T, 0.0, 1.0))  # (n, n_lost)
            scored.append((float(np.median(d)), lost.id))
        scored.sort()
        if not scored or scored[0][0] >= cfg.reid_d_max or (len(scored) > 1 and scored[1][0] - scored[0][0] < _REID_MARGIN):
            return
        # Lighting differs between cameras, so the scale of "same colours" does too: the people
        # present now are certainly not the lost one, and must all look clearly less like it.
        for other in self._tracks.values():
            m = min(other._n_hist, cfg.history_q)
            if other is tr or other.state != "confirmed" or m == 0:
                continue
            d = np.sqrt(np.clip(1.0 - mine @ other._amp[:m].T, 0.0, 1.0))
            if float(np.median(d)) - scored[0][0] < _REID_MARGIN:
                return
        lost = self._lost.pop(scored[0][1])
        del self._tracks[tr.id]
        tr.id, tr.label = lost.id, lost.label
        self._tracks[tr.id] = tr
        self.stats["reidentified"] += 1

    def _forget_lost(self, now_ns: int) -> None:
        for pid in [pid for pid, lost in self._lost.items() if now_ns - lost.last_seen_ns > self._reid_ns]:
            del self._lost[pid]

    def set_position(self, track_id: int, xy: NDArray | tuple[float, float], stamp_ns: int, std_m: float = 0.1) -> bool:
        """Feed back a better position (e.g. the GNN's) for a track, as a measurement of 1-sigma ``std_m``.

        Returns:
            False if no such track (it may just have been removed).
        """
        tr = self._tracks.get(track_id)
        xy = np.asarray(xy, dtype=np.float64).reshape(2)
        if tr is None or not np.isfinite(xy).all() or not (std_m > 0 and math.isfinite(std_m)):
            return False
        _fuse_positions([tr], xy[None], np.array([float(std_m)]), int(stamp_ns), self.config.accel_std_mps2)
        return True

    def set_positions(self, track_ids: Sequence[int], xy: NDArray, stamps_ns: Sequence[int], std_m: float = 0.1) -> NDArray[np.bool_]:
        """``set_position`` for many tracks at once (one Kalman batch): ids (B,), xy (B, 2), stamps (B,).

        Returns:
            (B,) bool, False where there is no such track or the point is not finite.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if not (std_m > 0 and math.isfinite(std_m)):
            return np.zeros(len(xy), dtype=bool)
        tracks = [self._tracks.get(int(i)) for i in track_ids]
        ok = np.array([tr is not None for tr in tracks], dtype=bool) & np.isfinite(xy).all(axis=1)
        if ok.any():
            idx = np.flatnonzero(ok)
            _fuse_positions([tracks[i] for i in idx], xy[idx], np.full(len(idx), float(std_m)),  # type: ignore[misc]
                            np.asarray(stamps_ns, dtype=np.int64)[idx], self.config.accel_std_mps2)
        return ok

    def prune(self, now_ns: int) -> list[Track]:
        """Remove tracks unseen for ``remove_after_s`` and return them."""
        gone = [tr for tr in self._tracks.values() if now_ns - tr.last_seen_ns >= self._remove_ns]
        for tr in gone:
            del self._tracks[tr.id]
            self.stats["removed" if tr.state == "confirmed" else "dropped_candidates"] += 1
            n = min(tr._n_hist, self.config.history_q)
            if tr.state == "confirmed" and n > 0 and self._reid_ns > 0:
                self._lost[tr.id] = _Lost(tr.id, tr.label, tr._amp[:n].copy(), tr.position, tr.last_seen_ns)
        while len(self._lost) > self.config.max_tracks:  # bounded whatever the input
            del self._lost[next(iter(self._lost))]
        self._forget_lost(now_ns)
        return gone

    def people(self, now_ns: int) -> list[Track]:
        """Confirmed tracks still alive at ``now_ns``, oldest first."""
        return [
            tr for tr in self._tracks.values()
            if tr.state == "confirmed" and now_ns - tr.last_seen_ns < self._remove_ns
        ]

    def view_sets(self, now_ns: int, freshness_s: float = 0.5) -> dict[int, dict[str, PersonView]]:
        """Set S of each confirmed person: its latest view per camera captured within ``freshness_s`` of now.

        People with no fresh view are left out.
        """
        if not (freshness_s > 0 and math.isfinite(freshness_s)):
            raise ValueError(f"view_sets: freshness_s must be a positive number of seconds, got {freshness_s!r}")
        fresh_ns = round(freshness_s * _NS_PER_S)
        out: dict[int, dict[str, PersonView]] = {}
        for tr in self.people(now_ns):
            s = {cam: sv.view for cam, sv in tr.views.items() if now_ns - sv.stamp_ns <= fresh_ns}
            if s:
                out[tr.id] = s
        return out
