"""Blocked k-fold cross-validation of simulation + real training on a WheresTheFellow file.

    superbody crossval --site deploy/sites/wtf-apartment.toml --real dev.json --init sim.pt --folds 5

The file is split into ``folds`` contiguous time segments (consecutive samples are nearly the
same picture, so random folds would leak). For each fold a model is trained on the simulated
data plus the real samples of the other folds (starting from ``--init``, typically the
simulation-only checkpoint: fine-tuning), and predicts the held-out fold. The held-out
predictions of all folds together are scored like ``superbody eval`` (every real sample is
predicted by a model that never saw it), with the analytic baseline beside them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
from pathlib import Path

import numpy as np

from superbody.edge.site import SiteError, load_site
from superbody.models.train import TrainConfig, add_train_args, config_from_args, train

__all__ = ["fold_ranges", "crossvalidate", "register"]

log = logging.getLogger("superbody.crossval")


def fold_ranges(n: int, folds: int) -> list[tuple[int, int]]:
    """[start, end) of ``folds`` contiguous, nearly equal segments of ``n`` samples."""
    if not 2 <= folds <= n:
        raise ValueError(f"folds must be in [2, {n}] for {n} samples, got {folds}")
    edges = np.linspace(0, n, folds + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def crossvalidate(cfg: TrainConfig, folds: int, truth_offset_m: float | None = None, progress: bool = False) -> dict:
    """Train one model per fold and score the held-out predictions.

    Returns:
        ``{"folds": [...], "reports": {"model": report, "analytic": report}}`` with reports as
        ``models.evaluate.summarise`` gives them.
    """
    from superbody.host.analytic import AnalyticEstimator
    from superbody.models.evaluate import predict, score
    from superbody.models.wtf import TRUTH_OFFSET_M, load_wtf

    if not cfg.real:
        raise ValueError("cross-validation needs real data (--real)")
    offset = TRUTH_OFFSET_M if truth_offset_m is None else truth_offset_m
    site = load_site(cfg.site)
    samples = load_wtf(cfg.real, site=site if cfg.use_3d else None)
    pred = np.full((len(samples), 3), np.nan)
    info = []
    for k, (a, b) in enumerate(fold_ranges(len(samples), folds)):
        fold_cfg = dataclasses.replace(cfg, real_exclude=(a, b), seed=cfg.seed + k)
        log.info("fold %d/%d: holding out samples %d..%d", k + 1, folds, a, b - 1)
        result = train(fold_cfg, progress=progress)
        est = _TorchEstimator(result.model, result.spec, site)
        pred[a:b] = est.estimate([s.views for s in samples[a:b]])
        info.append({"fold": k + 1, "held_out": [a, b], "best_epoch": result.best_epoch, "minutes": round(result.minutes, 2)})
    baseline = predict(samples, AnalyticEstimator(site))
    return {"folds": info, "reports": score(samples, {"model": pred, "analytic": baseline}, offset), "truth_offset_m": offset,
            "predictions": pred}


class _TorchEstimator:
    """A trained PyTorch model used as an estimator (cross-validation does not export each fold)."""

    def __init__(self, model, spec, site):
        self.model, self.spec, self.site = model, spec, site

    def estimate(self, view_sets):
        import torch

        from superbody.host.graph import build_batch

        if not view_sets:
            return np.zeros((0, 3))
        b = build_batch(list(view_sets), self.site, self.spec)
        with torch.no_grad():
            out = self.model(torch.from_numpy(b.x), torch.from_numpy(b.adj), torch.from_numpy(b.mask)).numpy()
        return self.model.decode(out, self.site)


def _run(args: argparse.Namespace) -> int:
    from superbody.models.evaluate import format_table

    try:
        cfg = config_from_args(args)
        load_site(cfg.site)
        if not cfg.real or not Path(cfg.real).is_file():
            raise ValueError(f"--real {cfg.real}: no such file (cross-validation needs the real data)")
        if cfg.init and not Path(cfg.init).is_file():
            raise ValueError(f"--init {cfg.init}: no such file")
    except (ValueError, SiteError) as e:
        print(f"superbody crossval: error: {e}", file=sys.stderr)
        return 2
    out = crossvalidate(cfg, args.folds, args.truth_offset, progress=sys.stderr.isatty() and not args.no_progress)
    print(f"blocked {args.folds}-fold cross-validation on {cfg.real} ({cfg.arch}, {cfg.variant}{', 3D' if cfg.use_3d else ''}):")
    print(format_table(out["reports"], out["truth_offset_m"]))
    if args.json_out:
        doc = {"config": cfg.to_json(), "folds": out["folds"], "truth_offset_m": out["truth_offset_m"], **out["reports"]}
        Path(args.json_out).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crossval", help="blocked k-fold cross-validation of sim + real training on a WheresTheFellow file")
    add_train_args(p)
    p.add_argument("--folds", type=int, default=5, help="contiguous folds (default 5)")
    p.add_argument("--truth-offset", type=float, default=None, help="chest-tracker offset of the file's truth, metres (default: the dataset's)")
    p.add_argument("--json-out", help="write the reports as JSON")
    p.set_defaults(func=_run)
