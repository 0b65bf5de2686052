"""``superbody eval``, ``crossval`` and ``coverage``: every option of the evaluation commands,
and the runs they start."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from superbody.edge.angles import wrap_angle
from superbody.edge.cli_args import fail as _fail
from superbody.edge.floor import point_in_polygon
from superbody.edge.resources import site_path
from superbody.edge.site import SiteError, load_site
from superbody.models.evaluation.coverage import coverage_figures
from superbody.models.evaluation.crossval import SPLITS, crossvalidate
from superbody.models.training.cli import add_train_args, config_from_args

__all__ = ["register"]

_DEFAULT_SITE = "wtf-apartment"  # a shipped site (edge/resources.py)
_BASELINE = "analytic"
# The truth offset is a physical distance on a person: anything beyond a metre is a typo.
_MAX_TRUTH_OFFSET_M = 1.0
_EVAL_ESTIMATORS = ("onnx", "analytic")  # onnx: each --model as the host runs it (hybrid when it carries a calibration)
_TEMPORAL_AT = ("first", "last")  # models.evaluation.temporal.SCORE_AT, without importing it for --help


_SIGNATURE_NOTE = "one constant flat hue-saturation histogram on every view (the dataset has no colour)"



def register(sub: argparse._SubParsersAction) -> None:
    """Add ``eval``, ``crossval`` and ``coverage``."""
    _add_eval(sub)
    _register_crossval(sub)
    _register_degraded(sub)
    _register_coverage(sub)


def _run_crossval(args: argparse.Namespace) -> int:
    from superbody.models.evaluation.evaluate import format_table

    try:
        cfg = config_from_args(args)
        load_site(cfg.site)
        if not cfg.real or not Path(cfg.real).is_file():
            raise ValueError(f"--real {cfg.real}: no such file (cross-validation needs the real data)")
        if cfg.init and not Path(cfg.init).is_file():
            raise ValueError(f"--init {cfg.init}: no such file")
        if not 0.0 <= args.buffer <= 5.0:
            raise ValueError(f"--buffer must be in [0, 5] metres, got {args.buffer}")
        if args.models_out is not None and not args.temporal:
            raise ValueError("--models-out needs --temporal (the fold models are kept with their live calibration)")
    except (ValueError, SiteError) as e:
        print(f"superbody crossval: error: {e}", file=sys.stderr)
        return 2
    out = crossvalidate(cfg, args.folds, args.truth_offset, progress=sys.stderr.isatty() and not args.no_progress,
                        split=args.split, buffer_m=args.buffer, int8=args.int8, temporal=args.temporal,
                        models_out=args.models_out)
    print(f"blocked {args.folds}-fold cross-validation ({args.split} blocks) on {cfg.real} ({cfg.arch}, {cfg.variant}{', 3D' if cfg.use_3d else ''}):")
    print(format_table(out["reports"], out["truth_offset_m"]))
    if args.json_out:
        doc = {"config": cfg.to_json(), "split": args.split, "folds": out["folds"], "truth_offset_m": out["truth_offset_m"], **out["reports"]}
        Path(args.json_out).write_text(json.dumps(doc, indent=1) + "\n")
    if args.predictions_out:
        keys = (("predictions", "std", "analytic", "truth", "views", "fold") + (("predictions_int8", "std_int8") if args.int8 else ())
                + (("hybrid", "temporal_network", "temporal_hybrid", "temporal_analytic") if args.temporal else ()))
        np.savez(args.predictions_out, **{k: out[k] for k in keys},
                 truth_offset_m=out["truth_offset_m"], split=args.split)
    return 0


def _register_crossval(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crossval", help="blocked k-fold cross-validation of sim + real training on a WheresTheFellow file")
    add_train_args(p)
    p.add_argument("--folds", type=int, default=5, help="folds (default 5)")
    p.add_argument("--split", choices=SPLITS, default="time", help="block the file by time segments or by floor regions (default time)")
    p.add_argument("--buffer", type=float, default=0.3, help="--split space: also keep samples this close (m) to the held-out region out of training")
    p.add_argument("--int8", action="store_true",
                   help="also quantise each fold's model to int8 as train writes it and score its held-out predictions (kept in --predictions-out)")
    p.add_argument("--temporal", action="store_true",
                   help="also the live system's figures: each fold's model, calibrated as a hybrid on the other folds, "
                        "replayed through the host's aggregator as eval --temporal does (network, hybrid and geometry)")
    p.add_argument("--predictions-out", help="write the held-out predictions, sigmas, analytic poses and truth (.npz)")
    p.add_argument("--models-out", type=Path, metavar="DIR",
                   help="with --temporal: keep each fold's fp32 model, hybrid-calibrated on the other folds, as DIR/fold<k>.fp32.onnx")
    p.add_argument("--truth-offset", type=float, default=None, help="chest-tracker offset of the file's truth, metres (default: the dataset's)")
    p.add_argument("--json-out", help="write the reports as JSON")
    p.set_defaults(func=_run_crossval)


def _run_degraded(args: argparse.Namespace) -> int:
    from superbody.models.evaluation.degraded import format_report, run

    try:
        site = load_site(args.site)
        for flag, path in (("--cv", args.cv), ("--dataset", args.dataset)):
            if not path.is_file():
                raise ValueError(f"{flag} {path}: no such file")
        if not args.models.is_dir():
            raise ValueError(f"--models {args.models}: no such folder")
        report = run(args.cv, args.models, args.dataset, site, seed=args.seed, progress=lambda m: print(m, file=sys.stderr))
    except (ValueError, SiteError, OSError, KeyError) as e:
        print(f"superbody crossval-degraded: error: {e}", file=sys.stderr)
        return 2
    print(f"spatial cross-validation on {args.dataset}, plain and with degraded views, per view-quality bucket:")
    print(format_report(report))
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(report, indent=1) + "\n")
    return 0


def _register_degraded(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crossval-degraded",
                       help="the spatial cross-validation's fold models on their held-out samples, plain and with the views made "
                            "as hard as far, cut-off cameras make them, per view-quality bucket")
    p.add_argument("--cv", type=Path, required=True, metavar="CV.npz", help="superbody crossval --split space --predictions-out's file")
    p.add_argument("--models", type=Path, required=True, metavar="DIR", help="its fold models (crossval --temporal --models-out DIR)")
    p.add_argument("--dataset", type=Path, required=True, metavar="PATH.json", help="the WheresTheFellow file the cross-validation used")
    p.add_argument("--site", type=Path, default=site_path(_DEFAULT_SITE), metavar="SITE.toml", help="site file (default: the shipped wtf-apartment)")
    p.add_argument("--seed", type=int, default=0, help="seed of the degradations (default 0)")
    p.add_argument("--json-out", type=Path, metavar="F", help="write the per-bucket report as JSON")
    p.set_defaults(func=_run_degraded)


def _run_coverage(args: argparse.Namespace) -> int:
    from superbody.edge.site import SiteError, load_site
    from superbody.host.estimation import build_estimator
    from superbody.models.data.simdata import SimDataConfig, generate
    from superbody.models.evaluation.evaluate import predict

    try:
        site = load_site(args.site)
        if args.model and not Path(args.model).is_file():
            raise ValueError(f"--model {args.model}: no such file")
        est, name = build_estimator(site, "auto", args.model)
        for flag, v, lo, hi in (("--train-samples", args.train_samples, 100, 1_000_000), ("--test-samples", args.test_samples, 100, 1_000_000)):
            if not lo <= v <= hi:
                raise ValueError(f"{flag} must be in [{lo}, {hi}], got {v}")
        real_xy = None
        if args.dataset:
            from superbody.models.data.wtf import load_wtf, truth_to_torso

            real_xy = truth_to_torso(np.array([s.truth for s in load_wtf(args.dataset, site)]))[:, :2]
    except (SiteError, ValueError) as e:
        print(f"superbody coverage: error: {e}", file=sys.stderr)
        return 2
    progress = sys.stderr.isatty()
    train = generate(site, SimDataConfig(samples=args.train_samples, seed=args.train_seed), progress=progress)
    test = generate(site, SimDataConfig(samples=args.test_samples, seed=args.test_seed), progress=progress)
    train_truth = np.array([s.truth for s in train])
    test_truth = np.array([s.truth for s in test])
    pred = predict(test, est, 256, desc=name, progress=None)
    paths, cells = coverage_figures(site, train_truth, test_truth, pred, Path(args.out), real_xy)
    for p in paths:
        print(f"wrote {p}")
    cams = np.array([len(s.views) for s in test])
    pos = np.linalg.norm(pred[:, :2] - test_truth[:, :2], axis=1) * 1000
    yaw = np.degrees(np.abs(wrap_angle(pred[:, 2] - test_truth[:, 2])))
    ok = np.isfinite(pos)
    by = {str(k): {"samples": int((ok & (cams == k)).sum()), "position_mm": float(np.mean(pos[ok & (cams == k)])),
                   "yaw_deg": float(np.mean(yaw[ok & (cams == k)]))} for k in np.unique(cams)}
    inside = point_in_polygon(train_truth[:, :2], site.floor).mean()
    print(f"{name} on {len(test)} simulated samples: position {np.mean(pos[ok]):.0f} mm, yaw {np.mean(yaw[ok]):.1f} deg; "
          + "; ".join(f"{k} cam: {v['position_mm']:.0f} mm, {v['yaw_deg']:.1f} deg" for k, v in by.items()))
    p = cells["position_mm"]
    print(f"cells: {int(np.isfinite(p).sum())} of 0.5 m with >= 5 samples; worst cell position {np.nanmax(p):.0f} mm, median {np.nanmedian(p):.0f} mm")
    if args.json_out:
        doc = {"estimator": name, "train_samples": len(train), "train_inside_floor": float(inside), "test_samples": len(test),
               "position_mm": float(np.mean(pos[ok])), "yaw_deg": float(np.mean(yaw[ok])), "by_cameras": by,
               "cells": {"x_edges": cells["x_edges"].tolist(), "y_edges": cells["y_edges"].tolist(),
                         "position_mm": np.asarray(np.where(np.isfinite(p), np.round(p, 1), None)).tolist(),
                         "yaw_deg": np.asarray(np.where(np.isfinite(cells["yaw_deg"]), np.round(cells["yaw_deg"], 2), None)).tolist(),
                         "count": cells["count"].astype(int).tolist()},
               "images": [str(x) for x in paths]}
        Path(args.json_out).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


def _register_coverage(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("coverage", help="maps of where a model was trained and of its simulated error across the floor (PNG)")
    p.add_argument("--site", default=str(site_path("wtf-apartment")), help="site file (default: the shipped wtf-apartment)")
    p.add_argument("--model", help="ONNX model (default: the site's shipped one)")
    p.add_argument("--out", required=True, help="folder for coverage.png and error-by-cell.png")
    p.add_argument("--dataset", help="a WheresTheFellow file whose path to draw (e.g. dev.json)")
    p.add_argument("--train-samples", type=int, default=10_000, help="training positions to show (the training set's first N)")
    p.add_argument("--train-seed", type=int, default=0, help="the training run's --sim-seed (default 0)")
    p.add_argument("--test-samples", type=int, default=6_000, help="simulated test samples")
    p.add_argument("--test-seed", type=int, default=12_345, help="seed of the simulated test set (not a training seed)")
    p.add_argument("--json-out", help="write the figures as JSON")
    p.set_defaults(func=_run_coverage)


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

    from superbody.edge.site import SiteError, load_site
    from superbody.models.data.wtf import DatasetError, load_wtf_raw, to_samples

    command = "eval"
    paths = args.model or []
    names = _model_names(paths) if paths else [_BASELINE]
    problem = _eval_arg_problem(args, paths, names)
    if problem:
        return _fail(command, problem)
    try:
        site = load_site(args.site)
        raw = load_wtf_raw(args.dataset)
        samples = to_samples(raw, site)
        estimators = {name: _load_model(path, site) for name, path in zip(names, paths)}
    except (DatasetError, SiteError, ValueError) as e:  # ModelMismatchError is a ValueError
        return _fail(command, str(e))

    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.estimation.hybrid import HybridEstimator
    from superbody.models.evaluation.evaluate import format_table, predict, score

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
        _write_eval_outputs(args, names, samples, estimators, reports, predictions, temporal, scans)
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    return 0


def _eval_arg_problem(args: argparse.Namespace, paths: list[Path], names: list[str]) -> str | None:
    """What is wrong with ``eval``'s arguments, or None."""
    import importlib.util
    import math

    if not (math.isfinite(args.truth_offset) and abs(args.truth_offset) <= _MAX_TRUTH_OFFSET_M):
        return f"--truth-offset must be metres in [-{_MAX_TRUTH_OFFSET_M:g}, {_MAX_TRUTH_OFFSET_M:g}], got {args.truth_offset}"
    if args.batch_size < 1:
        return f"--batch-size must be >= 1, got {args.batch_size}"
    if args.estimator == _BASELINE and paths:
        return "--model cannot be combined with --estimator analytic (it scores the analytic estimator alone)"
    if args.estimator == "onnx" and not paths:
        return "--model M.onnx is required (or --estimator analytic)"
    if paths and len(set(names)) < len(names):
        return f"--model: the same model is given twice: {', '.join(sorted({n for n in names if names.count(n) > 1}))}"
    if paths and _BASELINE in names:
        return f"--model {_BASELINE!r}: the name is taken by the baseline; rename the file"
    if args.plots is not None and importlib.util.find_spec("matplotlib") is None:
        return "--plots needs matplotlib (pip install 'superbody[train]')"
    return None


def _write_eval_outputs(args: argparse.Namespace, names: list[str], samples, estimators: dict, reports, predictions: dict,
                        temporal, scans) -> None:
    """``eval``'s --json-out, --predictions-out and --plots (OSError for a file it cannot write)."""
    from superbody.models.evaluation.evaluate import json_report, write_predictions_csv

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


def _eval_temporal(args, raw, samples, site, estimators: dict, host_names: dict, predictions: dict) -> tuple[dict, dict, dict]:
    """Replay the recording through the host aggregator per estimator; print per-frame and temporal side by side.

    Returns:
        ``(temporal reports, replay summaries, temporal poses)``, each keyed by estimator name.
    """
    import numpy as np

    from superbody.host.settings import host_config
    from superbody.models.evaluation.evaluate import format_table, score
    from superbody.models.evaluation.temporal import replay, view_stamps
    from superbody.models.evaluation.temporal_scores import format_replay, replay_summary

    config = host_config(site)  # the host as the site file sets it up ([host]; SiteError is a ValueError)
    stamps = view_stamps(raw)
    truth = np.array([s.truth for s in samples])
    poses, summaries = {}, {}
    for name, est in estimators.items():
        rep = replay(samples, stamps, predictions[name], site, est, host_names.get(name, name), config, at=args.temporal_at)
        poses[name] = rep.poses
        summaries[name] = replay_summary(rep, predictions[name], truth, args.truth_offset)
    reports = score(samples, {**predictions, **{f"{n} temporal": p for n, p in poses.items()}}, args.truth_offset)
    table = {}
    for name in estimators:
        table[f"{name} per-frame"], table[f"{name} temporal"] = reports[name], reports[f"{name} temporal"]
    settings = "the site file's [host] settings" if site.host else "host run's defaults"
    print(f"temporal: replayed in capture-time order through the host aggregator (tracker, estimator, filter; {settings}), scored at each sample's {args.temporal_at} view; {_SIGNATURE_NOTE}")
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
