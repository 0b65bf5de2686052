"""What each simulated camera's 2D detector reports of the world.

``render_views`` projects each person's joints through the camera model, drops those outside
the image, behind obstacles or other people (a few hidden ones are still guessed, as detectors
do, but only for a person with a joint in plain view), applies the detector noise model
(``edge/sim/noise.py``) and computes each person's colour signature from a synthetic patch of
their clothing under the camera's lighting (``edge/sim/appearance.py``); ``SimCamera`` turns
that into Observations.
"""

from __future__ import annotations

import dataclasses
import math
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge import body
from superbody.edge.camera import Camera, project, world_to_camera
from superbody.edge.colour import hs_histogram
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.sim.appearance import Appearance, Lighting, _person_histogram
from superbody.edge.sim.noise import NoiseModel, facing_factor
from superbody.edge.sim.skeleton import _LEFT, _RIGHT
from superbody.edge.sim.world import _PERSON_RADIUS_M, PersonState, World
from superbody.edge.site import Site, obstacles_hide

__all__ = ["render_views", "SimCamera"]


def render_views(
    states: list[PersonState],
    appearances: list[Appearance],
    cam: Camera,
    rng: np.random.Generator,
    noise: NoiseModel = NoiseModel(),
    site: Site | None = None,
    lighting: Lighting = Lighting(),
    histograms: bool = True,
    depth: bool = False,
) -> list[tuple[int, PersonView]]:
    """What one camera's detector reports for one frame.

    Args:
        states: every person in the world at the frame's time.
        appearances: their appearances, same order.
        cam: the camera.
        rng: randomness for this frame (seed it from (seed, camera, frame) for repeatability).
        noise: detector noise model.
        site: for obstacle occlusion (None: no obstacles).
        lighting: the camera's colour rendering.
        histograms: compute colour histograms (training does not need them).
        depth: also report camera-frame 3D joints (depth cameras).

    Returns:
        ``(person index, view)`` pairs; index -1 marks a spurious detection.
    """
    out: list[tuple[int, PersonView]] = []
    centres = np.array([[s.x, s.y] for s in states]).reshape(-1, 2)
    heights = np.array([s.joints[:, 2].max() + 0.1 for s in states])
    for k, st in enumerate(states):
        uv, z = project(st.joints, cam)  # (17, 2), (17,)
        quality = rng.normal(0.0, noise.view_quality_std)
        p = np.clip(np.asarray(noise.joint_rate) + quality, 0.0, 1.0)  # (17,) detection probability
        to_person = np.array([st.x, st.y]) - cam.t[:2]
        dist = float(np.linalg.norm(to_person))
        view_dir = to_person / max(dist, 1e-6)
        facing = np.array([math.cos(st.yaw), math.sin(st.yaw)])
        if noise.facing_visibility is not None:
            # The face needs the person to face the camera (ears show from the side and back);
            # the arm on the far side is hidden by the torso.
            rel = math.atan2(-view_dir[0] * facing[1] + view_dir[1] * facing[0], -float(view_dir @ facing))
            p = np.clip(p * facing_factor(noise.facing_visibility, rel), 0.0, 1.0)
        p *= max(0.0, 1.0 - noise.distance_drop * max(0.0, dist - 3.0))
        edge_px = np.minimum.reduce([uv[:, 0], cam.width - uv[:, 0], uv[:, 1], cam.height - uv[:, 1]])
        p *= 1.0 - 0.5 * np.clip((noise.border_px - edge_px) / max(noise.border_px, 1e-6), 0.0, 1.0)
        inside = (z > 0.1) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        occluded = _occluded(cam.t, st.joints, k, centres, heights, site)
        p = np.where(occluded, p * noise.occluded_keep, p)
        visible = inside & (rng.uniform(size=body.NUM_KEYPOINTS) < p)
        miss = noise.view_miss_prob + noise.truncated_miss_prob * (1.0 - inside.mean())
        # A detector guesses the hidden joints of a person it sees, never a person it cannot
        # see: one found joint at least must be in plain view (not someone behind a wall).
        if visible.sum() < max(noise.min_joints, 1) or not (visible & ~occluded).any() or rng.uniform() < miss:
            continue
        score = rng.normal(noise.score_mean + 0.5 * quality, noise.score_std, size=body.NUM_KEYPOINTS)
        # Pixel noise grows with the person's apparent size (closer = bigger errors in pixels).
        sigma = noise.pixel_noise_px * 3.0 / np.maximum(z, 0.5)
        # Detectors report keypoints inside the image.
        uv_noisy = np.clip(uv + rng.normal(size=uv.shape) * sigma[:, None], 0.0, [cam.width - 1, cam.height - 1])
        kp = np.full((body.NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
        kp[visible, :2] = uv_noisy[visible]
        kp[visible, 2] = np.clip(score[visible], noise.score_threshold, 1.0)
        p3d = None
        if depth:
            pc = world_to_camera(st.joints, cam)
            pc *= 1 + rng.normal(size=(body.NUM_KEYPOINTS, 1)) * noise.depth_noise_m
            p3d = np.where(visible[:, None], pc, np.nan).astype(np.float32)
        if rng.uniform() < noise.swap_prob:
            kp[_LEFT], kp[_RIGHT] = kp[_RIGHT].copy(), kp[_LEFT].copy()
            if p3d is not None:
                p3d[_LEFT], p3d[_RIGHT] = p3d[_RIGHT].copy(), p3d[_LEFT].copy()
        bbox = _bbox(kp, cam)
        hist = _person_histogram(appearances[k], kp, lighting, rng) if histograms else np.zeros((16, 8), np.float32)
        out.append((k, PersonView(keypoints=kp, bbox=bbox, histogram=hist, points3d=p3d)))
    if rng.uniform() < noise.spurious_prob:
        out.append((-1, _spurious_view(cam, rng, lighting, histograms, depth)))
    return out


class SimCamera:
    """A simulated camera: turns world time into Observations for one camera of a world.

    The noise of each frame is seeded from (world seed, camera index, frame number), so a run
    is repeatable. ``fps`` replaces the site camera's capture rate (``edge run --fps``): the frame
    numbers, hence the noise, follow it.
    """

    def __init__(self, world: World, camera_id: str, noise: NoiseModel = NoiseModel(), depth: bool = False, fps: float | None = None):
        self.world = world
        self.camera = world.site.camera(camera_id)
        if fps is not None:
            self.camera = dataclasses.replace(self.camera, fps=float(fps))
        self.index = world.site.camera_index(camera_id)
        self.noise = noise
        self.depth = depth
        lrng = np.random.default_rng([world.seed, 0x11, self.index])
        self.lighting = Lighting(
            gain=float(lrng.uniform(0.75, 1.15)),
            hue_shift=float(lrng.normal(0, 1.5)),
            sat_gain=float(lrng.uniform(0.88, 1.08)),
            background_hsv=(int(lrng.integers(0, 180)), int(lrng.integers(10, 60)), int(lrng.integers(90, 210))),
        )
        self.seq = 0

    def frame_index(self, stamp_ns: int) -> int:
        return int(round(stamp_ns * 1e-9 * self.camera.fps))

    def observe(self, stamp_ns: int) -> tuple[Observation, list[int]]:
        """The Observation at capture time ``stamp_ns`` and the true person index of each view."""
        states = self.world.states(stamp_ns * 1e-9)
        rng = np.random.default_rng([self.world.seed, self.index, self.frame_index(stamp_ns)])
        views = render_views(
            states, [p.appearance for p in self.world.people], self.camera, rng, self.noise,
            self.world.site, self.lighting, histograms=True, depth=self.depth,
        )
        obs = Observation(
            site=self.world.site.name, camera=self.camera.id, seq=self.seq, stamp_ns=int(stamp_ns),
            width=self.camera.width, height=self.camera.height, people=tuple(v for _, v in views),
        )
        self.seq += 1
        return obs, [k for k, _ in views]


def _occluded(origin: NDArray, joints: NDArray, k: int, centres: NDArray, heights: NDArray, site: Site | None) -> NDArray[np.bool_]:
    """(17,) whether the segment from the camera to each joint is blocked by an obstacle or another person."""
    d = joints - origin  # (17, 3)
    hidden = np.zeros(len(joints), dtype=bool)
    # Other people as vertical cylinders.
    for q in range(len(centres)):
        if q == k:
            continue
        oq = centres[q] - origin[:2]  # (2,)
        dd = (d[:, :2] ** 2).sum(1)  # (17,)
        s = np.clip((d[:, :2] @ oq) / np.maximum(dd, 1e-9), 0.0, 1.0)  # closest approach along each segment
        closest = s[:, None] * d[:, :2] - oq
        zs = origin[2] + s * d[:, 2]
        hidden |= (np.linalg.norm(closest, axis=1) < _PERSON_RADIUS_M) & (s < 0.9) & (zs < heights[q])
    if site is not None:
        hidden |= obstacles_hide(origin, joints, site.obstacles, before=0.98)
    return hidden


def _bbox(kp: NDArray, cam: Camera) -> NDArray[np.float32]:
    v = kp[~np.isnan(kp[:, 0]), :2]
    lo, hi = v.min(0), v.max(0)
    pad = 0.1 * (hi - lo) + 8.0
    size = np.array([cam.width - 1, cam.height - 1], dtype=np.float64)
    lo = np.clip(lo - pad, 0.0, size)
    hi = np.clip(hi + pad, lo, size)
    return np.array([lo[0], lo[1], hi[0], hi[1]], dtype=np.float32)


def _spurious_view(cam: Camera, rng: np.random.Generator, light: Lighting, histograms: bool, depth: bool) -> PersonView:
    """A false detection: a few low-confidence joints clustered somewhere in the image."""
    kp = np.full((body.NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
    n = int(rng.integers(2, 7))
    idx = rng.choice(body.NUM_KEYPOINTS, size=n, replace=False)
    centre = rng.uniform([40, 40], [cam.width - 40, cam.height - 40])
    kp[idx, :2] = centre + rng.normal(size=(n, 2)) * 25
    kp[idx, :2] = np.clip(kp[idx, :2], 0, [cam.width - 1, cam.height - 1])
    kp[idx, 2] = rng.uniform(0.5, 0.65, size=n)
    hist = np.zeros((16, 8), np.float32)
    if histograms:
        bg = np.asarray(light.background_hsv, np.float32)
        hsv = np.clip(bg + rng.normal(size=(16, 16, 3)) * [6, 20, 20], 0, [179, 255, 255]).astype(np.uint8)
        hist = hs_histogram(cast("NDArray[np.uint8]", cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)))  # cv2 stubs: any MatLike
    p3d = np.where(np.isnan(kp[:, :1]), np.nan, rng.uniform(1, 5, size=(body.NUM_KEYPOINTS, 3))).astype(np.float32) if depth else None
    return PersonView(keypoints=kp, bbox=_bbox(kp, cam), histogram=hist, points3d=p3d)
