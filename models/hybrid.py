"""Calibrating the hybrid estimator (``host.hybrid``) and its uncertainties on real data.

    superbody calibrate hybrid --cv build/models/crossval-space.npz --dataset dev.json \\
        --model M.fp32.onnx --model M.int8.onnx

Two things are measured and written into each model's metadata:

- ``pose.std_scale``: the network's predicted 1-sigma (trained in simulation) times this, per
  axis and per camera count (1, 2, 3+), matches its real errors. Fitted on the held-out predictions of a cross-validation
  (``superbody crossval --predictions-out``), robustly: the scale that makes the median of
  |error| / sigma equal 0.674, the median of |z| for a unit Gaussian (a few 180-degree yaw flips
  must not inflate every sigma).
- ``hybrid.calibration``: the analytic estimator's 1-sigma per camera count (1, 2, 3+), from
  its errors on the real file (the geometry has no parameters fitted to it), the same robust
  way; its yaw sigma without a shoulder or hip pair separately.

- ``hybrid.calibration``'s ``net_trust``: per camera count and axis, the factor on the network's
  precision that minimises the fused error on the held-out predictions (0 = geometry alone).

``leave_one_fold_out`` scores the hybrid honestly on the cross-validation itself: each fold is
fused with a calibration fitted on the other folds only.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Final, Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.site import Site
from superbody.host.estimator import META_STD_SCALE
from superbody.host.hybrid import META_HYBRID, HybridCalibration, combine, fuse
from superbody.models.samples import Sample

__all__ = ["robust_sigma", "fit_std_scale", "scaled_std", "fit_trust", "TRUST_GRID", "fit_analytic", "hybrid_poses", "leave_one_fold_out", "sigma_coverage", "write_calibration"]

_MEDIAN_ABS_Z: Final[float] = 0.6745  # median of |z| for z ~ N(0, 1)


def _errors(pred: NDArray, truth: NDArray) -> NDArray[np.float64]:
    """(N, 3) signed errors: dx, dy (m), wrapped dyaw (rad)."""
    d = np.asarray(pred, np.float64) - np.asarray(truth, np.float64)
    d[:, 2] = wrap_angle(d[:, 2])
    return d


def robust_sigma(err: NDArray) -> NDArray[np.float64]:
    """Per column, the Gaussian-consistent sigma median(|err|) / 0.6745 (NaN rows ignored)."""
    return np.nanmedian(np.abs(np.asarray(err, np.float64)), axis=0) / _MEDIAN_ABS_Z


def fit_std_scale(pred: NDArray, std: NDArray, truth: NDArray, cameras: NDArray | None = None, min_samples: int = 20) -> NDArray[np.float64]:
    """Factors k with median(|error| / (k sigma)) = 0.6745 per axis.

    Args:
        pred, std, truth: (N, 3) predictions, their predicted 1-sigma, torso truth.
        cameras: (N,) camera counts: one row of factors per count 1, 2, 3+ (a count with fewer
            than ``min_samples`` predictions gets the all-samples row).

    Returns:
        (3,) without ``cameras``, else (3, 3) rows for 1, 2, 3+ cameras.
    """
    z = np.abs(_errors(pred, truth)) / np.asarray(std, np.float64)
    ok = np.isfinite(z).all(1)
    if ok.sum() < 10:
        raise ValueError(f"fit_std_scale: {int(ok.sum())} usable predictions, need at least 10")
    overall = np.median(z[ok], axis=0) / _MEDIAN_ABS_Z
    if cameras is None:
        return overall
    cams = np.clip(np.asarray(cameras), 1, 3)
    rows = [np.median(z[ok & (cams == k)], axis=0) / _MEDIAN_ABS_Z if (ok & (cams == k)).sum() >= min_samples else overall for k in (1, 2, 3)]
    return np.array(rows)


def scaled_std(std: NDArray, scale: NDArray, cameras: NDArray) -> NDArray[np.float64]:
    """(N, 3) sigmas times their scale: (3,) for all, or (3, 3) rows by camera count 1, 2, 3+."""
    scale = np.broadcast_to(np.asarray(scale, np.float64), (3, 3))
    return np.asarray(std, np.float64) * scale[np.clip(np.asarray(cameras), 1, 3) - 1]


def fit_analytic(analytic: NDArray, pair: NDArray, truth: NDArray, cameras: NDArray, source: str = "") -> HybridCalibration:
    """The analytic estimator's 1-sigma per camera count, and its yaw sigma without a pair.

    Args:
        analytic: (N, 3) analytic poses; pair: (N,) whether its yaw came from a shoulder or hip pair.
        truth: (N, 3) torso truth; cameras: (N,) camera counts.
    """
    err = _errors(analytic, truth)
    ok = np.isfinite(err).all(1)
    cams = np.clip(np.asarray(cameras), 1, 3)
    rows = []
    for k in (1, 2, 3):
        m = ok & (cams == k)
        rows.append(robust_sigma(err[m & pair]) if (m & pair).sum() >= 5 else robust_sigma(err[ok & pair]))
    no_pair = ok & ~np.asarray(pair, bool)
    yaw_no_pair = float(robust_sigma(err[no_pair])[2]) if no_pair.sum() >= 5 else np.pi
    # Position sigmas from all samples of a count (the pair only matters for yaw).
    for k in (1, 2, 3):
        m = ok & (cams == k)
        if m.sum() >= 5:
            rows[k - 1][:2] = robust_sigma(err[m])[:2]
    table = tuple(tuple(float(max(v, 1e-3)) for v in r) for r in rows)
    return HybridCalibration(analytic_std=table, analytic_yaw_std_no_pair=float(min(max(yaw_no_pair, 0.05), 99.0)), source=source)


def hybrid_poses(
    net: NDArray, net_std: NDArray, analytic: NDArray, pair: NDArray, cameras: NDArray, calibration: HybridCalibration, site: Site,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.str_]]:
    """What ``host.hybrid.HybridEstimator`` does, on arrays (for offline scoring): ``host.hybrid.combine``."""
    return combine(net, net_std, analytic, pair, cameras, calibration, site)


TRUST_GRID: Final[tuple[float, ...]] = (0.0, 0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0)


def fit_trust(net: NDArray, net_std: NDArray, analytic: NDArray, pair: NDArray, truth: NDArray, cameras: NDArray,
              calibration: HybridCalibration, min_samples: int = 10) -> HybridCalibration:
    """The calibration with ``net_trust`` chosen per camera count and axis (from ``TRUST_GRID``)
    to minimise the fused pose's mean absolute error against the truth; 1 where a count has fewer
    than ``min_samples`` samples. Axes fuse independently, so each is searched on its own."""
    cams = np.clip(np.asarray(cameras), 1, 3)
    geo_std = calibration.analytic_sigmas(cams, pair)
    ok = np.isfinite(analytic).all(1) & np.isfinite(net).all(1)
    rows = []
    for k in (1, 2, 3):
        m = ok & (cams == k)
        if m.sum() < min_samples:
            rows.append((1.0, 1.0, 1.0))
            continue
        best = []
        for axis in range(3):
            maes = []
            for t in TRUST_GRID:
                s = net_std[m] / np.sqrt(t) if t > 0 else np.full_like(net_std[m], np.inf)
                pose, _ = fuse(net[m], s, analytic[m], geo_std[m])
                maes.append(float(np.mean(np.abs(_errors(pose, truth[m])[:, axis]))))
            best.append(TRUST_GRID[int(np.argmin(maes))])
        rows.append(tuple(best))
    return replace(calibration, net_trust=tuple(rows))


def leave_one_fold_out(
    net: NDArray, net_std: NDArray, analytic: NDArray, pair: NDArray, truth: NDArray, cameras: NDArray, fold: NDArray, site: Site,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.str_]]:
    """Hybrid poses where each fold's calibration (std scale and analytic sigmas) comes from the
    other folds only: an honest figure for the hybrid on the cross-validation."""
    pose = np.full_like(net, np.nan)
    std = np.full_like(net, np.nan)
    source = np.full(len(net), "", dtype=object)
    for k in np.unique(fold):
        test, train = fold == k, fold != k
        scale = fit_std_scale(net[train], net_std[train], truth[train], cameras[train])
        cal = fit_analytic(analytic[train], pair[train], truth[train], cameras[train])
        cal = fit_trust(net[train], scaled_std(net_std[train], scale, cameras[train]), analytic[train], pair[train], truth[train], cameras[train], cal)
        pose[test], std[test], source[test] = hybrid_poses(net[test], scaled_std(net_std[test], scale, cameras[test]), analytic[test],
                                                           pair[test], cameras[test], cal, site)
    return pose, std, source.astype(str)


def sigma_coverage(pred: NDArray, std: NDArray, truth: NDArray) -> dict[str, list[float]]:
    """Share of errors within 1 and 2 sigma per axis (x, y, yaw): a calibrated Gaussian gives
    0.683 and 0.954."""
    z = np.abs(_errors(pred, truth)) / np.asarray(std, np.float64)
    ok = np.isfinite(z).all(1)
    return {"within_1_sigma": [float(v) for v in (z[ok] <= 1).mean(0)], "within_2_sigma": [float(v) for v in (z[ok] <= 2).mean(0)],
            "samples": [int(ok.sum())] * 3}


def analytic_with_pairs(samples: Sequence[Sample], site: Site) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The analytic estimator's poses and pair flags on samples."""
    from superbody.host.analytic import AnalyticEstimator

    return AnalyticEstimator(site).estimate_with_pairs([s.views for s in samples])


def write_calibration(model: str | Path, std_scale: NDArray, calibration: HybridCalibration) -> None:
    """Store ``pose.std_scale`` and ``hybrid.calibration`` in an ONNX model's metadata, in place."""
    import onnx

    proto = onnx.load(str(model))
    meta = {META_STD_SCALE: json.dumps(np.round(np.asarray(std_scale, np.float64), 5).tolist()), META_HYBRID: calibration.to_json()}
    keep = [p for p in proto.metadata_props if p.key not in meta]
    del proto.metadata_props[:]
    proto.metadata_props.extend(keep)
    for k, v in meta.items():
        proto.metadata_props.add(key=k, value=v)
    onnx.save(proto, str(model))
