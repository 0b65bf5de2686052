"""Simulated training data (the paper's DS2, made from a site file), and random sites.

``generate(site, config)`` places simulated people in the site (edge/sim/), renders
what each camera's detector reports, and returns one ``Sample`` per person and instant seen by
at least one camera, with the ground truth. Work is split into seeded chunks run in parallel,
so the result depends only on the config, not on the number of workers.

Ground truth: the torso centre, what the product reports. ``truth_offset_m`` can move it
forward (to imitate a chest-worn tracker such as the WheresTheFellow ground truth; the
project instead converts that dataset's truth, see models.data.wtf.truth_to_torso).

``random_site(rng)`` makes plausible rooms with 2-5 wall-mounted cameras, for the
site-independent ("rays") model.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import cast

import numpy as np
from tqdm import tqdm

from superbody.edge.angles import wrap_angle
from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.messages.observation import PersonView
from superbody.edge.sim import NoiseModel, PersonState, World, render_views
from superbody.edge.sim.world import _free_space
from superbody.edge.site import Obstacle, Site
from superbody.models.data.samples import Sample

__all__ = ["SimDataConfig", "generate", "random_site", "save_samples", "load_samples"]
_CHUNK = 400
# Training sees up to this share of views with left and right swapped, more than the measured
# detector (NoiseModel.swap_prob): another site's detector may swap more, and a network that has
# seen swaps is robust to them.
TRAIN_SWAP_MAX = 0.06


@dataclass(frozen=True)
class SimDataConfig:
    """How to simulate a dataset.

    Attributes:
        samples: how many samples (person views sets) to make.
        seed: everything follows from it.
        max_people: people per scene, 1 to this (others occlude).
        truth_offset_m: the truth is this far in front of the torso centre.
        depth: include camera-frame 3D joints (depth cameras).
        noise: the detector noise model; each chunk jitters it (domain randomisation).
        randomise_noise: whether to jitter the noise per chunk.
        placed_fraction: share of instants at which every person is moved, as they are (body,
            gait, arms), to a uniformly random free floor point with a uniformly random heading:
            walks between random goals visit the middle of a room far more than its edges and
            corners, where single-view cases live; placement covers the whole floor evenly.
    """

    samples: int = 20_000
    seed: int = 0
    max_people: int = 3
    truth_offset_m: float = 0.0
    depth: bool = False
    noise: NoiseModel = field(default_factory=NoiseModel)
    randomise_noise: bool = True
    placed_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0.0 <= self.placed_fraction <= 1.0:
            raise ValueError(f"placed_fraction must be in [0, 1], got {self.placed_fraction}")
        if not 1 <= self.samples <= 5_000_000:
            raise ValueError(f"samples must be in [1, 5000000], got {self.samples}")
        if not 1 <= self.max_people <= 10:
            raise ValueError(f"max_people must be in [1, 10], got {self.max_people}")
        if not 0.0 <= abs(self.truth_offset_m) <= 0.5:
            raise ValueError(f"truth_offset_m must be in [-0.5, 0.5], got {self.truth_offset_m}")


def _jitter(noise: NoiseModel, rng: np.random.Generator) -> NoiseModel:
    """A nearby noise model: real detectors and cameras differ from the tuned defaults."""
    return replace(
        noise,
        pixel_noise_px=noise.pixel_noise_px * float(rng.uniform(0.6, 1.8)),
        joint_rate=tuple(float(np.clip(r + rng.normal(0, 0.05), 0.05, 1.0)) for r in noise.joint_rate),
        swap_prob=float(rng.uniform(0.0, TRAIN_SWAP_MAX)),
        view_miss_prob=float(np.clip(noise.view_miss_prob + rng.normal(0, 0.05), 0.0, 0.5)),
    )


def _chunk(site: Site, config: SimDataConfig, index: int, count: int) -> list[Sample]:
    """``count`` samples from scene ``index``: its own people, noise and times."""
    rng = np.random.default_rng([config.seed, index, 0xDA7A])
    noise = _jitter(config.noise, rng) if config.randomise_noise else config.noise
    people = int(rng.integers(1, config.max_people + 1))
    world = World(site, people, seed=int(rng.integers(0, 2**31)))
    out: list[Sample] = []
    apps = [p.appearance for p in world.people]
    free = _free_space(site)
    while len(out) < count:
        t = float(rng.uniform(0, 1e5))
        states = world.states(t)
        if rng.uniform() < config.placed_fraction:
            states = _placed(states, free, rng)
        seen: dict[int, dict[str, PersonView]] = {}
        for cam in site.cameras:
            for k, view in render_views(states, apps, cam, rng, noise, site, histograms=False, depth=config.depth):
                if k >= 0:
                    seen.setdefault(k, {})[cam.id] = view
        for k, views in seen.items():
            s = states[k]
            x = s.x + config.truth_offset_m * math.cos(s.yaw)
            y = s.y + config.truth_offset_m * math.sin(s.yaw)
            out.append(Sample(views=views, truth=np.array([x, y, s.yaw]), stamp_ns=int(t * 1e9)))
            if len(out) == count:
                break
    return out


def _placed(states: list[PersonState], free, rng: np.random.Generator, clearance_m: float = 0.6) -> list[PersonState]:
    """The same people, each rigidly moved to a random free point and heading, kept apart."""
    out: list[PersonState] = []
    for s in states:
        for _ in range(20):  # bounded: a crowded small floor keeps the last draw
            xy = free.random_point(rng)
            if all(math.hypot(xy[0] - o.x, xy[1] - o.y) >= clearance_m for o in out):
                break
        yaw = float(rng.uniform(-math.pi, math.pi))
        c, si = math.cos(yaw - s.yaw), math.sin(yaw - s.yaw)
        rel = s.joints[:, :2] - [s.x, s.y]  # (17, 2)
        joints = s.joints.copy()
        joints[:, :2] = rel @ np.array([[c, si], [-si, c]]) + xy  # rotate by (yaw - s.yaw), then move
        out.append(PersonState(x=float(xy[0]), y=float(xy[1]), yaw=float(wrap_angle(yaw)), joints=joints))
    return out


def _chunk_job(args: tuple) -> list[Sample]:
    return _chunk(*args)


def generate(site: Site | list[Site], config: SimDataConfig, workers: int | None = None, progress: bool = True) -> list[Sample]:
    """Simulate ``config.samples`` samples in ``site`` (or spread over several sites).

    Args:
        site: one site, or a list of sites used in turn by successive chunks.
        config: what to simulate.
        workers: processes (default: the machine's cores, at most 8).
        progress: show a progress bar.

    Returns:
        The samples, in a deterministic order.
    """
    sites = site if isinstance(site, list) else [site]
    sizes = [min(_CHUNK, config.samples - i) for i in range(0, config.samples, _CHUNK)]
    jobs = [(sites[i % len(sites)], config, i, n) for i, n in enumerate(sizes)]
    workers = workers or min(os.cpu_count() or 1, 8)
    out: list[Sample] = []
    bar = tqdm(total=config.samples, desc="simulating", unit="sample", disable=not progress)
    if workers <= 1 or len(jobs) == 1:
        for job in jobs:
            out += _chunk_job(job)
            bar.update(job[3])
    else:
        with ProcessPoolExecutor(workers) as pool:
            for job, chunk in zip(jobs, pool.map(_chunk_job, jobs)):
                out += chunk
                bar.update(job[3])
    bar.close()
    return out


def random_site(rng: np.random.Generator, name: str = "random") -> Site:
    """A random room: 4-10 m by 3-8 m, 2-5 cameras high on the walls looking into the room,
    random intrinsics and image sizes, up to 2 low obstacles."""
    w, d = float(rng.uniform(4, 10)), float(rng.uniform(3, 8))
    floor = ((0.0, 0.0), (w, 0.0), (w, d), (0.0, d))
    cams = []
    n = int(rng.integers(2, 6))
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    for i, a in enumerate(angles):
        # A point on the walls in direction a from the room centre.
        c = np.array([w / 2, d / 2])
        v = np.array([math.cos(a), math.sin(a)])
        s = min((w / 2 - 0.1) / max(abs(v[0]), 1e-9), (d / 2 - 0.1) / max(abs(v[1]), 1e-9))
        pos = np.array([*(c + s * v), rng.uniform(1.8, 3.0)])
        target = np.array([*(c + rng.normal(0, 0.06, 2) * [w, d]), rng.uniform(0.5, 1.2)])
        width, height = [(640, 480), (1280, 720), (1920, 1080), (800, 600)][int(rng.integers(0, 4))]
        f = float(rng.uniform(0.55, 1.1)) * width
        R = look_at_rotation(pos, target)
        cams.append(Camera(
            id=f"c{i}", width=width, height=height, fps=15.0, fx=f, fy=f * float(rng.uniform(0.98, 1.02)),
            cx=width / 2 + float(rng.normal(0, 5)), cy=height / 2 + float(rng.normal(0, 5)),
            dist=(), position=cast("tuple[float, float, float]", tuple(map(float, pos))), rotation=cast("tuple[tuple[float, float, float], ...]", tuple(tuple(map(float, r)) for r in R)),
        ))
    obstacles = []
    for k in range(int(rng.integers(0, 3))):
        ox, oy = float(rng.uniform(1, w - 2)), float(rng.uniform(1, d - 2))
        obstacles.append(Obstacle(f"box{k}", (ox, oy, 0.0), (ox + float(rng.uniform(0.5, 1.2)), oy + float(rng.uniform(0.5, 1.0)), float(rng.uniform(0.4, 1.0)))))
    return Site(name=name, cameras=tuple(cams), floor=floor, obstacles=tuple(obstacles))


# -- storage --------------------------------------------------------------------------------------


def save_samples(path: str | Path, samples: list[Sample], camera_ids: tuple[str, ...]) -> None:
    """Write samples of one site to an .npz file (views as dense per-camera arrays)."""
    S, C = len(samples), len(camera_ids)
    kp = np.full((S, C, 17, 3), np.nan, np.float32)
    p3 = np.full((S, C, 17, 3), np.nan, np.float32)
    bbox = np.zeros((S, C, 4), np.float32)
    present = np.zeros((S, C), bool)
    has3d = False
    for i, s in enumerate(samples):
        for c, cid in enumerate(camera_ids):
            v = s.views.get(cid)
            if v is None:
                continue
            present[i, c] = True
            kp[i, c], bbox[i, c] = v.keypoints, v.bbox
            if v.points3d is not None:
                p3[i, c], has3d = v.points3d, True
    arrays = dict(keypoints=kp, bbox=bbox, present=present, camera_ids=np.array(camera_ids),
                  truth=np.array([s.truth for s in samples]).reshape(S, 3), stamp_ns=np.array([s.stamp_ns for s in samples], np.int64))
    if has3d:
        arrays["points3d"] = p3
    np.savez_compressed(path, **arrays)  # type: ignore[arg-type]  # mypy also matches **arrays against allow_pickle: bool


def load_samples(path: str | Path) -> list[Sample]:
    """Read samples written by ``save_samples``."""
    z = np.load(path)
    ids = [str(c) for c in z["camera_ids"]]
    p3 = z["points3d"] if "points3d" in z.files else None
    zero = np.zeros((16, 8), np.float32)
    out = []
    for i in range(len(z["truth"])):
        views = {
            cid: PersonView(keypoints=z["keypoints"][i, c], bbox=z["bbox"][i, c], histogram=zero,
                            points3d=None if p3 is None else p3[i, c])
            for c, cid in enumerate(ids) if z["present"][i, c]
        }
        out.append(Sample(views=views, truth=z["truth"][i].astype(np.float64), stamp_ns=int(z["stamp_ns"][i])))
    return out

