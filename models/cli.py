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

from superbody.edge.cli_args import fail as _fail
from superbody.edge.resources import site_path

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the offline commands (``calibrate``, ``train``, ``eval``, ...)."""
    from superbody.models.evaluation import cli as evaluation_cli
    from superbody.models.training import cli as training_cli  # light: torch is imported only when a run starts

    _add_calibrate(sub)
    training_cli.register(sub)
    evaluation_cli.register(sub)


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
    hs = csub.add_parser(
        "hybrid-sim",
        help="fit the hybrid estimator's uncertainties on simulation of the site (no real data) and write them into models",
        description=(
            "For a site with no labelled real data: simulate people in the site's cameras (a seed no training used), "
            "run each --model and geometry on them, fit the hybrid calibration as calibrate hybrid does (sigma scale, "
            "geometry sigmas, trust per camera count and axis) and write it into each --model (models/sim_calibration.py)."
        ),
    )
    hs.add_argument("--site", type=Path, required=True, metavar="SITE.toml", help="the site the models were trained for")
    hs.add_argument("--model", type=Path, action="append", required=True, metavar="M.onnx", help="model to calibrate (repeatable)")
    hs.add_argument("--samples", type=_samples, default=4000, help="simulated people to fit on, 500-100000 (default 4000)")
    hs.add_argument("--seed", type=int, default=7_2026, help="simulation seed (default 72026, no training's)")
    hs.add_argument("--json-out", type=Path, metavar="F", help="write each model's calibration and scores as JSON")
    hs.set_defaults(func=_run_calibrate_hybrid_sim)
    from superbody.edge.calibration import cli as calibration_cli  # board, intrinsics, oak-intrinsics; OpenCV loads on run

    calibration_cli.register(csub)
    from superbody.host.calibration import cli as people_cli  # calibrate people: the tracker and scipy load on run

    people_cli.register(csub)


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
        "a standing person's hips (0.9 m) or shoulders (1.4 m) fall inside some camera's image, at any",
        "distance (no range cut-off: far is poorly seen, not outside the room; the only limit is a person",
        "spanning 48 image rows), in front of every camera's wall (0.3 m margin), traced on a 5 cm grid.",
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


def _samples(text: str) -> int:
    v = int(text)
    if not 500 <= v <= 100_000:
        raise argparse.ArgumentTypeError(f"must be in [500, 100000], got {text}")
    return v


def _run_calibrate_hybrid_sim(args: argparse.Namespace) -> int:
    from superbody.edge.site import SiteError, load_site
    from superbody.host.estimation.estimator import ModelMismatchError
    from superbody.models.sim_calibration import calibrate_on_simulation, format_fits

    command = "calibrate hybrid-sim"
    try:
        site = load_site(args.site)
        for m in args.model:
            if not m.is_file():
                raise ValueError(f"--model {m}: no such file")
        fits = calibrate_on_simulation(site, args.model, args.samples, args.seed, progress=sys.stderr.isatty())
    except (SiteError, ValueError, ModelMismatchError) as e:
        return _fail(command, str(e))
    print(format_fits(fits))
    if args.json_out is not None:
        doc = {p: {**f, "calibration": json.loads(f["calibration"].to_json())} for p, f in fits.items()}
        args.json_out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
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
    trust_samples = hybrid_fit.trust_samples(net, analytic, cams, len(site.cameras))  # every camera count of the site
    print("\n".join(hybrid_fit.format_trust(cal, trust_samples)))
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
        print("int8 " + "\n".join(hybrid_fit.format_trust(fits["int8"][1], hybrid_fit.trust_samples(kinds["int8"][0], analytic, cams, len(site.cameras)))))
    for m in args.model:
        kind = "int8" if quantised[m] and has_int8 else "fp32"
        hybrid_fit.write_calibration(m, *fits[kind])
        print(f"wrote the {'int8 ' if kind == 'int8' else ''}calibration into {m}"
              + (" (int8 model, but no int8 predictions in --cv: the fp32 calibration)" if quantised[m] and kind == "fp32" else ""))
    # Does each constant hold? The same fit on each fold's complement (for --split space: four of five floor regions).
    per_fold = []
    for k in np.unique(fold):
        keep = fold != k
        s_k, c_k = hybrid_fit.fit_calibration(net[keep], std[keep], analytic[keep], pair[keep], truth[keep], cams[keep])
        per_fold.append({"fold": int(k), "std_scale": s_k.tolist(), "net_trust": [list(r) for r in c_k.net_trust],
                         "analytic_std": [list(r) for r in c_k.analytic_std]})
    print("fitted without each fold, trust (x, y, yaw) by cameras: " + " | ".join(
        f"fold {f['fold']}: " + "; ".join(",".join(f"{v:g}" for v in row) for row in f["net_trust"]) for f in per_fold))
    if args.json_out is not None:
        doc = {"std_scale": scale.tolist(), "calibration": json.loads(cal.to_json()), "coverage": coverage, "per_fold": per_fold,
               "sources": {s: int((source == s).sum()) for s in ("hybrid", "onnx", "analytic")}, "reports": reports, "truth_offset_m": offset,
               "int8_vs_fp32_percent": int8_change,
               "int8": {"std_scale": fits["int8"][0].tolist(), "calibration": json.loads(fits["int8"][1].to_json())} if has_int8 else None}
        args.json_out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {args.json_out}")
    return 0


