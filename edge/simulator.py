"""Simulator of people walking in a site, and of what each camera's 2D detector reports.

Library code shared by the simulated camera nodes, the tests, the demo and training.

Two parts:

- ``World``: people with varied body sizes and clothing move through the site's floor,
  avoiding obstacles: they walk between waypoints with gait and arm swing, turn in place,
  stand still and sometimes side-step. A person's plan is periodic and is a pure function of
  absolute time, so any process that builds a ``World`` from the same site and seed sees the
  same people at the same instant (the shared world clock of the simulated camera nodes).
- ``render_views``: for one camera, what a detector such as OpenPifPaf would output: joints
  projected through the camera model, dropped outside the image, behind obstacles or other
  people, with a noise model (latent per-joint confidence thresholded at 0.5 as the
  WheresTheFellow data was, pixel noise, left/right swaps, occasional spurious people) and a
  hue-saturation histogram computed by ``edge.colour.hs_histogram`` from a synthetic patch of
  the person's clothing under the camera's lighting.

Ground truth is each person's torso pose (x, y, yaw) in REP-103.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Final

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge import body
from superbody.edge.angles import wrap_angle
from superbody.edge.camera import Camera, project, world_to_camera
from superbody.edge.colour import hs_histogram
from superbody.edge.observation import Observation, PersonView
from superbody.edge.site import Site

__all__ = [
    "NoiseModel",
    "Appearance",
    "SimPerson",
    "PersonState",
    "World",
    "Lighting",
    "skeleton",
    "render_views",
    "SimCamera",
    "FACING_VISIBILITY",
    "facing_factor",
]

# Lateral (left-positive), forward and height offsets of each joint for a 1.75 m person
# standing still, in metres. Arms and legs are recomputed with the gait.
_LATERAL: Final = np.array([0.0, 0.032, -0.032, 0.075, -0.075, 0.19, -0.19, 0.21, -0.21, 0.2, -0.2, 0.1, -0.1, 0.1, -0.1, 0.1, -0.1])
_FORWARD: Final = np.array([0.1, 0.075, 0.075, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.03, 0.03, 0.0, 0.0, 0.02, 0.02, 0.0, 0.0])
_HEIGHT: Final = np.asarray(body.TYPICAL_HEIGHT_M)
_LEFT: Final = np.array([i for i, n in enumerate(body.KEYPOINTS) if n.startswith("left_")])
_RIGHT: Final = np.array([body.MIRROR[i] for i in _LEFT])
_PERSON_RADIUS_M: Final = 0.2

# How often a real detector reports each joint by where the person faces, relative to its
# average over all directions: measured on WheresTheFellow's dev.json (500 views; the truth's
# yaw against the direction to the camera, 8 bins of 45 degrees centred on -157.5 ... 157.5;
# each view counted twice, as itself and mirrored left-right, so the table is symmetric).
# `python scripts/sim_vs_dataset.py` prints it again. From the back the nose and eyes vanish
# but the ears stay; side-on the far eye, ear, elbow and wrist are hidden.
FACING_VISIBILITY: Final[tuple[tuple[float, ...], ...]] = (
    (0.01, 1.28, 1.55, 1.47, 1.47, 1.55, 1.28, 0.01),  # nose
    (0.04, 2.10, 2.26, 2.07, 1.90, 0.34, 0.00, 0.00),  # left_eye
    (0.00, 0.00, 0.34, 1.90, 2.07, 2.26, 2.10, 0.04),  # right_eye
    (1.47, 1.81, 1.64, 0.89, 0.73, 0.00, 0.06, 1.18),  # left_ear
    (1.18, 0.06, 0.00, 0.73, 0.89, 1.64, 1.81, 1.47),  # right_ear
    (1.10, 1.10, 0.97, 1.01, 0.92, 0.86, 1.09, 0.94),  # left_shoulder
    (0.94, 1.09, 0.86, 0.92, 1.01, 0.97, 1.10, 1.10),  # right_shoulder
    (1.35, 1.41, 1.24, 1.31, 1.18, 0.23, 0.10, 1.09),  # left_elbow
    (1.09, 0.10, 0.23, 1.18, 1.31, 1.24, 1.41, 1.35),  # right_elbow
    (0.85, 1.64, 1.57, 1.71, 1.56, 0.24, 0.02, 0.65),  # left_wrist
    (0.65, 0.02, 0.24, 1.56, 1.71, 1.57, 1.64, 0.85),  # right_wrist
    (1.01, 1.08, 0.97, 1.04, 1.02, 0.97, 1.00, 0.94),  # left_hip
    (0.94, 1.00, 0.97, 1.02, 1.04, 0.97, 1.08, 1.01),  # right_hip
    (1.02, 1.07, 0.98, 1.08, 1.05, 0.90, 0.99, 0.94),  # left_knee
    (0.94, 0.99, 0.90, 1.05, 1.08, 0.98, 1.07, 1.02),  # right_knee
    (0.98, 0.98, 1.00, 1.14, 1.10, 0.97, 0.96, 0.91),  # left_ankle
    (0.91, 0.96, 0.97, 1.10, 1.14, 1.00, 0.98, 0.98),  # right_ankle
)


def facing_factor(table: tuple[tuple[float, ...], ...] | NDArray, rel: float) -> NDArray[np.float64]:
    """(17,) factors of a facing-visibility table (17, K) at a relative facing angle.

    Args:
        table: per joint, K factors at angles -pi + (k + 0.5) 2 pi / K (``FACING_VISIBILITY``).
        rel: the person's facing relative to the direction from them to the camera, radians
            (0: facing the camera; positive: turned counter-clockwise, the camera sees the
            person's right side).

    Returns:
        (17,) factors, linearly interpolated around the circle.
    """
    t = np.asarray(table, dtype=np.float64)
    k = t.shape[1]
    u = (rel + math.pi) / (2 * math.pi / k) - 0.5
    k0 = math.floor(u)
    f = u - k0
    return (1.0 - f) * t[:, k0 % k] + f * t[:, (k0 + 1) % k]


@dataclass(frozen=True)
class NoiseModel:
    """What a real 2D pose detector does to the truth. Defaults tuned against WheresTheFellow
    (``scripts/sim_vs_dataset.py`` prints the comparison).

    Whether a joint is reported and the confidence it is reported with are drawn separately:
    in the real data often-missed joints (wrists, faces) still come with high scores.

    Attributes:
        pixel_noise_px: std of Gaussian pixel noise at 3 m; grows as the person comes closer.
        joint_rate: per-joint probability (COCO order) that a clearly visible joint is reported.
        view_quality_std: std of a detection-probability change shared by all joints of a view
            (blur, lighting, pose): views are good or bad as a whole.
        facing_visibility: per joint (COCO order), the factor on its detection probability by
            where the person faces relative to the camera, at 8 angles 45 degrees apart from
            -157.5 (the camera behind the person's right shoulder) through 0 (facing the camera)
            to 157.5, interpolated between; ``None``: the same in every direction.
        distance_drop: detection probability lost per metre beyond 3 m.
        border_px: joints within this many pixels of the image border are found less often.
        occluded_keep: probability that a joint hidden by an obstacle or a person is still
            reported (detectors hallucinate plausible joints).
        score_mean, score_std: the reported confidence of a detected joint, before clipping to
            [score_threshold, 1].
        score_threshold: nothing below this confidence is reported (OpenPifPaf used 0.5).
        swap_prob: probability that a view has its left and right joints swapped.
        spurious_prob: probability per frame of a spurious partial person.
        view_miss_prob: probability that the detector misses a person entirely in a view.
        truncated_miss_prob: extra miss probability for a person whose joints are all out of
            the image, scaled by the fraction that is out.
        min_joints: a person is reported only with at least this many joints.
        depth_noise_m: std of the depth noise of 3D points, per metre of depth.
    """

    pixel_noise_px: float = 2.5
    joint_rate: tuple[float, ...] = (0.66, 0.5, 0.5, 0.56, 0.56, 1.0, 1.0, 0.86, 0.86, 0.66, 0.66, 1.0, 1.0, 0.99, 0.99, 0.95, 0.95)
    view_quality_std: float = 0.06
    facing_visibility: tuple[tuple[float, ...], ...] | None = FACING_VISIBILITY
    distance_drop: float = 0.05
    border_px: float = 12.0
    occluded_keep: float = 0.15
    score_mean: float = 0.805
    score_std: float = 0.105
    score_threshold: float = 0.5
    swap_prob: float = 0.03
    spurious_prob: float = 0.01
    view_miss_prob: float = 0.2
    truncated_miss_prob: float = 0.3
    min_joints: int = 1
    depth_noise_m: float = 0.01


@dataclass(frozen=True)
class Appearance:
    """A person's body, clothing and what they carry. Colours are OpenCV HSV (hue 0-179,
    sat/val 0-255). ``carry`` (left, right): that forearm is held up in front of the chest
    (a phone, a cup, a tracker) instead of swinging, as the right arm in the real recordings."""

    height_m: float
    width_scale: float
    shirt_hsv: tuple[int, int, int]
    trousers_hsv: tuple[int, int, int]
    skin_hsv: tuple[int, int, int]
    carry: tuple[bool, bool] = (False, False)


@dataclass(frozen=True)
class Lighting:
    """One camera's view of colour: brightness gain, hue shift, saturation gain, background."""

    gain: float = 1.0
    hue_shift: float = 0.0
    sat_gain: float = 1.0
    background_hsv: tuple[int, int, int] = (20, 30, 160)


@dataclass(frozen=True)
class PersonState:
    """One person at one instant: ground truth and 3D joints.

    Attributes:
        x, y, yaw: torso pose in REP-103 (metres, radians in (-pi, pi]).
        joints: (17, 3) world positions of the COCO-17 joints, metres.
    """

    x: float
    y: float
    yaw: float
    joints: NDArray[np.float64]


def skeleton(x: float, y: float, yaw: float, phase: float, walk: float, height_m: float = 1.75, width_scale: float = 1.0,
             carry: tuple[bool, bool] = (False, False)) -> NDArray[np.float64]:
    """3D COCO-17 joints of a person standing or walking.

    Args:
        x, y, yaw: torso pose on the floor.
        phase: gait phase in radians (one stride per 2 pi).
        walk: 0 standing still .. 1 walking at full stride.
        height_m: body height; all lengths scale with it.
        width_scale: lateral scale (build).
        carry: (left, right) forearm held up in front of the chest.

    Returns:
        Joints, shape (17, 3), world frame.
    """
    s = height_m / 1.75
    f = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # facing
    l = np.array([-math.sin(yaw), math.cos(yaw), 0.0])  # left
    z = np.array([0.0, 0.0, 1.0])
    base = np.array([x, y, 0.0])
    lateral = _LATERAL * s * width_scale
    forward = _FORWARD * s
    j = base + lateral[:, None] * l + forward[:, None] * f + (_HEIGHT * s)[:, None] * z  # (17, 3)
    leg_amp, arm_amp = 0.38 * walk, 0.32 * walk
    leg = (_HEIGHT[11] - _HEIGHT[15]) * s  # hip to ankle
    thigh, shin, upper, fore = 0.52 * leg, 0.48 * leg, 0.31 * s, 0.27 * s
    for side, held, (hip, knee, ankle, sh, elb, wri) in ((0.0, carry[0], (11, 13, 15, 5, 7, 9)), (math.pi, carry[1], (12, 14, 16, 6, 8, 10))):
        theta = leg_amp * math.sin(phase + side)  # leg swing, forward positive
        bend = walk * 0.5 * max(0.0, math.cos(phase + side))  # knee flexes in the swing phase
        j[knee] = j[hip] + thigh * (math.sin(theta) * f - math.cos(theta) * z)
        j[ankle] = j[knee] + shin * (math.sin(theta - bend) * f - math.cos(theta - bend) * z)
        alpha = -arm_amp * math.sin(phase + side)  # arms swing against the legs
        beta = 0.15 + 0.35 * walk * max(0.0, math.sin(-(phase + side)))  # elbow flex
        if held:  # upper arm a little forward, forearm raised: the wrist at chest height
            alpha, beta = 0.35 + 0.05 * math.sin(phase), 1.8
        j[elb] = j[sh] + upper * (math.sin(alpha) * f - math.cos(alpha) * z) + 0.02 * s * l * (1 if side == 0 else -1)
        j[wri] = j[elb] + fore * (math.sin(alpha + beta) * f - math.cos(alpha + beta) * z)
    # The stance foot carries the body: keep the lowest ankle at its standing height.
    j[:, 2] += _HEIGHT[15] * s - min(j[15, 2], j[16, 2])
    return j


class _Plan:
    """A person's motion plan: segments (start time, kind, parameters) in plan time, with
    vectorised floor positions so that other people's plans can be checked against it."""

    def __init__(self) -> None:
        self.starts: list[float] = []
        self.segments: list[tuple] = []
        self.end = 0.0  # plan time at which the last segment ends
        self.period = 0.0  # set by the World: every person's plan repeats with the same period
        self.last = np.zeros(2)  # where the person is at ``end`` (and stays until ``period``)
        self._arrays: tuple | None = None

    def add(self, duration: float, seg: tuple) -> None:
        self.starts.append(self.end)
        self.segments.append((duration,) + seg)
        self.end += duration
        self.last = np.asarray(seg[2] if seg[0] == "walk" else seg[1], dtype=np.float64)
        self._arrays = None

    def positions(self, taus: NDArray) -> NDArray[np.float64]:
        """(T, 2) floor positions at plan times ``taus`` (T,); beyond ``end``, the last position."""
        if not self.segments:
            return np.broadcast_to(self.last, (len(taus), 2))
        if self._arrays is None:
            st = np.array(self.starts)
            dur = np.array([g[0] for g in self.segments])
            p0 = np.array([g[2] for g in self.segments])
            p1 = np.array([g[3] if g[1] == "walk" else g[2] for g in self.segments])
            self._arrays = (st, dur, p0, p1)
        st, dur, p0, p1 = self._arrays
        i = np.clip(np.searchsorted(st, taus, side="right") - 1, 0, len(st) - 1)
        u = np.clip((taus - st[i]) / np.maximum(dur[i], 1e-9), 0.0, 1.0)[:, None]
        return np.where((taus >= self.end)[:, None], self.last, p0[i] + u * (p1[i] - p0[i]))


# People keep at least this far apart (centre to centre): real people do not walk through each other.
_CLEARANCE_M: Final = 0.6


class _Planner:
    """Builds one person's plan an action at a time, keeping clear of the others' plans."""

    def __init__(self, person: SimPerson, rng: np.random.Generator, free: _FreeSpace, others: list[_Planner]):
        self.rng, self.free, self.others = rng, free, others
        self.plan = _Plan()
        self.stride = 0.75 * person.appearance.height_m / 1.75
        for _ in range(200):
            start = free.random_point(rng)
            if all(np.linalg.norm(o.start - start) >= _CLEARANCE_M + 0.2 for o in others):
                break
        self.start = self.pos = start
        self.plan.last = start
        self.yaw = float(rng.uniform(-np.pi, np.pi))

    def _clear(self, t0: float, t1: float, p0: NDArray, p1: NDArray) -> bool:
        """Whether moving p0 -> p1 over [t0, t1] keeps clear of the others: never closer than
        the clearance, or than they already are (so two people too close can move apart)."""
        # After the move this person stays at p1 while the others' known plans go on: check that too.
        horizon = max([t1] + [o.plan.end for o in self.others])
        taus = np.linspace(t0, horizon, max(2, int((horizon - t0) / 0.1) + 1))
        u = np.clip((taus - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)[:, None]
        mine = p0 + u * (p1 - p0)  # (T, 2)
        for o in self.others:
            d = np.linalg.norm(o.plan.positions(taus) - mine, axis=1)  # (T,)
            if d.min() < min(_CLEARANCE_M, d[0] - 1e-6):
                return False
        return True

    def stand(self, duration: float, force: bool = False) -> bool:
        t = self.plan.end
        if not force and not self._clear(t, t + duration, self.pos, self.pos):
            return False
        self.plan.add(duration, ("stand", self.pos.copy(), self.yaw))
        return True

    def turn(self, angle: float, rate: float) -> bool:
        duration = max(abs(angle) / rate, 0.05)
        t = self.plan.end
        if not self._clear(t, t + duration, self.pos, self.pos):
            return False
        self.plan.add(duration, ("turn", self.pos.copy(), self.yaw, angle))
        self.yaw = float(wrap_angle(self.yaw + angle))
        return True

    def walk_to(self, target: NDArray, speed: float, yaw_offset: float = 0.0) -> bool:
        d = target - self.pos
        dist = float(np.linalg.norm(d))
        if dist < 1e-3:
            return True
        new_yaw = float(wrap_angle(math.atan2(d[1], d[0]) + yaw_offset))
        angle = float(wrap_angle(new_yaw - self.yaw))
        t_turn = abs(angle) / 2.5 if abs(angle) > 1e-3 else 0.0  # turn in place at ~140 deg/s
        t = self.plan.end
        if not (self.free.segment_free(self.pos, target) and self._clear(t, t + t_turn, self.pos, self.pos)
                and self._clear(t + t_turn, t + t_turn + dist / speed, self.pos, target)):
            return False
        if t_turn:
            self.turn(angle, 2.5)
        self.plan.add(dist / speed, ("walk", self.pos.copy(), target.copy(), new_yaw, self.stride))
        self.pos, self.yaw = target, new_yaw
        return True

    def step(self) -> None:
        """Add one action: walk somewhere, side-step, turn, or stand; wait a moment if blocked."""
        rng = self.rng
        r = rng.uniform()
        if r < 0.55:  # walk to a random point
            done = self.walk_to(self.free.random_point(rng), float(rng.uniform(0.6, 1.4)))
        elif r < 0.65:  # side-step or step backwards a short way
            off = float(rng.choice([np.pi / 2, -np.pi / 2, np.pi]))
            done = self.walk_to(self.free.random_point(rng, near=self.pos, max_dist=1.5), float(rng.uniform(0.3, 0.6)), off)
        elif r < 0.8:  # turn in place
            done = self.turn(float(rng.uniform(-np.pi, np.pi)), float(rng.uniform(1.0, 3.0)))
        else:  # stand still
            done = self.stand(float(rng.uniform(0.5, 4.0)))
        if not done and not self.stand(0.3):
            # Someone is coming through here: step aside if possible, else let them pass close by.
            for _ in range(10):
                if self.walk_to(self.free.random_point(rng, near=self.pos, max_dist=1.0), 1.2):
                    return
            self.stand(0.3, force=True)

    def close(self) -> None:
        """Walk back to the start and face the starting direction, so the plan can repeat."""
        for _ in range(40):
            if self.walk_to(self.start, 1.0):
                break
            via = self.free.random_point(self.rng)
            if self.free.segment_free(via, self.start) and self.walk_to(via, 1.0) and self.walk_to(self.start, 1.0):
                break
            self.stand(0.5, force=True)
        if np.linalg.norm(self.pos - self.start) > 1e-6:  # rare: walk back regardless
            d = self.start - self.pos
            self.yaw = math.atan2(d[1], d[0])
            self.plan.add(float(np.linalg.norm(d)), ("walk", self.pos.copy(), self.start.copy(), self.yaw, self.stride))
            self.pos = self.start
        first = self.plan.segments[0]
        first_yaw = first[3] if first[1] in ("stand", "turn") else first[4]
        angle = float(wrap_angle(first_yaw - self.yaw))
        self.plan.add(max(abs(angle) / 2.5, 0.05), ("turn", self.pos.copy(), self.yaw, angle))
        self.yaw = first_yaw


class _FreeSpace:
    """Where a person's centre may be: inside the floor polygon and clear of obstacles, on a
    5 cm grid, so that path checks are array lookups."""

    _CELL = 0.05

    def __init__(self, site: Site, margin: float = _PERSON_RADIUS_M + 0.1):
        poly = np.asarray(site.floor, dtype=np.float32)
        self.lo = poly.min(0) - self._CELL
        shape = np.ceil((poly.max(0) + self._CELL - self.lo) / self._CELL).astype(int) + 1
        xs = self.lo[0] + np.arange(shape[0]) * self._CELL
        ys = self.lo[1] + np.arange(shape[1]) * self._CELL
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        contour = poly.reshape(-1, 1, 2)
        dist = np.array([cv2.pointPolygonTest(contour, (float(x), float(y)), True) for x, y in zip(gx.ravel(), gy.ravel())]).reshape(gx.shape)
        free = dist >= margin
        for o in site.obstacles:
            free &= ~((gx >= o.min[0] - margin) & (gx <= o.max[0] + margin) & (gy >= o.min[1] - margin) & (gy <= o.max[1] + margin))
        if not free.any():
            raise ValueError(f"site {site.name!r}: no free floor (floor too small or covered by obstacles)")
        self.free = free
        self.cells = np.argwhere(free)

    def _ok(self, pts: NDArray) -> NDArray[np.bool_]:
        ij = np.round((pts - self.lo) / self._CELL).astype(int)
        inside = (ij >= 0).all(1) & (ij[:, 0] < self.free.shape[0]) & (ij[:, 1] < self.free.shape[1])
        ij = np.clip(ij, 0, np.array(self.free.shape) - 1)
        return inside & self.free[ij[:, 0], ij[:, 1]]

    def segment_free(self, a: NDArray, b: NDArray) -> bool:
        n = max(2, int(np.linalg.norm(b - a) / 0.05) + 1)
        return bool(self._ok(np.linspace(a, b, n)).all())

    def random_point(self, rng: np.random.Generator, near: NDArray | None = None, max_dist: float = math.inf) -> NDArray:
        """A random free point (within ``max_dist`` of ``near`` if given, when one exists)."""
        cells = self.cells
        if near is not None:
            close = np.linalg.norm(self.lo + cells * self._CELL - near, axis=1) <= max_dist
            if close.any():
                cells = cells[close]
        return self.lo + (cells[rng.integers(len(cells))] + rng.uniform(-0.5, 0.5, 2)) * self._CELL


class SimPerson:
    """One simulated person: appearance and a periodic plan of motion through the site (made
    by the ``World`` together with everyone else's, see ``World``)."""

    def __init__(self, appearance: Appearance):
        self.appearance = appearance
        self.phase_offset = 0.0
        self._plan = _Plan()

    # -- state at a time ----------------------------------------------------------------------

    def state(self, t_s: float) -> PersonState:
        """The person's pose and joints at absolute time ``t_s`` (seconds)."""
        tau = (t_s + self.phase_offset) % self._plan.period
        a = self.appearance
        if tau >= self._plan.end:  # waiting at the start for the others' plans to end
            seg = self._plan.segments[0]
            yaw = seg[3] if seg[1] in ("stand", "turn") else seg[4]
            x, y = float(self._plan.last[0]), float(self._plan.last[1])
            return PersonState(x, y, float(wrap_angle(yaw)), skeleton(x, y, yaw, 0.0, 0.0, a.height_m, a.width_scale, a.carry))
        i = max(bisect.bisect_right(self._plan.starts, tau) - 1, 0)
        seg = self._plan.segments[i]
        u = min(max((tau - self._plan.starts[i]) / seg[0], 0.0), 1.0) if seg[0] > 0 else 1.0
        kind = seg[1]
        if kind == "walk":
            _, _, p0, p1, yaw, stride = seg
            p = p0 + u * (p1 - p0)
            travelled = u * float(np.linalg.norm(p1 - p0))
            # A little ramp at both ends so the stride starts and stops smoothly.
            walk = min(1.0, travelled / 0.3, (1 - u) * float(np.linalg.norm(p1 - p0)) / 0.3 + 0.2)
            phase = 2 * np.pi * travelled / (2 * stride)
            x, y = float(p[0]), float(p[1])
        elif kind == "turn":
            _, _, p0, yaw0, turn = seg
            yaw = float(wrap_angle(yaw0 + u * turn))
            x, y, walk, phase = float(p0[0]), float(p0[1]), 0.15, u * abs(turn) * 2
        else:  # stand
            _, _, p0, yaw = seg
            x, y, walk, phase = float(p0[0]), float(p0[1]), 0.0, 0.0
            yaw = float(wrap_angle(yaw + 0.05 * math.sin(0.7 * tau)))  # a little sway
        joints = skeleton(x, y, yaw, phase, walk, a.height_m, a.width_scale, a.carry)
        return PersonState(x, y, float(wrap_angle(yaw)), joints)


class World:
    """People moving through a site, as a pure function of time.

    Plans are made together, an action at a time for whoever's plan ends first, each action
    checked against what the others will be doing, so nobody walks through anybody. They
    share one period (the others wait at their start for the longest), so the whole scene
    repeats.

    Args:
        site: the site (floor polygon, obstacles, cameras).
        num_people: how many people.
        seed: every person's body, clothes and plan follow from it.
        period_s: the plans repeat after about this long.
        epoch_s: the absolute time (seconds) at which the scene starts: the plans are a
            function of ``t_s - epoch_s``, so worlds with the same seed and epoch show the
            same scene at the same times since the epoch. With the default 0 the scene's
            phase follows the wall clock, a different stretch of it on every run.
    """

    def __init__(self, site: Site, num_people: int = 3, seed: int = 0, period_s: float = 600.0, epoch_s: float = 0.0):
        if not 0 <= num_people <= 64:
            raise ValueError(f"num_people must be in [0, 64], got {num_people}")
        if not math.isfinite(epoch_s):
            raise ValueError(f"epoch_s must be finite, got {epoch_s}")
        self.site = site
        self.seed = seed
        self.epoch_s = float(epoch_s)
        rng = np.random.default_rng([seed, 0x5B0D])
        hues = _distinct_hues(rng, num_people)
        free = _free_space(site)
        self.people: list[SimPerson] = []
        planners: list[_Planner] = []
        for k in range(num_people):
            prng = np.random.default_rng([seed, k])
            h = float(np.clip(prng.normal(1.72, 0.08), 1.5, 1.95))
            person = SimPerson(_recolour(_random_appearance(prng, h), hues[k], rng))
            planners.append(_Planner(person, prng, free, list(planners)))
            self.people.append(person)
        for p in planners:
            p.others = [o for o in planners if o is not p]
        active = list(planners)
        while active:
            p = min(active, key=lambda q: q.plan.end)
            p.step()
            if p.plan.end >= period_s:
                active.remove(p)
        for p in planners:
            p.close()
        period = max((p.plan.end for p in planners), default=period_s)
        offset = float(rng.uniform(0, period))
        for person, p in zip(self.people, planners):
            p.plan.period = period
            person._plan = p.plan
            person.phase_offset = offset - self.epoch_s

    def states(self, t_s: float) -> list[PersonState]:
        """Every person's state at absolute time ``t_s`` (seconds)."""
        return [p.state(t_s) for p in self.people]


_FREE_CACHE: dict[int, tuple[Site, _FreeSpace]] = {}


def _free_space(site: Site) -> _FreeSpace:
    hit = _FREE_CACHE.get(id(site))
    if hit is None or hit[0] is not site:
        hit = (site, _FreeSpace(site))
        _FREE_CACHE[id(site)] = hit
    return hit[1]


# -- rendering what a camera's detector reports ------------------------------------------------------


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
        if visible.sum() < max(noise.min_joints, 1) or rng.uniform() < miss:
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
    is repeatable.
    """

    def __init__(self, world: World, camera_id: str, noise: NoiseModel = NoiseModel(), depth: bool = False):
        self.world = world
        self.camera = world.site.camera(camera_id)
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


# -- helpers -----------------------------------------------------------------------------------


def _random_appearance(rng: np.random.Generator, height_m: float) -> Appearance:
    return Appearance(
        height_m=height_m,
        width_scale=float(np.clip(rng.normal(1.0, 0.08), 0.8, 1.25)),
        shirt_hsv=(int(rng.integers(0, 180)), int(rng.integers(90, 240)), int(rng.integers(90, 230))),
        trousers_hsv=(int(rng.integers(0, 180)), int(rng.integers(20, 200)), int(rng.integers(40, 180))),
        skin_hsv=(int(rng.integers(5, 20)), int(rng.integers(60, 150)), int(rng.integers(90, 220))),
        carry=(bool(rng.uniform() < 0.15), bool(rng.uniform() < 0.3)),
    )


def _distinct_hues(rng: np.random.Generator, n: int) -> list[int]:
    """Shirt hues spread around the colour wheel so that simulated people are told apart."""
    start = int(rng.integers(0, 180))
    return [(start + (180 * k) // max(n, 1)) % 180 for k in range(n)]


def _recolour(a: Appearance, hue: int, rng: np.random.Generator) -> Appearance:
    trousers_hue = (hue + int(rng.integers(30, 150))) % 180
    return Appearance(
        a.height_m, a.width_scale, (hue, int(rng.integers(140, 240)), a.shirt_hsv[2]),
        (trousers_hue, a.trousers_hsv[1], a.trousers_hsv[2]), a.skin_hsv, a.carry,
    )


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
        for o in site.obstacles:
            # Slab test on the segment origin + s d, s in [0, 1).
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = (np.asarray(o.min) - origin) / d
                t2 = (np.asarray(o.max) - origin) / d
            tmin = np.nanmax(np.minimum(t1, t2), axis=1)
            tmax = np.nanmin(np.maximum(t1, t2), axis=1)
            hidden |= (tmax >= np.maximum(tmin, 0.0)) & (tmin < 0.98)
    return hidden


def _bbox(kp: NDArray, cam: Camera) -> NDArray[np.float32]:
    v = kp[~np.isnan(kp[:, 0]), :2]
    lo, hi = v.min(0), v.max(0)
    pad = 0.1 * (hi - lo) + 8.0
    size = np.array([cam.width - 1, cam.height - 1], dtype=np.float64)
    lo = np.clip(lo - pad, 0.0, size)
    hi = np.clip(hi + pad, lo, size)
    return np.array([lo[0], lo[1], hi[0], hi[1]], dtype=np.float32)


def _person_histogram(a: Appearance, kp: NDArray, light: Lighting, rng: np.random.Generator) -> NDArray[np.float32]:
    """HS histogram of a synthetic 32-pixel-wide patch: head, shirt and trousers where their
    joints are visible, plus background at the sides, under the camera's lighting, through the
    real colour code."""
    vis = ~np.isnan(kp[:, 0])
    rows: list[tuple[tuple[int, int, int], int]] = []
    if vis[:5].any():
        rows.append((a.skin_hsv, 8))
    if vis[5:11].any():
        rows.append((a.shirt_hsv, 28))
    if vis[11:].any():
        rows.append((a.trousers_hsv, 28))
    h = sum(n for _, n in rows)
    patch = np.empty((h, 32, 3), dtype=np.float32)
    r = 0
    for hsv, n in rows:
        patch[r : r + n] = hsv
        r += n
    # Background shows at the sides of the box.
    patch[:, :3] = light.background_hsv
    patch[:, 29:] = light.background_hsv
    hsv = patch + rng.normal(size=patch.shape) * [3.0, 22.0, 20.0]  # texture, folds, shading
    hsv[..., 0] = np.mod(hsv[..., 0] + light.hue_shift, 180)
    hsv[..., 1] = np.clip(hsv[..., 1] * light.sat_gain, 0, 255)
    hsv[..., 2] = np.clip(hsv[..., 2] * light.gain, 0, 255)
    bgr = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2BGR)
    return hs_histogram(bgr)


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
        hist = hs_histogram(cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR))
    p3d = np.where(np.isnan(kp[:, :1]), np.nan, rng.uniform(1, 5, size=(body.NUM_KEYPOINTS, 3))).astype(np.float32) if depth else None
    return PersonView(keypoints=kp, bbox=_bbox(kp, cam), histogram=hist, points3d=p3d)
