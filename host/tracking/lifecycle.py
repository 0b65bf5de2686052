"""The tracks' lifecycle: birth, confirmation, death, merge and re-identification, as named rules.

Each rule is a predicate and the counter (``Tracker.stats``) that reports it, read top to bottom:

**Birth** (``BIRTH_VETOES``): a view no track took starts a candidate unless a veto holds, the
first that does being counted. Views that fail are usually a known person under another camera's
light, or a partial view whose box puts them metres away; a candidate started from them breeds
duplicates that later split a person's views between two ids.

- ``no_signature``: neither a colour nor (with geometry) a ground point: nothing to match it on again;
- ``unplaced_new``: (with geometry) no ground point surer than ``gate_m`` (1 sigma);
- ``suppressed``: it stands inside the gate of a track this frame did not see: that person in
  another camera's light, not a newcomer (a newcomer beside someone is still started by any
  camera that sees both in one frame);
- ``track_cap``: the tracker holds ``max_tracks`` and no candidate unseen in this frame can make
  room (the stalest is evicted: ``evicted_candidates``). Confirmed people are never evicted, so a
  flood of fake people costs candidates, never the people already tracked.

**Confirmation** (``CONFIRMATION``, all must hold): ``steady`` (matches spanning
``confirm_after_s``, the paper's 2 s, without a gap over ``confirm_max_gap_s``), ``corroborated``
(the cameras that clearly see where it stands matched it in ``confirm_min_support`` of their
frames: ``host.tracking.evidence``), ``apart`` (not within ``min_separation_m`` of a confirmed
person). Counted: ``confirmed``; then ``reidentified`` when it is a person removed a moment ago,
or a person unseen for over ``confirm_max_gap_s`` whose views it took (that track goes: one body,
one id; ``host.tracking.reid``).

**Death** (``prune``): ``merged`` (the younger of two confirmed tracks that stood inside each other,
or whose views each fit the other's position, for ``merge_after_s``: ``host.tracking.merge``), ``removed`` (a person unseen for ``remove_after_s``, remembered
for re-identification) and ``dropped_candidates`` (a candidate unseen as long).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import too_close
from superbody.host.tracking.merge import coincident
from superbody.host.tracking.motion import NS_PER_S
from superbody.host.tracking.reid import Lost, remember, remembered_as
from superbody.host.tracking.track import Track

__all__ = ["Newcomer", "BIRTH_VETOES", "CONFIRMATION", "Lifecycle"]


class Newcomer(NamedTuple):
    """A view no track took, as the birth rules see it."""

    has_colour: bool
    has_ground: bool
    ground_std_m: float  # NaN: no ground point
    near_unseen: bool  # inside the gate of a track this frame did not see


# (counter, veto): the first veto that holds is counted and the view starts nobody.
BIRTH_VETOES: tuple[tuple[str, Callable[[Newcomer, TrackerConfig], bool]], ...] = (
    ("no_signature", lambda v, c: not (v.has_colour or (v.has_ground and c.use_geometry))),
    ("unplaced_new", lambda v, c: c.use_geometry and not v.ground_std_m < c.gate_m),
    ("suppressed", lambda v, c: v.near_unseen),
)


class Lifecycle:
    """The tracks and the people remembered for re-identification, and the rules that change them.

    Args:
        config: the tracker's parameters.
        stats: the tracker's counters, which the rules increment.
        id_prefix: prepended to ids in ``Track.label``.
    """

    def __init__(self, config: TrackerConfig, stats: dict[str, int], id_prefix: str = "") -> None:
        self.config, self.stats, self.id_prefix = config, stats, id_prefix
        self.tracks: dict[int, Track] = {}  # by id, oldest first
        self.lost: dict[int, Lost] = {}  # removed people, oldest first
        self._next_id = 1
        self.confirm_ns = round(config.confirm_after_s * NS_PER_S)
        self.remove_ns = round(config.remove_after_s * NS_PER_S)
        self.gap_ns = round(config.confirm_max_gap_s * NS_PER_S)
        self._reid_ns = round(config.reid_window_s * NS_PER_S)

    def birth(self, view: Newcomer, t: int) -> Track | None:
        """A candidate from a view no track took at ``t``, or None (the veto that held is counted)."""
        for name, veto in BIRTH_VETOES:
            if veto(view, self.config):
                self.stats[name] += 1
                return None
        if len(self.tracks) >= self.config.max_tracks and not self._evict_candidate(t):
            self.stats["track_cap"] += 1
            return None
        tr = Track(self._next_id, f"{self.id_prefix}{self._next_id}", "candidate", t, t, self.config.history_q)
        self._next_id += 1
        self.tracks[tr.id] = tr
        self.stats["new_candidates"] += 1
        return tr

    def _evict_candidate(self, t: int) -> bool:
        """Make room for a new candidate: drop the stalest candidate not seen at ``t``, if any."""
        stale = [tr for tr in self.tracks.values() if tr.state == "candidate" and tr.last_seen_ns < t]
        if not stale:
            return False
        victim = min(stale, key=lambda tr: (tr.last_seen_ns, tr.hits))
        del self.tracks[victim.id]
        self.stats["evicted_candidates"] += 1
        return True

    def confirm_if_due(self, tr: Track, t: int) -> None:
        """Confirm a candidate that meets every rule of ``CONFIRMATION`` at ``t``; give it back the id
        of the one remembered person it clearly is, if any."""
        if tr.state != "candidate" or not all(rule(self, tr) for _, rule in CONFIRMATION):
            return
        tr.state, tr.confirmed_ns = "confirmed", t
        self.stats["confirmed"] += 1
        self._forget_lost(t)
        others = [o for o in self.tracks.values() if o is not tr and o.state == "confirmed"]
        unseen = [o for o in others if t - o.last_seen_ns > self.gap_ns] if self._reid_ns > 0 else []
        present = [o for o in others if o not in unseen]
        lost = remembered_as(tr, [*self.lost.values(), *map(remember, unseen)], present, self.config)
        if lost is None:
            return
        if lost.id in self.lost:
            del self.lost[lost.id]
        else:  # a person whose views this candidate took: one body, their id
            del self.tracks[lost.id]
        del self.tracks[tr.id]
        tr.id, tr.label = lost.id, lost.label
        self.tracks[tr.id] = tr
        self.stats["reidentified"] += 1

    def prune(self, now_ns: int) -> list[Track]:
        """Remove the merged and the unseen (module docstring); return them."""
        cfg = self.config
        people = [tr for tr in self.tracks.values() if tr.state == "confirmed"]
        merged = coincident(people, now_ns, cfg) if cfg.min_separation_m > 0 else []
        for tr in merged:
            del self.tracks[tr.id]
        self.stats["merged"] += len(merged)
        gone = [tr for tr in self.tracks.values() if now_ns - tr.last_seen_ns >= self.remove_ns]
        for tr in gone:
            del self.tracks[tr.id]
            self.stats["removed" if tr.state == "confirmed" else "dropped_candidates"] += 1
            if tr.state == "confirmed" and len(tr.colours) and self._reid_ns > 0:
                self.lost[tr.id] = remember(tr)
        while len(self.lost) > cfg.max_tracks:  # bounded whatever the input
            del self.lost[next(iter(self.lost))]
        self._forget_lost(now_ns)
        return merged + gone

    def _forget_lost(self, now_ns: int) -> None:
        self.lost = {pid: lost for pid, lost in self.lost.items() if now_ns - lost.last_seen_ns <= self._reid_ns}


def _apart(life: Lifecycle, tr: Track) -> bool:
    if life.config.min_separation_m <= 0 or tr.position is None:
        return True
    people = [p.position for p in life.tracks.values() if p.state == "confirmed" and p is not tr and p.position is not None]
    return not too_close(tr.position, people, life.config.min_separation_m)[0]


# (name, rule): a candidate is confirmed when every rule holds, checked in this order.
CONFIRMATION: tuple[tuple[str, Callable[[Lifecycle, Track], bool]], ...] = (
    ("steady", lambda life, tr: tr.last_seen_ns - tr.streak_start_ns >= life.confirm_ns),
    ("corroborated", lambda life, tr: tr.corroborated(life.config.confirm_min_support)),
    ("apart", _apart),
)
