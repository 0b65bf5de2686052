"""Blocked k-fold cross-validation of simulation + real training on a WheresTheFellow file.

    superbody crossval --site deploy/sites/wtf-apartment.toml --real dev.json --init sim.pt --folds 5 [--split space]

Two ways to block the file into ``folds`` (random folds would leak: consecutive samples are
nearly the same picture):

- ``--split time``: contiguous time segments;
- ``--split space``: regions of the floor (k-means on the true positions, seeded), and the
  training side also loses every sample within ``--buffer`` metres of the held-out region.
  This is the proxy for a recording that walks where this one did not.

For each fold a model is trained on the simulated data plus the real samples of the other folds
(starting from ``--init``, typically the simulation-only checkpoint: fine-tuning), and predicts
the held-out fold. The held-out predictions of all folds together are scored like ``superbody
eval`` (every real sample is predicted by a model that never saw it), with the analytic baseline
beside them. ``--predictions-out F.npz`` keeps them (pose, predicted sigma, analytic pose, truth,
camera count, fold) for calibrating the hybrid estimator (``superbody calibrate hybrid``).

``--temporal`` also gives the live system's figures on the cross-validation: each fold's model
is exported as ``superbody train`` writes it, given the hybrid calibration fitted on the other
folds' held-out predictions (``models.hybrid_fit.fit_calibration``), and the whole recording is
replayed through the host's aggregator with it (``models.evaluation.temporal.replay``: tracker, estimator,
filter, as ``superbody eval --temporal``); the fold's own samples are scored on what the host
publishes at their capture times. Every sample is thus scored on a live host whose model and
calibration never saw it, with the network alone, the hybrid, and geometry alone beside them.
``--models-out DIR`` (with ``--temporal``) keeps those fold models, ``DIR/fold<k>.fp32.onnx``
each with its calibration from the other folds, so that a change to the host (tracker, filter,
set S) can be scored live on the cross-validation again without retraining
(``models.evaluation.temporal.replay`` on fold k's samples, ``fold`` in ``--predictions-out``).
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from superbody.edge.site import load_site
from superbody.models.training.train import TrainConfig, train

__all__ = ["fold_ranges", "spatial_folds", "crossvalidate", "SPLITS"]

SPLITS = ("time", "space")

log = logging.getLogger("superbody.crossval")


def fold_ranges(n: int, folds: int) -> list[tuple[int, int]]:
    """[start, end) of ``folds`` contiguous, nearly equal segments of ``n`` samples."""
    if not 2 <= folds <= n:
        raise ValueError(f"folds must be in [2, {n}] for {n} samples, got {folds}")
    edges = np.linspace(0, n, folds + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def spatial_folds(xy: NDArray, folds: int, buffer_m: float = 0.3, seed: int = 0) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Floor regions as folds: k-means (k = ``folds``) on the positions (N, 2).

    Returns:
        Per fold ``(held_out, excluded)``: the indices of the region, and the indices the
        training side must not see (the region plus every sample within ``buffer_m`` of it).
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if not 2 <= folds <= len(xy):
        raise ValueError(f"folds must be in [2, {len(xy)}] for {len(xy)} samples, got {folds}")
    rng = np.random.default_rng(seed)
    # k-means++ seeding then Lloyd iterations: plain, deterministic for a seed.
    centres = [xy[rng.integers(len(xy))]]
    for _ in range(folds - 1):
        d2 = np.min([((xy - c) ** 2).sum(1) for c in centres], axis=0)
        centres.append(xy[rng.choice(len(xy), p=d2 / d2.sum())])
    C = np.array(centres)
    for _ in range(100):
        label = np.argmin(((xy[:, None] - C[None]) ** 2).sum(-1), axis=1)  # (N,)
        new = np.array([xy[label == k].mean(0) if (label == k).any() else C[k] for k in range(folds)])
        if np.allclose(new, C):
            break
        C = new
    out = []
    for k in range(folds):
        held = np.flatnonzero(label == k)
        d = np.sqrt(((xy[:, None] - xy[None, held]) ** 2).sum(-1)).min(1)  # distance to the region
        out.append((held, np.flatnonzero(d <= buffer_m)))
    return out


def crossvalidate(cfg: TrainConfig, folds: int, truth_offset_m: float | None = None, progress: bool = False,
                  split: str = "time", buffer_m: float = 0.3, int8: bool = False, temporal: bool = False,
                  models_out: Path | None = None) -> dict:
    """Train one model per fold and score the held-out predictions.

    With ``int8``, each fold's model is also exported and quantised as ``superbody train``
    writes it (fast-GAT ONNX, static int8 with the shipped keep-list, MinMax ranges from its
    training graphs; ``superbody ensemble`` takes them from simulated graphs) and predicts its held-out
    samples through onnxruntime: ``"predictions_int8"``, ``"std_int8"`` and a ``"model int8"``
    report, the int8 figure on data no fold model saw.

    With ``temporal``, the live figures (module docstring): ``"temporal_network"``,
    ``"temporal_hybrid"`` and ``"temporal_analytic"`` poses, ``"hybrid"`` (the per-frame
    leave-one-fold-out hybrid) and a report for each; with ``models_out`` too, each fold's fp32
    model with that calibration is copied there as ``fold<k>.fp32.onnx``.

    Returns:
        ``{"folds": [...], "reports": {"model": report, "analytic": report}, "predictions",
        "std", "analytic", ...}`` with reports as ``models.evaluation.evaluate.summarise`` gives them.
    """
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.models.data.wtf import TRUTH_OFFSET_M, load_wtf_raw, to_samples
    from superbody.models.evaluation.evaluate import score
    from superbody.models.hybrid_fit import analytic_with_pairs
    from superbody.models.training.train import save

    if not cfg.real:
        raise ValueError("cross-validation needs real data (--real)")
    offset = TRUTH_OFFSET_M if truth_offset_m is None else truth_offset_m
    site = load_site(cfg.site)
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
    if models_out is not None and not temporal:
        raise ValueError("models_out needs temporal (the fold models are kept with their live calibration)")
    raw = load_wtf_raw(cfg.real)
    samples = to_samples(raw, site if cfg.use_3d else None)
    if split == "time":
        blocks = [(np.arange(a, b), np.arange(a, b)) for a, b in fold_ranges(len(samples), folds)]
    else:
        blocks = spatial_folds(np.array([s.truth[:2] for s in samples]), folds, buffer_m, seed=cfg.seed)
    pred = np.full((len(samples), 3), np.nan)
    std = np.full((len(samples), 3), np.nan)
    pred8 = np.full((len(samples), 3), np.nan)
    std8 = np.full((len(samples), 3), np.nan)
    fold_of = np.zeros(len(samples), np.int64)
    info = []
    fp32_models: dict[int, Path] = {}  # fold -> its exported fp32 model (temporal)
    with tempfile.TemporaryDirectory(prefix="superbody-crossval-") as tmp:
        for k, (held, excluded) in enumerate(blocks):
            fold_cfg = dataclasses.replace(cfg, real_exclude=None, real_holdout=tuple(int(i) for i in excluded), seed=cfg.seed + k)
            log.info("fold %d/%d: holding out %d samples (%d kept from training)", k + 1, folds, len(held), len(excluded))
            result = train(fold_cfg, progress=progress)
            est = _TorchEstimator(result.model, result.spec, site)
            pred[held], std[held] = est.estimate_with_std([samples[i].views for i in held])
            if int8 or temporal:
                paths = save(result, fold_cfg, tmp, f"fold{k + 1}")  # as superbody train writes it
                fp32_models[k + 1] = paths["fp32"]
                if int8:  # the int8 model's poses and raw 1-sigmas (no std scale in its metadata yet)
                    pred8[held], std8[held] = OnnxEstimator(paths["int8"], site).estimate_with_std([samples[i].views for i in held])
            fold_of[held] = k + 1
            info.append({"fold": k + 1, "held_out": int(len(held)), "excluded": int(len(excluded)), "best_epoch": result.best_epoch,
                         "minutes": round(result.minutes, 2)})
        baseline, pair = analytic_with_pairs(samples, site)
        live = _temporal(raw, samples, site, pred, std, baseline, pair, fold_of, fp32_models, offset) if temporal else {}
        if models_out is not None:
            models_out.mkdir(parents=True, exist_ok=True)
            for k, path in fp32_models.items():  # each now carries its calibration from the other folds
                shutil.copyfile(path, models_out / f"fold{k}.fp32.onnx")
    candidates = {"model": pred, "hybrid": live.get("hybrid"), "model int8": pred8 if int8 else None, "model temporal": live.get("temporal_network"),
                  "hybrid temporal": live.get("temporal_hybrid"), "analytic": baseline, "analytic temporal": live.get("temporal_analytic")}
    scored = {name: p for name, p in candidates.items() if p is not None}  # what was run, in table order
    out = {"folds": info, "reports": score(samples, scored, offset), "truth_offset_m": offset,
           "predictions": pred, "std": std, "analytic": baseline, "fold": fold_of, "split": split,
           "truth": np.array([s.truth for s in samples]), "views": np.array([len(s.views) for s in samples]), **live}
    if int8:
        out.update(predictions_int8=pred8, std_int8=std8)
    return out


def _temporal(raw, samples, site, pred: NDArray, std: NDArray, analytic: NDArray, pair: NDArray, fold_of: NDArray,
              fp32_models: dict[int, Path], offset: float) -> dict:
    """The live system on the cross-validation (module docstring): per fold, its fp32 model with the
    hybrid calibration of the other folds, the whole recording replayed through the aggregator,
    the fold's samples taken from what it publishes."""
    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.host.estimation.hybrid import HybridEstimator
    from superbody.host.settings import host_config
    from superbody.models import hybrid_fit
    from superbody.models.data.wtf import truth_to_torso
    from superbody.models.evaluation.temporal import replay, view_stamps

    config = host_config(site)  # the host as the site file's [host] sets it up
    stamps = view_stamps(raw)
    truth = truth_to_torso(np.array([s.truth for s in samples]), offset)
    cams = np.array([len(s.views) for s in samples])
    lofo = hybrid_fit.leave_one_fold_out(pred, std, analytic, pair, truth, cams, fold_of, site)[0]
    net_live, hyb_live = np.full_like(pred, np.nan), np.full_like(pred, np.nan)
    for k, path in fp32_models.items():
        held, train = fold_of == k, fold_of != k
        hybrid_fit.write_calibration(path, *hybrid_fit.fit_calibration(pred[train], std[train], analytic[train], pair[train], truth[train], cams[train]))
        net = OnnxEstimator(path, site)  # the host's --estimator onnx on it: the calibrated sigmas feed the filter
        net_live[held] = replay(samples, stamps, pred, site, net, f"onnx:fold{k}", config).poses[held]
        hyb_live[held] = replay(samples, stamps, lofo, site, HybridEstimator(net, site), f"hybrid:fold{k}", config).poses[held]
        log.info("fold %d: replayed through the host aggregator", k)
    geo_live = replay(samples, stamps, analytic, site, AnalyticEstimator(site), "analytic", config).poses
    return {"hybrid": lofo, "temporal_network": net_live, "temporal_hybrid": hyb_live, "temporal_analytic": geo_live}


class _TorchEstimator:
    """A trained PyTorch model used as an estimator (cross-validation does not export each fold)."""

    def __init__(self, model, spec, site):
        self.model, self.spec, self.site = model, spec, site

    def estimate(self, view_sets):
        return self.estimate_with_std(view_sets)[0]

    def estimate_with_std(self, view_sets):
        import torch

        from superbody.host.estimation.graph import build_batch
        from superbody.models.nets import decode_std

        if not view_sets:
            return np.zeros((0, 3)), np.zeros((0, 3))
        b = build_batch(list(view_sets), self.site, self.spec)
        with torch.no_grad():
            out = self.model(torch.from_numpy(b.x), torch.from_numpy(b.adj), torch.from_numpy(b.mask)).numpy()
        return self.model.decode(out, self.site), decode_std(out, self.model.scale)


