"""Whether a candidate is a person: the evidence the tracker weighs before it confirms one.

The paper confirms a candidate after 2 s of matches. A detector's false positives pass that
test: a coat on a stand that one camera reports in most frames, random partial skeletons that
keep landing inside a candidate's gate. Two physical facts tell them from people:

- **A person is seen by every camera that clearly sees where they stand** (negative evidence).
  Each frame of a camera that clearly sees a candidate's position (``clearly_sees``: the torso
  centre, 1.15 m up, inside the image less ``EDGE_MARGIN`` of its size on each side, in front
  of the camera, within the detector's range, no obstacle of the site in between) is a chance
  to see it; a candidate is
  confirmed only if at least ``TrackerConfig.confirm_min_support`` of its chances since its
  steady matches began were matches. A person in full view of three cameras is matched in most
  of their frames; the coat, reported by one of the three cameras that see its spot, in at most
  a third of them. A camera that sees the spot only near its image edge (where a detector may
  miss a person cut in half) gives no chance, so people cut off at the edges are not penalised.
- **Two people cannot stand inside each other.** A candidate whose position lies within
  ``TrackerConfig.min_separation_m`` of a confirmed person's is that person seen again (a
  detector's second, partial skeleton of them, another camera's odd colours), not a newcomer:
  it is not confirmed. Two confirmed tracks that stay that close for ``MERGE_AFTER_S``, and that
  no camera saw in one frame (``seen_together``: two detections in one frame are two bodies), are
  one person whose views went to two tracks: the younger is removed (``Tracker.prune``). Torsos are about 0.25 m deep and 0.4 m
  wide, so centres closer than 0.3 m are one body; people standing shoulder to shoulder, or
  hugging, stay further apart than that.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.edge.camera import Camera, project
from superbody.edge.floor import detectable_range_m
from superbody.edge.site import Obstacle, obstacles_hide
from superbody.host.tracking.motion import _NS_PER_S
from superbody.host.tracking.track import Track

__all__ = ["EDGE_MARGIN", "MERGE_AFTER_S", "TORSO_CENTRE_M", "clearly_sees", "too_close", "coincident", "seen_together"]

TORSO_CENTRE_M = 1.15  # height of a standing adult's torso centre (between hips 0.9 m and shoulders 1.4 m)
EDGE_MARGIN = 0.1  # fraction of the image's width and height left out on each side
MERGE_AFTER_S = 0.5  # how long two confirmed tracks may stand inside each other before they are one


def clearly_sees(cam: Camera, xy: NDArray, obstacles: Sequence[Obstacle] = ()) -> NDArray[np.bool_]:
    """(N,) whether the camera clearly sees a person standing at each floor point (N, 2).

    Clearly: their torso centre projects inside the image less ``EDGE_MARGIN`` on each side,
    in front of the camera, within ``edge.floor.detectable_range_m``, and no obstacle of the
    site (a shelf, a pillar) stands between the camera and it. Other people are not modelled.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if not len(xy):
        return np.zeros(0, dtype=bool)
    centre = np.column_stack([xy, np.full(len(xy), TORSO_CENTRE_M)])
    uv, z = project(centre, cam)
    mu, mv = EDGE_MARGIN * cam.width, EDGE_MARGIN * cam.height
    inside = (uv[:, 0] >= mu) & (uv[:, 0] <= cam.width - mu) & (uv[:, 1] >= mv) & (uv[:, 1] <= cam.height - mv)
    near = np.hypot(xy[:, 0] - cam.t[0], xy[:, 1] - cam.t[1]) <= detectable_range_m(cam)
    return np.asarray((z > 0.1) & inside & near & ~obstacles_hide(cam.t, centre, obstacles), dtype=bool)


def too_close(xy: NDArray, others: Sequence[NDArray] | NDArray, min_separation_m: float) -> NDArray[np.bool_]:
    """(N,) whether each point (N, 2) lies within ``min_separation_m`` of any of ``others`` (M, 2)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    o = np.asarray(others, dtype=np.float64).reshape(-1, 2)
    if not len(xy) or not len(o):
        return np.zeros(len(xy), dtype=bool)
    return np.asarray((np.linalg.norm(xy[:, None, :] - o[None, :, :], axis=2) < min_separation_m).any(axis=1), dtype=bool)


def coincident(people: Sequence[Track], now_ns: int, min_separation_m: float) -> list[Track]:
    """The confirmed tracks that stood within ``min_separation_m`` of an older one for ``MERGE_AFTER_S``.

    Older: confirmed earlier (then the lower id). Each track's ``_close_since_ns`` keeps when it
    came that close (None while it stands apart); a track found here is the younger of a pair
    and is to be removed, so it is no longer anyone's elder.
    """
    placed = sorted((tr for tr in people if tr._kf_t is not None), key=lambda tr: (tr.confirmed_ns or 0, tr.id))
    xy = np.array([tr._kf_x[0] for tr in placed]).reshape(-1, 2)
    close = np.linalg.norm(xy[:, None] - xy[None], axis=2) < min_separation_m  # (M, M)
    out: list[Track] = []
    for j, tr in enumerate(placed):
        elders = [placed[i] for i in np.flatnonzero(close[j, :j])]  # older and close: only these pairs are checked
        if not any(o not in out and not seen_together(o, tr) for o in elders):
            tr._close_since_ns = None
            continue
        tr._close_since_ns = now_ns if tr._close_since_ns is None else tr._close_since_ns
        if now_ns - tr._close_since_ns >= MERGE_AFTER_S * _NS_PER_S:
            out.append(tr)
    return out


def seen_together(a: Track, b: Track) -> bool:
    """Whether some camera's latest frame matched a view to each of the two tracks: two
    detections in one frame are two people (or one person split by a detector, which the
    candidate rule catches), never one person whose views went to two tracks."""
    return any(b.views.get(cam) is not None and b.views[cam].stamp_ns == sv.stamp_ns for cam, sv in a.views.items())
