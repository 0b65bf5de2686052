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

from superbody.edge.resources import site_path

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the offline commands (``calibrate``, ``train``, ``eval``, ...)."""
    _add_calibrate(sub)
    _add_train(sub)
    _add_eval(sub)


def _add_train(sub: argparse._SubParsersAction) -> None:
    from superbody.models.evaluation import coverage, crossval
    from superbody.models.training import ensemble, train  # light: torch is imported only when a run starts

    train.register(sub)
    ensemble.register(sub)
    crossval.register(sub)
    coverage.register(sub)


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
    h = csub.add_parser(
        "hybrid",
        help="fit the hybrid estimator's uncertainties on real data and write them into models",
        description=(
            "From a cross-validation's held-out predictions (superbody crossval --predictions-out) and the real "
            "file: scale the network's predicted sigmas to its real errors, measure the analytic estimator's "
            "sigmas per camera count, score the hybrid on the cross-validation (each fold calibrated on the "
            "others), and write the calibration into each --model (metadata pose.std_scale, hybrid.calibration). "
            "An int8 model (metadata quant.format) gets the calibration fitted on the int8 fold models' held-out "
            "predictions when every --cv file has them (superbody crossval --int8), else the fp32 one."
        ),
    )
    h.add_argument("--cv", type=Path, action="append", required=True, metavar="CV.npz",
                   help="held-out predictions from superbody crossval --predictions-out; repeat it for an ensemble's members "
                        "(same file, folds and split; combined as the ensemble model does, models/training/ensemble.py)")
    h.add_argument("--dataset", type=Path, required=True, metavar="PATH.json", help="the WheresTheFellow file the cross-validation used")
    h.add_argument("--site", type=Path, default=site_path("wtf-apartment"), metavar="SITE.toml", help="site file (default: the shipped wtf-apartment)")
    h.add_argument("--model", type=Path, action="append", default=[], metavar="M.onnx", help="model to write the calibration into (repeatable)")
    h.add_argument("--json-out", type=Path, metavar="F", help="write the calibration, coverage and scores as JSON")
    h.set_defaults(func=_run_calibrate_hybrid)
    from superbody.edge.calibration import cli as calibration_cli  # board, intrinsics, oak-intrinsics; OpenCV loads on run

    calibration_cli.register(csub)


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
        "floor: the room the cameras see, not the recording's path (edge/floor.py): floor points where",
        "a standing person's hips (0.9 m) or shoulders (1.4 m) fall inside some camera's image within",
        "5 m of it, in front of every camera's wall (0.3 m margin), traced on a 5 cm grid and simplified.",
        "No obstacles: the data does not show the furniture.",
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
    from superbody.models.data.wtf import DatasetError, load_wtf_raw

    command = "calibrate from-dataset"
    if not args.fps > 0:
        return _fail(command, f"--fps must be > 0, got {args.fps}")
    try:
        raw = load_wtf_raw(args.path)
        # Imported after the file is read: a bad path fails fast, without loading scipy.
        import numpy as np

        from superbody.models.dataset_calibration import calibrate_dataset, dataset_pairs, reprojection_errors

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


def _run_calibrate_hybrid(args: argparse.Namespace) -> int:
    import numpy as np
    from google.protobuf.message import DecodeError

    from superbody.edge.site import SiteError, load_site
    from superbody.models import hybrid_fit
    from superbody.models.data.wtf import DatasetError, load_wtf, truth_to_torso
    from superbody.models.evaluation.evaluate import format_table, relative_change, score
    from superbody.models.training.export import read_metadata

    command = "calibrate hybrid"
    try:
        site = load_site(args.site)
        samples = load_wtf(args.dataset, site=site)
    except (DatasetError, SiteError) as e:
        return _fail(command, str(e))
    members = []
    for path in args.cv:
        try:
            with np.load(path) as cv:
                members.append({k: cv[k] for k in ("predictions", "std", "fold", "truth", "truth_offset_m")
                                + tuple(k for k in ("predictions_int8", "std_int8") if k in cv.files)})
        except (OSError, ValueError, KeyError) as e:
            return _fail(command, f"--cv {path}: not a crossval predictions file ({e})")
        if len(members[-1]["predictions"]) != len(samples):
            return _fail(command, f"--cv {path} has {len(members[-1]['predictions'])} predictions, --dataset {args.dataset} has {len(samples)} samples")
        first = members[0]
        if not (np.array_equal(members[-1]["fold"], first["fold"]) and np.allclose(members[-1]["truth"], first["truth"])
                and float(members[-1]["truth_offset_m"]) == float(first["truth_offset_m"])):
            return _fail(command, f"--cv {path}: other folds, samples or truth offset than --cv {args.cv[0]} (an ensemble's members "
                                  "must be cross-validated on the same split)")
    fold, offset = members[0]["fold"], float(members[0]["truth_offset_m"])
    from superbody.models.training.ensemble import combine

    def combined(key: str):  # the members' held-out predictions combined as the ensemble combines them
        return combine(np.stack([m[f"predictions{key}"] for m in members]), np.stack([m[f"std{key}"] for m in members]))

    # int8: each fold model quantised as train quantises (crossval --int8); its errors are not the
    # fp32 model's, so the int8 model gets its own calibration, fitted the same way on them
    kinds = {"fp32": combined("")} | ({"int8": combined("_int8")} if all("predictions_int8" in m for m in members) else {})
    has_int8 = "int8" in kinds
    quantised = {}
    for m in args.model:
        if not m.is_file():
            return _fail(command, f"--model {m}: no such file")
        try:  # an int8 export carries quant.format (models.training.export.quantize_int8)
            quantised[m] = "quant.format" in read_metadata(m)
        except DecodeError as e:
            return _fail(command, f"--model {m}: not an ONNX model ({e})")
    truth = truth_to_torso(np.array([s.truth for s in samples]), offset)
    cams = np.array([len(s.views) for s in samples])
    analytic, pair = hybrid_fit.analytic_with_pairs(samples, site)
    try:
        fits = {k: hybrid_fit.fit_calibration(n, sd, analytic, pair, truth, cams, source=(
                    f"{args.dataset.name}, {len(samples)} samples; {'int8 ' if k == 'int8' else ''}network sigmas from "
                    f"{' + '.join(p.name for p in args.cv)}")) for k, (n, sd) in kinds.items()}
        lofos = {k: hybrid_fit.leave_one_fold_out(n, sd, analytic, pair, truth, cams, fold, site) for k, (n, sd) in kinds.items()}
    except ValueError as e:
        return _fail(command, str(e))
    (net, std), (scale, cal), (lofo, lofo_std, source) = kinds["fp32"], fits["fp32"], lofos["fp32"]
    scored = {"hybrid (CV)": lofo, "network (CV)": net}
    if has_int8:
        scored.update({"hybrid int8 (CV)": lofos["int8"][0], "network int8 (CV)": kinds["int8"][0]})
    reports = score(samples, {**scored, "analytic": analytic}, offset)
    coverage = {"network": hybrid_fit.sigma_coverage(net, hybrid_fit.scaled_std(std, scale, cams), truth),
                "hybrid": hybrid_fit.sigma_coverage(lofo, lofo_std, truth)}
    print("network sigma scale (x, y, yaw) by cameras: " + "; ".join(f"{k}: {', '.join(f'{v:.2f}' for v in row)}" for k, row in zip((1, 2, 3), scale)))
    print("analytic sigma by cameras (x mm, y mm, yaw deg): " + "; ".join(
        f"{k}: {s[0] * 1000:.0f}, {s[1] * 1000:.0f}, {np.degrees(s[2]):.1f}" for k, s in zip((1, 2, 3), cal.analytic_std))
        + f"; yaw without a shoulder/hip pair {np.degrees(cal.analytic_yaw_std_no_pair):.0f} deg")
    print("analytic bias by cameras (x mm, y mm, yaw deg), subtracted: " + "; ".join(
        f"{k}: {b[0] * 1000:.0f}, {b[1] * 1000:.0f}, {np.degrees(b[2]):.1f}" for k, b in zip((1, 2, 3), cal.analytic_bias)))
    print("trust in the network (x, y, yaw) by cameras: " + "; ".join(f"{k}: {', '.join(f'{v:g}' for v in row)}" for k, row in zip((1, 2, 3), cal.net_trust)))
    for name, cov in coverage.items():
        print(f"{name}: errors within 1 sigma (x, y, yaw) {', '.join(f'{v:.2f}' for v in cov['within_1_sigma'])}; "
              f"within 2 sigma {', '.join(f'{v:.2f}' for v in cov['within_2_sigma'])} (a calibrated Gaussian: 0.68, 0.95)")
    print("hybrid sources: " + ", ".join(f"{s} {int((source == s).sum())}" for s in ("hybrid", "onnx", "analytic")))
    print(format_table(reports, offset))
    int8_change = ({k: round(v, 2) for k, v in relative_change(reports["hybrid (CV)"], reports["hybrid int8 (CV)"], ("x MAE", "y MAE", "yaw MAE")).items()}
                   if has_int8 else None)
    if int8_change is not None:
        print("hybrid int8 vs fp32 on the cross-validation: " + ", ".join(f"{k} {v:+.1f}%" for k, v in int8_change.items()))
    else:
        print("no int8 figure: not every --cv file has int8 predictions (superbody crossval --int8)")
    if has_int8:
        print("int8 trust in the network (x, y, yaw) by cameras: " + "; ".join(f"{k}: {', '.join(f'{v:g}' for v in row)}" for k, row in zip((1, 2, 3), fits["int8"][1].net_trust)))
    for m in args.model:
        kind = "int8" if quantised[m] and has_int8 else "fp32"
        hybrid_fit.write_calibration(m, *fits[kind])
        print(f"wrote the {'int8 ' if kind == 'int8' else ''}calibration into {m}"
              + (" (int8 model, but no int8 predictions in --cv: the fp32 calibration)" if quantised[m] and kind == "fp32" else ""))
    if args.json_out is not None:
        doc = {"std_scale": scale.tolist(), "calibration": json.loads(cal.to_json()), "coverage": coverage,
               "sources": {s: int((source == s).sum()) for s in ("hybrid", "onnx", "analytic")}, "reports": reports, "truth_offset_m": offset,
               "int8_vs_fp32_percent": int8_change,
               "int8": {"std_scale": fits["int8"][0].tolist(), "calibration": json.loads(fits["int8"][1].to_json())} if has_int8 else None}
        args.json_out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {args.json_out}")
    return 0


# --- calibrate oak-intrinsics -------------------------------------------------------------------


# --- eval ---------------------------------------------------------------------------------------

_DEFAULT_SITE = "wtf-apartment"  # a shipped site (edge/resources.py)
_BASELINE = "analytic"
# The truth offset is a physical distance on a person: anything beyond a metre is a typo.
_MAX_TRUTH_OFFSET_M = 1.0
_EVAL_ESTIMATORS = ("onnx", "analytic")  # onnx: each --model as the host runs it (hybrid when it carries a calibration)
_TEMPORAL_AT = ("first", "last")  # models.evaluation.temporal.SCORE_AT, without importing it for --help


def _add_eval(sub: argparse._SubParsersAction) -> None:
    from superbody.models.data.wtf import TRUTH_OFFSET_M  # numpy only

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
        "--model", type=Path, action="append", metavar="M.onnx",
        help="ONNX model; repeat to compare several (the first is the one --json-out and --predictions-out report)",
    )
    p.add_argument("--estimator", choices=_EVAL_ESTIMATORS, default="onnx",
                   help="onnx: score --model (required); analytic: score the analytic baseline alone, without --model (default: %(default)s)")
    p.add_argument(
        "--temporal", action="store_true",
        help=("also replay the recording in capture-time order through the host's own aggregator (tracker, estimator, "
              "filter) and score the pose it publishes at each sample's time, beside the per-frame figures; "
              "--predictions-out then writes these poses"),
    )
    p.add_argument("--temporal-at", choices=_TEMPORAL_AT, default="first",
                   help="with --temporal, score each sample when its first view (its time) or its last view is in (default: %(default)s)")
    p.add_argument(
        "--latency-scan", action="store_true",
        help=("also score each estimator's per-frame poses against the truth taken L ms before the views' mean capture time, "
              "L from -100 to 400 ms: the lag that fits best is how much older the images are than their stamps, on the "
              "truth's clock (each view carries its own truth)"),
    )
    p.add_argument("--site", type=Path, default=site_path(_DEFAULT_SITE), metavar="SITE.toml", help=f"site file (default: the shipped {_DEFAULT_SITE})")
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
    from superbody.models.data.wtf import DatasetError, load_wtf_raw, to_samples

    command = "eval"
    if not (math.isfinite(args.truth_offset) and abs(args.truth_offset) <= _MAX_TRUTH_OFFSET_M):
        return _fail(command, f"--truth-offset must be metres in [-{_MAX_TRUTH_OFFSET_M:g}, {_MAX_TRUTH_OFFSET_M:g}], got {args.truth_offset}")
    if args.batch_size < 1:
        return _fail(command, f"--batch-size must be >= 1, got {args.batch_size}")
    paths = args.model or []
    if args.estimator == _BASELINE and paths:
        return _fail(command, "--model cannot be combined with --estimator analytic (it scores the analytic estimator alone)")
    if args.estimator == "onnx" and not paths:
        return _fail(command, "--model M.onnx is required (or --estimator analytic)")
    names = _model_names(paths) if paths else [_BASELINE]
    if paths and len(set(names)) < len(names):
        return _fail(command, f"--model: the same model is given twice: {', '.join(sorted({n for n in names if names.count(n) > 1}))}")
    if paths and _BASELINE in names:
        return _fail(command, f"--model {_BASELINE!r}: the name is taken by the baseline; rename the file")
    if args.plots is not None:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            return _fail(command, "--plots needs matplotlib (pip install 'superbody[train]')")
    try:
        site = load_site(args.site)
        raw = load_wtf_raw(args.dataset)
        samples = to_samples(raw, site)
        estimators = {name: _load_model(path, site) for name, path in zip(names, paths)}
    except (DatasetError, SiteError, ValueError) as e:  # ModelMismatchError is a ValueError
        return _fail(command, str(e))

    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.estimation.hybrid import HybridEstimator
    from superbody.models.evaluation.evaluate import format_table, json_report, predict, score, write_predictions_csv

    # A hybrid model is also scored as its network alone, to show what the fusion adds.
    host_names = {}
    for name, path in zip(names, paths):
        if isinstance(estimators[name], HybridEstimator):
            host_names[name] = f"hybrid:{path.name}"
            estimators[f"{name} (network)"] = estimators[name].net
            host_names[f"{name} (network)"] = f"onnx:{path.name}"
        else:
            host_names[name] = f"onnx:{path.name}"
    estimators[_BASELINE] = AnalyticEstimator(site)
    try:
        predictions = {
            name: predict(samples, est, args.batch_size, desc=name, progress=None) for name, est in estimators.items()
        }
    except ValueError as e:
        return _fail(command, str(e))
    reports = score(samples, predictions, args.truth_offset)
    print(f"{args.dataset}: {len(samples)} samples, site {site.name!r}")
    temporal = None
    if args.temporal:
        try:
            temporal = _eval_temporal(args, raw, samples, site, estimators, host_names, predictions)
        except ValueError as e:
            return _fail(command, str(e))
    else:
        print(format_table(reports, args.truth_offset))
    scans = None
    if args.latency_scan:
        from superbody.models.evaluation.temporal import view_stamps
        from superbody.models.evaluation.temporal_scores import format_latency_scan, latency_scan, truth_track

        track, stamps = truth_track(raw), view_stamps(raw)
        scans = {name: latency_scan(pred, stamps, track, args.truth_offset) for name, pred in predictions.items()}
        for name, scan in scans.items():
            print(format_latency_scan(name, scan))
    try:
        if args.json_out is not None:
            shown = names + [n for n in estimators if n.endswith(" (network)")]
            doc = json_report(reports, shown, _BASELINE, args.truth_offset)
            doc["dataset"], doc["site"] = str(args.dataset), str(args.site)
            if temporal is not None:
                doc["temporal"] = dict(json_report(temporal[0], shown, _BASELINE, args.truth_offset), at=args.temporal_at,
                                       replay=temporal[1], signature=_SIGNATURE_NOTE)
            if scans is not None:
                doc["latency_scan"] = scans
            args.json_out.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
            print(f"wrote {args.json_out}")
        if args.predictions_out is not None:
            pred = temporal[2][names[0]] if temporal is not None else predictions[names[0]]
            write_predictions_csv(args.predictions_out, samples, pred, args.truth_offset)
            print(f"wrote {args.predictions_out}")
        if args.plots is not None:
            from superbody.models.evaluation.plots import write_plots

            for path in write_plots(args.plots, samples, predictions, args.truth_offset):
                print(f"wrote {path}")
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    return 0


_SIGNATURE_NOTE = "one constant flat hue-saturation histogram on every view (the dataset has no colour)"


def _eval_temporal(args, raw, samples, site, estimators: dict, host_names: dict, predictions: dict) -> tuple[dict, dict, dict]:
    """Replay the recording through the host aggregator per estimator; print per-frame and temporal side by side.

    Returns:
        ``(temporal reports, replay summaries, temporal poses)``, each keyed by estimator name.
    """
    import numpy as np

    from superbody.models.evaluation.evaluate import format_table, score
    from superbody.models.evaluation.temporal import replay, view_stamps
    from superbody.models.evaluation.temporal_scores import format_replay, replay_summary

    stamps = view_stamps(raw)
    truth = np.array([s.truth for s in samples])
    poses, summaries = {}, {}
    for name, est in estimators.items():
        rep = replay(samples, stamps, predictions[name], site, est, host_names.get(name, name), at=args.temporal_at)
        poses[name] = rep.poses
        summaries[name] = replay_summary(rep, predictions[name], truth, args.truth_offset)
    reports = score(samples, {**predictions, **{f"{n} temporal": p for n, p in poses.items()}}, args.truth_offset)
    table = {}
    for name in estimators:
        table[f"{name} per-frame"], table[f"{name} temporal"] = reports[name], reports[f"{name} temporal"]
    print(f"temporal: replayed in capture-time order through the host aggregator (tracker, estimator, filter; host run's "
          f"defaults), scored at each sample's {args.temporal_at} view; {_SIGNATURE_NOTE}")
    print(format_table(table, args.truth_offset))
    for name in estimators:
        print(format_replay(name, summaries[name]))
    return {n: reports[f"{n} temporal"] for n in estimators}, summaries, poses


def _load_model(path: Path, site):
    """The estimator the host would run on this model (``host.estimation.build_estimator``, "auto": the
    hybrid when the model carries its calibration); ValueError (one line) if the file is missing
    or unreadable."""
    from superbody.host.estimation import build_estimator
    from superbody.host.estimation.estimator import ModelMismatchError

    if not path.is_file():
        raise ValueError(f"--model {path}: no such file")
    try:
        return build_estimator(site, "auto", path)[0]
    except ModelMismatchError:
        raise
    except Exception as e:  # onnxruntime's load errors (InvalidProtobuf, Fail, ...) derive from Exception only
        detail = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise ValueError(f"--model {path}: cannot load the model ({detail})") from None
