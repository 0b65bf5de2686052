"""Evaluation plots like the paper's figures: predictions against the truth over time, error bars.

matplotlib is imported inside the functions (object API on the Agg canvas, no pyplot state), so
importing this module, and the host, never needs it.

All poses here are REP-103 (x, y, yaw). Predictions are torso poses and are moved to the
dataset's chest-tracker point (``models.data.wtf.torso_to_truth``) by ``truth_offset_m`` first, as in
``models.evaluation.evaluate``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.models.data.samples import Sample
from superbody.models.data.wtf import torso_to_truth
from superbody.models.evaluation.evaluate import CAMERA_COUNTS, camera_counts, sample_errors

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["plot_time_series", "plot_error_bars", "plot_error_bars_by_cameras", "write_plots", "PLOT_FILES"]

# The files ``write_plots`` writes, in order.
PLOT_FILES: Final[tuple[str, ...]] = ("timeseries.png", "errors.png", "errors_by_cameras.png")
_METRICS: Final[tuple[tuple[str, str], ...]] = (("x MAE", "mm"), ("y MAE", "mm"), ("yaw MAE", "deg"))
_DPI: Final[int] = 120


def _figure(width: float, height: float, rows: int, cols: int, **kw) -> tuple[Figure, NDArray]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.asarray(fig.subplots(rows, cols, squeeze=False, **kw))
    return fig, axes


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=_DPI)
    return path


def _mean_sem(err: NDArray) -> tuple[NDArray, NDArray]:
    """(n, 3) errors -> mean (3,) and standard error of the mean (3,); NaN for n < 1 / n < 2."""
    n = len(err)
    if n == 0:
        return np.full(3, np.nan), np.full(3, np.nan)
    sem = err.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(3, np.nan)
    return err.mean(axis=0), sem


def plot_time_series(path: str | Path, times_s: NDArray, truth: NDArray, preds: Mapping[str, NDArray]) -> Path:
    """Three stacked panels, x, y and yaw against time: the truth in black, a line per estimator.

    Args:
        path: the PNG to write.
        times_s: (N,) seconds since the first sample.
        truth: (N, 3) ground truth (x, y, yaw).
        preds: name -> (N, 3) predictions at the truth's point; NaN rows are gaps.
    """
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    fig, axes = _figure(11, 8, 3, 1, sharex=True)
    # Yaw is unwrapped along the truth, and each prediction drawn within 180 deg of it, so the
    # lines do not jump at +-180.
    yaw_truth = np.unwrap(truth[:, 2])
    series = {"ground truth": np.column_stack([truth[:, :2], yaw_truth])}
    for name, p in preds.items():
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        series[name] = np.column_stack([p[:, :2], yaw_truth + np.reshape(wrap_angle(p[:, 2] - truth[:, 2]), -1)])
    labels = ("x (m)", "y (m)", "yaw (deg)")
    for k, ax in enumerate(axes[:, 0]):
        for i, (name, s) in enumerate(series.items()):
            v = np.degrees(s[:, k]) if k == 2 else s[:, k]
            if name == "ground truth":
                ax.plot(times_s, v, color="black", lw=2.0, label=name, zorder=3)
            else:
                ax.plot(times_s, v, color=f"C{i - 1}", lw=1.1, marker=".", ms=3, label=name, alpha=0.85)
        ax.set_ylabel(labels[k])
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper left", ncols=len(series), fontsize="small")
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle("Predictions (moved to the chest tracker's point) and ground truth, REP-103")
    return _save(fig, Path(path))


def _bars(ax, groups: Sequence[str], values: NDArray, errors: NDArray, names: Sequence[str], unit: str) -> None:
    """Grouped bars: values, errors (G, E) for G groups and E estimators."""
    G, E = values.shape
    width = 0.8 / E
    x = np.arange(G)
    for e, name in enumerate(names):
        pos = x - 0.4 + width * (e + 0.5)
        err = np.nan_to_num(errors[:, e])
        ax.bar(pos, values[:, e], width, yerr=err, capsize=3, color=f"C{e}", label=name)
        for px, v, dv in zip(pos, values[:, e], err):
            if not np.isnan(v):  # the value just above its error bar
                ax.annotate(f"{v:.0f}" if unit == "mm" else f"{v:.1f}", (px, v + dv), xytext=(0, 2),
                            textcoords="offset points", ha="center", va="bottom", fontsize="x-small")
    ax.set_xticks(x, groups)
    ax.set_ylabel(unit)
    ax.grid(True, axis="y", alpha=0.3)
    ax.margins(y=0.15)


def plot_error_bars(path: str | Path, errors: Mapping[str, NDArray]) -> Path:
    """Bars of x and y MAE (mm) and yaw MAE (deg) per estimator, with standard-error bars.

    Args:
        path: the PNG to write.
        errors: name -> (n, 3) per-sample absolute errors (``models.evaluation.evaluate.sample_errors``),
            failed samples left out.
    """
    names = list(errors)
    stats = [_mean_sem(np.asarray(errors[n]).reshape(-1, 3)) for n in names]
    mean = np.array([m for m, _ in stats])  # (E, 3)
    sem = np.array([s for _, s in stats])  # (E, 3)
    fig, axes = _figure(10, 4.5, 1, 2, width_ratios=(2, 1))
    _bars(axes[0, 0], ["x", "y"], mean[:, :2].T, sem[:, :2].T, names, "mm")
    axes[0, 0].set_title("position MAE")
    _bars(axes[0, 1], ["yaw"], mean[:, 2:].T, sem[:, 2:].T, names, "deg")
    axes[0, 1].set_title("yaw MAE")
    axes[0, 0].legend(fontsize="small")
    n = ", ".join(f"{name}: n={len(errors[name])}" for name in names)
    fig.suptitle(f"Mean absolute error +- standard error ({n})")
    return _save(fig, Path(path))


def plot_error_bars_by_cameras(path: str | Path, errors: Mapping[str, NDArray], cameras: Mapping[str, NDArray]) -> Path:
    """Bars of x, y and yaw MAE by number of cameras, per estimator, with standard-error bars.

    Args:
        path: the PNG to write.
        errors: name -> (n, 3) per-sample absolute errors.
        cameras: name -> (n,) cameras that saw each of those samples.
    """
    names = list(errors)
    mean = np.full((len(CAMERA_COUNTS), len(names), 3), np.nan)  # (G, E, 3)
    sem = np.full_like(mean, np.nan)
    counts = np.zeros(len(CAMERA_COUNTS), dtype=int)
    for g, k in enumerate(CAMERA_COUNTS):
        for e, name in enumerate(names):
            sel = np.asarray(cameras[name]).reshape(-1) == int(k)
            mean[g, e], sem[g, e] = _mean_sem(np.asarray(errors[name]).reshape(-1, 3)[sel])
            counts[g] = max(counts[g], int(sel.sum()))
    groups = [f"{k} camera{'s' if k != '1' else ''}\n(n={c})" for k, c in zip(CAMERA_COUNTS, counts)]
    fig, axes = _figure(13, 4.5, 1, 3)
    for m, (label, unit) in enumerate(_METRICS):
        _bars(axes[0, m], groups, mean[:, :, m], sem[:, :, m], names, unit)
        axes[0, m].set_title(label)
    axes[0, 0].legend(fontsize="small")
    fig.suptitle("Mean absolute error +- standard error, by number of cameras that saw the person")
    return _save(fig, Path(path))


def write_plots(
    out_dir: str | Path, samples: Sequence[Sample], predictions: Mapping[str, NDArray], truth_offset_m: float
) -> list[Path]:
    """Write the evaluation plots (``PLOT_FILES``) for several estimators.

    Args:
        out_dir: the folder (created if missing).
        samples: the samples, in time order.
        predictions: name -> (N, 3) torso poses (x, y, yaw).
        truth_offset_m: how far in front of the torso the dataset's truth is.

    Returns:
        The paths written.
    """
    out_dir = Path(out_dir)
    truth = np.array([s.truth for s in samples], dtype=np.float64).reshape(-1, 3)
    stamps = np.array([s.stamp_ns for s in samples], dtype=np.int64)
    times_s = (stamps - stamps.min()) / 1e9 if len(stamps) else np.zeros(0)
    cams = camera_counts(samples)
    points = {name: torso_to_truth(p, truth_offset_m) for name, p in predictions.items()}
    ok = {name: np.isfinite(p).all(axis=1) for name, p in points.items()}
    errors = {name: sample_errors(p[ok[name]], truth[ok[name]]) for name, p in points.items()}
    return [
        plot_time_series(out_dir / PLOT_FILES[0], times_s, truth, points),
        plot_error_bars(out_dir / PLOT_FILES[1], errors),
        plot_error_bars_by_cameras(out_dir / PLOT_FILES[2], errors, {name: cams[ok[name]] for name in points}),
    ]
