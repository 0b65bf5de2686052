"""Re-identification: whether a just-confirmed track is a person the tracker lost a moment ago.

A removed person is remembered (``Lost``) for ``TrackerConfig.reid_window_s``; so is, for this test
only, a person still tracked but unseen for over ``confirm_max_gap_s`` (``Lifecycle.confirm_if_due``:
a candidate that took a person's views is confirmed 2 s after it began, which may come before the
person it took them from is removed, 2 s after their last view). A new person takes a lost
person's id back when their colours match that one lost person clearly (median Bhattacharyya
distance between the two histories below ``d_max``, the test a view passes to match a track; the
next lost person and every person present at least ``TrackerConfig.colour_margin`` further). See
``host.tracking.tracker``'s module docstring.

Where the new person stands is not asked. A test that the lost person could have walked there
(at 1.5 m/s, plus ``gate_m``; ``reid_speed_mps`` until December 2026) changed nothing in scenes g
and m (people leaving every view and coming back) at seeds 1-8, 20 s, nor in any scene at 45 s or
k and l over 30 seeds: re-identification comes 2.5 s or more after a person was last seen, when
1.5 m/s reaches across a room.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.track import Track

__all__ = ["Lost", "remember", "remembered_as"]


class Lost(NamedTuple):
    """A removed person, remembered for re-identification."""

    id: int
    label: str
    amp: NDArray[np.float64]  # (n, B) their last histograms as amplitudes
    last_seen_ns: int


def remember(tr: Track) -> Lost:
    """A person as re-identification remembers them: id, colours and when last seen."""
    return Lost(tr.id, tr.label, tr.colours.copy(), tr.last_seen_ns)


def remembered_as(tr: Track, lost: Iterable[Lost], present: Iterable[Track], cfg: TrackerConfig) -> Lost | None:
    """The one remembered person a just-confirmed track clearly is, or None.

    Args:
        tr: the track just confirmed.
        lost: the people remembered (removed, or unseen a while).
        present: the other confirmed people now, seen lately (certainly not the lost one).
        cfg: the tracker's parameters.
    """
    mine = tr.colours  # (n, B)
    if not len(mine):
        return None
    scored: list[tuple[float, Lost]] = []
    for person in lost:
        # d = sqrt(1 - BC) for every pair of histories; the median is robust to odd views
        d = np.sqrt(np.clip(1.0 - mine @ person.amp.T, 0.0, 1.0))  # (n, n_lost)
        scored.append((float(np.median(d)), person))
    scored.sort(key=lambda s: s[0])
    if not scored or scored[0][0] >= cfg.d_max or (len(scored) > 1 and scored[1][0] - scored[0][0] < cfg.colour_margin):
        return None
    # Lighting differs between cameras, so the scale of "same colours" does too: the people
    # present now are certainly not the lost one, and must all look clearly less like it.
    for other in present:
        theirs = other.colours
        if not len(theirs):
            continue
        d = np.sqrt(np.clip(1.0 - mine @ theirs.T, 0.0, 1.0))
        if float(np.median(d)) - scored[0][0] < cfg.colour_margin:
            return None
    return scored[0][1]
