"""Bundle adjustment over people's joints (host/calibration/bundle.py): a knocked camera comes
back from exact views, the held cameras stay put, the focal length, and the arguments it refuses."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.people_calibration import knock, sim_site
from superbody.host.calibration.bundle import build_problem, pose_change, refine_cameras
from tests.host.calibration.simulated import exact_instants

# (site, knocked camera, knock is a view move): each comes back to its true pose from exact
# views of 40 people standing about the floor, the other cameras held.
CASES = [
    ("wtf-apartment", "1", True),   # three cameras: two held, the least that fixes the scale
    ("lab-example", "se", False),   # lens distortion, a random knock
    ("room5", "c0", True),          # a camera 1 m up among five
]


@pytest.mark.parametrize("name, cam, view", CASES)
def test_a_knocked_camera_comes_back_from_exact_views(name: str, cam: str, view: bool) -> None:
    site = sim_site(name)
    instants = exact_instants(site, 40)
    host = knock(site, cam, 2.0, 0.10, seed=2, view=view)
    res = refine_cameras(host.cameras, instants, [cam])
    i = site.camera_index(cam)
    err = pose_change(site.cameras[i], res.cameras[i])
    assert err.rotation_deg < 0.01 and err.position_m < 0.001
    assert res.free == (cam,)
    assert all(a == b for a, b in zip(host.cameras, res.cameras) if a.id != cam)  # held exactly
    assert res.changes[cam].rotation_deg == pytest.approx(2.0, abs=0.01)
    assert res.cost_after < 1e-3 * res.cost_before


def test_two_knocked_cameras_come_back_together() -> None:
    site = sim_site("room5")
    host = knock(knock(site, "c1", seed=1), "c3", seed=2)
    res = refine_cameras(host.cameras, exact_instants(site, 40), ["c1", "c3"])
    for c in ("c1", "c3"):
        err = pose_change(site.camera(c), res.cameras[site.camera_index(c)])
        assert err.rotation_deg < 0.01 and err.position_m < 0.001, c


def test_focal_length() -> None:
    site = sim_site("lab-example")
    cam = site.camera("ne")
    zoomed = dataclasses.replace(cam, fx=cam.fx * 1.03, fy=cam.fy * 1.03)
    host = dataclasses.replace(site, cameras=tuple(zoomed if c.id == "ne" else c for c in knock(site, "ne", seed=4).cameras))
    instants = exact_instants(site, 60)
    res = refine_cameras(host.cameras, instants, ["ne"], focal=True)
    out = res.cameras[site.camera_index("ne")]
    assert out.fx == pytest.approx(cam.fx, rel=2e-3) and out.fy == pytest.approx(cam.fy, rel=2e-3)
    assert pose_change(cam, out).rotation_deg < 0.05
    without = refine_cameras(host.cameras, instants, ["ne"])
    assert without.cost_after > 10 * res.cost_after  # the pose alone cannot absorb a 3 % zoom


def test_problem_keeps_joints_two_cameras_saw() -> None:
    site = sim_site("lab-example")
    instants = exact_instants(site, 10)
    prob = build_problem(instants, site.cameras)
    assert len(prob.points) > 100
    counts = np.bincount(prob.point)
    assert counts.min() >= 2  # every point seen by two cameras at least
    assert np.array_equal(np.sort(np.unique(prob.point)), np.arange(len(prob.points)))
    assert len(build_problem([], site.cameras).points) == 0


# (free cameras, the error's words)
REFUSED = [
    (["1", "2"], "at least 2 cameras must be held"),
    (["9"], "not in the site"),
]


@pytest.mark.parametrize("free, words", REFUSED)
def test_refused(free: list[str], words: str) -> None:
    site = sim_site("wtf-apartment")
    with pytest.raises(ValueError, match=words):
        refine_cameras(site.cameras, exact_instants(site, 5), free)


def test_no_joint_seen_twice() -> None:
    site = sim_site("wtf-apartment")
    with pytest.raises(ValueError, match="no joint was seen by two cameras"):
        refine_cameras(site.cameras, [], ["1"])
