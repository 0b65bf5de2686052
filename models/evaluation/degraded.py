"""The degraded-view cross-validation: dev.json's held-out views made as hard as far, cut-off
cameras make them, and every figure per view-quality bucket.

    superbody crossval-degraded --cv build/models/crossval-space-m1.npz --models build/models/folds-space-m1 \\
        --dataset dev.json [--site S] [--seed 0] [--json-out F]

dev.json walked where two or three cameras saw the person whole. Another recording of the same
room (and any other site) also has people seen by one camera from 5 m, their head above the top
edge of its image or their body beyond a side edge, with 5-8 joints. dev.json cannot walk where
it did not walk, but its views can be made hard the way such cameras make them (``KINDS``), each
held-out sample once per kind, seeded:

- ``top_edge``: in one of its views, a virtual top image edge between the shoulders' and the
  hips' rows: every joint above it is gone (the head above the top edge, shoulders on it);
- ``side_edge``: in one view, a virtual side edge within half a shoulder width of the torso's
  middle: every joint beyond it is gone (the body beyond a side edge);
- ``far_single``: one view only, with the joints a far camera loses gone (each face joint with
  probability 0.7, each elbow and wrist with 0.5) and 2 px more pixel noise;
- ``drop_camera``: one view less (leave-one-camera-out; samples seen by one camera are left out).

Each sample is estimated by its spatial fold's model (``crossval --temporal --models-out``:
``fold<k>.fp32.onnx``, its hybrid calibration fitted on the other folds), as the network alone,
as the hybrid, and by geometry, plain and degraded. ``BUCKETS`` sort the samples by what their
views show (after degradation): one view; one view from a camera more than ``FAR_M`` away;
at most ``FEW_JOINTS`` joints in the best view; every view side-on (the torso's facing 55-125
degrees from the camera). The share of the hybrid's errors within its 1 and 2 sigma is given
per bucket too (a calibrated Gaussian gives 0.68 and 0.95).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.models.data.samples import Sample

__all__ = ["KINDS", "BUCKETS", "FAR_M", "FEW_JOINTS", "degrade", "degraded_set", "bucket_masks", "run", "format_report"]

KINDS: Final[tuple[str, ...]] = ("top_edge", "side_edge", "far_single", "drop_camera")
BUCKETS: Final[tuple[str, ...]] = ("all", "one view", "one far view", "<= 8 joints", "all views side-on")
FAR_M: Final[float] = 4.0  # the farthest tenth of dev.json's views (median 3.2 m; the test recording's hard end: 5.5 m)
FEW_JOINTS: Final[int] = 8
SIDE_ON_DEG: Final[tuple[float, float]] = (55.0, 125.0)
_FACE, _ARMS = (0, 1, 2, 3, 4), (7, 8, 9, 10)
_SHOULDERS, _HIPS = (5, 6), (11, 12)


def _cut(v: PersonView, gone: NDArray[np.bool_]) -> PersonView | None:
    """The view without the joints ``gone`` (17,), its box fitted to what is left; None if nothing is."""
    kp = v.keypoints.copy()
    kp[gone] = np.nan
    seen = ~np.isnan(kp[:, 0])  # what is left
    if not seen.any():
        return None
    lo, hi = kp[seen, :2].min(0), kp[seen, :2].max(0)
    return dataclasses.replace(v, keypoints=kp, bbox=np.array([*lo, *hi], np.float32),
                               points3d=None if v.points3d is None else np.where(seen[:, None], v.points3d, np.nan).astype(np.float32))


def _row(v: PersonView, joints: Sequence[int]) -> float:
    """Mean image row of the joints seen among ``joints`` (NaN if none)."""
    rows = v.keypoints[list(joints), 1]
    return float(np.nanmean(rows)) if np.isfinite(rows).any() else math.nan


def degrade(sample: Sample, kind: str, rng: np.random.Generator) -> Sample | None:
    """One sample made hard (module docstring); None where the kind does not apply or nothing is left."""
    cams = sorted(sample.views)
    views = dict(sample.views)
    if kind == "drop_camera":
        if len(cams) < 2:
            return None
        del views[cams[int(rng.integers(len(cams)))]]
        return dataclasses.replace(sample, views=views)
    cam = cams[int(rng.integers(len(cams)))]
    v = views[cam]
    kp = v.keypoints
    seen = v.visible
    if kind == "top_edge":
        top, bottom = _row(v, _SHOULDERS), _row(v, _HIPS)
        if not math.isfinite(top):
            return None
        span = (bottom - top) if math.isfinite(bottom) else 0.3 * (np.nanmax(kp[:, 1]) - np.nanmin(kp[:, 1]))
        edge = top + rng.uniform(-0.1, 0.4) * span
        gone = seen & (kp[:, 1] < edge)
    elif kind == "side_edge":
        torso = [j for j in (*_SHOULDERS, *_HIPS) if seen[j]]
        if not torso:
            return None
        middle = float(np.mean(kp[torso, 0]))
        width = float(np.ptp(kp[[j for j in _SHOULDERS if seen[j]] or torso, 0])) or 20.0
        edge = middle + rng.uniform(-0.5, 0.5) * width
        gone = seen & ((kp[:, 0] > edge) if rng.uniform() < 0.5 else (kp[:, 0] < edge))
    elif kind == "far_single":
        views = {cam: v}
        p = np.zeros(len(kp))
        p[list(_FACE)], p[list(_ARMS)] = 0.7, 0.5
        gone = seen & (rng.uniform(size=len(kp)) < p)
        v = dataclasses.replace(v, keypoints=kp.copy())
        v.keypoints[seen, :2] += rng.normal(0.0, 2.0, (int(seen.sum()), 2)).astype(np.float32)
    else:
        raise ValueError(f"unknown degradation {kind!r}; kinds: {', '.join(KINDS)}")
    cut = _cut(v, gone)
    if cut is None:
        del views[cam]
    else:
        views[cam] = cut
    return dataclasses.replace(sample, views=views) if views else None


def degraded_set(samples: Sequence[Sample], seed: int = 0) -> tuple[list[Sample], NDArray[np.int64], NDArray[np.str_]]:
    """Every sample degraded once per kind: ``(samples, source index (M,), kind (M,))``."""
    out: list[Sample] = []
    src: list[int] = []
    kinds: list[str] = []
    for i, s in enumerate(samples):
        for k, kind in enumerate(KINDS):
            d = degrade(s, kind, np.random.default_rng([seed, i, k]))
            if d is not None:
                out.append(d)
                src.append(i)
                kinds.append(kind)
    return out, np.array(src, np.int64), np.array(kinds, dtype=str)


def bucket_masks(samples: Sequence[Sample], torso: NDArray, site: Site) -> dict[str, NDArray[np.bool_]]:
    """(N,) membership of each ``BUCKETS`` entry, from what each sample's views show and where the
    person (``torso``: (N, 3) true torso poses) stood and faced."""
    n = len(samples)
    one = np.array([len(s.views) == 1 for s in samples])
    far = np.zeros(n, bool)
    few = np.zeros(n, bool)
    side = np.zeros(n, bool)
    for i, s in enumerate(samples):
        x, y, yaw = torso[i]
        dists, rels = [], []
        for cid in s.views:
            c = site.camera(cid).t
            dists.append(math.hypot(c[0] - x, c[1] - y))
            rels.append(abs(math.degrees(float(wrap_angle(yaw - math.atan2(c[1] - y, c[0] - x))))))
        far[i] = one[i] and dists[0] > FAR_M
        few[i] = max(int(v.visible.sum()) for v in s.views.values()) <= FEW_JOINTS
        side[i] = all(SIDE_ON_DEG[0] <= r <= SIDE_ON_DEG[1] for r in rels)
    return {"all": np.ones(n, bool), "one view": one, "one far view": far, "<= 8 joints": few, "all views side-on": side}


def _in_image(samples: Sequence[Sample], site: Site) -> None:
    """Raise if a view's joints lie outside its camera's image: the file does not fit the site."""
    for s in samples[:20]:
        for cid, v in s.views.items():
            cam = site.camera(cid)
            uv = v.keypoints[~np.isnan(v.keypoints[:, 0]), :2]
            if len(uv) and ((uv < -1).any() or (uv[:, 0] > cam.width + 1).any() or (uv[:, 1] > cam.height + 1).any()):
                raise ValueError(f"camera {cid}: joints outside its {cam.width} x {cam.height} image: is this the site of the file?")


def _estimate(samples: Sequence[Sample], folds: NDArray, models: dict[int, Path], site: Site) -> dict[str, tuple[NDArray, NDArray]]:
    """Per estimator (hybrid, network, analytic): (N, 3) poses and (N, 3) sigmas (NaN where none)."""
    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.host.estimation.hybrid import HybridEstimator

    n = len(samples)
    out = {name: (np.full((n, 3), np.nan), np.full((n, 3), np.nan)) for name in ("hybrid", "network", "analytic")}
    for k, path in models.items():
        idx = np.flatnonzero(folds == k)
        if not len(idx):
            continue
        views = [samples[int(i)].views for i in idx]
        net = OnnxEstimator(path, site)
        p, s = net.estimate_with_std(views)
        out["network"][0][idx], out["network"][1][idx] = p, s
        e = HybridEstimator(net, site).estimate_detailed(views)
        out["hybrid"][0][idx], out["hybrid"][1][idx] = e.pose, e.std
    out["analytic"][0][:] = AnalyticEstimator(site).estimate([s.views for s in samples])
    return out


def _score(est: dict[str, tuple[NDArray, NDArray]], truth: NDArray, masks: dict[str, NDArray], offset: float) -> dict[str, Any]:
    from superbody.models.data.wtf import truth_to_torso
    from superbody.models.evaluation.evaluate import summarise

    torso = truth_to_torso(truth, offset)
    cams = np.ones(len(truth), np.int64)
    out: dict[str, Any] = {}
    for bucket, m in masks.items():
        row: dict[str, Any] = {"samples": int(m.sum())}
        for name, (pose, _std) in est.items():
            r = summarise(pose[m], truth[m], cams[m], offset)
            row[name] = {"x_mm": r["position_mae_mm"]["x"], "y_mm": r["position_mae_mm"]["y"], "yaw_deg": r["yaw_mae_deg"], "failed": r["failed"]}
        pose, std = est["hybrid"]
        err = pose[m] - torso[m]
        err[:, 2] = wrap_angle(err[:, 2])
        z = np.abs(err) / std[m]
        ok = np.isfinite(z).all(1)
        row["hybrid_within_1_sigma"] = [float(v) for v in (z[ok] <= 1).mean(0)] if ok.any() else None
        row["hybrid_within_2_sigma"] = [float(v) for v in (z[ok] <= 2).mean(0)] if ok.any() else None
        out[bucket] = row
    return out


def run(cv: Path, models_dir: Path, dataset: Path, site: Site, seed: int = 0,
        progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The plain and the degraded spatial cross-validation, per bucket (module docstring).

    Raises:
        ValueError: the cross-validation file, the fold models or the dataset do not fit together.
    """
    from superbody.models.data.wtf import load_wtf, truth_to_torso

    d = np.load(cv, allow_pickle=False)
    for key in ("fold", "truth"):
        if key not in d:
            raise ValueError(f"{cv}: no {key!r} array (write it with superbody crossval --predictions-out)")
    if str(d["split"]) != "space":
        raise ValueError(f"{cv}: a {d['split']} split; the degraded-view cross-validation runs on the spatial folds (--split space)")
    folds = np.asarray(d["fold"], np.int64)
    offset = float(d["truth_offset_m"])
    samples = load_wtf(dataset, site)
    if len(samples) != len(folds) or not np.allclose([s.truth for s in samples], d["truth"]):
        raise ValueError(f"{cv} was not made from {dataset}: {len(folds)} predictions for {len(samples)} samples")
    _in_image(samples, site)
    models = {int(k): models_dir / f"fold{int(k)}.fp32.onnx" for k in np.unique(folds)}
    missing = [str(p) for p in models.values() if not p.is_file()]
    if missing:
        raise ValueError(f"fold models missing: {', '.join(missing)} (superbody crossval --temporal --models-out {models_dir})")
    report: dict[str, Any] = {"cv": str(cv), "seed": seed, "far_m": FAR_M, "few_joints": FEW_JOINTS, "side_on_deg": list(SIDE_ON_DEG)}
    truth = np.array([s.truth for s in samples])
    for name, (group, src, kinds) in {"plain": (samples, np.arange(len(samples)), None),
                                      "degraded": degraded_set(samples, seed)}.items():
        if progress:
            progress(f"{name}: {len(group)} samples")
        t = truth[src]
        est = _estimate(group, folds[src], models, site)
        masks = bucket_masks(group, truth_to_torso(t, offset), site)
        if kinds is not None:
            masks.update({f"kind {k}": kinds == k for k in KINDS})
        report[name] = _score(est, t, masks, offset)
    return report


def format_report(report: dict[str, Any]) -> str:
    """Markdown tables: per set and bucket, each estimator's MAE and the hybrid's sigma coverage."""
    lines = []
    for name in ("plain", "degraded"):
        lines += ["", f"{name} ({'dev.json as recorded' if name == 'plain' else 'each held-out sample once per degradation'}):", "",
                  "| bucket | samples | hybrid x / y mm, yaw deg | network x / y mm, yaw deg | geometry x / y mm, yaw deg "
                  "| hybrid within 1 sigma x / y / yaw | within 2 sigma |",
                  "| --- | --- | --- | --- | --- | --- | --- |"]
        for bucket, r in report[name].items():
            if not r["samples"]:
                lines.append(f"| {bucket} | 0 | - | - | - | - | - |")
                continue
            cells = []
            for est in ("hybrid", "network", "analytic"):
                e = r[est]
                cells.append("-" if e["x_mm"] is None else f"{e['x_mm']:.0f} / {e['y_mm']:.0f}, {e['yaw_deg']:.1f}")
            one, two = r["hybrid_within_1_sigma"], r["hybrid_within_2_sigma"]
            fmt = lambda v: "-" if v is None else " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
            lines.append(f"| {bucket} | {r['samples']} | {' | '.join(cells)} | {fmt(one)} | {fmt(two)} |")
    return "\n".join(lines).lstrip("\n")
