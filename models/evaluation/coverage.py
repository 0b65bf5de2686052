"""Where a model was trained and how good it is across the floor: the coverage maps.

    superbody coverage --site deploy/sites/wtf-apartment.toml --model models/wtf-apartment.int8.onnx \\
        --out build/models/coverage [--dataset dev.json] [--json-out F]

Writes two PNGs (matplotlib):

- ``coverage.png``: the density of training positions (the first ``--train-samples`` of the
  training run's simulated set, same seed), the floor polygon, how many cameras see each point,
  the cameras, and (with ``--dataset``) the path the real recording walked;
- ``error-by-cell.png``: the model's mean position and yaw error per 0.5 m floor cell, on a fresh
  simulated test set (another seed), as the host would run it (``host.estimation.build_estimator``).

and, with ``--json-out``, the per-cell and per-camera-count figures.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.floor import point_in_polygon, views_at
from superbody.edge.site import Site

__all__ = ["cell_errors", "coverage_figures"]

CELL_M = 0.5


def cell_errors(site: Site, truth: NDArray, pred: NDArray, cell_m: float = CELL_M, min_samples: int = 5) -> dict:
    """Mean position error (mm) and yaw error (deg) per floor cell.

    Args:
        truth, pred: (N, 3) poses.

    Returns:
        ``{"x_edges", "y_edges", "position_mm" (ny, nx), "yaw_deg" (ny, nx), "count" (ny, nx)}``;
        cells with fewer than ``min_samples`` samples are NaN.
    """
    x0, y0, x1, y1 = site.floor_bounds
    xe = np.arange(np.floor(x0 / cell_m) * cell_m, x1 + cell_m, cell_m)
    ye = np.arange(np.floor(y0 / cell_m) * cell_m, y1 + cell_m, cell_m)
    pos = np.linalg.norm(pred[:, :2] - truth[:, :2], axis=1) * 1000  # (N,)
    yaw = np.degrees(np.abs(wrap_angle(pred[:, 2] - truth[:, 2])))
    ok = np.isfinite(pos) & np.isfinite(yaw)
    count, _, _ = np.histogram2d(truth[ok, 1], truth[ok, 0], bins=[ye, xe])
    psum, _, _ = np.histogram2d(truth[ok, 1], truth[ok, 0], bins=[ye, xe], weights=pos[ok])
    ysum, _, _ = np.histogram2d(truth[ok, 1], truth[ok, 0], bins=[ye, xe], weights=yaw[ok])
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(count >= min_samples, psum / count, np.nan)
        y = np.where(count >= min_samples, ysum / count, np.nan)
    return {"x_edges": xe, "y_edges": ye, "position_mm": p, "yaw_deg": y, "count": count}


def _draw_site(ax, site: Site) -> None:
    poly = np.asarray(site.floor + (site.floor[0],))
    ax.plot(poly[:, 0], poly[:, 1], "k-", lw=1.2, label="floor")
    for cam in site.cameras:
        d = cam.R[:2, 2] / max(float(np.linalg.norm(cam.R[:2, 2])), 1e-9)
        ax.plot(*cam.t[:2], "rv", ms=8)
        ax.annotate(f"cam {cam.id}", cam.t[:2], textcoords="offset points", xytext=(4, 4), fontsize=8, color="r")
        ax.arrow(cam.t[0], cam.t[1], 0.6 * d[0], 0.6 * d[1], color="r", width=0.02)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def coverage_figures(site: Site, train_truth: NDArray, test_truth: NDArray, test_pred: NDArray, out: Path,
                     real_xy: NDArray | None = None) -> tuple[list[Path], dict]:
    """Write coverage.png and error-by-cell.png; return their paths and the cell figures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    x0, y0, x1, y1 = site.floor_bounds
    fig, axes = plt.subplots(1, 2, figsize=(12, 6))
    ax = axes[0]
    h = ax.hist2d(train_truth[:, 0], train_truth[:, 1], bins=[np.arange(x0, x1 + 0.1, 0.1), np.arange(y0, y1 + 0.1, 0.1)], cmap="Blues")
    fig.colorbar(h[3], ax=ax, label="training samples per 10 cm cell")
    _draw_site(ax, site)
    if real_xy is not None:
        ax.plot(real_xy[:, 0], real_xy[:, 1], "-", color="orange", lw=1, label="dev.json path (real)")
    ax.set_title(f"training positions ({len(train_truth)} shown)")
    ax.legend(loc="lower right", fontsize=8)
    ax = axes[1]
    gx, gy = np.meshgrid(np.arange(x0, x1, 0.05), np.arange(y0, y1, 0.05))
    g = np.column_stack([gx.ravel(), gy.ravel()])
    n = views_at(site.cameras, g).astype(float)
    n[~point_in_polygon(g, site.floor)] = np.nan
    m = ax.pcolormesh(gx, gy, n.reshape(gx.shape), cmap="viridis", vmin=0, vmax=max(3, len(site.cameras)), shading="auto")
    fig.colorbar(m, ax=ax, label="cameras that see a person here")
    _draw_site(ax, site)
    ax.set_title("camera count over the floor")
    fig.tight_layout()
    p1 = out / "coverage.png"
    fig.savefig(p1, dpi=90)
    plt.close(fig)

    cells = cell_errors(site, test_truth, test_pred)
    fig, axes = plt.subplots(1, 2, figsize=(12, 6))
    for ax, key, label, vmax in ((axes[0], "position_mm", "mean position error (mm)", 400), (axes[1], "yaw_deg", "mean yaw error (deg)", 40)):
        m = ax.pcolormesh(cells["x_edges"], cells["y_edges"], cells[key], cmap="magma_r", vmin=0, vmax=vmax)
        fig.colorbar(m, ax=ax, label=label)
        _draw_site(ax, site)
        ax.set_title(f"{label} per {CELL_M} m cell, simulated test set")
    fig.tight_layout()
    p2 = out / "error-by-cell.png"
    fig.savefig(p2, dpi=90)
    plt.close(fig)
    return [p1, p2], cells


