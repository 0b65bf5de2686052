"""A site's floor plan to draw the floor polygon by hand (``superbody site floor-plot``).

Top view, REP-103 metres: the cameras at their optical centres with their viewing direction and
height, each camera's view on the floor (the outline of where it sees a standing person's torso,
``edge.floor.seen_by``), shading by how many cameras see each place, the site's floor polygon
with its corners' coordinates, the obstacles, and a labelled grid to read new corners off. The
installer writes them, counter-clockwise, into the site's ``[floor] polygon``.

Needs matplotlib (the ``dev`` or ``train`` extra); imported only when a plot is drawn.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from superbody.edge.floor import detectable_range_m, seen_by
from superbody.edge.site import Site

__all__ = ["plot_floor", "plot_extent", "MAX_MARGIN_M"]

MAX_MARGIN_M = 3.0  # how far past the cameras and the floor the plot may reach to show what the cameras see
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


def plot_extent(site: Site, cell_m: float = 0.25) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1): the cameras, the floor and where two cameras (one, for a single camera)
    see a person, within ``MAX_MARGIN_M`` of the cameras and the floor, with a 1 m margin."""
    pts = np.vstack([np.asarray(site.floor), np.array([c.t[:2] for c in site.cameras])])
    lo, hi = pts.min(0), pts.max(0)
    reach = min(MAX_MARGIN_M, max(detectable_range_m(c) for c in site.cameras))
    gx, gy = np.meshgrid(np.arange(lo[0] - reach, hi[0] + reach, cell_m), np.arange(lo[1] - reach, hi[1] + reach, cell_m))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    views = np.sum([seen_by(c, xy) for c in site.cameras], axis=0)
    seen = xy[views >= min(2, len(site.cameras))]
    if len(seen):
        lo, hi = np.minimum(lo, seen.min(0)), np.maximum(hi, seen.max(0))
    return float(lo[0] - 1.0), float(lo[1] - 1.0), float(hi[0] + 1.0), float(hi[1] + 1.0)


def _step(span: float) -> float:
    """A grid step that gives 8-20 lines over ``span`` metres."""
    for s in (0.25, 0.5, 1.0, 2.0, 5.0, 10.0):
        if span / s <= 20:
            return s
    return 20.0


def plot_floor(site: Site, out: Path, cell_m: float = 0.05, dpi: int = 110) -> Path:
    """Draw the site's floor plan into ``out`` (PNG; see the module docstring).

    Raises:
        ImportError: matplotlib is not installed.
    """
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Polygon, Rectangle

    x0, y0, x1, y1 = plot_extent(site)
    cell = max(cell_m, max(x1 - x0, y1 - y0) / 600)  # at most ~600 x 600 points per camera
    xs, ys = np.arange(x0, x1 + cell, cell), np.arange(y0, y1 + cell, cell)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    seen = np.array([seen_by(c, xy) for c in site.cameras]).reshape(len(site.cameras), *gx.shape)  # (C, ny, nx)
    views = seen.sum(0)

    span = max(x1 - x0, y1 - y0)
    height = float(np.clip(9.0 * (y1 - y0) / max(x1 - x0, 1e-6) + 1.5, 6.0, 16.0))  # inches: the plot's aspect, a legend below
    fig, ax = plt.subplots(figsize=(10.5, height), dpi=dpi)
    top = max(2, int(views.max()))
    cmap = ListedColormap(plt.get_cmap("Greys")(np.linspace(0.12, 0.7, top)))  # 1 camera: light grey, none: white
    norm = BoundaryNorm(np.arange(0.5, top + 1.5), top)
    shade = ax.pcolormesh(gx, gy, np.ma.masked_equal(views, 0), cmap=cmap, norm=norm, shading="nearest", alpha=0.6)
    fig.colorbar(shade, ax=ax, fraction=0.035, pad=0.02, ticks=np.arange(1, top + 1), label="cameras that see a standing person's torso")
    for i, cam in enumerate(site.cameras):
        colour = _COLOURS[i % len(_COLOURS)]
        if seen[i].any():
            ax.contour(gx, gy, seen[i].astype(float), levels=[0.5], colors=[colour], linewidths=1.2)
        x, y = cam.t[0], cam.t[1]
        d = cam.R[:2, 2]
        ax.plot(x, y, "s", ms=9, color=colour, label=f"camera {cam.id}: {cam.t[2]:.2f} m up (its view: the outline)")
        if np.linalg.norm(d) > 0.05:
            d = d / np.linalg.norm(d) * 0.06 * span
            ax.annotate("", xy=(x + d[0], y + d[1]), xytext=(x, y), arrowprops=dict(arrowstyle="->", color=colour, lw=1.6))
        ax.annotate(f"{cam.id}", (x, y), xytext=(6, 6), textcoords="offset points", fontsize=9, color=colour, weight="bold")
    ax.add_patch(Polygon(site.floor, closed=True, fill=False, edgecolor="black", lw=1.8, ls="--", label="floor polygon (site file)"))
    for k, (fx, fy) in enumerate(site.floor):
        ax.annotate(f"{k}: ({fx:.2f}, {fy:.2f})", (fx, fy), fontsize=7, xytext=(3, -9), textcoords="offset points")
    for j, ob in enumerate(site.obstacles):
        ax.add_patch(Rectangle(ob.min[:2], ob.max[0] - ob.min[0], ob.max[1] - ob.min[1], facecolor="#9aa3ad", alpha=0.7,
                               edgecolor="#5b6573", label="obstacle" if j == 0 else None))
    step = _step(span)
    ax.set_xticks(np.arange(math.floor(x0 / step) * step, x1 + step, step))
    ax.set_yticks(np.arange(math.floor(y0 / step) * step, y1 + step, step))
    ax.minorticks_on()
    ax.grid(True, which="major", lw=0.6, alpha=0.6)
    ax.grid(True, which="minor", lw=0.3, alpha=0.3)
    ax.tick_params(axis="x", labelrotation=90, labelsize=8)
    ax.tick_params(axis="y", labelsize=8)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel(f"x (m), grid every {step:g} m")
    ax.set_ylabel("y (m)")
    ax.set_title(f"site {site.name}: {len(site.cameras)} cameras, top view (REP-103: x right, y up the page)\n"
                 "read the corners of the floor people can walk off the grid and write them, counter-clockwise, as [floor] polygon",
                 fontsize=9)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.08), fontsize=8, ncol=2, frameon=False)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
