"""The calibration readers (edge/calibration/formats.py, colmap.py, kalibr.py) on the forms tools
write: OpenCV 4's and 5's YAML headers, ROS's camera_info YAML, several cameras in one file,
COLMAP's quaternions and hand-written models, Kalibr's block lists."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from superbody.edge.calibration.colmap import colmap_projection, quaternion_matrix, read_colmap
from superbody.edge.calibration.formats import line_of, read_matrices, read_tree
from superbody.edge.calibration.frames import ImportFailure
from superbody.edge.calibration.kalibr import parse_transform
from superbody.edge.calibration.site_import import detect_format
from superbody.edge.camera import Camera, project

# An OpenCV 4 calibration sample's output (%YAML:1.0), with the world pose added.
OPENCV4 = """%YAML:1.0
---
calibration_time: "Thu Jan 30 14:43:57 2020"
image_width: 1920
image_height: 1080
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.3704890781669139e+03, 0., 9.4620086455694741e+02, 0.,
       1.3711542706267094e+03, 5.4099755744500317e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ 9.55e-02, 1.55e-01, 6.28e-04, -4.74e-03, -8.36e-01 ]
rvec: [ 0.1, -0.2, 0.05 ]
tvec: [ 10.0, 20.0, 300.0 ]
fps: 25
"""

# ROS camera_info YAML (matrices as {rows, cols, data}), plus a pose.
ROS = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [430.2, 0, 306.6, 0, 430.9, 227.6, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.33, 0.11, 0.001, -0.002, 0]
R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
t: [0, 0, 2]
"""

# Two cameras in one file, under their own keys; block lists at the key's indentation (as Kalibr writes).
TWO = """left:
  K: [[800, 0, 320], [0, 800, 240], [0, 0, 1]]
  R:
  - [1, 0, 0]
  - [0, 1, 0]
  - [0, 0, 1]
  t: [0, 0, 0]
  size: [640, 480]
right:
  K: [[800, 0, 320], [0, 800, 240], [0, 0, 1]]
  rvec: [0, 0.1, 0]
  t: [-0.12, 0, 0]
  size: [640, 480]
"""


@pytest.mark.parametrize("name, text, ids, size, fps", [
    ("cam7.yaml", OPENCV4, ["cam7"], (1920, 1080), 25.0),  # OpenCV 4's header; the id from the file's name
    ("info.yaml", ROS, ["narrow_stereo"], (640, 480), None),  # ROS: the id from camera_name
    ("pair.yaml", TWO, ["left", "right"], (640, 480), None),  # one camera per key
])
def test_read_matrices_reads_what_tools_write(tmp_path, name, text, ids, size, fps):
    path = tmp_path / name
    path.write_text(text)
    cams = read_matrices([path])
    assert [c.id for c in cams] == ids
    for c in cams:
        assert (c.width, c.height, c.fps) == (*size, fps)
        np.testing.assert_allclose(c.R.T @ c.R, np.eye(3), atol=1e-12)
        assert c.K[2, 2] == 1.0 and c.K[0, 0] > 100


def test_read_tree_gives_opencv_matrices_as_arrays(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(OPENCV4)
    tree, _ = read_tree(path)
    assert tree["camera_matrix"].shape == (3, 3) and tree["distortion_coefficients"].shape == (5, 1)
    assert tree["calibration_time"].startswith("Thu") and tree["image_width"] == 1920


@pytest.mark.parametrize("text, key, line", [
    (OPENCV4, "camera_matrix", 6),  # a YAML key
    ('{\n  "cameras": [\n    {"K": 1}\n  ]\n}', "K", 3),  # a JSON key, quoted
    (TWO, "rvec", 11),  # nested
    (TWO, "nope", 0),  # absent: no line
])
def test_line_of(text, key, line):
    assert line_of(text, key) == line


@pytest.mark.parametrize("files, fmt", [
    ({"cameras.txt": "", "images.txt": ""}, "colmap"),  # a COLMAP text model's files
    ({"camchain.yaml": "cam0:\n  camera_model: pinhole\n  intrinsics: [1, 1, 1, 1]\n"}, "kalibr"),  # Kalibr's cam0 and intrinsics
    ({"c.json": '{"cameras": [{"K": [[1,0,0],[0,1,0],[0,0,1]]}]}'}, "json"),  # plain JSON with a cameras list
    ({"c.json": '{"camera_matrix": {"type_id": "opencv-matrix", "rows": 3}}'}, "opencv"),  # cv2.FileStorage's JSON
    ({"c.yaml": OPENCV4}, "opencv"),  # FileStorage YAML
])
def test_detect_format(tmp_path, files, fmt):
    paths = []
    for name, text in files.items():
        (tmp_path / name).write_text(text)
        paths.append(tmp_path / name)
    assert detect_format(paths) == fmt


def test_detect_format_needs_existing_files(tmp_path):
    with pytest.raises(ImportFailure, match="no such file"):
        detect_format([tmp_path / "nope.yaml"])


@pytest.mark.parametrize("q", [
    (1.0, 0.0, 0.0, 0.0),  # identity
    (0.0, 1.0, 0.0, 0.0),  # half a turn about x
    (0.7071067811865476, 0.0, 0.0, 0.7071067811865476),  # a quarter turn about z
    (0.5, -0.5, 0.5, 0.5),  # an oblique one
    (-0.2, 0.3, 0.8, -0.4690415759823429),  # negative scalar part
])
def test_quaternion_matrix_is_hamilton_scalar_first(q):
    w, x, y, z = q
    np.testing.assert_allclose(quaternion_matrix(np.array(q)), Rotation.from_quat([x, y, z, w]).as_matrix(), atol=1e-12)


def test_colmap_full_opencv_and_a_model_without_points_lines(tmp_path):
    """A hand-written model: FULL_OPENCV (8 coefficients), image lines with no points lines between them."""
    ref = Camera(id="a", width=1280, height=960, fps=30.0, fx=1000.0, fy=990.0, cx=641.0, cy=479.0,
                 dist=(-0.2, 0.05, 0.001, -0.002, 0.01, 0.1, 0.02, 0.003))
    (tmp_path / "cameras.txt").write_text("1 FULL_OPENCV 1280 960 1000 990 641.5 479.5 -0.2 0.05 0.001 -0.002 0.01 0.1 0.02 0.003\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n2 1 0 0 0 0.5 0 0 1 b.png\n")
    cams = read_colmap([tmp_path])
    assert [c.id for c in cams] == ["a", "b"]
    assert cams[0].dist == ref.dist and cams[0].K[0, 2] == 641.0  # OpenCV's pixel centres
    p = np.array([[0.3, -0.2, 2.0], [-0.5, 0.4, 3.0]])
    np.testing.assert_allclose(project(p, ref)[0], cams[0].project(p) - 0.5, atol=1e-9)


@pytest.mark.parametrize("model, params", [
    ("SIMPLE_RADIAL", [800.0, 320.5, 240.5, -0.1]),  # k
    ("RADIAL", [800.0, 320.5, 240.5, -0.1, 0.02]),  # k1, k2
    ("OPENCV", [800.0, 810.0, 320.5, 240.5, -0.1, 0.02, 0.001, -0.001]),  # k1, k2, p1, p2
])
def test_colmap_models_match_opencvs(model, params):
    q, t = np.array([1.0, 0, 0, 0]), np.zeros(3)
    theirs = colmap_projection(model, np.array(params), q, t)
    f = params[:2] if model == "OPENCV" else [params[0]] * 2
    c = params[2:4] if model == "OPENCV" else params[1:3]
    d = params[4:] if model == "OPENCV" else params[3:]
    cam = Camera(id="a", width=640, height=480, fps=1.0, fx=f[0], fy=f[1], cx=c[0] - 0.5, cy=c[1] - 0.5, dist=tuple(d) + (0.0,) * (4 - len(d)))
    p = np.array([[0.3, -0.2, 2.0], [-0.5, 0.4, 3.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(theirs(p) - 0.5, project(p, cam)[0], atol=1e-9)


@pytest.mark.parametrize("text, ok", [
    ("1 0 0 0  0 1 0 0  0 0 1 2  0 0 0 1", True),  # 16 numbers
    ("1,0,0,0,0,1,0,0,0,0,1,2", True),  # 12: the last row implied
    ("1 0 0 0 0 1 0 0 0 0 2 0 0 0 0 1", False),  # not a rotation
    ("1 2 3", False),  # too few
])
def test_parse_transform(text, ok):
    if ok:
        assert parse_transform(text)[2, 3] == 2.0
    else:
        with pytest.raises(ImportFailure, match="--T-cam0-world"):
            parse_transform(text)


def test_an_error_in_the_second_camera_of_a_file_names_its_line(tmp_path):
    path = tmp_path / "pair.yaml"
    path.write_text(TWO.replace("  rvec: [0, 0.1, 0]\n", "  rvec: [0, 0.1]\n"))
    with pytest.raises(ImportFailure, match=r"pair.yaml:11: right.rvec must be 3 numbers, got shape \(2,\)"):
        read_matrices([path])
