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
    _add_train(sub)
    _add_eval(sub)


def _add_train(sub: argparse._SubParsersAction) -> None:
    from superbody.models import crossval, train  # light: torch is imported only when a run starts

    train.register(sub)
    crossval.register(sub)


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
    _add_calibrate_oak_intrinsics(csub)


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
    from superbody.edge.site import SiteError, dump_site, load_site, parse_site
    from superbody.models.wtf import DatasetError, load_wtf_raw

    command = "calibrate from-dataset"
    if not args.fps > 0:
        return _fail(command, f"--fps must be > 0, got {args.fps}")
    try:
        raw = load_wtf_raw(args.path)
        # Imported after the file is read: a bad path fails fast, without loading scipy.
        import numpy as np

        from superbody.models.calibrate import calibrate_dataset, dataset_pairs, reprojection_errors

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


# --- calibrate oak-intrinsics -------------------------------------------------------------------


def _add_calibrate_oak_intrinsics(csub: argparse._SubParsersAction) -> None:
    o = csub.add_parser(
        "oak-intrinsics",
        help="take a camera's intrinsics from its OAK device's calibration",
        description=(
            "Read the intrinsics and distortion of an OAK's colour camera for the NN frame the OAK source "
            "uses (the site camera's size, or --size; centre crop) from the device's calibration, print them "
            "beside the site's, and with --out write the site with them."
        ),
    )
    o.add_argument("--site", type=Path, required=True, metavar="SITE.toml", help="site file")
    o.add_argument("--camera", required=True, metavar="ID", help="camera id in the site")
    o.add_argument("--device", default=None, metavar="DEVICE_ID", help="OAK MX id / serial, IP or USB path (default: the first found)")
    o.add_argument("--size", default=None, metavar="WxH", help="NN frame size (default: the site camera's width x height)")
    o.add_argument("--out", type=Path, default=None, metavar="SITE.toml", help="write the site with this camera's intrinsics here")
    o.set_defaults(func=_run_calibrate_oak_intrinsics)


def _frame_size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or not (16 <= int(w) <= 16384 and 16 <= int(h) <= 16384):
        raise ValueError(f"--size must be WIDTHxHEIGHT with each in [16, 16384], e.g. 512x288, got {text!r}")
    return int(w), int(h)


def _leading_comments(path: Path) -> str:
    """The comment lines at the top of a file, without their '# ' (dump_site writes them back)."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[1:].removeprefix(" "))
    return "\n".join(lines)


def _run_calibrate_oak_intrinsics(args: argparse.Namespace) -> int:
    import numpy as np

    from superbody.edge import oak
    from superbody.edge.oak_convert import camera_with_intrinsics, site_with_camera
    from superbody.edge.site import SiteError, dump_site, load_site
    from superbody.edge.source import SourceError

    command = "calibrate oak-intrinsics"
    try:
        site = load_site(args.site)
        cam = site.camera(args.camera)
        width, height = _frame_size(args.size) if args.size else (cam.width, cam.height)
        K, dist, device_id = oak.read_device_intrinsics(args.device, width, height)
        new = camera_with_intrinsics(cam, K, dist, width, height)
        print(f"OAK {device_id}, {width}x{height} NN frame (site camera {cam.id!r}: {cam.width}x{cam.height})")
        print(f"{'':>4} {'site':>12} {'device':>12}")
        for name in ("fx", "fy", "cx", "cy"):
            print(f"{name:>4} {getattr(cam, name):>12.3f} {getattr(new, name):>12.3f}")
        print(f"dist site {list(cam.dist)}, device {list(new.dist)}")
        if args.out is not None:
            header = _leading_comments(args.site)
            note = f"Camera {cam.id} intrinsics from OAK {device_id} ({width}x{height}): superbody calibrate oak-intrinsics"
            text = dump_site(site_with_camera(site, new), header="\n".join(filter(None, (header, note))))
            args.out.write_text(text, encoding="utf-8")
            back = load_site(args.out).camera(cam.id)
            fields = lambda c: [c.width, c.height, c.fx, c.fy, c.cx, c.cy, *c.dist]  # noqa: E731
            if len(back.dist) != len(new.dist) or not np.allclose(fields(back), fields(new), rtol=0, atol=1e-6):
                return _fail(command, f"{args.out}: the site file read back differs from the one written")
            print(f"wrote {args.out}")
    except KeyError as e:
        return _fail(command, str(e.args[0]))
    except (SiteError, SourceError, ValueError) as e:
        return _fail(command, str(e))
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    return 0


# --- eval ---------------------------------------------------------------------------------------

_DEFAULT_SITE = "deploy/sites/wtf-apartment.toml"
_BASELINE = "analytic"
# The truth offset is a physical distance on a person: anything beyond a metre is a typo.
_MAX_TRUTH_OFFSET_M = 1.0


def _add_eval(sub: argparse._SubParsersAction) -> None:
    from superbody.models.wtf import TRUTH_OFFSET_M  # numpy only

    p = sub.add_parser(
        "eval",
        help="score models and the analytic baseline on a WheresTheFellow file",
        description=(
            "Run one or more ONNX models and the analytic baseline on every sample of a WheresTheFellow "
            "JSON file and print the paper's metrics (MSE in the original code's units) and the MAE of x, y "
            "and yaw, overall and by number of cameras. Predictions (torso centres) are moved forward by "
            "--truth-offset to the dataset's chest-worn tracker before scoring."
        ),
    )
    p.add_argument("--dataset", type=Path, required=True, metavar="PATH.json", help="WheresTheFellow JSON file (e.g. dev.json)")
    p.add_argument(
        "--model", type=Path, action="append", required=True, metavar="M.onnx",
        help="ONNX model; repeat to compare several (the first is the one --json-out and --predictions-out report)",
    )
    p.add_argument("--site", type=Path, default=Path(_DEFAULT_SITE), metavar="SITE.toml", help="site file (default: %(default)s)")
    p.add_argument("--json-out", type=Path, metavar="F", help="write the first model's metrics, the baseline's and the per-camera breakdown as JSON")
    p.add_argument("--predictions-out", type=Path, metavar="F.csv",
                   help="write the first model's predictions in the dataset's frame: index,timestamp_ms,x_mm,z_mm,angle_rad")
    p.add_argument("--plots", type=Path, metavar="DIR", help="write PNG plots here (needs matplotlib)")
    p.add_argument(
        "--truth-offset", type=float, default=TRUTH_OFFSET_M, metavar="M",
        help="metres the dataset's truth lies in front of the torso centre (default: %(default)s; 0 scores torso against tracker)",
    )
    p.add_argument("--batch-size", type=int, default=64, help="samples per estimator call (default: %(default)s)")
    p.set_defaults(func=_run_eval)


def _model_names(paths: list[Path]) -> list[str]:
    """File names, or the paths as given where two models share a file name."""
    names = [p.name for p in paths]
    return [str(p) if names.count(p.name) > 1 else p.name for p in paths]


def _run_eval(args: argparse.Namespace) -> int:
    import math

    from superbody.edge.site import SiteError, load_site
    from superbody.models.wtf import DatasetError, load_wtf

    command = "eval"
    if not (math.isfinite(args.truth_offset) and abs(args.truth_offset) <= _MAX_TRUTH_OFFSET_M):
        return _fail(command, f"--truth-offset must be metres in [-{_MAX_TRUTH_OFFSET_M:g}, {_MAX_TRUTH_OFFSET_M:g}], got {args.truth_offset}")
    if args.batch_size < 1:
        return _fail(command, f"--batch-size must be >= 1, got {args.batch_size}")
    names = _model_names(args.model)
    if len(set(names)) < len(names):
        return _fail(command, f"--model: the same model is given twice: {', '.join(sorted({n for n in names if names.count(n) > 1}))}")
    if _BASELINE in names:
        return _fail(command, f"--model {_BASELINE!r}: the name is taken by the baseline; rename the file")
    if args.plots is not None:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            return _fail(command, "--plots needs matplotlib (pip install 'superbody[train]')")
    try:
        site = load_site(args.site)
        samples = load_wtf(args.dataset, site=site)
        estimators = {name: _load_model(path, site) for name, path in zip(names, args.model)}
    except (DatasetError, SiteError, ValueError) as e:  # ModelMismatchError is a ValueError
        return _fail(command, str(e))

    from superbody.host.analytic import AnalyticEstimator
    from superbody.models.evaluate import format_table, json_report, predict, score, write_predictions_csv

    estimators[_BASELINE] = AnalyticEstimator(site)
    try:
        predictions = {
            name: predict(samples, est, args.batch_size, desc=name, progress=None) for name, est in estimators.items()
        }
    except ValueError as e:
        return _fail(command, str(e))
    reports = score(samples, predictions, args.truth_offset)
    print(f"{args.dataset}: {len(samples)} samples, site {site.name!r}")
    print(format_table(reports, args.truth_offset))
    try:
        if args.json_out is not None:
            doc = json_report(reports, names, _BASELINE, args.truth_offset)
            doc["dataset"], doc["site"] = str(args.dataset), str(args.site)
            args.json_out.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
            print(f"wrote {args.json_out}")
        if args.predictions_out is not None:
            write_predictions_csv(args.predictions_out, samples, predictions[names[0]], args.truth_offset)
            print(f"wrote {args.predictions_out}")
        if args.plots is not None:
            from superbody.models.plots import write_plots

            for path in write_plots(args.plots, samples, predictions, args.truth_offset):
                print(f"wrote {path}")
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    return 0


def _load_model(path: Path, site):
    """An OnnxEstimator for the site; ValueError (one line) if the file is missing or unreadable."""
    from superbody.host.estimator import ModelMismatchError, OnnxEstimator

    if not path.is_file():
        raise ValueError(f"--model {path}: no such file")
    try:
        return OnnxEstimator(path, site)
    except ModelMismatchError:
        raise
    except Exception as e:  # onnxruntime's load errors (InvalidProtobuf, Fail, ...) derive from Exception only
        detail = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise ValueError(f"--model {path}: cannot load the model ({detail})") from None
