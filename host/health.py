"""The host's health: per camera, what the host sees of it; overall, ``ok`` or ``degraded`` with the reasons.

A monitoring app alarms on ``HostStatus.health.state``; people read ``reasons``. A camera is
degraded when its timing leaves the range the host can use (``host.timeline.Timeline.problems``:
silent, too late, slow, over its rate, two publishers on its key), its liveliness token went
away, or its views of people stopped agreeing with the other cameras' (``host.calibration.health``:
moved, suspect). ``CameraWatch`` logs a warning when a camera's problems start and a line when they end.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence

from superbody.host.calibration.health import CameraHealth
from superbody.host.messages import status as host_status
from superbody.host.timeline import Timeline

__all__ = ["camera_statuses", "calibration_problems", "health_of", "CameraWatch"]

log = logging.getLogger("superbody.host")


def calibration_problems(report: Mapping[str, CameraHealth]) -> dict[str, list[str]]:
    """The calibration monitor's findings as camera problems: "moved" and "suspect"."""
    out: dict[str, list[str]] = {}
    for cid, h in report.items():
        if h.state == "moved":
            out[cid] = [f"moved: its views of people disagree with the other cameras' by {h.residual_deg:.1f} deg (median), and "
                        f"turning it {h.correction_deg:.1f} deg and moving it {100 * h.correction_m:.0f} cm explains that: it moved "
                        "since it was calibrated (superbody calibrate people refines it from a recording: docs/calibration.md)"]
        elif h.state == "suspect":
            out[cid] = [f"suspect: its views of people disagree with the other cameras' by {h.residual_deg:.1f} deg (median), "
                        "more than a calibrated camera's; the people do not say which camera is off"]
    return out


def camera_statuses(timeline: Timeline, alive: Iterable[str], gone: Iterable[str], now_ns: int,
                    calibration: Mapping[str, CameraHealth] | None = None) -> list[host_status.CameraStatus]:
    """Every camera of the site as the status reports it, in site order.

    Args:
        timeline: the cameras' timeline.
        alive: ids whose liveliness token is present.
        gone: ids whose token went away (and has not come back).
        now_ns: the host's clock.
        calibration: the calibration monitor's report (``host.calibration.health``), if any.
    """
    alive, gone = set(alive), set(gone)
    problems = timeline.problems(now_ns)
    extra = calibration_problems(calibration or {})
    out = []
    for cid, cam in timeline.cameras.items():
        found = (["gone: its liveliness token dropped: its node stopped or lost the network"] if cid in gone else []) \
            + problems.get(cid, []) + extra.get(cid, [])
        h = (calibration or {}).get(cid)
        cal = None if h is None else host_status.Calibration(
            state=h.state, residual_deg=None if h.residual_deg != h.residual_deg else round(h.residual_deg, 3),
            residual_px=None if h.residual_px != h.residual_px else round(h.residual_px, 2), samples=h.samples)
        fps = cam.fps
        out.append(host_status.CameraStatus(
            id=cid, alive=cid in alive, state=found[0].split(":", 1)[0] if found else "ok",
            fps=None if fps != fps else round(fps, 2), delay_ms=host_status.delay(cam.delay_s(50), cam.delay_s(95)),
            frames=cam.admitted, fused=cam.fused, dropped=dict(cam.dropped), problems=found[:16], calibration=cal,
        ))
    return out


def health_of(cameras: Sequence[host_status.CameraStatus], host_reasons: Sequence[str] = ()) -> host_status.Health:
    """``degraded`` if any camera or the host itself has a problem, with one reason each."""
    reasons = [*host_reasons, *(f"camera {c.id}: {p}" for c in cameras for p in c.problems)][: host_status.MAX_REASONS]
    return host_status.Health(state="degraded" if reasons else "ok", reasons=[r[:512] for r in reasons])


class CameraWatch:
    """Logs each camera's problems as they start (a warning) and end (a line), once each."""

    def __init__(self) -> None:
        self._seen: dict[str, set[str]] = {}

    def update(self, cameras: Sequence[host_status.CameraStatus]) -> None:
        for c in cameras:
            now = {p.split(":", 1)[0]: p for p in c.problems}
            before = self._seen.get(c.id, set())
            for kind in now.keys() - before:
                log.warning("camera %s: %s", c.id, now[kind])
            for kind in before - now.keys():
                log.info("camera %s: no longer %s", c.id, kind)
            self._seen[c.id] = set(now)
