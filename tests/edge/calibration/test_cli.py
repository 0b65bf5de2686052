"""``superbody calibrate board`` and ``calibrate intrinsics`` on images rendered from known cameras."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from superbody.edge.calibration.board import BoardSpec
from superbody.edge.calibration.render import placement_in_front, render_board
from superbody.edge.cli import main
from superbody.edge.site import load_site
from tests.conftest import WTF_SITE
from tests.edge.calibration.test_board import SMALL, _camera, intrinsics_views

SPEC = BoardSpec(5, 7, 0.16, 0.12, "DICT_5X5_100")
BOARD_FLAGS = ["--squares", "5x7", "--square", "0.16", "--marker", "0.12", "--dict", "DICT_5X5_100"]


def _superbody() -> list[str]:
    exe = shutil.which("superbody", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "superbody.edge.cli"]


def _angle_deg(Ra, Rb) -> float:
    return math.degrees(math.acos(np.clip((np.trace(np.asarray(Ra) @ np.asarray(Rb).T) - 1.0) / 2.0, -1.0, 1.0)))


@pytest.fixture(scope="module")
def board_shot(tmp_path_factory):
    """Camera 2 of the apartment photographing the board 2.5 m in front of it: (image, origin, yaw in degrees)."""
    cam = load_site(WTF_SITE).camera("2")
    origin, yaw = placement_in_front(cam, SPEC, 2.5)
    path = tmp_path_factory.mktemp("board") / "cam2.png"
    assert cv2.imwrite(str(path), render_board(SPEC, cam, origin, yaw, seed=4))
    return path, origin, math.degrees(yaw)


def _board_args(site: Path, image: Path, origin, yaw_deg, *extra: str) -> list[str]:
    return ["calibrate", "board", "--site", str(site), "--camera", "2", "--image", str(image), *BOARD_FLAGS,
            f"--origin={origin[0]!r},{origin[1]!r}", f"--yaw={yaw_deg!r}", *extra]


def test_board_cli_recovers_the_camera_and_rewrites_the_site_in_place(tmp_path, board_shot):
    image, origin, yaw_deg = board_shot
    site_path, report = tmp_path / "site.toml", tmp_path / "pose.json"
    shutil.copy(WTF_SITE, site_path)
    proc = subprocess.run(
        [*_superbody(), *_board_args(site_path, image, origin, yaw_deg, "--out", str(site_path), "--json-out", str(report))],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and "camera 2: position" in proc.stdout and f"wrote {site_path}" in proc.stdout
    truth = load_site(WTF_SITE)
    cam = truth.camera("2")
    doc = json.loads(report.read_text())
    assert set(doc) == {"camera", "position_m", "rotation", "reprojection_px", "corners"}
    assert doc["camera"] == "2" and isinstance(doc["corners"], int) and doc["corners"] >= 12
    assert 0.0 < doc["reprojection_px"] < 0.5
    assert np.linalg.norm(np.array(doc["position_m"]) - cam.t) < 0.03
    assert _angle_deg(doc["rotation"], cam.R) < 0.5
    written = load_site(site_path)
    new = written.camera("2")
    assert np.allclose(new.t, doc["position_m"], atol=1e-8) and np.allclose(new.R, doc["rotation"], atol=1e-8)
    assert (new.fx, new.fy, new.cx, new.cy, new.width, new.height) == (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
    assert written.camera("1") == truth.camera("1") and written.camera("3") == truth.camera("3")
    assert written.floor == truth.floor and written.name == truth.name
    text = site_path.read_text()
    assert text.startswith(WTF_SITE.read_text().split("\n", 1)[0])  # the original header is kept
    assert text.count("# camera 2: pose from superbody calibrate board") == 1
    # A second calibration of the same camera replaces the note rather than adding one.
    assert main(_board_args(site_path, image, origin, yaw_deg, "--out", str(site_path))) == 0
    assert site_path.read_text().count("# camera 2: pose from superbody calibrate board") == 1


@pytest.mark.parametrize(
    ("change", "message"),
    [
        # (arguments replaced or added, text of the one-line error)
        ({"--squares": "5-7"}, "--squares must be COLUMNSxROWS, e.g. 5x7, got '5-7'"),
        ({"--squares": "1x7"}, "--squares must be in [2, 64] each way"),
        ({"--square": "-0.16"}, "--square must be a number in [0.001, 10], got '-0.16'"),
        ({"--marker": "abc"}, "--marker must be a number in [0.001, 10], got 'abc'"),
        ({"--marker": "0.2"}, "--marker must be smaller than --square (0.16), got 0.2"),
        ({"--dict": "DICT_5X5_99"}, "--dict must be one of DICT_4X4_100, DICT_4X4_1000"),
        ({"--origin": "1.0"}, "--origin must be X,Y in metres"),
        ({"--origin": "1.0,inf"}, "--origin must be a number in [-10000, 10000], got 'inf'"),
        ({"--yaw": "400"}, "--yaw must be a number in [-360, 360], got '400'"),
        ({"--camera": "9"}, "--camera: camera '9' is not in site 'wtf-apartment'; cameras: 1, 2, 3"),
        ({"--image": "missing.png"}, "missing.png: no such file"),
        ({"--image": "text.png"}, "text.png: not an image OpenCV can read"),
        ({"--image": "blank.png"}, "blank.png: found 0 ChArUco corners (0 markers), need at least 6"),
        ({"--image": "small.png"}, "small.png: image is 320x240 but camera '2' is 640x480 in the site"),
        ({"--site": "nosite.toml"}, "nosite.toml: cannot read site file"),
        ({"--out": "missing/site.toml"}, "No such file or directory"),
    ],
)
def test_board_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, board_shot, change, message):
    image, origin, yaw_deg = board_shot
    (tmp_path / "text.png").write_text("not a png")
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((480, 640), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "small.png"), cv2.imread(str(image))[::2, ::2])
    values = {"--site": str(WTF_SITE), "--camera": "2", "--image": str(image), "--squares": "5x7", "--square": "0.16",
              "--marker": "0.12", "--dict": "DICT_5X5_100", "--origin": f"{origin[0]!r},{origin[1]!r}", "--yaw": repr(yaw_deg),
              "--out": str(tmp_path / "out.toml")}
    for flag, value in change.items():
        values[flag] = str(tmp_path / value) if flag in ("--image", "--site", "--out") else value
    argv = ["calibrate", "board"] + [f"{flag}={value}" for flag, value in values.items()]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("superbody calibrate board: error: "), err
    assert message in err[0]
    assert not (tmp_path / "out.toml").exists()


@pytest.fixture(scope="module")
def intrinsics_dir(tmp_path_factory):
    """Five views of an A4 board by a 640x480 camera with fx 600, fy 605, cx 322, cy 238."""
    truth = _camera((0, 0, 1), (0, 1, 1), fx=600.0, fy=605.0, cx=322.0, cy=238.0)
    folder = tmp_path_factory.mktemp("views")
    for k, img in enumerate(intrinsics_views(truth, SMALL, n=5)):
        cv2.imwrite(str(folder / f"view{k}.png"), img)
    cv2.imwrite(str(folder / "view9_blank.png"), np.full((480, 640), 128, np.uint8))
    return folder


_SMALL_FLAGS = ["--squares", "9x6", "--square", "0.03", "--marker", "0.022", "--dict", "DICT_4X4_50"]


def test_intrinsics_cli_fits_k_and_writes_the_site(tmp_path, capsys, intrinsics_dir):
    site_path, report = tmp_path / "site.toml", tmp_path / "k.json"
    shutil.copy(WTF_SITE, site_path)
    argv = ["calibrate", "intrinsics", "--images", str(intrinsics_dir / "*.png"), *_SMALL_FLAGS,
            "--site", str(site_path), "--camera", "3", "--out", str(site_path), "--json-out", str(report)]
    assert main(argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "5 views of 6 images (640x480)" in out and "view9_blank.png: too few corners" in out
    doc = json.loads(report.read_text())
    assert set(doc) == {"camera", "width", "height", "fx", "fy", "cx", "cy", "dist", "rms_px", "views", "skipped"}
    assert doc["camera"] == "3" and (doc["width"], doc["height"]) == (640, 480) and doc["views"] == 5
    assert doc["skipped"] == [str(intrinsics_dir / "view9_blank.png")]
    assert doc["fx"] == pytest.approx(600.0, rel=0.015) and doc["fy"] == pytest.approx(605.0, rel=0.015)
    assert len(doc["dist"]) == 5 and doc["dist"][4] == 0.0 and doc["rms_px"] < 0.3
    cam = load_site(site_path).camera("3")
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((doc["fx"], doc["fy"], doc["cx"], doc["cy"]), abs=1e-8)
    assert cam.dist == pytest.approx(tuple(doc["dist"]), abs=1e-8)
    assert cam.position == load_site(WTF_SITE).camera("3").position  # the pose is left alone
    assert "# camera 3: intrinsics from superbody calibrate intrinsics" in site_path.read_text()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        # (arguments after --images GLOB and the board flags, text of the one-line error)
        (["--out", "OUT"], "--out needs --site and --camera"),
        (["--site", "SITE"], "--site and --camera go together"),
        (["--site", "SITE", "--camera", "7"], "--camera: camera '7' is not in site"),
        (["GLOB", "nothing/*.png"], "no file matches"),
        (["GLOB", "view9_blank.png"], "0 of 1 images show at least 6 corners, need at least 4"),
        (["--squares", "9"], "--squares must be COLUMNSxROWS"),
    ],
)
def test_intrinsics_cli_bad_input(tmp_path, capsys, intrinsics_dir, extra, message):
    pattern = str(intrinsics_dir / "*.png")
    if extra[:1] == ["GLOB"]:
        pattern, extra = str(intrinsics_dir / extra[1]), []
    extra = [{"OUT": str(tmp_path / "out.toml"), "SITE": str(WTF_SITE)}.get(a, a) for a in extra]
    argv = ["calibrate", "intrinsics", "--images", pattern, *_SMALL_FLAGS, *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("superbody calibrate intrinsics: error: "), err
    assert message in err[0]
    assert not (tmp_path / "out.toml").exists()


def test_intrinsics_cli_image_size_must_match_the_site(tmp_path, capsys):
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((240, 320), 128, np.uint8))
    argv = ["calibrate", "intrinsics", "--images", str(small), *_SMALL_FLAGS, "--site", str(WTF_SITE), "--camera", "1"]
    assert main(argv) == 2
    assert "is 320x240 but camera '1' is 640x480 in the site" in capsys.readouterr().err
