"""Draw a site's floor plan with its cameras and a few simulated people: the README's picture.

    python scripts/floor_plot.py --out docs/img/floor.png [--site wtf-apartment] [--seed 3]
        [--people 3] [--time 40] [--trail 6]

The floor polygon and obstacles come from the site file; each camera is drawn at its optical
centre with its horizontal field of view (the rays through the left and right ends of the
image's principal row, projected onto the floor) and its viewing direction. The people are the
simulator's (``superbody.edge.sim.World``, the same people the demo and training use): each is an
arrow along their torso yaw at ``--time`` seconds after the scene's start, with the path they
walked over the ``--trail`` seconds before. World frame REP-103: metres, yaw counter-clockwise
from +x. Needs matplotlib (the ``dev`` extra).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Polygon, Rectangle, Wedge  # noqa: E402

from superbody.edge.camera import Camera, pixel_to_ray  # noqa: E402
from superbody.edge.resources import DEFAULT_SITE, site_path  # noqa: E402
from superbody.edge.sim import World  # noqa: E402
from superbody.edge.site import Site, load_site  # noqa: E402

__all__ = ["camera_view", "main"]

_CAMERA_COLOUR = "#1f3b73"
_PEOPLE_COLOURS = ("#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2")
_FOV_RADIUS_M = 1.4  # how far the drawn field-of-view wedge reaches


def camera_view(cam: Camera) -> tuple[float, float, float]:
    """A camera's horizontal view on the floor plan.

    Args:
        cam: the camera.

    Returns:
        ``(heading, left, right)`` in degrees counter-clockwise from +x: the azimuth of the
        optical axis and of the rays through the two ends of the image's principal row.
    """
    uv = np.array([[cam.cx, cam.cy], [0.0, cam.cy], [cam.width - 1.0, cam.cy]])  # (3, 2) centre, left, right
    _, d = pixel_to_ray(uv, cam)  # (3, 3) unit world rays
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))  # (3,)
    return float(az[0]), float(az[1]), float(az[2])


def _wedge_angles(heading: float, a: float, b: float) -> tuple[float, float]:
    """The wedge from ``a`` to ``b`` (degrees) that contains ``heading``, counter-clockwise."""
    lo, hi = sorted((a, b))
    if not lo <= heading <= hi:  # the view straddles +-180 deg
        lo, hi = hi, lo + 360.0
    return lo, hi


def main(site: Site, out: Path, seed: int, people: int, time_s: float, trail_s: float) -> Path:
    """Draw ``site`` with ``people`` simulated people (scene ``seed``) at ``time_s`` into ``out`` (PNG)."""
    world = World(site, num_people=people, seed=seed, epoch_s=0.0)
    fig, ax = plt.subplots(figsize=(8.6, 6.6), dpi=100)

    ax.add_patch(Polygon(site.floor, closed=True, facecolor="#eef1f5", edgecolor="#5b6573", lw=1.5,
                         label="floor the cameras see"))
    for i, ob in enumerate(site.obstacles):
        ax.add_patch(Rectangle(ob.min[:2], ob.max[0] - ob.min[0], ob.max[1] - ob.min[1], facecolor="#9aa3ad",
                               edgecolor="#5b6573", label="obstacle" if i == 0 else None))

    for i, cam in enumerate(site.cameras):
        x, y = cam.t[0], cam.t[1]
        heading, left, right = camera_view(cam)
        lo, hi = _wedge_angles(heading, left, right)
        ax.add_patch(Wedge((x, y), _FOV_RADIUS_M, lo, hi, facecolor=_CAMERA_COLOUR, alpha=0.12, lw=0,
                           label="camera's horizontal field of view" if i == 0 else None))
        h = math.radians(heading)
        ax.annotate("", xy=(x + 0.8 * math.cos(h), y + 0.8 * math.sin(h)), xytext=(x, y),
                    arrowprops=dict(arrowstyle="->", color=_CAMERA_COLOUR, lw=1.3))
        ax.plot(x, y, "s", ms=9, color=_CAMERA_COLOUR, label="camera (at its optical centre)" if i == 0 else None)
        ax.annotate(f"cam {cam.id}\n{cam.t[2]:.1f} m up", (x, y), xytext=(-26 * math.cos(h), -26 * math.sin(h)),
                    textcoords="offset points", ha="center", va="center", fontsize=8, color=_CAMERA_COLOUR)

    ts = np.linspace(time_s - trail_s, time_s, max(2, int(trail_s * 10) + 1))  # (T,) 10 Hz trail
    for k in range(people):
        colour = _PEOPLE_COLOURS[k % len(_PEOPLE_COLOURS)]
        path = np.array([(s.x, s.y) for s in (world.people[k].state(float(t)) for t in ts)])  # (T, 2)
        ax.plot(path[:, 0], path[:, 1], "-", color=colour, lw=1, alpha=0.5)
        now = world.people[k].state(time_s)
        ax.add_patch(plt.Circle((now.x, now.y), 0.2, facecolor=colour, alpha=0.25, edgecolor=colour))
        ax.arrow(now.x, now.y, 0.45 * math.cos(now.yaw), 0.45 * math.sin(now.yaw), width=0.035, head_width=0.16,
                 head_length=0.14, length_includes_head=True, color=colour,
                 label=f"person {k + 1}: yaw {math.degrees(now.yaw):+.0f} deg")

    x0, y0, x1, y1 = _limits(site)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"site {site.name}: {len(site.cameras)} cameras, {people} simulated people\n"
                 f"(seed {seed}, t = {time_s:g} s; arrows: torso yaw, lines: last {trail_s:g} s)", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def _limits(site: Site) -> tuple[float, float, float, float]:
    """The plot's extent: the floor and every camera, with a margin, in metres."""
    pts = np.vstack([np.asarray(site.floor), np.array([c.t[:2] for c in site.cameras])])  # (P, 2)
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0  # room for the cameras' labels
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write, e.g. docs/img/floor.png")
    parser.add_argument("--seed", type=int, default=3, help="the simulated scene's seed (default 3)")
    parser.add_argument("--site", default=DEFAULT_SITE, help=f"a shipped site's name or a site file (default {DEFAULT_SITE})")
    parser.add_argument("--people", type=int, default=3, help="simulated people, 1-6 (default 3)")
    parser.add_argument("--time", type=float, default=40.0, help="seconds after the scene's start (default 40)")
    parser.add_argument("--trail", type=float, default=6.0, help="seconds of path drawn behind each person (default 6)")
    args = parser.parse_args()
    if not 1 <= args.people <= len(_PEOPLE_COLOURS):
        parser.error(f"--people must be in [1, {len(_PEOPLE_COLOURS)}], got {args.people}")
    if not args.trail >= 0:
        parser.error(f"--trail must be >= 0 seconds, got {args.trail}")
    site_file = Path(args.site) if args.site.endswith(".toml") else site_path(args.site)
    print(main(load_site(site_file), args.out, args.seed, args.people, args.time, args.trail))
