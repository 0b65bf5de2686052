"""``superbody calibrate people``'s work, without the command line: a recording's people through
the tracker (collect.py), which cameras moved (health.py), and the bundle adjustment that
refines them holding the others (bundle.py).

Which cameras are held: those named (``fix``), or by default every camera the health monitor
did not find moved over the whole recording. They carry the world frame, the floor and the
scale (``bundle.MIN_FIXED`` of them at least); every other camera is refined.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Final

import numpy as np

from superbody.edge.camera import Camera
from superbody.edge.site import Site
from superbody.host.calibration.bundle import MIN_FIXED, Refinement, refine_cameras
from superbody.host.calibration.collect import MAX_SKEW_S, Frame, person_instants
from superbody.host.calibration.health import CalibrationHealth, CameraHealth
from superbody.host.calibration.residuals import Instant, instant_residuals

__all__ = ["PeopleCalibration", "calibrate_from_people", "camera_residuals", "subsample", "MAX_INSTANTS", "NothingToRefine"]

# Instants the bundle adjustment takes, evenly spread over the recording: 1500 instants of 2-5
# views are 10,000-20,000 joints, seconds to solve; a camera's 6 unknowns need far fewer.
MAX_INSTANTS: Final[int] = 1500


class NothingToRefine(ValueError):
    """No camera to refine: none was found moved and none was left free by ``fix``."""


@dataclass(frozen=True)
class PeopleCalibration:
    """What ``calibrate_from_people`` found and did.

    Attributes:
        site: the site with the refined cameras.
        refinement: the bundle adjustment's result.
        health: each camera's health over the whole recording, before the refinement.
        fixed: the cameras held.
        residuals_before, residuals_after: camera id -> (median px, median deg, joints) of the
            leave-one-out residuals over every instant, with the old and the new cameras.
        instants: instants found; ``used``: those the adjustment took.
        counts: the recording's counts (``person_instants``).
    """

    site: Site
    refinement: Refinement
    health: dict[str, CameraHealth]
    fixed: tuple[str, ...]
    residuals_before: dict[str, tuple[float, float, int]]
    residuals_after: dict[str, tuple[float, float, int]]
    instants: int
    used: int
    counts: dict[str, int]


def subsample(instants: Sequence[Instant], max_instants: int = MAX_INSTANTS) -> list[Instant]:
    """At most ``max_instants`` of the instants, evenly spread in time."""
    if len(instants) <= max_instants:
        return list(instants)
    idx = np.unique(np.linspace(0, len(instants) - 1, max_instants).round().astype(int))
    return [instants[i] for i in idx]


def camera_residuals(instants: Sequence[Instant], cameras: Sequence[Camera]) -> dict[str, tuple[float, float, int]]:
    """Each camera's median leave-one-out residual over the instants: (px, deg, joints measured)."""
    by_id = {c.id: c for c in cameras}
    deg: dict[str, list[np.ndarray]] = {c.id: [] for c in cameras}
    px: dict[str, list[np.ndarray]] = {c.id: [] for c in cameras}
    for ins in instants:
        d, p = instant_residuals(ins, by_id)
        for i, c in enumerate(ins.cameras):
            m = ~np.isnan(d[i])
            deg[c].append(d[i, m])
            px[c].append(p[i, m])
    out = {}
    for c in by_id:
        dd, pp = np.concatenate(deg[c] or [np.zeros(0)]), np.concatenate(px[c] or [np.zeros(0)])
        out[c] = (float(np.median(pp)) if len(pp) else math.nan, float(np.median(dd)) if len(dd) else math.nan, len(dd))
    return out


def calibrate_from_people(frames: Sequence[Frame], site: Site, fix: Sequence[str] | None = None, *, focal: bool = False,
                          max_instants: int = MAX_INSTANTS, max_skew_s: float = MAX_SKEW_S,
                          progress: Callable[[str, int, int], None] | None = None) -> PeopleCalibration:
    """Refine the cameras of ``site`` that moved, from a recording of people walking.

    Args:
        frames: the recording's camera frames (``collect.read_recording``).
        site: the site file the recording's host used.
        fix: the cameras to hold (they carry the world frame); None: those the health monitor
            did not find moved.
        focal: also refine the free cameras' focal lengths.
        max_instants: the adjustment takes at most this many instants.
        max_skew_s: views further apart are not one instant.
        progress: called as ``progress(stage, done, total)`` with stage "track" (frames) or
            "adjust" (residual evaluations, total the cap).

    Raises:
        ValueError: an unknown camera in ``fix``, fewer than ``MIN_FIXED`` cameras to hold, or
            no joint two cameras saw.
        NothingToRefine: every camera is held (none found moved and no ``fix``, or ``fix``
            names them all); its message says what the monitor found.
    """
    ids = site.camera_ids
    if fix is not None:
        unknown = [c for c in fix if c not in ids]
        if unknown:
            raise ValueError(f"--fix: camera(s) {', '.join(unknown)} not in site {site.name!r}; cameras: {', '.join(ids)}")
        if len(set(fix)) < MIN_FIXED:
            raise ValueError(f"--fix: at least {MIN_FIXED} cameras must be held (they carry the world frame, floor and scale); got {len(set(fix))}")
    instants, counts = person_instants(frames, site, max_skew_s=max_skew_s,
                                       progress=None if progress is None else lambda n: progress("track", n, len(frames)))
    monitor = CalibrationHealth(site, window_s=3600.0, check_every_s=0.0)
    for ins in instants:
        monitor.observe_instant(ins)
    health = monitor.report(instants[-1].stamp_ns) if instants else monitor.report(0)
    fixed = tuple(c for c in ids if (c in fix if fix is not None else not health[c].moved))
    free = [c for c in ids if c not in fixed]
    if not free:
        suspect = [c for c, h in health.items() if h.state == "suspect"]
        why = (f"camera(s) {', '.join(suspect)} fit badly, but the people do not tell which camera moved: name the trusted ones with --fix"
               if suspect and fix is None else "no camera was found moved" if fix is None else "--fix names every camera")
        raise NothingToRefine(why)
    if len(fixed) < MIN_FIXED:
        raise ValueError(f"at least {MIN_FIXED} cameras must be held (they carry the world frame, floor and scale); held: "
                         f"{', '.join(fixed) or 'none'}" + ("" if fix is not None else " (the others were found moved; name trusted ones with --fix)"))
    used = subsample(instants, max_instants)
    total = 200
    res = refine_cameras(site.cameras, used, free, focal=focal, max_nfev=total,
                         progress=None if progress is None else lambda n: progress("adjust", n, total))
    new_site = replace(site, cameras=res.cameras)
    return PeopleCalibration(new_site, res, health, fixed, camera_residuals(instants, site.cameras), camera_residuals(instants, res.cameras),
                             len(instants), len(used), counts)
