"""One tracked person (``Track``): views, colour history, position filter state, confirmation."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.observation import PersonView
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.motion import NS_PER_S, predict_positions

__all__ = ["StampedView", "Track"]

BINS = HIST_BINS[0] * HIST_BINS[1]


class StampedView(NamedTuple):
    """A view, the capture time of its frame (UNIX ns), where it puts the person on the floor
    (``host.tracking.ground``: metres, and its 1-sigma; NaN when it gave none) and the floor point
    below its camera (the point is sure across the line between the two: ``evidence.one_body``;
    NaN: unknown, the sigma then holds in every direction)."""

    stamp_ns: int
    view: PersonView
    ground_xy: tuple[float, float] = (math.nan, math.nan)
    ground_std_m: float = math.nan
    camera_xy: tuple[float, float] = (math.nan, math.nan)


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
    _kf_P: NDArray[np.float64] = field(init=False, repr=False)  # (4, 4) of (x, y, vx, vy)
    # Since the steady matches began (host.tracking.evidence): frames of cameras that clearly saw
    # where the candidate stood, or matched it (chances), and those that matched it.
    _chances: int = field(default=1, init=False, repr=False)
    _support: int = field(default=1, init=False, repr=False)
    # Confirmed: since when it has stood inside an older confirmed track (host.tracking.merge.coincident).
    close_since_ns: int | None = field(default=None, init=False, repr=False)
    # Set S as last checked (evidence.one_body): its (camera, stamp) pairs, and the cameras kept.
    checked_set: tuple[tuple[tuple[str, int], ...], list[str]] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self._hist = np.zeros((self.history_q, BINS), dtype=np.float32)
        self._amp = np.zeros((self.history_q, BINS))
        self._streak_ns = self.first_seen_ns
        self._kf_x = np.zeros((2, 2))
        self._kf_P = np.eye(4)

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
        """1-sigma of the position estimate per axis (the root of the mean of the x and y variances), metres (NaN if unknown)."""
        return math.nan if self._kf_t is None else math.sqrt(0.5 * (self._kf_P[0, 0] + self._kf_P[1, 1]))

    @property
    def position_stamp_ns(self) -> int | None:
        return self._kf_t

    def predict_position(self, t_ns: int, accel_std_mps2: float = TrackerConfig.accel_std_mps2) -> tuple[NDArray[np.float64], float] | None:
        """Predicted floor position (2,) at ``t_ns`` and its 1-sigma per axis (as ``position_std``), or None if unknown."""
        if self._kf_t is None:
            return None
        x, P = predict_positions(self._kf_x[None], self._kf_P[None], np.array([(t_ns - self._kf_t) / NS_PER_S]), accel_std_mps2)
        return x[0, 0], math.sqrt(0.5 * (P[0, 0, 0] + P[0, 1, 1]))

    @property
    def colours(self) -> NDArray[np.float64]:
        """The histograms matched so far (up to Q), as amplitudes (``association.amplitudes``), (n, B), in no order."""
        return self._amp[: min(self._n_hist, self.history_q)]

    @property
    def colour_rows(self) -> tuple[NDArray[np.float64], int]:
        """The ring buffer of amplitudes (Q, B) and how many of its rows are in use."""
        return self._amp, min(self._n_hist, self.history_q)

    def add_colour(self, h: NDArray, amp: NDArray) -> None:
        """Keep a matched view's histogram (flattened) and its amplitudes, the oldest of Q going."""
        slot = self._n_hist % self.history_q
        self._hist[slot], self._amp[slot] = h.reshape(-1), amp
        self._n_hist += 1

    @property
    def motion(self) -> tuple[NDArray[np.float64], NDArray[np.float64], int] | None:
        """The position filter's state: x (2, 2) rows (position, velocity), columns (x, y); P (4, 4) of x read row by row; its time (ns)."""
        return None if self._kf_t is None else (self._kf_x, self._kf_P, self._kf_t)

    def set_motion(self, x: NDArray[np.float64], P: NDArray[np.float64], t_ns: int) -> None:
        """The position filter's new state (``host.tracking.motion``)."""
        self._kf_x, self._kf_P, self._kf_t = x, P, int(t_ns)

    @property
    def streak_start_ns(self) -> int:
        """When its current run of steady matches began (host.tracking.tracker)."""
        return self._streak_ns

    def restart_streak(self, t_ns: int) -> None:
        """A gap in its matches: confirmation and the evidence count again from ``t_ns``."""
        self._streak_ns, self._chances, self._support = int(t_ns), 1, 1

    def count_chance(self, hit: bool, seen: bool) -> None:
        """A camera's frame was a chance to see it (``seen``: that camera clearly sees where it stands,
        or it was matched) and it was matched in it or not (``hit``) (host.tracking.evidence)."""
        self._chances += int(hit or seen)
        self._support += int(hit)

    @property
    def support(self) -> float:
        """The share of its chances it was matched in since its steady matches began (1 for a person)."""
        return 1.0 if self.state == "confirmed" else self._support / self._chances

    def corroborated(self, min_support: float) -> bool:
        """Confirmed, or matched in at least ``min_support`` of its chances since its steady matches began."""
        return self.state == "confirmed" or self._support >= min_support * self._chances
