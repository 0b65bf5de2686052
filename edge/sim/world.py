"""Simulated people moving through a site's free floor.

People with varied body sizes and clothing walk between waypoints with gait and arm swing, turn
in place, stand still and sometimes side-step, avoiding obstacles. A person's plan is periodic
and a pure function of absolute time, so any process that builds a ``World`` from the same site
and seed sees the same people at the same instant (the shared world clock of the simulated
camera nodes). Ground truth is each person's torso pose (x, y, yaw) in REP-103.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Final

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.sim.appearance import Appearance, _distinct_hues, _random_appearance, _recolour
from superbody.edge.sim.skeleton import skeleton
from superbody.edge.site import Site

__all__ = ["PersonState", "SimPerson", "World"]


_PERSON_RADIUS_M: Final = 0.2


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

    start: NDArray  # (2,) where the person starts, and ends the plan

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
