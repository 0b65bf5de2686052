"""Merging: two confirmed tracks that are one person whose views went to two tracks (``coincident``).

The rule is ``host.tracking.evidence``'s second point: two people cannot stand inside each other.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.evidence import sigmas_from
from superbody.host.tracking.motion import NS_PER_S, predict_tracks
from superbody.host.tracking.track import Track

__all__ = ["coincident", "seen_together"]


def coincident(people: Sequence[Track], now_ns: int, cfg: TrackerConfig) -> list[Track]:
    """The confirmed tracks that stood within ``cfg.min_separation_m`` of an older one for
    ``cfg.merge_after_s``, or (with ``same_body_sigmas``) as close as one body: each track's latest views
    all put their person within ``same_body_sigmas`` of the other's position (``sigmas_from``), as
    when two cameras' views of one person, a few decimetres apart along their lines of sight, each
    went to a track of their own (scene m: a person in the doorway, two tracks 0.32 m apart for 6 s).

    Older: confirmed earlier (then the lower id). Each track's ``close_since_ns`` keeps when it
    came that close (None while it stands apart); a track found here is the younger of a pair
    and is to be removed, so it is no longer anyone's elder.
    """
    placed = sorted((tr for tr in people if tr.motion is not None), key=lambda tr: (tr.confirmed_ns or 0, tr.id))
    xy = np.array([tr.position for tr in placed]).reshape(-1, 2)
    close = np.linalg.norm(xy[:, None] - xy[None], axis=2) < cfg.min_separation_m  # (M, M)
    if cfg.same_body_sigmas > 0 and len(placed) > 1:
        explained = _explained(placed, now_ns, cfg)
        close |= explained & explained.T
    out: list[Track] = []
    for j, tr in enumerate(placed):
        elders = [placed[i] for i in np.flatnonzero(close[j, :j])]  # older and close: only these pairs are checked
        if not any(o not in out and not seen_together(o, tr) for o in elders):
            tr.close_since_ns = None
            continue
        tr.close_since_ns = now_ns if tr.close_since_ns is None else tr.close_since_ns
        if now_ns - tr.close_since_ns >= cfg.merge_after_s * NS_PER_S:
            out.append(tr)
    return out


def _explained(tracks: Sequence[Track], now_ns: int, cfg: TrackerConfig) -> NDArray[np.bool_]:
    """(M, M): whether each track's latest views (those of its last ``merge_after_s``) all put
    their person within ``same_body_sigmas`` of each track's position at ``now_ns`` (``sigmas_from``)."""
    pos, cov = predict_tracks(list(tracks), now_ns, cfg.accel_std_mps2)  # all at one time
    views = [(i, sv) for i, tr in enumerate(tracks) for sv in tr.views.values()
             if tr.last_seen_ns - sv.stamp_ns <= cfg.merge_after_s * NS_PER_S and np.isfinite(sv.ground_std_m)]
    out = np.zeros((len(tracks), len(tracks)), dtype=bool)
    if not views:
        return out
    owner = np.array([i for i, _ in views])
    sig, _ = sigmas_from(np.array([sv.ground_xy for _, sv in views]), np.array([sv.ground_std_m for _, sv in views]),
                         np.array([sv.camera_xy for _, sv in views]), pos, cov, cfg.same_body_across_m)  # (V, M)
    fits = np.nan_to_num(sig, nan=np.inf) <= cfg.same_body_sigmas
    for i in np.unique(owner):
        out[i] = fits[owner == i].all(axis=0)
    return out


def seen_together(a: Track, b: Track) -> bool:
    """Whether some camera's latest frame matched a view to each of the two tracks: two
    detections in one frame are two people (or one person split by a detector, which the
    candidate rule catches), never one person whose views went to two tracks."""
    return any(b.views.get(cam) is not None and b.views[cam].stamp_ns == sv.stamp_ns for cam, sv in a.views.items())
