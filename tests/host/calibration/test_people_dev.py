"""People calibration on the real recording (WheresTheFellow dev.json: 3 cameras, one person,
27 s), run through the host's tracker as ``superbody calibrate people`` runs it.

What the real detections allow, measured in docs/calibration.md: each camera's leave-one-out
residual is 0.8-1.4 deg on the shipped calibration (the detector places a joint a little
differently from each side), and a bundle adjustment that frees one camera of the shipped site
moves it 1.9-2.6 deg and 14-18 cm (0.6-0.85 deg of image over the walked area): that is where
these joints put it. So a camera knocked 2 deg and 10 cm is found when its view moved (3.4-3.9 deg
of image) and the recording tells which camera moved (cameras 1 and 3 in each of four knocks,
camera 2 in one), never another camera; the refinement brings its image back to within
0.9 deg, and its pose to where the untouched site's refinement puts it (within 0.3 deg and 2 cm),
not to the shipped pose (which these joints do not support).
"""

from __future__ import annotations

import pytest

from benchmarks.people_calibration import dev_frames, knock
from superbody.edge.site import load_site
from superbody.host.calibration.bundle import build_problem, pose_change, refine_cameras
from superbody.host.calibration.collect import person_instants
from superbody.host.calibration.health import CalibrationHealth, image_shift_deg
from superbody.host.calibration.refine import camera_residuals
from tests.conftest import WTF_SITE

S = 1_000_000_000


@pytest.fixture(scope="module")
def site():
    return load_site(WTF_SITE)


@pytest.fixture(scope="module")
def frames(dev_json, site):
    return dev_frames(dev_json, site)


def _monitor(host, frames) -> tuple[dict[str, float], dict]:
    """The recording through the tracker and the monitor, reported each second: when each
    camera was first flagged (capture seconds from the recording's start), and the last report."""
    instants, _ = person_instants(frames, host)
    mon = CalibrationHealth(host, check_every_s=5.0)
    flagged: dict[str, float] = {}
    nxt = instants[0].stamp_ns
    for ins in instants:
        mon.observe_instant(ins)
        if ins.stamp_ns >= nxt:
            nxt = ins.stamp_ns + S
            for c, h in mon.report(ins.stamp_ns).items():
                if h.moved:
                    flagged.setdefault(c, (ins.stamp_ns - frames[0].stamp_ns) / S)
    return flagged, mon.report(instants[-1].stamp_ns)


def test_the_shipped_calibration_is_healthy(site, frames) -> None:
    flagged, rep = _monitor(site, frames)
    assert not flagged
    assert all(h.state == "ok" and h.samples > 500 and h.residual_deg < 1.5 for h in rep.values()), rep


# (knocked camera, knock seed, found): view-moving knocks of 2 deg and 10 cm
KNOCKS = [
    ("3", 0, True),   # found, and the refinement below
    ("1", 0, True),
    ("2", 0, False),  # the recording cannot tell camera 2 from the others here: nobody is flagged
]


@pytest.mark.parametrize("cam, seed, found", KNOCKS)
def test_a_knocked_camera_is_found_and_no_other_is(site, frames, cam: str, seed: int, found: bool) -> None:
    flagged, rep = _monitor(knock(site, cam, seed=seed, view=True), frames)
    assert set(flagged) <= {cam}
    assert (cam in flagged) == found
    if found:
        assert flagged[cam] <= 30.0
    assert max(h.residual_deg for h in rep.values()) > 2.0  # the misfit shows either way


@pytest.fixture(scope="module")
def refined(site, frames):
    host = knock(site, "3", seed=0, view=True)
    instants, _ = person_instants(frames, host)
    return host, instants, refine_cameras(host.cameras, instants, ["3"])


def test_the_refinement_brings_the_view_back(site, refined) -> None:
    host, instants, res = refined
    points = build_problem(instants, site.cameras).points
    truth, knocked, back = site.camera("3"), host.camera("3"), res.cameras[2]
    assert image_shift_deg(truth, knocked, points) > 3.0
    assert image_shift_deg(truth, back, points) < 0.9
    before, after = camera_residuals(instants, host.cameras), camera_residuals(instants, res.cameras)
    assert all(after[c][1] < before[c][1] for c in site.camera_ids)
    assert after["3"][1] < 1.0
    assert res.cameras[:2] == host.cameras[:2]  # held


def test_the_refinement_finds_the_pose_these_joints_say_whatever_the_knock(site, frames, refined) -> None:
    # dev.json's 2D joints put camera 3 1.9-2.6 deg and 14-18 cm from the shipped (depth-based)
    # calibration, so the "within 0.3 deg and 2 cm of the original" cannot be met on it;
    # what the refinement must do is find the pose the people say, from wherever it starts: from
    # the knocked site and from the untouched one, on the same people's views, it ends at the same
    # pose. (The views themselves come from the knocked site's tracker: it refuses a few of the
    # knocked camera's views that one body could not explain, 145 instants instead of 150, and the
    # untouched site's own instants put camera 3 0.33 deg and 2 cm from that; measured, not tested.)
    _, instants, from_knock = refined
    from_truth = refine_cameras(site.cameras, instants, ["3"])
    gap = pose_change(from_knock.cameras[2], from_truth.cameras[2])
    moved = pose_change(site.camera("3"), from_truth.cameras[2])
    assert gap.rotation_deg < 0.3 and gap.position_m < 0.02, gap
    assert 1.0 < moved.rotation_deg < 3.5 and 0.05 < moved.position_m < 0.25, moved  # what dev.json's joints say
