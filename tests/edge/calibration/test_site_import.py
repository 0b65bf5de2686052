"""``superbody site import``: every format round-trips, the issue's bar (an OpenCV calibration in cm,
world y down, becomes a site the host places people on as on a hand-made one, to 1 mm), and bad
inputs fail naming the field."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from superbody.edge import body
from superbody.edge.camera import Camera, project
from superbody.edge.cli import main
from superbody.edge.messages.observation import PersonView
from superbody.edge.sim.skeleton import skeleton
from superbody.edge.site import Site, load_site
from tests.edge.calibration import calibration_files as cf


def _import(tmp_path, inputs, flags, capsys=None) -> tuple[int, Site | None, str, str]:
    """``superbody site import INPUTS FLAGS --out imported.toml``: exit code, the site, stdout, stderr."""
    out = tmp_path / "imported.toml"
    rc = main(["site", "import", *map(str, inputs), *flags, "--out", str(out)])
    std = capsys.readouterr() if capsys is not None else None
    return rc, (load_site(out) if rc == 0 else None), std.out if std else "", std.err if std else ""


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Radians between two rotations."""
    return float(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1.0, 1.0)))


def _points_in_front(cam: Camera, rng: np.random.Generator, n: int = 200) -> np.ndarray:
    """(n, 3) world points 0.5-10 m in front of the camera, across its image."""
    uv = rng.uniform([0, 0], [cam.width, cam.height], size=(n, 2))
    xn = (uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    pc = np.column_stack([xn, np.ones(n)]) * rng.uniform(0.5, 10.0, size=(n, 1))
    return pc @ cam.R.T + cam.t


def assert_same_cameras(ref: Site, got: Site, fps: float | None, same_ids: bool = True) -> None:
    """Every camera of ``got`` is its counterpart in ``ref`` (in order): pose, intrinsics, projections."""
    rng = np.random.default_rng(0)
    assert len(got.cameras) == len(ref.cameras)
    if same_ids:
        assert got.camera_ids == ref.camera_ids
    for a, b in zip(ref.cameras, got.cameras):
        assert np.abs(a.t - b.t).max() < 1e-6, a.id  # metres
        assert _angle(a.R, b.R) < 1e-6, a.id  # radians
        assert (b.width, b.height) == (a.width, a.height)
        assert b.fps == (a.fps if fps is None else fps)
        np.testing.assert_allclose([b.fx, b.fy, b.cx, b.cy], [a.fx, a.fy, a.cx, a.cy], atol=1e-6)
        np.testing.assert_allclose(b.D, a.D, atol=1e-9)
        p = _points_in_front(a, rng)
        assert np.abs(project(p, a)[0] - project(p, b)[0]).max() < 1e-3, a.id  # pixels


# (writer and its arguments, the reference site, the fps the site gets: None = the source's, whether ids carry over)
ROUND_TRIPS = [
    (lambda s, d: cf.write_opencv(s, d, "yaml", "R"), cf.dome_site, 15.0, True),  # OpenCV YAML, cm, y down, R; no fps: the default
    (lambda s, d: cf.write_opencv(s, d, "yaml", "rvec"), cf.dome_site, 15.0, True),  # the same with a Rodrigues vector
    (lambda s, d: cf.write_opencv(s, d, "json", "R"), cf.dome_site, 15.0, True),  # cv2.FileStorage's JSON
    (lambda s, d: cf.write_opencv(s, d, "xml", "rvec"), cf.dome_site, 15.0, True),  # and its XML
    (cf.write_colmap, cf.dome_site, None, True),  # COLMAP: five models, quaternions, half a metre per unit, --fps 30
    (cf.write_kalibr, cf.dome_site, None, False),  # Kalibr chain (cam0, cam1, ...), the world given as T_cam0_world
    (lambda s, d: cf.write_kalibr(s, d, world=False), cf.level_cam0_site, None, True),  # Kalibr, the world is camera 0 (level)
    (cf.write_json, cf.dome_site, None, True),  # plain JSON: mm, y up, camera-to-world, OpenGL camera axes
    (cf.write_left_handed, cf.dome_site, None, True),  # plain JSON of a left-handed Y-up world (R with det -1), mm
]


@pytest.mark.parametrize("write, make_site, fps, same_ids", ROUND_TRIPS)
def test_each_format_round_trips(tmp_path, write, make_site, fps, same_ids):
    ref = make_site()
    inputs, flags = write(ref, tmp_path)
    rc, got, _, _ = _import(tmp_path, inputs, flags)
    assert rc == 0
    assert_same_cameras(ref, got, fps, same_ids)


def test_the_report_says_what_it_assumed(tmp_path, capsys):
    inputs, flags = cf.write_opencv(cf.dome_site(), tmp_path)
    rc, site, out, _ = _import(tmp_path, inputs, flags, capsys)
    assert rc == 0
    assert "0.01 m per source unit" in out and "z = -y (up)" in out and "floor at source y = 150" in out  # unit, up axis, floor
    assert "1920 x 1080 px (from dome0.yaml)" in out  # where the image size came from
    assert "15 fps (the default 15 fps; --fps sets it)" in out and "fps: the default 15 fps for 5 cameras" in out  # the fps default
    assert "image size: from the files for 5 cameras" in out
    assert "layout ring" in out and "reprojection against the source" in out
    text = (tmp_path / "imported.toml").read_text()
    assert text.startswith("# Site imported: imported by superbody site import from dome0.yaml")


def test_fps_and_size_from_flags_when_the_source_has_none(tmp_path, capsys):
    ref = cf.dome_site()
    inputs, flags = cf.write_json(ref, tmp_path)
    doc = json.loads(inputs[0].read_text())
    for c in doc["cameras"]:
        del c["width"], c["height"], c["fps"]
    inputs[0].write_text(json.dumps(doc))
    rc, _, _, err = _import(tmp_path, inputs, flags, capsys)
    assert rc == 2 and "--size WIDTHxHEIGHT" in err
    rc, site, out, _ = _import(tmp_path, inputs, [*flags, "--size", "1920x1080", "--fps", "25"], capsys)
    assert rc == 0 and "(from --size)" in out and "25 fps (from --fps)" in out
    assert all((c.width, c.height, c.fps) == (1920, 1080, 25.0) for c in site.cameras)


# --- the bar: an OpenCV calibration (cm, world y down) to a site in one command ----------


def _views(site: Site, joints: np.ndarray) -> dict[str, PersonView]:
    """What each camera of ``site`` sees of a person's joints (17, 3): exact projections, no noise."""
    out = {}
    for cam in site.cameras:
        uv, z = project(joints, cam)
        ok = (z > 0.1) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        if ok.sum() < 5:
            continue
        kp = np.full((body.NUM_KEYPOINTS, 3), np.nan, np.float32)
        kp[ok, :2], kp[ok, 2] = uv[ok], 0.9
        out[cam.id] = PersonView(kp, np.array([*uv[ok].min(0), *uv[ok].max(0)], np.float32), np.zeros((16, 8), np.float32))
    return out


def test_an_opencv_calibration_in_cm_gives_the_host_the_hand_made_sites_positions_to_1_mm(tmp_path):
    """Simulated people projected through the hand-made reference site's cameras; geometry (the
    host's analytic estimator) on the reference and on the imported site places them alike."""
    from superbody.host.estimation.analytic import AnalyticEstimator

    ref = cf.dome_site()
    inputs, flags = cf.write_opencv(ref, tmp_path)  # centimetres, y down, origin 1.5 m up, distortion
    rc, got, _, _ = _import(tmp_path, inputs, flags)  # one command
    assert rc == 0
    rng = np.random.default_rng(7)
    people = []
    for _ in range(40):
        x, y = rng.uniform(-1.5, 2.5), rng.uniform(-2.5, 1.5)
        joints = skeleton(x, y, rng.uniform(-np.pi, np.pi), rng.uniform(0, 2 * np.pi), rng.uniform(0, 1), rng.uniform(1.55, 1.95))
        people.append(_views(ref, joints))
    people = [p for p in people if len(p) >= 2]
    assert len(people) >= 30
    on_ref = AnalyticEstimator(ref).estimate(people)
    on_got = AnalyticEstimator(got).estimate(people)
    assert np.abs(on_ref[:, :2] - on_got[:, :2]).max() < 1e-3  # metres
    assert np.abs(np.angle(np.exp(1j * (on_ref[:, 2] - on_got[:, 2])))).max() < 1e-3  # radians


# --- bad inputs: exit code 2 and the field named --------------------------------------------------


def _opencv(tmp_path, edit=None, ext="yaml") -> list:
    """The dome's OpenCV files, the first one's text passed through ``edit``."""
    inputs, _ = cf.write_opencv(cf.dome_site(), tmp_path, ext)
    if edit is not None:
        inputs[0].write_text(edit(inputs[0].read_text()))
    return inputs


def _drop(key):
    """Remove a top-level field (its line and those indented under it) from a FileStorage YAML."""
    def edit(text):
        lines = text.splitlines()
        i = next(k for k, line in enumerate(lines) if line.startswith(f"{key}:"))
        j = next((k for k in range(i + 1, len(lines)) if not lines[k].startswith(" ")), len(lines))
        return "\n".join(lines[:i] + lines[j:]) + "\n"
    return edit


# (what to do to the dome's OpenCV files, extra flags, text the error must hold)
BAD = [
    (_drop("camera_matrix"), [], "dome0.yaml:.*camera_matrix is missing"),  # no K
    (lambda t: t.replace("rows: 3\n   cols: 3\n   dt: d\n   data: [ 1400., 0., 960., 0., 1400., 540., 0., 0., 1. ]",
                         "rows: 2\n   cols: 3\n   dt: d\n   data: [ 1400., 0., 960., 0., 1400., 540. ]"), [],
     r"camera_matrix must be 3 x 3 matrix, got shape \(2, 3\)"),  # K of the wrong shape
    (_drop("R"), [], "dome0.yaml:.*R is missing"),  # no rotation
    (_drop("tvec"), [], "dome0.yaml:.*t is missing"),  # no translation
    (lambda t: t.replace("rows: 5", "rows: 3").replace("data: [ 0., 0., 0., 0., 0. ]", "data: [ 0.1, 0., 0. ]"), [],
     "distortion_coefficients must be 0, 4, 5 or 8 finite numbers .*got 3"),  # 3 distortion coefficients
    (lambda t: t.replace("image_width: 1920", "image_width: 8"), [], r"image_width must be a whole number of pixels in \[16, 16384\]"),
    (None, ["--up", "+y"], r"position.*not above the floor.*--up's sign"),  # the up axis' sign flipped: every camera under the floor
    (None, ["--up", "q"], r"--up must be one of \+x, -x, \+y, -y, \+z, -z, got 'q'"),  # unknown axis flag
    (None, ["--x-axis", "-y"], "--x-axis must be across --up"),  # x along up
    (None, ["--unit", "furlong"], "--unit must be one of m, cm, mm"),  # unknown unit
    (None, ["--layout", "dome"], "--layout must be one of auto, wall, ring, ceiling"),  # unknown layout
    (None, ["--format", "blender"], "--format must be one of auto, opencv, json, colmap, kalibr"),  # unknown format
    (None, ["--size", "1920"], "--size must be WIDTHxHEIGHT"),  # malformed size
    (None, ["--fps", "0"], r"--fps must be a number in \[0.1, 1000\]"),  # zero fps
    (None, ["--cameras", "dome9"], "--cameras: dome9 not in the source"),  # unknown camera
    (None, ["--T-cam0-world", "1,2,3"], "--T-cam0-world must be a file"),  # not a transform
    (lambda t: t.replace("image_width: 1920\n", "image_width: 1920\n  bad: [1, 2\n"), [], "dome0.yaml:"),  # not YAML
]


@pytest.mark.parametrize("edit, extra, message", BAD)
def test_bad_opencv_inputs_name_the_field(tmp_path, capsys, edit, extra, message):
    inputs = _opencv(tmp_path, edit)
    flags = ["--unit", "cm", "--up", "-y", "--floor-at", "150", *extra]
    rc, _, _, err = _import(tmp_path, inputs, flags, capsys)
    assert rc == 2, err
    assert re.search(message, err), err
    assert not (tmp_path / "imported.toml").exists()


def test_the_floor_behind_a_camera_is_an_error(tmp_path, capsys):
    ref = cf.dome_site()
    up = cf._camera("sky", (0.0, 0.0, 2.0), (3.0, 0.0, 4.5), (900.0, 900.0, 640.0, 360.0, ()), 1280, 720)  # aimed 40 deg above the horizon
    site = Site(name="x", cameras=(*ref.cameras, up), floor=ref.floor)
    inputs, flags = cf.write_opencv(site, tmp_path)
    rc, _, _, err = _import(tmp_path, inputs, flags, capsys)
    assert rc == 2 and "cameras[5] (sky).rotation: no pixel sees the floor" in err, err


def _colmap(tmp_path, camera_line=None, image_line=None):
    inputs, flags = cf.write_colmap(cf.dome_site(), tmp_path / "m")
    for name, new in (("cameras.txt", camera_line), ("images.txt", image_line)):
        if new is not None:
            path = tmp_path / "m" / name
            lines = path.read_text().splitlines()
            i = next(k for k, line in enumerate(lines) if not line.startswith("#"))
            lines[i] = new(lines[i])
            path.write_text("\n".join(lines) + "\n")
    return inputs, flags


def _kalibr(tmp_path, edit):
    inputs, flags = cf.write_kalibr(cf.dome_site(), tmp_path)
    inputs[0].write_text(edit(inputs[0].read_text()))
    return inputs, flags


# (files, text the error must hold)
BAD_FILES = [
    (lambda p: _colmap(p, lambda line: line.replace("SIMPLE_PINHOLE", "OPENCV_FISHEYE")), r"cameras.txt:3: camera model must be one of"),
    (lambda p: _colmap(p, lambda line: line + " 0.1"), "cameras.txt:3: SIMPLE_PINHOLE takes 3 parameters"),  # a parameter too many
    (lambda p: _colmap(p, None, lambda line: line.replace(" 1 dome0.jpg", " 9 dome0.jpg")), "images.txt:4: CAMERA_ID 9 is not in cameras.txt"),
    (lambda p: _colmap(p, None, lambda line: " ".join(["11", "2", "0", "0", "0"] + line.split()[5:])), "QW QX QY QZ must be a unit quaternion"),
    (lambda p: _kalibr(p, lambda t: t.replace("distortion_model: radtan", "distortion_model: equidistant", 1)),
     r"camchain.yaml:\d+: cam2.distortion_model must be one of radtan, none"),  # fisheye
    (lambda p: _kalibr(p, lambda t: t.replace("camera_model: pinhole", "camera_model: omni", 1)), r"cam0.camera_model must be pinhole"),
    (lambda p: _kalibr(p, lambda t: t.replace("T_cn_cnm1", "T_cam_cam", 1)), r"cam1.T_cn_cnm1 is missing"),  # a broken chain
    (lambda p: _kalibr(p, lambda t: t.replace("intrinsics: [1400.0, 1400.0, 960.0, 540.0]", "intrinsics: [1400.0, 960.0, 540.0]")),
     r"cam0.intrinsics must be \[fu, fv, pu, pv\]"),  # three intrinsics
]


@pytest.mark.parametrize("make, message", BAD_FILES)
def test_bad_colmap_and_kalibr_files_name_the_line_and_field(tmp_path, capsys, make, message):
    inputs, flags = make(tmp_path)
    rc, _, _, err = _import(tmp_path, inputs, flags, capsys)
    assert rc == 2, err
    assert re.search(message, err), err
