"""People seen by a site's cameras, straight from the simulator, for the calibration tests:
``Instant``s grouped by the simulator's own person index (no tracker: fast), and the knocked
sites of ``benchmarks.people_calibration``."""

from __future__ import annotations

import math

import numpy as np

from superbody.edge.camera import project
from superbody.edge.sim import NoiseModel, World, render_views, skeleton
from superbody.edge.site import Site
from superbody.host.calibration.residuals import Instant

S = 1_000_000_000
T0 = 1_700_000_000 * S


def exact_instants(site: Site, n: int, seed: int = 0) -> list[Instant]:
    """``n`` people standing still at random places of the floor, every joint every camera
    sees (in the image, in front) exactly where it projects, score 0.9."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = site.floor_bounds
    out = []
    for k in range(n):
        x, y = rng.uniform(x0 + 0.5, x1 - 0.5), rng.uniform(y0 + 0.5, y1 - 0.5)
        joints = skeleton(x, y, rng.uniform(-math.pi, math.pi), rng.uniform(0, 2 * math.pi), rng.uniform(0, 1))
        cams, kps = [], []
        for cam in site.cameras:
            uv, z = project(joints, cam)
            inside = (z > 0.2) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
            if inside.sum() < 3:
                continue
            kp = np.full((17, 3), np.nan)
            kp[inside, :2], kp[inside, 2] = uv[inside], 0.9
            cams.append(cam.id)
            kps.append(kp)
        if len(cams) >= 2:
            out.append(Instant(T0 + k * S, tuple(cams), np.stack(kps), np.zeros((len(cams), 3)), k))
    return out


def noisy_instants(site: Site, people: int, seconds: float, seed: int = 1, fps: float = 15.0,
                   noise: NoiseModel | None = None) -> list[Instant]:
    """``people`` walking for ``seconds``, each camera at ``fps`` staggered within the frame
    period, the detector's noise model; one instant per person per frame period from the
    cameras that reported them, moved to its time by the person's true floor velocity."""
    noise = noise or NoiseModel(spurious_prob=0.0)
    world = World(site, people, seed=seed, period_s=max(60.0, seconds + 10.0), epoch_s=T0 / S)
    looks = [p.appearance for p in world.people]
    n = len(site.cameras)
    out = []
    for f in range(int(seconds * fps)):
        t_ref = T0 + round(f * S / fps)
        views: dict[int, list[tuple[str, np.ndarray, int]]] = {}
        for i, cam in enumerate(site.cameras):
            t = t_ref + round(i * S / fps / n)
            rng = np.random.default_rng([seed, i, f])
            for who, view in render_views(world.states(t / S), looks, cam, rng, noise, site, histograms=False):
                if who >= 0 and view.num_visible >= 3:
                    views.setdefault(who, []).append((cam.id, view.keypoints.astype(np.float64), t))
        for who, vs in views.items():
            if len(vs) < 2:
                continue
            stamps = np.array([t for _, _, t in vs])
            t_mid = int(stamps.mean())
            a, b = world.states(t_mid / S - 0.05)[who], world.states(t_mid / S + 0.05)[who]
            v = np.array([b.x - a.x, b.y - a.y, 0.0]) / 0.1
            out.append(Instant(t_mid, tuple(c for c, _, _ in vs), np.stack([k for _, k, _ in vs]),
                               ((stamps - t_mid) / S)[:, None] * v, who))
    return out
