"""How closely the simulator's detector output matches a real WheresTheFellow file.

``scripts/sim_vs_dataset.py`` prints the comparison; the tests keep it from drifting.
"""

from __future__ import annotations

import math

import numpy as np
from tqdm import tqdm

from superbody.edge import body
from superbody.edge.sim import NoiseModel, SimCamera, World
from superbody.edge.site import Site, load_site

__all__ = ["statistics", "simulate", "facing_rates", "view_buckets", "lr_disagreement", "path_floor", "FACING_BINS",
           "DISTANCE_BINS_M", "EDGE_PX"]

FACING_BINS = 8
DISTANCE_BINS_M = (2.0, 3.0, 4.0, 5.0)  # edges of the distance buckets: < 2, 2-3, 3-4, 4-5, >= 5 m
EDGE_PX = 8.0  # a view with a joint this close to the image border is cut off at an edge


def statistics(samples: list[dict]) -> dict:
    """samples: list of {camera id: (17, 3) keypoints} for one person."""
    views = [kp for s in samples for kp in s.values()]
    vis = np.array([~np.isnan(kp[:, 0]) for kp in views])  # (V, 17)
    jpv = vis.sum(1)
    scores = np.concatenate([kp[~np.isnan(kp[:, 0]), 2] for kp in views])
    vps = np.bincount([len(s) for s in samples], minlength=4)[1:4] / len(samples)
    return {
        "samples": len(samples),
        "views": len(views),
        "joints_per_view_mean": float(jpv.mean()),
        "joints_per_view_median": float(np.median(jpv)),
        "joints_per_view_buckets": {k: float(np.mean((jpv >= lo) & (jpv <= hi))) for k, (lo, hi) in
                                    {"1-4": (1, 4), "5-8": (5, 8), "9-12": (9, 12), "13-17": (13, 17)}.items()},
        "views_per_person": {str(k + 1): float(v) for k, v in enumerate(vps)},
        "joints_per_person_median": float(np.median([sum(int((~np.isnan(kp[:, 0])).sum()) for kp in s.values()) for s in samples])),
        "score_quantiles": {q: float(np.quantile(scores, float(q))) for q in ("0.05", "0.25", "0.5", "0.75", "0.95")},
        "score_is_1": float(np.mean(scores >= 0.999)),
        "joint_rate": {name: float(vis[:, i].mean()) for i, name in enumerate(body.KEYPOINTS)},
    }


def facing_rates(samples: list[dict], truths: list, site: Site, bins: int = FACING_BINS) -> tuple[np.ndarray, np.ndarray]:
    """How often each joint is reported by where the person faces relative to the camera.

    Args:
        samples: {camera id: (17, 3) keypoints} per instant, one person.
        truths: (x, y, yaw) of that person per instant.
        site: the cameras.
        bins: angle bins centred on -pi + (k + 0.5) 2 pi / bins (0: facing the camera).

    Returns:
        ``(rates, counts)``: (17, bins) share of views reporting each joint, and (bins,) views
        per bin; every view is counted twice, as itself and mirrored left-right, so the table is
        symmetric (``edge.sim.FACING_VISIBILITY`` is it divided by its mean per joint).
    """
    rel, vis = [], []
    for s, (x, y, yaw) in zip(samples, truths):
        for cam_id, kp in s.items():
            c = site.camera(cam_id).t
            rel.append(math.remainder(yaw - math.atan2(c[1] - y, c[0] - x), 2 * math.pi))
            vis.append(~np.isnan(kp[:, 0]))
    mirror = np.asarray(body.MIRROR)
    r = np.concatenate([np.asarray(rel), -np.asarray(rel)])
    v = np.concatenate([np.asarray(vis, float).reshape(-1, body.NUM_KEYPOINTS), np.asarray(vis, float).reshape(-1, body.NUM_KEYPOINTS)[:, mirror]])
    b = np.floor((r + math.pi) / (2 * math.pi / bins)).astype(int) % bins
    counts = np.bincount(b, minlength=bins)
    rates = np.array([v[b == k].mean(0) if counts[k] else np.full(body.NUM_KEYPOINTS, np.nan) for k in range(bins)]).T
    return rates, counts


def view_buckets(samples: list[dict], truths: list, site: Site) -> dict[str, dict[str, float]]:
    """Views by the camera's floor distance to the person: per bucket its share of the views, the
    mean joints per view, the share with at most 8 joints and the share cut off at an image edge
    (a joint within ``EDGE_PX`` of the border).

    Args:
        samples: {camera id: (17, 3) keypoints} per instant, one person.
        truths: (x, y, yaw) of that person per instant.
        site: the cameras (their image sizes too).
    """
    dist, joints, edge = [], [], []
    for s, (x, y, _yaw) in zip(samples, truths):
        for cam_id, kp in s.items():
            cam = site.camera(cam_id)
            seen = kp[~np.isnan(kp[:, 0]), :2]
            dist.append(math.hypot(cam.t[0] - x, cam.t[1] - y))
            joints.append(len(seen))
            near = (seen[:, 0] < EDGE_PX) | (seen[:, 0] > cam.width - 1 - EDGE_PX) | (seen[:, 1] < EDGE_PX) | (seen[:, 1] > cam.height - 1 - EDGE_PX)
            edge.append(bool(near.any()))
    d, j, e = np.asarray(dist), np.asarray(joints), np.asarray(edge)
    edges = (0.0, *DISTANCE_BINS_M, math.inf)
    out = {}
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (d >= lo) & (d < hi)
        name = f"< {hi:g} m" if lo == 0 else (f">= {lo:g} m" if math.isinf(hi) else f"{lo:g}-{hi:g} m")
        n = int(m.sum())
        out[name] = {"views": n, "share": n / max(len(d), 1), "joints_mean": float(j[m].mean()) if n else math.nan,
                     "few_joints": float((j[m] <= 8).mean()) if n else math.nan, "at_edge": float(e[m].mean()) if n else math.nan}
    return out


_TORSO = [body.LEFT_SHOULDER, body.RIGHT_SHOULDER, body.LEFT_HIP, body.RIGHT_HIP]
_TORSO_SWAPPED = [_TORSO.index(body.MIRROR[j]) for j in _TORSO]  # each torso joint's partner, as a row of _TORSO


def lr_disagreement(samples: list[dict], site: Site) -> tuple[int, int]:
    """How often two cameras disagree about which side of a person is the left: needs no truth.

    For every pair of views of one instant that both report the four torso joints, each joint's
    two rays should nearly meet. A pair disagrees when its rays meet at least twice as closely
    (summed over the four joints) with one view's left and right joints swapped: one of the two
    detections mislabelled the sides. The share grows with the detector's swap rate (about
    twice the rate, less the side-on views in which a swap changes little).

    Args:
        samples: {camera id: (17, 3) keypoints} per instant, one person.
        site: the cameras.

    Returns:
        ``(disagreeing, pairs)``.
    """
    from itertools import combinations

    from superbody.edge.camera import pixel_to_ray

    def gap(o1: np.ndarray, d1: np.ndarray, o2: np.ndarray, d2: np.ndarray) -> float:
        n = np.cross(d1, d2)  # (4, 3) common normals: the rays' closest distance along them
        return float((np.abs(n @ (o2 - o1)) / np.maximum(np.linalg.norm(n, axis=1), 1e-9)).sum())

    bad = total = 0
    for s in samples:
        rays = [pixel_to_ray(kp[_TORSO, :2].astype(np.float64), site.camera(cam_id))
                for cam_id, kp in s.items() if not np.isnan(kp[_TORSO, 0]).any()]  # (origin, (4, 3) directions) per view
        for (oa, da), (ob, db) in combinations(rays, 2):
            total += 1
            bad += gap(oa, da, ob, db[_TORSO_SWAPPED]) < 0.5 * gap(oa, da, ob, db)
    return bad, total


def path_floor(xy: np.ndarray, margin_m: float = 0.3) -> tuple[tuple[float, float], ...]:
    """The convex floor around a recording's path (N, 2), widened by ``margin_m``: where the
    simulated person walks to compare the detector with that recording's, like for like (what a
    detector reports depends on how far and where the person stands)."""
    import cv2

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    ring = margin_m * np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 16, endpoint=False)])
    pts = (xy[:, None, :] + ring[None]).reshape(-1, 2).astype(np.float32)
    hull = cv2.convexHull(pts)[:, 0, :].astype(np.float64)
    return tuple((round(float(x), 3), round(float(y), 3)) for x, y in hull)


def simulate(site_path: str, seconds: float, seed: int, rate_hz: float, noise: NoiseModel = NoiseModel(), progress: bool = True,
             truths: list | None = None, floor: tuple[tuple[float, float], ...] | None = None) -> list[dict]:
    """One simulated person seen by the site's cameras at ``rate_hz``; instants with no view are
    left out. ``truths``, if given, receives the person's (x, y, yaw) at each kept instant;
    ``floor``, if given, replaces the site's floor (``path_floor``)."""
    import dataclasses

    site = load_site(site_path)
    if floor is not None:
        site = dataclasses.replace(site, floor=floor)
    world = World(site, 1, seed)
    cams = [SimCamera(world, c, noise) for c in site.camera_ids]
    out = []
    t0 = 1.7e9
    for k in tqdm(range(int(seconds * rate_hz)), desc="simulating", unit="sample", leave=False, disable=not progress):
        t_ns = int((t0 + k / rate_hz) * 1e9)
        s = {}
        for cam in cams:
            obs, who = cam.observe(t_ns)
            for i, v in zip(who, obs.people):
                if i == 0:
                    s[cam.camera.id] = v.keypoints
        if s:
            out.append(s)
            if truths is not None:
                st = world.states(t_ns * 1e-9)[0]
                truths.append((st.x, st.y, st.yaw))
    return out
