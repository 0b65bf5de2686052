"""Tracker and estimators in hard conditions: seeded simulated scenes, MOTA-style scores (issue 28, item 4).

    python -m benchmarks.scenes [--scenes a,b,...] [--seconds 45] [--seed 1]
                                [--estimators analytic,rays,site] [--timing prompt,late0.8,...]
                                [--jobs 2] [--json-out F]

(from the repository; ``python benchmarks/scenes.py`` works too.)

Each scene is a site built in code (or the shipped apartment), a simulated ``World`` and
changes to what the cameras report (``SCENES``):

- a ``apartment``: the shipped wtf-apartment site, 3 cameras, 3 people (the baseline);
- b ``six-cameras``: 6 cameras around a 5 x 5 m room, 5 people: more cameras than the
  site-independent model's view slots (``graph.max_views``, 4);
- c ``low-cameras``: 4 cameras mounted 1.0 m above the floor, looking level, 4 people;
- d ``crowd``: 5 people within 2 x 2 m (their centres), 4 cameras around them: people
  0.6-0.8 m apart, hiding parts of each other;
- e ``same-colour``: the crowd, every view's histogram replaced by one flat signature
  (identical clothing): association must rest on geometry and time;
- f ``spurious``: a detector's random false positives raised (``NoiseModel.spurious_prob`` 0.3
  per camera frame), 4 people;
- g ``edges``: 4 narrow cameras (37 degrees wide) aimed at different parts of a 6 x 6 m room:
  people are cut off at the image edges and walk out of every view;
- h ``no-colour``: the crowd, every histogram empty (cameras that cannot compute colour);
- i ``phantom``: one camera's detector reports a static person-shaped false positive (a coat
  on a stand) in 80% of its frames; the other cameras, which see that spot, report nothing;
- j ``everything``: the crowd under 6 cameras mounted at 1 m, identical clothing, spurious
  false positives (0.3) and a phantom in a corner of the crowd's floor;
- k ``four-people``: like the real recording held out for issue 28: 5 cameras around a
  2.3 x 2 m area, alternately 1.0 and 2.2 m up, 4 people, no colour, and cameras that are not
  where the site file says (0.5 deg, 2 cm: ``Scene.calibration_error``);
- l ``four-noisy``: k with a real detector's false positives: random partial ones (0.3 per
  camera frame) and a phantom in a corner of the floor that the first camera reports.
- m ``door``: k's room with a doorway to a hallway no camera sees: people walk in and out,
  and stand in or beside the doorway, seen in part by one or two cameras through it.

Every camera runs at 15 fps, frames staggered within the frame period, through the host's pure
core in-process (``host.aggregator.Aggregator``: decode, tracker, set S, estimator, filter):
deterministic for a seed, and with no transport in the figures.

Camera timing (``TIMINGS``, ``--timing``): how the frames reach the host. Each variant feeds
the recording's frames to the aggregator in delivery order, ``now`` = the delivery time, with a
host step after each delivery time (after all the frames delivered then, as the live host steps
after draining its queue). A camera's frame captured at ``c`` is delivered at ``max(previous
delivery, c + delay + jitter)`` (``edge.delivery``: normal jitter clipped at no delay, in order
per camera), and its capture stamp is kept:

- ``prompt``: every frame delivered at its capture time (the figures before camera timing);
- ``late0.3``, ``late0.8``: every camera 0.3 / 0.8 s late;
- ``mixed``: 0.1 / 0.4 / 0.8 / 1.2 / 0.3 s late by camera index (cycling for more cameras),
  50 ms jitter;
- ``mixedfps``: 25 / 10 / 5 / 25 / 10 fps by camera index (cycling), 0.2 s late, 50 ms jitter.
  The cameras are simulated at those rates (a 15 fps recording cannot give 25 fps);
- ``step0.2``: every camera 0.3 s late, and the host steps at most every 0.2 s (a host publishing
  at 5 Hz, ``max_publish_hz``, or one that falls behind): each step fuses three frames of each camera.

Scoring (``MotScorer``), once per 15 fps frame period (at the instant the last camera's frame of
that period is captured), with the array the host last published by then: each published person
is compared with the truth at its own capture time (``PersonPose.stamp_ns``; ``Recording.truth_at``
asks the simulated world at any instant), and published people are matched to true people as
CLEAR MOT does: a true person's last track keeps them while within the gate (0.5 m), the rest by
the Hungarian algorithm on floor distance within the gate. A true person counts (``countable``,
``Visibility``, by capture time: what the cameras captured, delivered yet or not) while some
camera reports at least 3 of their joints (what the tracker uses) within the host's freshness
(0.5 s), once such sightings have gone on for 2.5 s (2 s confirmation + 0.5 s) without a gap over
1 s. A true person matched to a published person counts or not at that person's own capture
time; one matched to nobody, at the instant the array describes (its stamp minus its age
``latency_ns``: the host's watermark, ``host.timeline``; the scoring instant for a host that
publishes at once). A published person matched to a true person who does not count is neither a
hit nor a false positive. ``coverage`` is the share of true
person-steps that count at the scoring instants: what the cameras let the host see.

- ``empty_in_view``: the share of the PoseArrays the host published (one per step) that were
  empty while someone counted at the instant they describe;
- ``mean_views``: cameras per published person.

- recall = hits / countable person-steps; precision = hits / (hits + false positives), a false
  positive being a published person matched to nobody: ``dup`` if a true person is within the
  gate (matched to another track), else ``ghost``;
- identity switches: a true person's hit has a different track id from their previous hit;
- extra tracks: each published track id belongs to whom it was most often matched to or
  beside (within the gate), or to nobody: ghost tracks belong to nobody; duplicate tracks are,
  per true person, the ids beyond the first that belong to them (a person split in two, or a
  new id after a loss);
- MOTA = 1 - (misses + false positives + identity switches) / countable person-steps;
- position (mm) and yaw (deg) errors of the hits: median and p90.

Estimators: ``analytic`` (geometry; with the sigmas of the site's shipped model's hybrid
calibration where it has one, else none, so the filter uses its defaults), ``geo-sim`` (geometry
with its sigmas fitted on simulation of the site, ``models.sim_calibration.geometry_calibration``:
what a new site's no-ground-truth journey gives the host wherever its hybrid trusts the network
on no axis, as with three or more cameras), ``rays`` (the site-independent model
``models/site-independent.fp32.onnx``; ``views>max`` is the share of its estimates whose set S
had more views than its slots: it keeps the views with most joints and says so only in a log
line at start-up), ``site`` (the site's shipped model, apartment only).

The "bar" column applies the bar set for a real recording: recall >= 95%, no identity switch,
no extra track, false positives <= 5% of published people, median position <= 35 mm and
median yaw <= 7 deg.

``--json-out F`` writes ``{"config": {...}, "scenes": {key: {name, cameras, people, coverage,
..., "estimators": {estimator: {recall, precision, mota, id_switches, extra_tracks, ...}}}}}``.
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import json
import math
import os
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, Literal

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from superbody.edge import transport
from superbody.edge.angles import wrap_angle
from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.colour import HIST_BINS
from superbody.edge.delivery import DeliveryModel, delivery_times
from superbody.edge.messages import wire
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.resources import model_path, site_path
from superbody.edge.sim import Appearance, NoiseModel, PersonState, SimCamera, World, render_views, skeleton
from superbody.edge.site import Obstacle, Site, load_site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.estimation import build_estimator, default_model
from superbody.host.estimation.analytic import AnalyticEstimator
from superbody.host.estimation.estimator import Estimates, estimate_detailed
from superbody.host.settings import host_config
from superbody.host.tracking.config import TrackerConfig
from superbody.models.evaluation.temporal import SIGNATURE  # one flat histogram: identical clothing on everyone

__all__ = ["Scene", "SCENES", "Timing", "TIMINGS", "Recording", "MotScorer", "Visibility", "simulate", "deliveries", "replay",
           "run_scene", "tracker_setting", "main"]

FPS: Final = 15.0
T0_NS: Final = 1_700_000_000 * 1_000_000_000  # every scene starts here (the worlds' epoch)
GATE_M: Final = 0.5  # a published person farther than this from a true person is not them
SETTLE_S: Final = 0.5  # after the tracker's confirmation time, before a person counts
ESTIMATOR_NAMES: Final = ("analytic", "geo-sim", "rays", "site")
GEO_SIM_SAMPLES: Final = 1500  # simulated people the "geo-sim" estimator's sigmas are fitted on
_NOBODY: Final = -1  # a published person beside no true person


# -- scenes ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """One simulated scene: a site, its people, and what is changed in the cameras' reports.

    Attributes:
        key, name: the scene's letter and name.
        site: the cameras and floor.
        people: simulated people.
        noise: the detector noise model of every camera.
        colour: ``"own"`` each person's colours, ``"same"`` one flat signature on every view,
            ``"none"`` empty histograms (no colour).
        phantom: a static false person (x, y, yaw) reported by the first camera only, or None.
        phantom_rate: the share of that camera's frames that report it.
        calibration_error: (deg, m): each camera renders the world from a pose off the site
            file's by a rotation of this many degrees about a random axis and a shift of
            this 1-sigma per axis (a real board calibration's error); the host keeps the file's.
    """

    key: str
    name: str
    site: Site
    people: int
    noise: NoiseModel = NoiseModel()
    colour: Literal["own", "same", "none"] = "own"
    phantom: tuple[float, float, float] | None = None
    phantom_rate: float = 0.8
    calibration_error: tuple[float, float] = (0.0, 0.0)


def _camera(cid: str, pos: Sequence[float], target: Sequence[float], width: int = 1280, height: int = 720, f: float = 800.0) -> Camera:
    R = look_at_rotation(np.asarray(pos, float), np.asarray(target, float))
    x, y, z = map(float, pos)
    rows = tuple((float(r[0]), float(r[1]), float(r[2])) for r in R)
    return Camera(id=cid, width=width, height=height, fps=FPS, fx=f, fy=f, cx=width / 2, cy=height / 2, position=(x, y, z), rotation=rows)


def _wall_ring(n: int, w: float, d: float, z: float, aim_z: float, centre: tuple[float, float] | None = None,
               margin: float = 0.1, f: float = 800.0) -> tuple[Camera, ...]:
    """``n`` 720p cameras on the walls of a w x d room, ``z`` up, all aimed at the room's centre (``aim_z`` up)."""
    cx, cy = centre or (w / 2, d / 2)
    cams = []
    for i in range(n):
        a = 2 * math.pi * (i + 0.5) / n  # off the corners' diagonals for n = 4: cameras on the walls
        v = np.array([math.cos(a), math.sin(a)])
        s = min((w / 2 - margin) / max(abs(v[0]), 1e-9), (d / 2 - margin) / max(abs(v[1]), 1e-9))
        cams.append(_camera(f"c{i}", (w / 2 + s * v[0], d / 2 + s * v[1], z), (cx, cy, aim_z), f=f))
    return tuple(cams)


def _square(x0: float, y0: float, x1: float, y1: float) -> tuple[tuple[float, float], ...]:
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


def _room(name: str, n: int, z: float = 2.6, aim_z: float = 0.9) -> Site:
    return Site(name=name, cameras=_wall_ring(n, 5.0, 5.0, z, aim_z), floor=_square(0.0, 0.0, 5.0, 5.0))


def scene_apartment() -> Scene:
    return Scene("a", "apartment", load_site(site_path("wtf-apartment")), 3)


def scene_six_cameras() -> Scene:
    return Scene("b", "six-cameras", _room("room6", 6), 5)


def scene_low_cameras() -> Scene:
    return Scene("c", "low-cameras", _room("low4", 4, z=1.0, aim_z=1.0), 4)


def _crowd_site() -> Site:
    # A 2.6 x 2.6 m patch of a 5 x 5 m room: the simulator keeps people's centres 0.3 m inside
    # the floor, so they stay within 2 x 2 m, mostly standing, turning and shuffling about (the
    # planner keeps them about 0.6 m apart and finds few free paths).
    return Site(name="crowd", cameras=_wall_ring(4, 5.0, 5.0, 2.6, 0.9), floor=_square(1.2, 1.2, 3.8, 3.8))


def scene_crowd() -> Scene:
    return Scene("d", "crowd", _crowd_site(), 5)


def scene_same_colour() -> Scene:
    return Scene("e", "same-colour", _crowd_site(), 5, colour="same")


def scene_spurious() -> Scene:
    return Scene("f", "spurious", _room("room4", 4), 4, noise=NoiseModel(spurious_prob=0.3))


def scene_edges() -> Scene:
    # Narrow lenses (horizontal field of view 2 atan(640 / 1900) = 37 degrees), each camera on
    # a wall aimed at its own part of the room: most of the floor is seen by one camera or none.
    aims = ((1.5, 4.5), (1.5, 1.5), (4.5, 1.5), (4.5, 4.5))
    walls = ((0.1, 3.0), (3.0, 0.1), (5.9, 3.0), (3.0, 5.9))
    cams = tuple(_camera(f"c{i}", (*wall, 2.5), (*aim, 0.9), f=1900.0) for i, (wall, aim) in enumerate(zip(walls, aims)))
    return Scene("g", "edges", Site(name="edges", cameras=cams, floor=_square(0.0, 0.0, 6.0, 6.0)), 4)


def scene_no_colour() -> Scene:
    return Scene("h", "no-colour", _crowd_site(), 5, colour="none")


def scene_phantom() -> Scene:
    return Scene("i", "phantom", _room("room4", 4), 4, phantom=(1.6, 3.2, -0.5))


def scene_everything() -> Scene:
    # The crowd under 6 cameras mounted at 1 m, in identical clothes, with both kinds of false positive.
    site = Site(name="crowd-low6", cameras=_wall_ring(6, 5.0, 5.0, 1.0, 1.0), floor=_crowd_site().floor)
    return Scene("j", "everything", site, 5, noise=NoiseModel(spurious_prob=0.3), colour="same", phantom=(1.55, 3.45, -0.8))


def scene_four_person_room() -> Scene:
    # Like the real four-person recording held out for issue 28: 5 cameras around a 2.3 x 2 m
    # area, alternately 1.0 and 2.2 m up, 4 people, no colour, and a calibration that is not exact.
    ring = _wall_ring(5, 4.3, 4.0, 1.0, 1.0)
    cams = tuple(_camera(c.id, (c.position[0], c.position[1], 1.0 if i % 2 == 0 else 2.2), (2.15, 2.0, 1.0)) for i, c in enumerate(ring))
    site = Site(name="room5", cameras=cams, floor=_square(0.7, 0.7, 3.6, 3.3))
    return Scene("k", "four-people", site, 4, colour="none", calibration_error=(0.5, 0.02))


def scene_four_people_noisy() -> Scene:
    # The four-person room with a real detector's false positives: random partial ones (0.3 per
    # camera frame) and a static phantom in a corner of the floor that the first camera reports.
    k = scene_four_person_room()
    return dataclasses.replace(k, key="l", name="four-noisy", noise=NoiseModel(spurious_prob=0.3), phantom=(1.0, 3.0, -0.8))


def scene_door() -> Scene:
    # The four-person room with a doorway: a wall 2.5 m high along y = 4.0-4.15 m with a 1.6 m
    # opening (x 1.35-2.95), and a hallway behind it (y 4.25-5.2) that no camera sees but through
    # the opening. People walk in and out, stand in the doorway and just beside it: seen by one or
    # two cameras, in part (the door's edges cut their bodies), or not at all.
    k = scene_four_person_room()
    x0, x1 = 1.35, 2.95
    floor = ((0.7, 0.7), (3.6, 0.7), (3.6, 3.3), (x1, 3.3), (x1, 4.25), (3.6, 4.25), (3.6, 5.2), (0.7, 5.2), (0.7, 4.25),
             (x0, 4.25), (x0, 3.3), (0.7, 3.3))
    walls = (Obstacle("wall-west", (0.0, 4.0, 0.0), (x0, 4.15, 2.5)), Obstacle("wall-east", (x1, 4.0, 0.0), (4.3, 4.15, 2.5)))
    site = dataclasses.replace(k.site, name="room5-door", floor=floor, obstacles=walls)
    return dataclasses.replace(k, key="m", name="door", site=site)


SCENES: Final[dict[str, Callable[[], Scene]]] = {
    "a": scene_apartment, "b": scene_six_cameras, "c": scene_low_cameras, "d": scene_crowd, "e": scene_same_colour,
    "f": scene_spurious, "g": scene_edges, "h": scene_no_colour, "i": scene_phantom, "j": scene_everything,
    "k": scene_four_person_room, "l": scene_four_people_noisy, "m": scene_door,
}

# A coat on a stand: grey, person-sized.
_PHANTOM_LOOK: Final = Appearance(1.7, 1.0, (0, 15, 80), (0, 10, 50), (10, 30, 120))


# -- camera timing -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Timing:
    """How a scene's cameras deliver their frames (module docstring).

    Attributes:
        name: the variant's name (``TIMINGS``).
        delays_s: capture-to-delivery delay by camera index, seconds, cycling for more cameras.
        jitter_s: the delays' standard deviation (normal, clipped at no delay), every camera.
        fps: capture rate by camera index, cycling, or None: every camera at ``FPS``.
        step_s: the host steps at most this often, seconds of its clock (as ``max_publish_hz``
            makes it, or a host that falls behind); 0: after each delivery time.
    """

    name: str
    delays_s: tuple[float, ...] = (0.0,)
    jitter_s: float = 0.0
    fps: tuple[float, ...] | None = None
    step_s: float = 0.0

    def delivery(self, index: int) -> DeliveryModel:
        """Camera ``index``'s delay and jitter."""
        return DeliveryModel(self.delays_s[index % len(self.delays_s)], self.jitter_s)

    def camera_fps(self, cameras: int) -> tuple[float, ...]:
        """(cameras,) each camera's capture rate."""
        return tuple(FPS if self.fps is None else self.fps[i % len(self.fps)] for i in range(cameras))


TIMINGS: Final[dict[str, Timing]] = {t.name: t for t in (
    Timing("prompt"),
    Timing("late0.3", (0.3,)),
    Timing("late0.8", (0.8,)),
    Timing("mixed", (0.1, 0.4, 0.8, 1.2, 0.3), 0.05),
    Timing("mixedfps", (0.2,), 0.05, (25.0, 10.0, 5.0, 25.0, 10.0)),
    Timing("step0.2", (0.3,), step_s=0.2),
)}


# -- simulation --------------------------------------------------------------------------------


@dataclass
class Recording:
    """What a scene's cameras published, and the truth.

    Attributes:
        frames: per frame in capture order: (stamp ns, camera id, payload, the true people it
            reports with at least ``min_joints`` joints).
        truth: capture stamp -> (N, 3) every person's (x, y, yaw) then.
        people: N.
        phantom_views: views of the phantom published.
        score_at: the scoring instants (ns): once per ``FPS`` frame period, when the last
            camera's frame of that period is captured.
        fps: (cameras,) each camera's capture rate.
        states: the simulated world's ``states(t_s)``, for the truth at any instant.
    """

    frames: list[tuple[int, str, bytes, tuple[int, ...]]] = field(default_factory=list)
    truth: dict[int, NDArray[np.float64]] = field(default_factory=dict)
    people: int = 0
    phantom_views: int = 0
    score_at: list[int] = field(default_factory=list)
    fps: tuple[float, ...] = ()
    states: Callable[[float], list[PersonState]] | None = None

    def truth_at(self, stamp_ns: int) -> NDArray[np.float64]:
        """(N, 3) every person's (x, y, yaw) at any instant: a frame's remembered truth, else the world's."""
        hit = self.truth.get(stamp_ns)
        if hit is not None:
            return hit
        if self.states is None:
            raise KeyError(f"no truth at {stamp_ns} and no world to ask")
        return np.array([[s.x, s.y, s.yaw] for s in self.states(stamp_ns * 1e-9)]).reshape(-1, 3)


def _recolour(obs: Observation, colour: str) -> Observation:
    if colour == "own":
        return obs
    hist = SIGNATURE if colour == "same" else np.zeros(HIST_BINS, np.float32)
    return dataclasses.replace(obs, people=tuple(dataclasses.replace(v, histogram=hist) for v in obs.people))


def _phantom_view(scene: Scene, cam: SimCamera, frame: int, seed: int) -> PersonView | None:
    """The phantom as that camera's detector reports it in this frame, or None (not reported)."""
    assert scene.phantom is not None
    rng = np.random.default_rng([seed, 0xFA, frame])
    if rng.uniform() >= scene.phantom_rate:
        return None
    x, y, yaw = scene.phantom
    state = PersonState(x, y, yaw, skeleton(x, y, yaw, 0.0, 0.0, _PHANTOM_LOOK.height_m))
    views = render_views([state], [_PHANTOM_LOOK], cam.camera, rng, dataclasses.replace(scene.noise, view_miss_prob=0.0, spurious_prob=0.0),
                         None, cam.lighting)
    return views[0][1] if views else None


def miscalibrated(site: Site, degrees: float, metres: float, seed: int) -> Site:
    """The site with each camera turned by ``degrees`` about a random axis and moved by a
    Gaussian shift of ``metres`` per axis (seeded): where the cameras really are when the site
    file's calibration is off by that much."""
    if degrees == 0 and metres == 0:
        return site
    rng = np.random.default_rng([seed, 0xCA1])
    cams = []
    for c in site.cameras:
        axis = rng.normal(size=3)
        R = np.asarray(c.rotation) @ cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(degrees))[0]
        pos = np.asarray(c.position) + rng.normal(0.0, metres, 3)
        cams.append(dataclasses.replace(c, rotation=tuple(tuple(float(v) for v in r) for r in R), position=tuple(float(v) for v in pos)))
    return dataclasses.replace(site, cameras=tuple(cams))


def calibration_floor_mm(scene: Scene, seed: int, cell_m: float = 0.25) -> float:
    """How far the site's calibration alone puts people, mm: the median, over the floor (a
    ``cell_m`` grid) where two or more cameras see a torso, of the distance between a point and
    its torso centre as the host would place it from exact pixels: the hips' and shoulders'
    heights above the point projected through the cameras where they really are
    (``miscalibrated``: ``Scene.calibration_error`` drawn by ``seed``) and triangulated through
    the site's (``host.estimation.analytic.triangulate``), the two heights' points averaged.
    No detector noise, no tracker: the part of a scene's position error that no estimator can
    remove (a shift common to the cameras moves every person with it). 0 without a calibration
    error; NaN where no floor point is seen twice."""
    if scene.calibration_error == (0.0, 0.0):
        return 0.0
    from superbody.edge.body import LEFT_HIP, LEFT_SHOULDER, TYPICAL_HEIGHT_M
    from superbody.edge.camera import pixel_to_ray, project
    from superbody.edge.floor import floor_points, visible
    from superbody.host.estimation.analytic import triangulate

    site, real = scene.site, miscalibrated(scene.site, *scene.calibration_error, seed)
    xy = floor_points(site.floor, cell_m)  # (N, 2)
    heights = (TYPICAL_HEIGHT_M[LEFT_HIP], TYPICAL_HEIGHT_M[LEFT_SHOULDER])
    placed = np.full((len(heights), len(xy), 2), np.nan)
    for k, h in enumerate(heights):
        points = np.column_stack([xy, np.full(len(xy), h)])  # (N, 3)
        seen = np.array([visible(c, xy, (h,), 0.0, obstacles=site.obstacles) for c in real.cameras])  # (C, N)
        rays = [pixel_to_ray(project(points, c)[0], s)[1] for c, s in zip(real.cameras, site.cameras, strict=True)]  # C x (N, 3)
        for i in np.flatnonzero(seen.sum(axis=0) >= 2):
            cams = np.flatnonzero(seen[:, i])
            placed[k, i] = triangulate(np.array([site.cameras[c].t for c in cams]), np.array([rays[c][i] for c in cams]))[:2]
    err = np.linalg.norm(placed.mean(axis=0) - xy, axis=1)  # (N,) NaN where a height was not seen twice
    return float(np.nanmedian(err) * 1000.0) if np.isfinite(err).any() else math.nan


def simulate(scene: Scene, seconds: float, seed: int, min_joints: int = 3, progress: bool = False,
             fps: Sequence[float] | None = None) -> Recording:
    """Every camera's frames for ``seconds`` of the scene, encoded, with the truth; the cameras
    render from where they really are (``Scene.calibration_error``).

    Camera i captures frame k at ``(k + i / n) / fps_i`` seconds after the scene's start (``fps``:
    by camera, default ``FPS`` for all): staggered within the frame period."""
    site = miscalibrated(scene.site, *scene.calibration_error, seed)
    world = World(site, scene.people, seed=seed, period_s=max(60.0, seconds + 10.0), epoch_s=T0_NS / 1e9)
    # The cameras render the world's states at each capture time; the truth is those same
    # states: remembered as they are computed, not computed twice.
    states, memo = world.states, {}

    def remembered(t_s: float) -> list[PersonState]:
        if t_s not in memo:
            memo[t_s] = states(t_s)
        return memo[t_s]

    world.states = remembered  # type: ignore[method-assign]
    n = len(site.cameras)
    rates = tuple(float(f) for f in fps) if fps is not None else (FPS,) * n
    if len(rates) != n:
        raise ValueError(f"fps: one rate per camera ({n}), got {len(rates)}")
    cams = [SimCamera(world, c.id, noise=scene.noise, fps=f) for c, f in zip(site.cameras, rates)]
    rec = Recording(people=scene.people, fps=rates, states=states)
    rounds = int(seconds * FPS)
    rec.score_at = [T0_NS + int((k + (n - 1) / n) * 1e9 / FPS) for k in range(rounds)]
    # Every camera's capture instants, in capture order (at equal rates: round by round, camera by camera).
    schedule = sorted((T0_NS + int((k + i / n) * 1e9 / f), i, k) for i, f in enumerate(rates) for k in range(int(seconds * f)))
    bar = _bar(len(schedule), f"{scene.key} simulate", progress)
    for stamp, i, k in schedule:
        cam = cams[i]
        obs, who = cam.observe(stamp)
        if scene.phantom is not None and i == 0:
            view = _phantom_view(scene, cam, k, seed)
            if view is not None:
                obs = dataclasses.replace(obs, people=obs.people + (view,))
                rec.phantom_views += 1
        obs = _recolour(obs, scene.colour)
        seen = tuple(sorted({w for w, v in zip(who, obs.people) if w >= 0 and v.num_visible >= min_joints}))
        rec.frames.append((stamp, cam.camera.id, wire.encode(obs), seen))
        rec.truth[stamp] = np.array([[s.x, s.y, s.yaw] for s in memo.pop(stamp * 1e-9)]).reshape(-1, 3)
        bar.update()
    bar.close()
    return rec


def deliveries(rec: Recording, site: Site, timing: Timing, seed: int) -> list[tuple[int, int]]:
    """When each frame of a recording reaches the host: (delivery time ns, index in ``rec.frames``),
    in delivery order (ties in capture order). Each camera's delays are drawn from its own
    seeded generator (``seed``, camera index)."""
    index = {c.id: i for i, c in enumerate(site.cameras)}
    by_camera: dict[str, list[int]] = {}
    for j, frame in enumerate(rec.frames):
        by_camera.setdefault(frame[1], []).append(j)
    out: list[tuple[int, int]] = []
    for cam, idx in by_camera.items():
        i = index[cam]
        stamps = np.array([rec.frames[j][0] for j in idx], dtype=np.int64)
        model = timing.delivery(i)
        due = delivery_times(stamps, model.delays_ns(len(stamps), np.random.default_rng([seed, 0xDE1, i])))
        out.extend(zip(due.tolist(), idx))
    out.sort()
    return out


# -- scoring -----------------------------------------------------------------------------------


class Visibility:
    """Which true people count at a time: seen (by any camera, enough joints) within ``fresh_s``,
    in a run of sightings without a gap over ``gap_s`` that began at least ``settle_s`` ago.

    Sightings are kept by capture time, so ``countable`` answers for any instant (only the
    sightings up to it count), in whatever order the instants are asked.

    Args:
        people: N.
        fresh_s, gap_s, settle_s: as above (the host's freshness, the tracker's
            ``confirm_max_gap_s`` and its confirmation time plus ``SETTLE_S``).
    """

    def __init__(self, people: int, fresh_s: float = 0.5, gap_s: float = 1.0, settle_s: float = 2.5):
        self._times: list[list[int]] = [[] for _ in range(people)]  # per person, sighting stamps (ascending)
        self._starts: list[list[int]] = [[] for _ in range(people)]  # the start of the run each sighting belongs to
        self.fresh_ns, self.gap_ns, self.settle_ns = (round(v * 1e9) for v in (fresh_s, gap_s, settle_s))

    def saw(self, who: Sequence[int], stamp_ns: int) -> None:
        """People seen at capture time ``stamp_ns``; each person's sightings must come in capture order."""
        for k in who:
            times, starts = self._times[k], self._starts[k]
            if times and stamp_ns < times[-1]:
                raise ValueError(f"person {k}: sighting at {stamp_ns} ns before the one at {times[-1]} ns")
            starts.append(stamp_ns if not times or stamp_ns - times[-1] > self.gap_ns else starts[-1])
            times.append(stamp_ns)

    def countable(self, now_ns: int) -> NDArray[np.bool_]:
        """(N,) whether each person counts at ``now_ns``."""
        out = np.zeros(len(self._times), dtype=bool)
        for k, times in enumerate(self._times):
            i = bisect.bisect_right(times, now_ns) - 1
            out[k] = i >= 0 and now_ns - times[i] <= self.fresh_ns and now_ns - self._starts[k][i] >= self.settle_ns
        return out


class MotScorer:
    """MOTA-style scores of published people against the truth, one step at a time.

    Args:
        gate_m: a published person farther than this from a true person is not them.
    """

    def __init__(self, gate_m: float = GATE_M):
        self.gate_m = gate_m
        self.steps = self.truth_steps = self.gt = self.tp = self.fn = self.idsw = self.ghost_steps = self.dup_steps = 0
        self.visible = 0  # true person-steps that count at the scoring instants: what the cameras show, whatever is published
        self.published = 0
        self.pos_err: list[float] = []
        self.yaw_err: list[float] = []
        self._last_id: dict[int, int] = {}  # true person -> track id of their last hit
        self._owners: dict[int, Counter[int]] = {}  # track id -> steps matched to, or beside, each true person (or _NOBODY)
        self._ids: set[int] = set()  # every published track id

    def add(self, truth: NDArray, countable: NDArray, ids: Sequence[int], poses: NDArray, countable_at: NDArray | None = None) -> None:
        """Score one step.

        Args:
            truth: (N, 3) the true people's (x, y, yaw), or (M, N, 3): at each published
                person's own capture time.
            countable: (N,) which true people count now (``Visibility``): for those matched to nobody.
            ids: (M,) published track ids.
            poses: (M, 3) published (x, y, yaw).
            countable_at: (M, N) which true people count at each published person's own capture
                time: for those matched to that person (default: ``countable``).
        """
        countable = np.asarray(countable, dtype=bool)
        n, m = len(countable), len(ids)
        poses = np.asarray(poses, dtype=np.float64).reshape(m, 3)
        truth = np.broadcast_to(np.asarray(truth, dtype=np.float64).reshape(-1, n, 3), (m, n, 3)) if m else np.zeros((0, n, 3))
        self.steps += 1
        self.truth_steps += n
        self.visible += int(countable.sum())
        self.published += m
        self._ids.update(int(i) for i in ids)
        dist = np.linalg.norm(truth[:, :, :2] - poses[:, None, :2], axis=2)  # (M, N)
        rows, cols = self._match(dist, [int(i) for i in ids])
        counts = countable.copy()  # whether each true person counts, when the step is taken to see them
        if countable_at is not None:
            at = np.asarray(countable_at, dtype=bool).reshape(m, n)
            for r, k in zip(rows, cols):
                counts[k] = at[r, k]
        self.gt += int(counts.sum())
        hit = np.zeros(n, dtype=bool)
        taken = np.zeros(m, dtype=bool)
        for r, k in zip(rows, cols):
            taken[r] = True
            tid = int(ids[r])
            self._owners.setdefault(tid, Counter())[int(k)] += 1
            if not counts[k]:
                continue  # a person the cameras have not shown long enough: neither hit nor false positive
            hit[k] = True
            self.tp += 1
            if self._last_id.get(int(k), tid) != tid:
                self.idsw += 1
            self._last_id[int(k)] = tid
            self.pos_err.append(float(dist[r, k]))
            self.yaw_err.append(abs(float(wrap_angle(poses[r, 2] - truth[r, k, 2]))))
        self.fn += int((counts & ~hit).sum())
        for r in np.flatnonzero(~taken).tolist():
            if n and dist[r].min() <= self.gate_m:  # beside someone already matched: a duplicate of them
                self.dup_steps += 1
                self._owners.setdefault(int(ids[r]), Counter())[int(dist[r].argmin())] += 1
            else:
                self.ghost_steps += 1
                self._owners.setdefault(int(ids[r]), Counter())[_NOBODY] += 1

    def _match(self, dist: NDArray, ids: list[int]) -> tuple[list[int], list[int]]:
        """CLEAR MOT's matching (Bernardin and Stiefelhagen 2008): a true person's last track
        keeps them while it stays within the gate; the rest by the Hungarian algorithm on
        distance. Two people passing close by are not counted as swapping tracks when the
        tracks did not swap."""
        m, n = dist.shape
        row_of = {tid: r for r, tid in enumerate(ids)}
        rows: list[int] = []
        cols: list[int] = []
        for k, tid in self._last_id.items():
            r = row_of.get(tid)
            if r is not None and r not in rows and k < n and dist[r, k] <= self.gate_m:  # a track may have hopped between people
                rows.append(r)
                cols.append(k)
        free_r = [r for r in range(m) if r not in rows]
        free_k = [k for k in range(n) if k not in cols]
        if free_r and free_k:
            sub = dist[np.ix_(free_r, free_k)]
            for i, j in zip(*linear_sum_assignment(np.where(sub <= self.gate_m, sub, 1e6))):
                if sub[i, j] <= self.gate_m:
                    rows.append(free_r[i])
                    cols.append(free_k[j])
        return rows, cols

    def summary(self) -> dict:
        """The scores (module docstring); NaN where undefined (no countable person, no hit)."""
        fp = self.ghost_steps + self.dup_steps
        owner = {tid: c.most_common(1)[0][0] for tid, c in self._owners.items()}
        per_person = Counter(k for k in owner.values() if k != _NOBODY)
        ghosts = sum(k == _NOBODY for k in owner.values())
        dups = sum(c - 1 for c in per_person.values())
        pos = np.array(self.pos_err) * 1000
        yaw = np.degrees(self.yaw_err)

        def q(a: NDArray, p: float) -> float:
            return float(np.percentile(a, p)) if len(a) else math.nan

        return {
            "steps": self.steps, "true_person_steps": self.truth_steps, "countable_person_steps": self.gt,
            "published_person_steps": self.published, "hits": self.tp, "misses": self.fn, "false_positives": fp,
            "ghost_steps": self.ghost_steps, "duplicate_steps": self.dup_steps, "id_switches": self.idsw,
            "recall": self.tp / self.gt if self.gt else math.nan,
            "precision": self.tp / (self.tp + fp) if self.tp + fp else math.nan,
            "false_positive_share": fp / self.published if self.published else math.nan,
            "mota": 1.0 - (self.fn + fp + self.idsw) / self.gt if self.gt else math.nan,
            "tracks": len(self._ids), "ghost_tracks": ghosts, "duplicate_tracks": dups, "extra_tracks": ghosts + dups,
            "coverage": self.visible / self.truth_steps if self.truth_steps else math.nan,
            "position_mm_p50": q(pos, 50), "position_mm_p90": q(pos, 90), "yaw_deg_p50": q(yaw, 50), "yaw_deg_p90": q(yaw, 90),
        }


def bar_misses(s: Mapping[str, float]) -> list[str]:
    """The criteria of the bar for a real recording (module docstring) that a run's scores miss,
    each as ``"name value"`` (e.g. ``"position 37 mm"``); empty when it meets the bar."""
    checks = (("recall", s["recall"] >= 0.95, f"{s['recall']:.3f}"), ("switches", s["id_switches"] == 0, f"{s['id_switches']}"),
              ("extra tracks", s["extra_tracks"] == 0, f"{s['extra_tracks']}"),
              ("false positives", s["false_positive_share"] <= 0.05, f"{100 * s['false_positive_share']:.1f}%"),
              ("position", s["position_mm_p50"] <= 35, f"{s['position_mm_p50']:.0f} mm"), ("yaw", s["yaw_deg_p50"] <= 7, f"{s['yaw_deg_p50']:.1f} deg"))
    return [f"{name} {value}" for name, ok, value in checks if not ok]


def meets_bar(s: Mapping[str, float]) -> bool:
    """The bar for a real recording (module docstring)."""
    return not bar_misses(s)


# -- the host ----------------------------------------------------------------------------------


class _ViewLimit:
    """Wraps a "rays" model to count the estimates whose set S has more views than its slots
    (the model keeps the ``max_views`` with most joints; the host says so once, at start-up)."""

    def __init__(self, inner, source: str, max_views: int):
        self.inner, self.source, self.max_views = inner, source, max_views
        self.estimates = self.over = 0
        self.largest = 0

    def _count(self, view_sets: Sequence[Mapping[str, PersonView]]) -> None:
        sizes = [len(v) for v in view_sets]
        self.estimates += len(sizes)
        self.over += sum(s > self.max_views for s in sizes)
        self.largest = max([self.largest, *sizes])

    def estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> NDArray[np.float64]:
        self._count(view_sets)
        return self.inner.estimate(view_sets)

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates:
        self._count(view_sets)
        return estimate_detailed(self.inner, view_sets, self.source)


def estimators_for(site: Site, names: Sequence[str]) -> dict[str, tuple[object, str]]:
    """The estimators of ``names`` that can serve the site: name -> (estimator, name in PoseArrays).

    Raises:
        ValueError: an unknown name (listing the valid ones).
    """
    out: dict[str, tuple[object, str]] = {}
    for name in names:
        if name == "analytic":
            out[name] = build_estimator(site, "analytic")
        elif name == "geo-sim":
            from superbody.models.sim_calibration import geometry_calibration

            out[name] = (AnalyticEstimator(site, geometry_calibration(site, samples=GEO_SIM_SAMPLES)), "analytic")
        elif name == "rays":
            path = model_path("site-independent.fp32.onnx")
            if path is not None:
                est, label = build_estimator(site, "auto", path)
                spec = getattr(est, "spec", None)
                if spec is not None and spec.variant == "rays":
                    est = _ViewLimit(est, label.split(":", 1)[0], spec.max_views)
                out[name] = (est, label)
        elif name == "site":
            if default_model(site) is not None:
                out[name] = build_estimator(site, "auto")
        else:
            raise ValueError(f"unknown estimator {name!r}; valid estimators: {', '.join(ESTIMATOR_NAMES)}")
    return out


def replay(scene: Scene, rec: Recording, estimator, name: str, config: HostConfig = HostConfig(), progress: bool = False,
           timing: Timing = TIMINGS["prompt"], seed: int = 0) -> dict:
    """The recording through the host's aggregator in delivery order (``deliveries``), a step
    after each delivery time; the scores (module docstring)."""
    site = scene.site
    agg = Aggregator(site, estimator, name, config)
    keys = {c.id: transport.observation_key(site.name, c.id) for c in site.cameras}
    tc = config.tracker
    vis = Visibility(rec.people, config.freshness_s, tc.confirm_max_gap_s, tc.confirm_after_s + SETTLE_S)
    for stamp, _cam, _payload, seen in rec.frames:  # what the cameras captured, delivered yet or not
        vis.saw(seen, stamp)
    if isinstance(estimator, _ViewLimit):
        estimator.estimates = estimator.over = estimator.largest = 0
    scorer = MotScorer()
    views: list[int] = []
    order = deliveries(rec, site, timing, seed)
    bar = _bar(len(order), f"{scene.key} {name} {timing.name}", progress)
    published: tuple = ()  # the host's last PoseArray's people ...
    as_of = 0  # ... and the instant it describes: its stamp minus its age (the host's watermark)
    arrays = in_view = empty_in_view = 0
    todo = iter(rec.score_at)
    s_next = next(todo, None)

    def score(at_ns: int, people: tuple) -> None:
        truth = np.stack([rec.truth_at(p.stamp_ns) for p in people]) if people else np.zeros((0, rec.people, 3))
        at = np.stack([vis.countable(p.stamp_ns) for p in people]) if people else None
        scorer.add(truth, vis.countable(at_ns), [p.id for p in people], np.array([[p.x, p.y, p.yaw] for p in people]).reshape(-1, 3), at)
        views.extend(p.views for p in people)

    i = 0
    step_ns, next_step = round(timing.step_s * 1e9), -1
    while i < len(order):
        now = order[i][0]
        while s_next is not None and s_next < now:  # scored with what the host had published by then
            score(as_of, published)
            s_next = next(todo, None)
        while i < len(order) and order[i][0] == now:
            stamp, cam, payload, _seen = rec.frames[order[i][1]]
            agg.ingest(payload, keys[cam], now)
            i += 1
            bar.update()
        if now < next_step:
            continue
        next_step = now + step_ns
        arr = agg.step(now)
        published, as_of = arr.people, arr.stamp_ns - arr.latency_ns
        arrays += 1
        if vis.countable(as_of).any():
            in_view += 1
            empty_in_view += not published
    while s_next is not None:
        score(as_of, published)
        s_next = next(todo, None)
    bar.close()
    out = scorer.summary()
    out["meets_bar"] = meets_bar(out)
    out["mean_views"] = float(np.mean(views)) if views else math.nan
    out.update(timing=timing.name, frames_delivered=len(order), arrays=arrays, arrays_in_view=in_view,
               empty_in_view=empty_in_view / in_view if in_view else math.nan)
    if isinstance(estimator, _ViewLimit):
        out.update(max_views=estimator.max_views, largest_view_set=estimator.largest,
                   views_over_limit=estimator.over / estimator.estimates if estimator.estimates else 0.0)
    out["rejected"] = dict(agg.rejected)
    st = agg.tracker.stats
    out["tracker"] = {k: st[k] for k in ("new_candidates", "confirmed", "removed", "reidentified", "suppressed", "unplaced_new",
                                          "duplicate_views", "too_few_joints", "no_signature", "track_cap")}
    return out


def result_key(estimator: str, timing: str) -> str:
    """A run's key in a scene's ``estimators``: the estimator's name for ``prompt``, else ``name@timing``."""
    return estimator if timing == "prompt" else f"{estimator}@{timing}"


def tracker_setting(text: str) -> tuple[str, object]:
    """``"FIELD=VALUE"`` (a ``TrackerConfig`` field, as ``[host.tracker]`` sets it) as ``(field, value)``,
    the value of the field's type; checked against the field's range by ``run_scene``.

    Raises:
        argparse.ArgumentTypeError: no ``=``, an unknown field (listing them) or a value not of its type.
    """
    name, eq, raw = (part.strip() for part in text.partition("="))
    types = {f.name: type(getattr(TrackerConfig(), f.name)) for f in dataclasses.fields(TrackerConfig)}
    if not eq or name not in types:
        raise argparse.ArgumentTypeError(f"--tracker must be FIELD=VALUE with FIELD one of {', '.join(types)}; got {text!r}")
    kind = types[name]
    try:
        if kind is bool:
            if raw.lower() not in ("true", "false"):
                raise ValueError
            return name, raw.lower() == "true"
        return name, kind(raw)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tracker {name} must be {'true or false' if kind is bool else 'an integer' if kind is int else 'a number'}, "
                                         f"got {raw!r}") from None


def run_scene(key: str, seconds: float, seed: int, estimators: Sequence[str] = ESTIMATOR_NAMES, progress: bool = False,
              timings: Sequence[str] = ("prompt",), tracker: Mapping[str, object] | None = None) -> dict:
    """Simulate one scene and score every estimator that can serve it, under each camera timing
    (results keyed by ``result_key``), the host set up by ``host.settings.host_config``: its site's
    ``[host]`` table with ``tracker``'s ``TrackerConfig`` fields on top.

    Raises:
        ValueError: an unknown scene or timing; a tracker value out of its field's range (a
            ``SiteError`` naming ``[host.tracker]`` and the field).
    """
    if key not in SCENES:
        raise ValueError(f"unknown scene {key!r}; scenes: {', '.join(f'{k} ({SCENES[k]().name})' for k in SCENES)}")
    bad = [t for t in timings if t not in TIMINGS]
    if bad:
        raise ValueError(f"unknown timing {bad[0]!r}; timings: {', '.join(TIMINGS)}")
    scene = SCENES[key]()
    config = host_config(scene.site, tracker=tracker)  # the host as its site file and these settings set it up
    n = len(scene.site.cameras)
    t = time.monotonic()
    recordings: dict[tuple[float, ...], Recording] = {}  # one simulation per set of camera rates
    for name in timings:
        rates = TIMINGS[name].camera_fps(n)
        if rates not in recordings:
            recordings[rates] = simulate(scene, seconds, seed, progress=progress, fps=rates)
    first = next(iter(recordings.values()))
    per_estimator: dict[str, dict] = {}
    out = {"name": scene.name, "site": scene.site.name, "cameras": n, "people": scene.people,
           "camera_heights_m": [round(c.position[2], 3) for c in scene.site.cameras],
           "colour": scene.colour, "spurious_prob": scene.noise.spurious_prob, "phantom_views": first.phantom_views,
           "frames": len(first.frames), "simulate_s": time.monotonic() - t, "calibration_mm": calibration_floor_mm(scene, seed),
           "estimators": per_estimator}
    for name, (est, label) in estimators_for(scene.site, estimators).items():
        for timing in timings:
            tm = TIMINGS[timing]
            t = time.monotonic()
            r = replay(scene, recordings[tm.camera_fps(n)], est, label, config, progress=progress, timing=tm, seed=seed)
            r["estimator"], r["replay_s"] = label, time.monotonic() - t
            per_estimator[result_key(name, timing)] = r
    return out


def _bar(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", leave=False, disable=not enabled, mininterval=1.0)


# -- the table ---------------------------------------------------------------------------------

_HEADER = (f"{'scene':<15} {'estimator':<9} {'timing':<8} {'cams':>4} {'ppl':>3} {'cover':>5} {'recall':>6} {'prec':>6} {'MOTA':>6} "
           f"{'IDsw':>4} {'extra':>5} {'ghost':>5} {'dup':>4} {'FP%':>5} {'pos50':>5} {'pos90':>5} {'yaw50':>5} {'yaw90':>5} "
           f"{'views':>5} {'empty%':>6} {'views>max':>9} {'bar':>3}")


def _row(key: str, sc: dict, name: str, r: dict) -> str:
    over = f"{100 * r['views_over_limit']:.0f}%" if "views_over_limit" in r else "-"
    return (f"{key + ' ' + sc['name']:<15} {name.split('@')[0]:<9} {r['timing']:<8} {sc['cameras']:>4} {sc['people']:>3} "
            f"{r['coverage']:>5.2f} {r['recall']:>6.3f} {r['precision']:>6.3f} {r['mota']:>6.3f} {r['id_switches']:>4} "
            f"{r['extra_tracks']:>5} {r['ghost_tracks']:>5} {r['duplicate_tracks']:>4} {100 * r['false_positive_share']:>5.1f} "
            f"{r['position_mm_p50']:>5.0f} {r['position_mm_p90']:>5.0f} {r['yaw_deg_p50']:>5.1f} {r['yaw_deg_p90']:>5.1f} "
            f"{r['mean_views']:>5.2f} {100 * r['empty_in_view']:>6.1f} {over:>9} {'yes' if r['meets_bar'] else 'no':>3}")


def main(scenes: Sequence[str], seconds: float, seed: int, estimators: Sequence[str] = ESTIMATOR_NAMES, jobs: int = 1,
         json_out: str | None = None, progress: bool = True, timings: Sequence[str] = ("prompt",)) -> int:
    t = time.monotonic()
    results: dict[str, dict] = {}
    print(f"{len(scenes)} scene(s), {seconds:g} s each at {FPS:g} fps per camera, seed {seed}; scored after each frame period; "
          f"gate {GATE_M} m; positions in mm, yaw in deg (median, p90); extra = ghost + duplicate tracks; FP% = false positives "
          "/ published people; views = cameras per published person; empty% = empty PoseArrays / those published while someone "
          "counts; bar = the real-recording bar; timing = how the cameras deliver (benchmarks/scenes.py TIMINGS)", flush=True)
    print(_HEADER, flush=True)

    def show(key: str, sc: dict) -> None:
        results[key] = sc
        for name, r in sc["estimators"].items():
            print(_row(key, sc, name, r), flush=True)

    if jobs <= 1 or len(scenes) == 1:
        for key in scenes:
            show(key, run_scene(key, seconds, seed, estimators, progress=progress, timings=timings))
    else:
        from tqdm import tqdm

        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(run_scene, key, seconds, seed, tuple(estimators), False, tuple(timings)): key for key in scenes}
            for fut in tqdm(as_completed(futures), total=len(futures), desc="scenes", leave=False, disable=not progress):
                show(futures[fut], fut.result())
    elapsed = time.monotonic() - t
    print(f"{elapsed:.0f} s", flush=True)
    if json_out:
        doc = {"config": {"seconds": seconds, "seed": seed, "fps": FPS, "gate_m": GATE_M, "settle_s": SETTLE_S, "elapsed_s": elapsed,
                          "scenes": list(scenes), "estimators": list(estimators), "timings": list(timings)},
               "scenes": {k: results[k] for k in scenes}}
        Path(json_out).write_text(json.dumps(_jsonable(doc), indent=1, allow_nan=False) + "\n")
    return 0


def _jsonable(v: object) -> object:
    """Strict JSON: NaN (an undefined score) as null, numpy scalars as Python numbers."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.integer, np.floating)):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _keys(text: str, valid: Sequence[str], what: str) -> list[str]:
    keys = [k.strip() for k in text.split(",") if k.strip()]
    bad = [k for k in keys if k not in valid]
    if not keys or bad:
        raise argparse.ArgumentTypeError(f"--{what} must be a comma-separated list of {', '.join(valid)}; got {text!r}")
    return keys


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=lambda s: _keys(s, list(SCENES), "scenes"), default=list(SCENES),
                   help=f"scenes to run, e.g. a,d (default: all of {','.join(SCENES)})")
    p.add_argument("--seconds", type=float, default=45.0, help="simulated seconds per scene (default 45)")
    p.add_argument("--seed", type=int, default=1, help="the worlds' and detectors' seed")
    p.add_argument("--estimators", type=lambda s: _keys(s, ESTIMATOR_NAMES, "estimators"), default=list(ESTIMATOR_NAMES),
                   help="estimators to score (default: analytic,rays,site; site only where the site ships a model)")
    p.add_argument("--timing", type=lambda s: _keys(s, list(TIMINGS), "timing"), default=["prompt"],
                   help=f"camera timings to run, e.g. prompt,late0.8 (default prompt; any of {','.join(TIMINGS)})")
    p.add_argument("--jobs", type=int, default=1, help="scenes run in this many processes at once")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--json-out")
    a = p.parse_args()
    if not (3.0 <= a.seconds <= 3600.0):
        p.error(f"--seconds must be in [3, 3600], got {a.seconds}")
    if not 1 <= a.jobs <= (os.cpu_count() or 1) * 4:
        p.error(f"--jobs must be in [1, {(os.cpu_count() or 1) * 4}], got {a.jobs}")
    sys.exit(main(a.scenes, a.seconds, a.seed, a.estimators, a.jobs, a.json_out, progress=not a.no_progress, timings=a.timing))
