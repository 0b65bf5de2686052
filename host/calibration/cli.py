"""``superbody calibrate people``: refine the cameras that moved from a recording of people walking.

    superbody calibrate people --recording REC.mcap --site SITE.toml [--fix CAM ...] [--focal]
                               [--out NEW.toml] [--json-out F]

The recording is an MCAP file of ``superbody record`` (the site's camera observations). Its
people are tracked as the host tracks them, each person's near-simultaneous views grouped, the
cameras' health measured over the whole recording, and the cameras that moved (or every camera
``--fix`` does not name) refined by bundle adjustment over the people's joints, holding the
others (``host.calibration.refine``). It prints each camera's change and its residuals before
and after, and writes the new site file: ``--out``, else ``SITE.people.toml`` beside the
input (never the input itself unless ``--out`` names it). Errors are one line, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tomllib
from pathlib import Path

from superbody.edge.cli_args import fail

__all__ = ["register"]

_COMMAND = "calibrate people"


def register(csub: argparse._SubParsersAction) -> None:
    """Add ``people`` to the ``calibrate`` subcommands."""
    p = csub.add_parser(
        "people",
        help="refine cameras that moved from a recording of people walking (bundle adjustment over their joints)",
        description=(
            "Track the people of a recording (superbody record) as the host does, measure each camera's residual against "
            "the others, and refine the cameras that moved (or those --fix does not name) by bundle adjustment over the "
            "people's joints, holding the others: they carry the world frame, the floor and the scale (at least 2). "
            "Prints each camera's change and residuals before and after; writes the new site file."
        ),
    )
    p.add_argument("--recording", type=Path, required=True, metavar="REC.mcap", help="an MCAP recording of the site's cameras (superbody record)")
    p.add_argument("--site", type=Path, required=True, metavar="SITE.toml", help="the site file the recording's cameras were calibrated with")
    p.add_argument("--fix", action="append", metavar="CAM",
                   help="a camera to hold as it is (repeatable); default: every camera the health check did not find moved")
    p.add_argument("--focal", action="store_true", help="also refine the free cameras' focal lengths (fx and fy by one scale)")
    p.add_argument("--out", type=Path, metavar="SITE.toml", help="the site file to write (may be --site; default SITE.people.toml beside it)")
    p.add_argument("--json-out", type=Path, metavar="F", help="write the health, changes and residuals as JSON")
    p.add_argument("--max-instants", type=int, default=1500, metavar="N",
                   help="at most this many instants (one person's views at one time) go into the adjustment (default 1500)")
    p.add_argument("--max-skew", type=float, default=0.1, metavar="S",
                   help="views further apart than this many seconds are not one instant (default 0.1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)


def _default_out(site_path: Path) -> Path:
    return site_path.with_name(site_path.stem + ".people.toml")


def _run(args: argparse.Namespace) -> int:
    from superbody.edge.site import SiteError, load_site
    from superbody.host.calibration.collect import RecordingError, read_recording

    if not 1 <= args.max_instants <= 100_000:
        return fail(_COMMAND, f"--max-instants must be in [1, 100000], got {args.max_instants}")
    if not (0 < args.max_skew <= 1.0 and math.isfinite(args.max_skew)):
        return fail(_COMMAND, f"--max-skew must be in (0, 1] seconds, got {args.max_skew}")
    out = args.out or _default_out(args.site)
    try:
        site = load_site(args.site)
        frames, rejected = read_recording(args.recording, site)
    except (SiteError, RecordingError) as e:
        return fail(_COMMAND, str(e))
    from tqdm import tqdm

    from superbody.host.calibration.refine import NothingToRefine, calibrate_from_people

    bars: dict[str, tqdm] = {}
    show = not args.no_progress and sys.stderr.isatty()

    def progress(stage: str, done: int, total: int) -> None:
        bar = bars.get(stage)
        if bar is None:
            bar = bars[stage] = tqdm(total=total, desc={"track": "tracking people", "adjust": "bundle adjustment"}[stage],
                                     unit="frame" if stage == "track" else "eval", leave=False, disable=not show, mininterval=0.5)
        bar.update(max(0, min(done, total) - bar.n))

    try:
        result = calibrate_from_people(frames, site, args.fix, focal=args.focal, max_instants=args.max_instants,
                                       max_skew_s=args.max_skew, progress=progress)
    except NothingToRefine as e:
        for bar in bars.values():
            bar.close()
        print(f"nothing to refine: {e}; site file not written")
        return 0
    except ValueError as e:
        return fail(_COMMAND, str(e))
    finally:
        for bar in bars.values():
            bar.close()
    print(_table(result, rejected))
    note = _note(args, result)
    try:
        _write_site(result.site, args.site, out, note)
        if args.json_out is not None:
            args.json_out.write_text(json.dumps(_doc(result), indent=1, allow_nan=False, default=_json_value) + "\n", encoding="utf-8")
    except SiteError as e:
        return fail(_COMMAND, str(e))
    except OSError as e:
        return fail(_COMMAND, f"{e.filename}: {e.strerror or e}")
    print(f"wrote {out}")
    return 0


def _table(r, rejected: int) -> str:
    c = r.counts
    ref = r.refinement
    lines = [
        f"{c['frames']} camera frames ({rejected} rejected), {c['people']} people tracked, {r.instants} instants "
        f"(one person's views from 2+ cameras within --max-skew); the adjustment took {r.used} instants, {ref.points} joints, "
        f"{ref.observations} detections, {ref.seconds:.1f} s ({ref.nfev} evaluations: {ref.status})",
        "residual: median leave-one-out residual of the camera's joints (against those triangulated from the other cameras)",
        f"{'camera':>8} {'health':>8} {'role':>7} {'turned_deg':>10} {'moved_cm':>9} {'focal':>7} {'before_px':>9} {'after_px':>9} "
        f"{'before_deg':>10} {'after_deg':>10} {'joints':>7}",
    ]
    for cam in r.site.cameras:
        ch = ref.changes[cam.id]
        b, a = r.residuals_before[cam.id], r.residuals_after[cam.id]
        role = "held" if cam.id in r.fixed else "refined"
        lines.append(f"{cam.id:>8} {r.health[cam.id].state:>8} {role:>7} {ch.rotation_deg:>10.2f} {100 * ch.position_m:>9.1f} "
                     f"{ch.focal_scale:>7.4f} {b[0]:>9.1f} {a[0]:>9.1f} {b[1]:>10.2f} {a[1]:>10.2f} {b[2]:>7}")
    return "\n".join(lines)


def _note(args: argparse.Namespace, r) -> str:
    free = ", ".join(r.refinement.free)
    fix = " ".join(f"--fix {c}" for c in args.fix or [])
    before = "/".join(f"{r.residuals_before[c][1]:.2f}" for c in r.refinement.free)
    after = "/".join(f"{r.residuals_after[c][1]:.2f}" for c in r.refinement.free)
    return (f"camera {free}: pose{' and focal length' if args.focal else ''} from superbody calibrate people --recording "
            f"{args.recording}{' ' + fix if fix else ''} ({r.used} instants, held {', '.join(r.fixed)}; "
            f"residual {before} -> {after} deg)")


def _header(site_path: Path) -> list[str]:
    lines = []
    for line in site_path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[2:] if line.startswith("# ") else line[1:])
    return lines


def _write_site(site, source: Path, out: Path, note: str) -> None:
    """The site with the input's header and a note, checked by the site parser before it replaces anything."""
    from superbody.edge.site import dump_site, parse_site

    text = dump_site(site, header="\n".join([*_header(source), note]))
    parse_site(tomllib.loads(text), path=str(out))
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)


def _json_value(v: object) -> object:
    return float(v)  # type: ignore[arg-type]


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _doc(r) -> dict:
    ref = r.refinement
    return {
        "counts": r.counts, "instants": r.instants, "used": r.used, "points": ref.points, "observations": ref.observations,
        "seconds": ref.seconds, "fixed": list(r.fixed), "refined": list(ref.free),
        "cameras": {
            cam.id: {
                "health": {"state": r.health[cam.id].state, "residual_px": _finite(r.health[cam.id].residual_px),
                           "residual_deg": _finite(r.health[cam.id].residual_deg), "samples": r.health[cam.id].samples,
                           "explained": _finite(r.health[cam.id].explained)},
                "turned_deg": ref.changes[cam.id].rotation_deg, "moved_m": ref.changes[cam.id].position_m,
                "focal_scale": ref.changes[cam.id].focal_scale,
                "residual_px_before": _finite(r.residuals_before[cam.id][0]), "residual_px_after": _finite(r.residuals_after[cam.id][0]),
                "residual_deg_before": _finite(r.residuals_before[cam.id][1]), "residual_deg_after": _finite(r.residuals_after[cam.id][1]),
                "position": list(cam.position), "rotation": [list(row) for row in cam.rotation],
            } for cam in r.site.cameras
        },
    }
