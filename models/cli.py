"""The models package's ``superbody`` subcommands.

Each command is added by one small ``_add_<command>(sub)`` function and run by one
``_run_<command>(args)`` function that returns the exit code. Heavy modules are imported inside
the ``_run_`` functions so that ``superbody --help`` stays fast.

Exit codes: 0 success, 2 bad input (unreadable or invalid file, bad argument); errors are one
line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the offline commands (``calibrate``, ``train``, ``eval``, ...)."""
    _add_calibrate(sub)


def _fail(command: str, message: str) -> int:
    print(f"superbody {command}: error: {message}", file=sys.stderr)
    return 2


# --- calibrate ----------------------------------------------------------------------------------


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate a site's cameras", description="Calibrate a site's cameras.")
    csub = p.add_subparsers(dest="calibrate_command", metavar="SOURCE", required=True)
    d = csub.add_parser(
        "from-dataset",
        help="recover the WheresTheFellow cameras from the dataset's 2D-3D joint pairs",
        description=(
            "Recover each WheresTheFellow camera from the dataset's 2D-3D joint pairs (normalised DLT, "
            "zero skew, least-squares refinement), write the site file and print each camera's "
            "reprojection error."
        ),
    )
    d.add_argument("path", type=Path, metavar="PATH.json", help="WheresTheFellow JSON file (e.g. dev.json)")
    d.add_argument("--out", type=Path, required=True, metavar="SITE.toml", help="site file to write")
    d.add_argument("--json-out", type=Path, metavar="F", help='write {"cameras": {id: {"median_px", "max_px"}}} here')
    d.add_argument("--name", default="wtf-apartment", help="site name (default: %(default)s)")
    d.add_argument("--fps", type=float, default=15.0, help="publishing rate written for each camera (default: %(default)s)")
    d.set_defaults(func=_run_calibrate_from_dataset)


_FPS_NOTE = """\
fps: the dataset's samples come at ~8 Hz (the original recorder's rate), but a camera node
publishes one observation per pose-detector frame: {fps} Hz, the detector's rate in the product."""


def _calibration_header(args: argparse.Namespace, fits: dict, errors: dict[str, tuple[float, float, int]]) -> str:
    lines = [
        "WheresTheFellow apartment: the three RealSense D415 cameras of the paper's recordings.",
        "Generated, do not edit: from the repository root run",
        f"  superbody calibrate from-dataset {args.path} --out {args.out}",
        "Each camera: normalised DLT on its 2D-3D joint pairs (dataset mm, Y up, left-handed, converted",
        "to REP-103 as x = X/1000, y = Z/1000, z = Y/1000), decomposed into K, R, C; skew set to zero;",
        "fx, fy, cx, cy, R, C refined by least squares; no distortion (the dataset has none).",
        "Reprojection error of the dataset's joints through edge.camera.project of the cameras below:",
    ]
    for cid, (median, worst, n) in errors.items():
        lines.append(
            f"  camera {cid}: median {median:.2g} px, max {worst:.2g} px over {n} joints "
            f"(DLT skew before zeroing: {fits[cid].skew_px:.2g} px)"
        )
    lines += _FPS_NOTE.format(fps=args.fps).splitlines()
    lines += [
        "floor: bounding rectangle of every ground-truth position and ankle joint, plus 0.5 m,",
        "rounded outward to 0.1 m. No obstacles: the data does not show the furniture.",
    ]
    return "\n".join(lines)


def _print_calibration(site, fits: dict, errors: dict[str, tuple[float, float, int]], out: Path) -> None:
    print(f"{'camera':>6} {'pairs':>6} {'median_px':>10} {'max_px':>10} {'fx':>9} {'fy':>9} {'cx':>8} {'cy':>8} {'skew':>9}  position_m")
    for cam in site.cameras:
        median, worst, n = errors[cam.id]
        pos = ", ".join(f"{v:.3f}" for v in cam.position)
        print(
            f"{cam.id:>6} {n:>6} {median:>10.2g} {worst:>10.2g} {cam.fx:>9.3f} {cam.fy:>9.3f} {cam.cx:>8.3f} "
            f"{cam.cy:>8.3f} {fits[cam.id].skew_px:>9.2g}  [{pos}]"
        )
    print(f"wrote {out} (site {site.name!r}, {len(site.cameras)} cameras, floor x, y bounds {site.floor_bounds})")


def _run_calibrate_from_dataset(args: argparse.Namespace) -> int:
    from edge.site import SiteError, dump_site, load_site, parse_site
    from models.wtf import DatasetError, load_wtf_raw

    command = "calibrate from-dataset"
    if not args.fps > 0:
        return _fail(command, f"--fps must be > 0, got {args.fps}")
    try:
        raw = load_wtf_raw(args.path)
        # Imported after the file is read: a bad path fails fast, without loading scipy.
        import numpy as np

        from models.calibrate import calibrate_dataset, dataset_pairs, reprojection_errors

        site, fits = calibrate_dataset(raw, name=args.name, fps=args.fps)
        # The errors of the cameras exactly as written (dump_site rounds to 1e-9), for the header.
        written = parse_site(tomllib.loads(dump_site(site)), path=str(args.out))
        pairs = dataset_pairs(raw)
        errors = {}
        for cam in written.cameras:
            e = reprojection_errors(cam, *pairs[cam.id])
            errors[cam.id] = (float(np.median(e)), float(e.max()), len(e))
        args.out.write_text(dump_site(site, header=_calibration_header(args, fits, errors)), encoding="utf-8")
        if load_site(args.out).cameras != written.cameras:
            return _fail(command, f"{args.out}: the site file read back differs from the one written")
        if args.json_out is not None:
            report = {"cameras": {cid: {"median_px": m, "max_px": mx} for cid, (m, mx, _) in errors.items()}}
            args.json_out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    except (DatasetError, SiteError, ValueError) as e:
        return _fail(command, str(e))
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    _print_calibration(written, fits, errors, args.out)
    return 0
