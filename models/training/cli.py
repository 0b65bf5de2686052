"""``superbody train`` and ``superbody ensemble``: every option of the training commands, and
the runs they start (torch is imported only when a run starts)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from superbody.edge.site import SiteError, load_site
from superbody.models.training.ensemble import calibration_graphs, load_member
from superbody.models.training.train import ARCH_DEFAULTS, TrainConfig, _search, save, train

__all__ = ["register", "add_train_args", "config_from_args", "format_stages"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``train`` and ``ensemble``."""
    _register_train(sub)
    _register_ensemble(sub)


def _range(text: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--real-exclude must be START:END sample indices, got {text!r}") from None
    if not 0 <= a < b:
        raise argparse.ArgumentTypeError(f"--real-exclude needs 0 <= START < END, got {text!r}")
    return a, b


def add_train_args(p: argparse.ArgumentParser, after_limit: str = "") -> None:
    """The options of a training run; ``after_limit`` ends ``--max-minutes``'s help (what the
    command does outside the limit)."""
    p.add_argument("--site", required=True, help="site file (TOML)")
    p.add_argument("--arch", default="gat", choices=sorted(ARCH_DEFAULTS), help="network (default gat)")
    p.add_argument("--variant", default="site", choices=("site", "rays"), help="features: site cameras one-hot, or world rays (site-independent)")
    p.add_argument("--3d", dest="use_3d", action="store_true", help="add the joints' 3D positions (depth cameras)")
    p.add_argument("--max-views", type=int, default=4, help="rays variant: view slots per person (default 4)")
    p.add_argument("--geometry", action="store_true", help="add each joint's single-view floor position (beyond the paper)")
    p.add_argument("--hparams", type=json.loads, default={}, help='architecture hyper-parameters as JSON, e.g. \'{"hidden": 64}\'')
    p.add_argument("--sim-samples", type=int, default=30_000, help="simulated samples (default 30000)")
    p.add_argument("--sim-seed", type=int, default=0, help="simulation seed")
    p.add_argument("--random-sites", type=int, default=0, help="rays variant: simulate in this many random rooms instead of the site")
    p.add_argument("--real", help="a WheresTheFellow JSON file to mix in (DS1-like)")
    p.add_argument("--real-exclude", type=_range, help="hold out real samples START:END")
    p.add_argument("--real-repeat", type=int, default=20, help="times each real sample is seen per epoch (default 20)")
    p.add_argument("--real-subset-repeat", type=int, default=0,
                   help="also train on every proper subset of each real sample's views, this many times per epoch (default 0: off)")
    p.add_argument("--epochs", type=int, default=40)
    p.add_argument("--batch-size", type=int, default=128)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--patience", type=int, default=6, help="early stopping patience, epochs")
    p.add_argument("--yaw-weight", type=float, default=1.0, help="weight of the yaw (sin, cos) error against the position error (default 1)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-minutes", type=float, default=15.0,
                   help="time limit of a training run: building its data (simulation) and training, checked after every batch; at "
                        "the limit the epoch stops there and the best weights so far are kept (default 15)" + after_limit)
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    p.add_argument("--init", help="start from this checkpoint (.pt): fine-tuning")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    return TrainConfig(
        site=args.site, arch=args.arch, variant=args.variant, use_3d=args.use_3d, max_views=args.max_views, geometry=args.geometry, hparams=args.hparams,
        sim_samples=args.sim_samples, sim_seed=args.sim_seed, random_sites=args.random_sites, real=args.real,
        real_exclude=args.real_exclude, real_repeat=args.real_repeat, real_subset_repeat=args.real_subset_repeat, epochs=args.epochs, batch_size=args.batch_size,
        lr=args.lr, patience=args.patience, yaw_weight=args.yaw_weight, seed=args.seed, max_minutes=args.max_minutes, threads=args.threads, init=args.init,
    )


def _run_train(args: argparse.Namespace) -> int:
    try:
        cfg = config_from_args(args)
        load_site(cfg.site)
        if cfg.real and not Path(cfg.real).is_file():
            raise ValueError(f"--real {cfg.real}: no such file")
        if cfg.init and not Path(cfg.init).is_file():
            raise ValueError(f"--init {cfg.init}: no such file")
    except (ValueError, SiteError) as e:
        print(f"superbody train: error: {e}", file=sys.stderr)
        return 2
    progress = sys.stderr.isatty() and not args.no_progress
    start = time.monotonic()
    stages: list[tuple[str, float]] = []  # (what, minutes), printed at the end
    if args.search:
        cfg = _search(cfg, args.search, progress)
        stages.append((f"hyper-parameter search ({args.search} trials)", (time.monotonic() - start) / 60))
    result = train(cfg, progress=progress)
    stopped = {"time limit": f"stopped at the time limit of {cfg.max_minutes:g} min (--max-minutes)",
               "early stop": f"stopped early (no better validation loss for {cfg.patience} epochs)"}.get(
                   result.stop, f"{cfg.epochs} epoch{'s' if cfg.epochs > 1 else ''} (--epochs)")
    stages += [("building the training data", result.data_minutes), (f"training: {stopped}", result.minutes - result.data_minutes)]
    t = time.monotonic()
    paths = save(result, cfg, args.out, args.name, quantize=not args.no_int8)
    stages.append(("ONNX export" + ("" if args.no_int8 else " and int8 quantisation"), (time.monotonic() - t) / 60))
    print(f"trained {cfg.arch} ({cfg.variant}{', 3D' if cfg.use_3d else ''}) in {result.minutes:.1f} min, best epoch {result.best_epoch}: "
          f"validation MAE x {1000 * result.val.get('mae_x_m', math.nan):.0f} mm, y {1000 * result.val.get('mae_y_m', math.nan):.0f} mm, "
          f"yaw {result.val.get('yaw_mae_deg', math.nan):.1f} deg")
    for kind, p in paths.items():
        print(f"  {kind}: {p} ({p.stat().st_size / 1e6:.2f} MB)")
    if args.calibrate_sim:  # the hybrid's calibration from simulation: a site with no labelled data
        from superbody.models.sim_calibration import calibrate_on_simulation, format_fits

        t = time.monotonic()
        models = [p for kind, p in paths.items() if kind in ("fp32", "int8")]
        print(format_fits(calibrate_on_simulation(load_site(cfg.site), models, progress=progress)))
        stages.append(("hybrid calibration on simulation (--calibrate-sim)", (time.monotonic() - t) / 60))
    print(format_stages(stages, (time.monotonic() - start) / 60, cfg.max_minutes))
    return 0


def format_stages(stages: list[tuple[str, float]], total: float, max_minutes: float) -> str:
    """The command's time, stage by stage: what ``--max-minutes`` limits and what came after it."""
    lines = [f"time: {total:.1f} min in all (--max-minutes {max_minutes:g} limits building the data and training)"]
    lines += [f"  {what}: " + (f"{minutes:.1f} min" if minutes >= 1 else f"{60 * minutes:.0f} s") for what, minutes in stages]
    return "\n".join(lines)


def _register_train(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train a pose network from a site (simulation) and optional real data; export ONNX fp32 + int8",
                       description="Train a pose network from a site (simulation) and optional real data, and export it as ONNX fp32 "
                                   "and int8. Time: --max-minutes limits building the data and training; the export, int8 "
                                   "quantisation and --calibrate-sim follow it, and the command ends with the time of each stage "
                                   "(superbody train --site S --geometry --calibrate-sim, 5 cameras, 2 busy cores: 15.2 min of "
                                   "data and training, then 37 s more; docs/commands.md, Training time).")
    add_train_args(p, after_limit=". The ONNX export, int8 quantisation and --calibrate-sim come after it, and the command prints "
                                  "each stage's time; --search's trials come before it, each limited to 1/(N+1) of it")
    p.add_argument("--search", type=int, default=0, help="random hyper-parameter search: this many short trials first")
    p.add_argument("--out", default="build/models", help="output folder (default build/models)")
    p.add_argument("--name", default="model", help="file name stem (default model)")
    p.add_argument("--no-int8", action="store_true", help="skip int8 quantisation")
    p.add_argument("--calibrate-sim", action="store_true",
                   help="then calibrate the hybrid estimator on simulation of the site (calibrate hybrid-sim): "
                        "the host runs the model as a hybrid, with no labelled real data")
    p.set_defaults(func=_run_train)


def _run_ensemble(args: argparse.Namespace) -> int:
    from superbody.models.training.export import export_onnx, quantize_int8

    command = "superbody ensemble"
    if len(args.member) < 2:
        print(f"{command}: error: --member must be given at least twice (an ensemble of one is the model itself)", file=sys.stderr)
        return 2
    try:
        members = [load_member(p) for p in args.member]
    except ValueError as e:
        print(f"{command}: error: --member {e}", file=sys.stderr)
        return 2
    spec, site = members[0][1], members[0][2]
    for p, (_, s, _, cfg) in zip(args.member, members):
        if s != spec or cfg["site"] != members[0][3]["site"]:
            print(f"{command}: error: --member {p} was trained for another site or graph than {args.member[0]}", file=sys.stderr)
            return 2
    config = {"ensemble": [{"checkpoint": str(p), **cfg} for p, (_, _, _, cfg) in zip(args.member, members)]}
    out = Path(args.out)
    fp32 = out / f"{args.name}.fp32.onnx"
    try:
        export_onnx([m[0] for m in members], spec, config, fp32)
    except ValueError as e:
        print(f"{command}: error: {e}", file=sys.stderr)
        return 2
    paths = [fp32]
    if not args.no_int8:
        paths.append(quantize_int8(fp32, out / f"{args.name}.int8.onnx", calibration_graphs(site, spec)))
    print(f"an ensemble of {len(members)} {members[0][0].arch} networks for site {site.name!r}:")
    for p in paths:
        print(f"  {p} ({p.stat().st_size / 1e6:.2f} MB)")
    return 0


def _register_ensemble(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ensemble", help="combine trained networks into one ONNX model (fp32 + int8)",
        description="Export networks trained alike (superbody train checkpoints, .pt) as one ONNX model that combines their "
                    "estimates (models/training/ensemble.py): mean position, circular-mean yaw, the sigma of their mixture.",
    )
    p.add_argument("--member", action="append", default=[], metavar="M.pt", help="a member's checkpoint (repeat: at least two)")
    p.add_argument("--out", default="build/models", help="output folder (default build/models)")
    p.add_argument("--name", default="ensemble", help="file name stem (default ensemble)")
    p.add_argument("--no-int8", action="store_true", help="skip int8 quantisation")
    p.set_defaults(func=_run_ensemble)
