"""Evaluation against WheresTheFellow ground truth: the paper's metrics, MAEs, a table, a CSV.

The product's estimators report the person's *torso centre*; the dataset's ground truth is a
chest-worn tracker about ``models.data.wtf.TRUTH_OFFSET_M`` in front of it. Every prediction is
therefore moved forward along its own yaw by ``truth_offset_m`` (``models.data.wtf.torso_to_truth``)
before it is compared with the truth; every report says which offset was used.

Metrics, per estimator (``summarise``), overall and by the number of cameras that saw the person:

- ``position_mae_mm``: mean absolute error along REP-103 x and y, millimetres;
- ``yaw_mae_deg``: mean absolute wrapped yaw difference, degrees;
- ``paper_mse``: the paper's MSE tables (``paper_mse``), in the original code's normalised units,
  computed in the dataset's own frame.

Predictions that are not finite (e.g. the analytic estimator with no usable joint) are left out
of the errors and counted as ``failed``.

Typical use (what ``superbody eval`` does)::

    samples = load_wtf(path, site=site)
    predictions = {name: predict(samples, est) for name, est in estimators.items()}
    reports = score(samples, predictions, TRUTH_OFFSET_M)
    print(format_table(reports, TRUTH_OFFSET_M))
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from superbody.edge.angles import wrap_angle
from superbody.host.estimation.estimator import Estimator
from superbody.models.data.samples import Sample
from superbody.models.data.wtf import CAMERA_IDS, to_dataset_frame, torso_to_truth

__all__ = [
    "PAPER_POSITION_SCALE_MM",
    "PAPER_ANGLE_GAIN",
    "CAMERA_COUNTS",
    "PREDICTIONS_HEADER",
    "paper_mse",
    "dataset_frame",
    "sample_errors",
    "camera_counts",
    "predict",
    "summarise",
    "score",
    "REPORT_METRICS",
    "relative_change",
    "evaluate",
    "json_report",
    "format_table",
    "write_predictions_csv",
]

# The original code's target normalisation: x/4000, y/4000, z/4000 (mm) and 0.7 sin, 0.7 cos.
PAPER_POSITION_SCALE_MM: Final[float] = 4000.0
PAPER_ANGLE_GAIN: Final[float] = 0.7
# The breakdown keys: 1 to 3 cameras (a WheresTheFellow sample has 1 to 3 views).
CAMERA_COUNTS: Final[tuple[str, ...]] = tuple(str(k) for k in range(1, len(CAMERA_IDS) + 1))
PREDICTIONS_HEADER: Final[tuple[str, ...]] = ("index", "timestamp_ms", "x_mm", "z_mm", "angle_rad")


# --- the metrics, pure functions ----------------------------------------------------------------


def paper_mse(pred: NDArray, truth: NDArray) -> dict[str, float]:
    """The paper's MSE of poses in the dataset frame, in the original code's normalised units.

    The original code trained on ``(x/4000, y/4000, z/4000, 0.7 sin a, 0.7 cos a)`` (mm, dataset
    angle) and its tables average the squared errors over the x, y, z components ("position"),
    over the sin, cos components ("orientation"), and over all five ("global"). Our estimators
    do not predict the height y (the truth's y is not a height either, docs/dataset.md): its
    error is taken as 0, so ``position = (se_x + 0 + se_z) / 3``::

        se_x = ((X_p - X_t) / 4000)^2                  se_z = ((Z_p - Z_t) / 4000)^2
        se_s = (0.7 (sin a_p - sin a_t))^2             se_c = (0.7 (cos a_p - cos a_t))^2
        position    = mean(se_x + se_z) / 3
        orientation = mean(se_s + se_c) / 2
        global      = mean(se_x + se_z + se_s + se_c) / 5

    Args:
        pred: (N, 3) predictions (X mm, Z mm, angle rad), dataset frame (``dataset_frame``).
        truth: (N, 3) ground truth, same frame.

    Returns:
        ``{"orientation", "position", "global"}``; NaN for N = 0.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    if len(pred) != len(truth):
        raise ValueError(f"paper_mse: {len(pred)} predictions for {len(truth)} truths")
    if len(pred) == 0:
        return {"orientation": math.nan, "position": math.nan, "global": math.nan}
    se_xz = ((pred[:, :2] - truth[:, :2]) / PAPER_POSITION_SCALE_MM) ** 2  # (N, 2)
    sc_p = PAPER_ANGLE_GAIN * np.column_stack([np.sin(pred[:, 2]), np.cos(pred[:, 2])])  # (N, 2)
    sc_t = PAPER_ANGLE_GAIN * np.column_stack([np.sin(truth[:, 2]), np.cos(truth[:, 2])])  # (N, 2)
    se_sc = (sc_p - sc_t) ** 2  # (N, 2)
    position = se_xz.sum(axis=1).mean() / 3  # the height's squared error is the third, zero, term
    orientation = se_sc.sum(axis=1).mean() / 2
    return {
        "orientation": float(orientation),
        "position": float(position),
        "global": float((se_xz.sum(axis=1) + se_sc.sum(axis=1)).mean() / 5),
    }


def dataset_frame(poses: NDArray) -> NDArray[np.float64]:
    """(N, 3) REP-103 (x, y, yaw) -> (N, 3) dataset (X mm, Z mm, angle rad in (-pi, pi])."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return np.column_stack(to_dataset_frame(p[:, 0], p[:, 1], p[:, 2]))


def sample_errors(pred: NDArray, truth: NDArray) -> NDArray[np.float64]:
    """Per-sample absolute errors of REP-103 poses.

    Args:
        pred, truth: (N, 3) (x, y, yaw), metres and radians.

    Returns:
        (N, 3) |dx| mm, |dy| mm, |wrap(dyaw)| degrees.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    dxy = np.abs(pred[:, :2] - truth[:, :2]) * 1000.0  # (N, 2)
    dyaw = np.degrees(np.abs(wrap_angle(pred[:, 2] - truth[:, 2])))  # (N,)
    return np.column_stack([dxy, np.reshape(dyaw, -1)])


def camera_counts(samples: Sequence[Sample]) -> NDArray[np.int64]:
    """(N,) how many cameras saw the person in each sample."""
    return np.array([len(s.views) for s in samples], dtype=np.int64)


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _block(pred_point: NDArray, truth: NDArray) -> dict[str, Any]:
    """The four report keys for predictions already moved to the truth's point (finite rows)."""
    n = len(pred_point)
    err = sample_errors(pred_point, truth)  # (n, 3)
    mse = paper_mse(dataset_frame(pred_point), dataset_frame(truth))
    mean = err.mean(axis=0) if n else np.full(3, math.nan)
    return {
        "samples": n,
        "position_mae_mm": {"x": _finite(mean[0]), "y": _finite(mean[1])},
        "yaw_mae_deg": _finite(mean[2]),
        "paper_mse": {k: _finite(v) for k, v in mse.items()},
    }


def summarise(pred: NDArray, truth: NDArray, cameras: NDArray, truth_offset_m: float, counts: Sequence[int] | None = None) -> dict[str, Any]:
    """One estimator's report: overall and by number of cameras.

    Args:
        pred: (N, 3) the estimator's torso poses (x, y, yaw), REP-103.
        truth: (N, 3) the dataset's ground truth (the chest tracker), REP-103.
        cameras: (N,) cameras per sample (``camera_counts``).
        truth_offset_m: how far in front of the torso the truth is (``models.data.wtf.TRUTH_OFFSET_M``).
        counts: the camera counts to report (None: ``CAMERA_COUNTS``, the dataset's 1-3; a site
            with N cameras: 1..N).

    Returns:
        ``{"samples", "failed", "position_mae_mm": {"x", "y"}, "yaw_mae_deg",
        "paper_mse": {"orientation", "position", "global"}, "by_cameras": {"1": {...}, ...}}``;
        each by_cameras entry has the same four metric keys (``samples`` to ``paper_mse``).
        Metrics over no sample are None. Non-finite predictions are ``failed`` and left out.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    cameras = np.asarray(cameras).reshape(-1)
    if not len(pred) == len(truth) == len(cameras):
        raise ValueError(f"summarise: {len(pred)} predictions, {len(truth)} truths, {len(cameras)} camera counts")
    ok = np.isfinite(pred).all(axis=1)  # (N,)
    point = torso_to_truth(pred[ok], truth_offset_m)  # (n, 3) where the chest tracker would be
    truth, cameras = truth[ok], cameras[ok]
    report = _block(point, truth)
    report["failed"] = int((~ok).sum())
    keys = CAMERA_COUNTS if counts is None else tuple(str(int(k)) for k in counts)
    report["by_cameras"] = {k: _block(point[cameras == int(k)], truth[cameras == int(k)]) for k in keys}
    return report


# --- running estimators ------------------------------------------------------------------------


def predict(
    samples: Sequence[Sample],
    estimator: Estimator,
    batch_size: int = 64,
    desc: str | None = None,
    progress: bool | None = False,
) -> NDArray[np.float64]:
    """Run an estimator on every sample, in batches.

    Args:
        samples: the samples (their ``views`` are what the estimator sees).
        estimator: anything with ``estimate(view_sets) -> (B, 3)``.
        batch_size: samples per ``estimate`` call.
        desc: the progress bar's label.
        progress: show a tqdm bar on stderr (None: only on a terminal).

    Returns:
        (N, 3) torso poses (x, y, yaw), REP-103, in sample order.
    """
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    out = np.zeros((len(samples), 3))
    disable = None if progress is None else not progress
    with tqdm(total=len(samples), desc=desc, unit="sample", disable=disable, leave=False) as bar:
        for start in range(0, len(samples), batch_size):
            batch = samples[start : start + batch_size]
            out[start : start + len(batch)] = estimator.estimate([s.views for s in batch])
            bar.update(len(batch))
    return out


# A report's headline metrics (``summarise``): name -> its path in the report.
REPORT_METRICS: Final[dict[str, tuple[str, ...]]] = {
    "x MAE": ("position_mae_mm", "x"), "y MAE": ("position_mae_mm", "y"), "yaw MAE": ("yaw_mae_deg",),
    "MSE orientation": ("paper_mse", "orientation"), "MSE position": ("paper_mse", "position"), "MSE global": ("paper_mse", "global"),
}


def relative_change(before: Mapping, after: Mapping, metrics: Sequence[str] = tuple(REPORT_METRICS)) -> dict[str, float]:
    """The change (%) of ``after`` over ``before`` in each of ``metrics`` (keys of ``REPORT_METRICS``),
    both reports as ``summarise`` gives them: e.g. an int8 model against its fp32 twin."""

    def get(report: Mapping, path: tuple[str, ...]) -> float:
        for key in path:
            report = report[key]
        return float(report)  # type: ignore[arg-type]

    return {m: 100 * (get(after, REPORT_METRICS[m]) - get(before, REPORT_METRICS[m])) / get(before, REPORT_METRICS[m]) for m in metrics}


def score(samples: Sequence[Sample], predictions: Mapping[str, NDArray], truth_offset_m: float) -> dict[str, dict]:
    """Reports (``summarise``) of several estimators' torso predictions, keyed by estimator."""
    truth = np.array([s.truth for s in samples], dtype=np.float64).reshape(-1, 3)
    cameras = camera_counts(samples)
    return {name: summarise(pred, truth, cameras, truth_offset_m) for name, pred in predictions.items()}


def evaluate(
    samples: Sequence[Sample],
    estimators: Mapping[str, Estimator],
    truth_offset_m: float,
    batch_size: int = 64,
    progress: bool | None = False,
) -> dict[str, dict]:
    """Run each estimator on the samples and score it against their ground truth.

    Args:
        samples: e.g. ``models.data.wtf.load_wtf(path, site=site)``.
        estimators: name -> estimator.
        truth_offset_m: how far in front of the torso centre the truth is measured
            (``models.data.wtf.TRUTH_OFFSET_M`` for WheresTheFellow; 0 for truth at the torso).

    Returns:
        name -> report, see ``summarise``.
    """
    predictions = {name: predict(samples, est, batch_size, name, progress) for name, est in estimators.items()}
    return score(samples, predictions, truth_offset_m)


# --- reporting ----------------------------------------------------------------------------------

_METRIC_KEYS: Final[tuple[str, ...]] = ("samples", "position_mae_mm", "yaw_mae_deg", "paper_mse")


def json_report(reports: Mapping[str, dict], models: Sequence[str], baseline: str, truth_offset_m: float) -> dict:
    """The ``--json-out`` document: the first model's report at the top level.

    Shape: ``{samples, position_mae_mm, yaw_mae_deg, paper_mse, failed, by_cameras,
    baseline: {samples, position_mae_mm, yaw_mae_deg, paper_mse, failed},
    baseline_by_cameras, models: {name: report} (every model, the first included),
    model: name, truth_offset_m}``.
    """
    if not models:
        raise ValueError("json_report needs at least one model")
    first, base = reports[models[0]], reports[baseline]
    doc = {k: first[k] for k in (*_METRIC_KEYS, "failed", "by_cameras")}
    doc["baseline"] = {k: base[k] for k in (*_METRIC_KEYS, "failed")}
    doc["baseline_by_cameras"] = base["by_cameras"]
    doc["model"] = models[0]
    doc["models"] = {m: reports[m] for m in models}
    doc["truth_offset_m"] = truth_offset_m
    return doc


def _fmt(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


# (label, getter, decimals) of each table row.
_ROWS: Final[tuple[tuple[str, Any, int], ...]] = (
    ("x MAE (mm)", lambda b: b["position_mae_mm"]["x"], 1),
    ("y MAE (mm)", lambda b: b["position_mae_mm"]["y"], 1),
    ("yaw MAE (deg)", lambda b: b["yaw_mae_deg"], 2),
    ("paper MSE position", lambda b: b["paper_mse"]["position"], 5),
    ("paper MSE orientation", lambda b: b["paper_mse"]["orientation"], 5),
    ("paper MSE global", lambda b: b["paper_mse"]["global"], 5),
)


def format_table(reports: Mapping[str, dict], truth_offset_m: float) -> str:
    """A side-by-side table: a row per metric and estimator, a column per camera count."""
    names = list(reports)
    any_report = reports[names[0]]
    groups = [("all", None)] + [(f"{k} cam" + ("s" if k != "1" else ""), k) for k in CAMERA_COUNTS]

    def block(report: dict, key: str | None) -> dict:
        return report if key is None else report["by_cameras"][key]

    heads = [f"{label} (n={block(any_report, key)['samples']})" for label, key in groups]
    name_w = max(len(n) for n in names)
    label_w = max(len(r[0]) for r in _ROWS)
    col_w = max(12, *(len(h) for h in heads))
    lines = [
        f"predictions moved {truth_offset_m:g} m forward (torso centre -> the dataset's chest tracker) before scoring; "
        "paper MSE in the original code's units (x/4000 mm, 0.7 sin/cos), height error 0",
        f"{'metric':<{label_w}}  {'estimator':<{name_w}}  " + "  ".join(f"{h:>{col_w}}" for h in heads),
    ]
    for label, get, digits in _ROWS:
        for i, name in enumerate(names):
            cells = [_fmt(get(block(reports[name], key)), digits) for _, key in groups]
            lines.append(f"{label if i == 0 else '':<{label_w}}  {name:<{name_w}}  " + "  ".join(f"{c:>{col_w}}" for c in cells))
    for name in names:
        r = reports[name]
        if r["failed"]:
            lines.append(f"{name}: {r['failed']} sample(s) without a finite prediction, left out of its errors")
    return "\n".join(lines)


def write_predictions_csv(path: str | Path, samples: Sequence[Sample], pred: NDArray, truth_offset_m: float) -> Path:
    """Write one estimator's predictions in the dataset's own frame, units and angle convention.

    The torso poses are moved to the chest tracker's point (``torso_to_truth``) and converted
    with ``to_dataset_frame``: columns ``index,timestamp_ms,x_mm,z_mm,angle_rad``, one row per
    sample in file order; ``timestamp_ms`` is the sample's first view's; a failed prediction is
    written as ``nan``.

    Args:
        path: the .csv file.
        samples: the samples, in file order.
        pred: (N, 3) torso poses (x, y, yaw), REP-103.
        truth_offset_m: how far in front of the torso the dataset's truth is.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    if len(pred) != len(samples):
        raise ValueError(f"write_predictions_csv: {len(pred)} predictions for {len(samples)} samples")
    rows = dataset_frame(torso_to_truth(pred, truth_offset_m))  # (N, 3) X mm, Z mm, angle
    path = Path(path)
    with path.open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(PREDICTIONS_HEADER)
        for i, (s, (x, z, a)) in enumerate(zip(samples, rows)):
            w.writerow([i, s.stamp_ns // 1_000_000, f"{x:.3f}", f"{z:.3f}", f"{a:.6f}"])
    return path
