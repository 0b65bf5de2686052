"""Camera calibration: DLT on synthetic cameras, the CLI on dev.json, the shipped site file."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from superbody.edge.camera import Camera, look_at_rotation, project
from superbody.edge.site import load_site
from superbody.models.dataset_calibration import (
    calibrate_dataset,
    dataset_pairs,
    decompose_projection,
    fit_camera,
    floor_rectangle,
    normalised_dlt,
    reprojection_errors,
)
from tests.conftest import DEV_JSON
from tests.conftest import WTF_SITE as SITE_TOML


def _camera(position, target, fx=617.0, fy=617.0, cx=320.0, cy=240.0, width=640, height=480) -> Camera:
    R = look_at_rotation(np.array(position, dtype=float), np.array(target, dtype=float))
    return Camera(
        id="c", width=width, height=height, fps=15.0, fx=fx, fy=fy, cx=cx, cy=cy,
        position=tuple(position), rotation=tuple(map(tuple, R)),
    )


def _pairs(cam: Camera, n: int = 300, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points spread through a room, kept where the camera sees them; and their pixels."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform([-3.0, -3.0, 0.0], [3.0, 3.0, 2.0], (20 * n, 3))
    uv, depth = project(pts, cam)
    seen = (depth > 0.3) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    assert seen.sum() >= n
    return pts[seen][:n], uv[seen][:n]


SYNTHETIC = [
    # (name, camera)
    ("wall corner, RealSense-like", _camera((2.9, -1.8, 2.4), (0.0, 0.0, 1.0))),
    ("steeply down from the ceiling", _camera((0.2, 0.1, 3.0), (0.5, 0.3, 0.0))),
    ("off-centre principal point, non-square pixels", _camera((-2.5, 0.5, 1.2), (1.0, 0.0, 0.8), fx=900.0, fy=880.0, cx=600.0, cy=330.0, width=1280, height=720)),
    ("wide angle, low", _camera((0.0, -3.5, 0.6), (0.0, 0.0, 1.0), fx=300.0, fy=300.0)),
]


@pytest.mark.parametrize(("name", "cam"), SYNTHETIC, ids=[s[0] for s in SYNTHETIC])
@pytest.mark.parametrize("refine", [False, True])
def test_dlt_recovers_a_synthetic_camera_exactly(name, cam, refine):
    pts, uv = _pairs(cam)
    fit = fit_camera("c", pts, uv, width=cam.width, height=cam.height, refine=refine)
    got = fit.camera
    assert [got.fx, got.fy, got.cx, got.cy] == pytest.approx([cam.fx, cam.fy, cam.cx, cam.cy], abs=1e-6)
    assert np.allclose(got.t, cam.t, atol=1e-8)
    assert np.allclose(got.R, cam.R, atol=1e-9)
    assert abs(fit.skew_px) < 1e-6
    assert fit.max_px < 1e-6 and fit.n_points == len(pts)


def test_noisy_pixels_give_a_close_camera():
    cam = SYNTHETIC[0][1]
    pts, uv = _pairs(cam, n=500)
    noisy = uv + np.random.default_rng(1).normal(0.0, 0.5, uv.shape)
    fit = fit_camera("c", pts, noisy)
    assert fit.median_px < 1.0
    assert np.linalg.norm(fit.camera.t - cam.t) < 0.05
    assert abs(fit.camera.fx - cam.fx) < 5.0


def test_decompose_projection_of_a_known_matrix():
    cam = SYNTHETIC[1][1]
    K, R, C = decompose_projection(cam.projection_matrix * 3.7)  # any positive scale
    assert np.allclose(K, cam.K) and np.allclose(R, cam.R.T) and np.allclose(C, cam.t)


@pytest.mark.parametrize(
    ("pts", "uv", "match"),
    [
        (np.zeros((5, 3)), np.zeros((5, 2)), "at least 6"),  # too few pairs
        (np.zeros((0, 3)), np.zeros((0, 2)), "at least 6"),  # none
        (np.c_[np.random.default_rng(0).uniform(size=(20, 2)), np.ones(20)], np.zeros((20, 2)), "coplanar"),  # a plane
        (np.zeros((8, 3)), np.zeros((7, 2)), r"\(N, 3\)"),  # mismatched shapes
    ],
)
def test_dlt_rejects_degenerate_input(pts, uv, match):
    with pytest.raises(ValueError, match=match):
        normalised_dlt(pts, uv)


def test_fit_camera_rejects_a_mirrored_world():
    cam = SYNTHETIC[0][1]
    pts, uv = _pairs(cam)
    with pytest.raises(ValueError, match="left-handed"):
        fit_camera("c", pts * [1, -1, 1], uv)


@pytest.mark.parametrize(
    ("xy", "expected"),
    [
        # floor points -> (x0, y0, x1, y1) of the rectangle
        ([(0.0, 0.0), (1.0, 2.0)], (-0.5, -0.5, 1.5, 2.5)),  # on the grid already
        ([(0.04, -0.04), (1.01, 1.99)], (-0.5, -0.6, 1.6, 2.5)),  # rounded outward
        ([(-1.234, 0.5)], (-1.8, 0.0, -0.7, 1.0)),  # a single point
    ],
)
def test_floor_rectangle(xy, expected):
    corners = floor_rectangle(np.array(xy))
    (x0, y0), (x1, _), (_, y1), _ = corners
    assert (x0, y0, x1, y1) == pytest.approx(expected, abs=1e-12)
    assert all(round(v, 1) == v for c in corners for v in c)


# --- the dataset --------------------------------------------------------------------------------


def _superbody() -> list[str]:
    exe = shutil.which("superbody", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "superbody.edge.cli"]


def test_cli_calibrates_dev_json(tmp_path, raw):
    out, report = tmp_path / "site.toml", tmp_path / "errors.json"
    proc = subprocess.run(
        [*_superbody(), "calibrate", "from-dataset", str(DEV_JSON), "--out", str(out), "--json-out", str(report)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "median_px" in proc.stdout and "617.000" in proc.stdout
    site = load_site(out)
    assert site.name == "wtf-apartment" and site.camera_ids == ("1", "2", "3") and site.obstacles == ()
    doc = json.loads(report.read_text())
    assert set(doc) == {"cameras"} and set(doc["cameras"]) == {"1", "2", "3"}
    pairs = dataset_pairs(raw)
    for cam in site.cameras:
        entry = doc["cameras"][cam.id]
        assert set(entry) == {"median_px", "max_px"}
        assert all(isinstance(v, float) for v in entry.values())
        err = reprojection_errors(cam, *pairs[cam.id])
        assert np.median(err) < 1.0 and entry["median_px"] < 1.0
        assert entry["median_px"] == pytest.approx(np.median(err), abs=1e-9)
        assert entry["max_px"] == pytest.approx(err.max(), abs=1e-9)
        assert cam.fps == 15.0 and cam.dist == () and (cam.width, cam.height) == (640, 480)


def test_cli_missing_file_is_one_line_and_exit_2(tmp_path):
    proc = subprocess.run(
        [*_superbody(), "calibrate", "from-dataset", str(tmp_path / "nope.json"), "--out", str(tmp_path / "s.toml")],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"superbody calibrate from-dataset: error: {tmp_path / 'nope.json'}: cannot read dataset file (No such file or directory)"
    ]
    assert not (tmp_path / "s.toml").exists()


@pytest.mark.parametrize(
    ("content", "extra", "expected"),
    [
        # (input file, extra arguments, text of the one-line error)
        ('{"data_set": [', [], "not valid JSON (line 1"),  # truncated JSON
        ("[]", [], "top level: must be an object"),  # wrong shape
        ('{"data_set": [{"superbody": [{"cameraId": 9}]}]}', [], "data_set[0].superbody[0].cameraId: must be one of"),
        (None, ["--fps", "0"], "--fps must be > 0"),  # bad flag
        (None, ["--name", "my site"], "site.name must be"),  # not a valid site name
        (None, ["--out-dir-missing"], "No such file or directory"),  # cannot write the site file
    ],
)
def test_cli_bad_input_in_process(tmp_path, capsys, raw, content, extra, expected):
    from superbody.edge.cli import main

    path = tmp_path / "in.json"
    if content is None:
        path = DEV_JSON
    else:
        path.write_text(content)
    out = tmp_path / "s.toml"
    if extra == ["--out-dir-missing"]:
        out, extra = tmp_path / "missing" / "s.toml", []
    assert main(["calibrate", "from-dataset", str(path), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("superbody calibrate from-dataset: error: ") and expected in err[0]
    assert not out.exists()


def test_shipped_site_matches_a_fresh_calibration(raw):
    shipped = load_site(SITE_TOML)
    fresh, fits = calibrate_dataset(raw)
    assert shipped.name == fresh.name == "wtf-apartment"
    assert shipped.floor == fresh.floor and shipped.obstacles == ()
    assert shipped.camera_ids == fresh.camera_ids
    header = SITE_TOML.read_text().split("[site]")[0]
    assert "superbody calibrate from-dataset" in header and "fps" in header
    pairs = dataset_pairs(raw)
    for a, b in zip(shipped.cameras, fresh.cameras):
        assert [a.fx, a.fy, a.cx, a.cy, a.fps] == pytest.approx([b.fx, b.fy, b.cx, b.cy, b.fps], abs=1e-4)
        assert np.allclose(a.t, b.t, atol=1e-6) and np.allclose(a.R, b.R, atol=1e-6)
        assert np.median(reprojection_errors(a, *pairs[a.id])) < 1e-3
        assert fits[a.id].median_px < 1e-3


def test_shipped_site_is_what_the_readme_describes():
    site = load_site(SITE_TOML)
    for cam in site.cameras:
        assert cam.fx == pytest.approx(617.0, abs=0.01) and cam.fy == pytest.approx(617.0, abs=0.01)
        assert (cam.cx, cam.cy) == pytest.approx((320.0, 240.0), abs=0.01)
        assert 1.9 < cam.t[2] < 2.7  # hung about 2 to 2.6 m above the floor
        assert cam.R[:, 2][2] < 0  # looking down
    doc = tomllib.loads(SITE_TOML.read_text())
    assert all(c["dist"] == [] for c in doc["cameras"])
