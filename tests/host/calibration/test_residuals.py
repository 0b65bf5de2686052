"""Leave-one-out residuals (host/calibration/residuals.py): exact on exact views, a turned
camera's residual is its turn, what is left unmeasured, and views of a walking person brought
to one time."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from benchmarks.people_calibration import knock, sim_site
from superbody.edge.camera import project
from superbody.edge.messages.observation import PersonView, empty_histogram
from superbody.edge.sim import skeleton
from superbody.host.calibration.residuals import Instant, instant_from_views, instant_residuals, leave_one_out, rays
from tests.host.calibration.simulated import T0, exact_instants


def _residuals(site, instants):
    cams = {c.id: c for c in site.cameras}
    deg, px = {c: [] for c in cams}, {c: [] for c in cams}
    for ins in instants:
        d, p = instant_residuals(ins, cams)
        for i, c in enumerate(ins.cameras):
            deg[c].extend(d[i][~np.isnan(d[i])])
            px[c].extend(p[i][~np.isnan(p[i])])
    return {c: np.array(v) for c, v in deg.items()}, {c: np.array(v) for c, v in px.items()}


@pytest.mark.parametrize("name", ["wtf-apartment", "lab-example", "room5"])  # 3 cameras; 4 with lens distortion; 5 at two heights
def test_exact_views_have_no_residual(name: str) -> None:
    site = sim_site(name)
    deg, px = _residuals(site, exact_instants(site, 30))
    for c in site.camera_ids:
        assert len(deg[c]) > 20, c
        assert deg[c].max() < 1e-6 and px[c].max() < 1e-4, c


# (site, camera, turn about the camera's own axis): the turned camera's residual is the turn
# (rays near the turn's axis move less: its median within 15%); leaving it out keeps the others'
# points right wherever another camera saw them, so they are untouched there.
TURNS = [
    ("lab-example", "nw", (0.0, 1.0, 0.0), 2.0),   # pan
    ("lab-example", "se", (1.0, 0.0, 0.0), 1.0),   # tilt
    ("room5", "c2", (1.0, 1.0, 0.0), 3.0),         # both, a camera 1 m up
    ("wtf-apartment", "2", (0.0, 1.0, 0.0), 2.0),  # pan, three cameras
]


@pytest.mark.parametrize("name, cam, axis, degrees", TURNS)
def test_a_turned_camera_shows_its_turn(name: str, cam: str, axis: tuple, degrees: float) -> None:
    site = sim_site(name)
    instants = exact_instants(site, 40)
    turned = [dataclasses.replace(c, rotation=tuple(map(tuple, c.R @ cv2.Rodrigues(np.array(axis) / np.linalg.norm(axis)
                                                                                      * math.radians(degrees))[0])))
              if c.id == cam else c for c in site.cameras]
    deg, px = _residuals(dataclasses.replace(site, cameras=tuple(turned)), instants)
    assert np.median(deg[cam]) == pytest.approx(degrees, rel=0.15)
    c = site.camera(cam)
    assert np.median(px[cam]) == pytest.approx(math.radians(degrees) * c.fx, rel=0.2)  # pixels ~ angle x focal near the centre


def test_unmeasured_joints() -> None:
    site = sim_site("lab-example")
    ins = exact_instants(site, 1)[0]
    # (what is done to the instant, which residuals must be NaN)
    two = Instant(ins.stamp_ns, ins.cameras[:2], ins.keypoints[:2], ins.offsets_m[:2])
    deg, px = instant_residuals(two, {c.id: c for c in site.cameras})
    assert deg.shape == (2, 17) and np.isnan(deg).all() and np.isnan(px).all()  # one other view: nothing measured
    kp = ins.keypoints.copy()
    kp[1:, 0] = np.nan  # the nose seen by the first camera only
    deg, _ = instant_residuals(dataclasses.replace(ins, keypoints=kp), {c.id: c for c in site.cameras})
    assert np.isnan(deg[:, 0]).all()
    empty = Instant(ins.stamp_ns, (), np.zeros((0, 17, 3)), np.zeros((0, 3)))
    assert instant_residuals(empty, {})[0].shape == (0, 17)


def test_parallel_rays_place_no_point() -> None:
    site = sim_site("lab-example")
    cam = site.cameras[0]
    near = dataclasses.replace(cam, id="twin", position=tuple(cam.t + 0.01 * cam.R[:, 0]))  # 1 cm beside it: rays 0.2 deg apart at 3 m
    joints = skeleton(3.0, 2.5, 0.0, 0.0, 0.0)
    kps = np.stack([np.c_[project(joints, c)[0], np.full(17, 0.9)] for c in (cam, near, site.cameras[2])])
    ins = Instant(T0, (cam.id, "twin", site.cameras[2].id), kps, np.zeros((3, 3)))
    origins, dirs, seen = rays(ins, {c.id: c for c in (cam, near, site.cameras[2])})
    _, ok = leave_one_out(origins, dirs, seen)
    assert not ok[2].any()  # the third camera's joints: the other two barely meet
    assert ok[0].any() and ok[1].any()


def _view(kp) -> PersonView:
    return PersonView(keypoints=kp.astype(np.float32), bbox=np.array([0, 0, 10, 10], np.float32), histogram=empty_histogram())


def test_a_walking_person_seen_at_different_times() -> None:
    """Views 40 ms apart of a person walking at 1.5 m/s (6 cm): their velocity brings them to one time."""
    site = sim_site("lab-example")
    v = np.array([1.5, 0.0, 0.0])
    views, stamps = {}, {}
    for i, cam in enumerate(site.cameras):
        t = T0 + i * 40_000_000
        uv, _ = project(skeleton(2.0, 2.5, 0.0, 0.0, 0.0) + v * (t - T0) / 1e9, cam)
        views[cam.id], stamps[cam.id] = _view(np.c_[uv, np.full(17, 0.9)]), t
    cams = {c.id: c for c in site.cameras}
    still = instant_residuals(instant_from_views(views, T0, stamps), cams)[0]
    moving = instant_residuals(instant_from_views(views, T0, stamps, velocity=v[:2]), cams)[0]
    assert np.nanmedian(still) > 0.3
    assert np.nanmax(moving) < 1e-3  # float32 pixels


def test_knock_moves_a_camera_by_exactly_what_it_says() -> None:
    site = sim_site("room5")
    for view in (False, True):
        k = knock(site, "c1", 2.0, 0.1, seed=3, view=view)
        a, b = site.camera("c1"), k.camera("c1")
        assert math.degrees(math.acos((np.trace(a.R.T @ b.R) - 1) / 2)) == pytest.approx(2.0)
        assert np.linalg.norm(a.t - b.t) == pytest.approx(0.1)
        assert all(x == y for x, y in zip(site.cameras, k.cameras) if x.id != "c1")
