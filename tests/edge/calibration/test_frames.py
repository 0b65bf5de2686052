"""A calibration's world in the site's (edge/calibration/frames.py): axes, units, the floor, poses."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.calibration.frames import ImportFailure, WorldFrame, opengl_to_opencv, parse_axis, parse_unit, pose_to_extrinsics
from superbody.edge.camera import look_at_rotation


@pytest.mark.parametrize("text, vector", [
    ("+x", (1, 0, 0)),  # signed
    ("-y", (0, -1, 0)),  # down, as OpenCV's worlds
    ("z", (0, 0, 1)),  # no sign: positive
    (" -Z ", (0, 0, -1)),  # case and spaces
])
def test_parse_axis(text, vector):
    np.testing.assert_array_equal(parse_axis(text, "--up"), vector)


@pytest.mark.parametrize("text", ["q", "+w", "xy", "", "--y", "1"])
def test_parse_axis_names_the_flag_and_the_axes(text):
    with pytest.raises(ImportFailure, match=r"--up must be one of \+x, -x, \+y, -y, \+z, -z"):
        parse_axis(text, "--up")


@pytest.mark.parametrize("text, metres", [
    ("m", 1.0), ("cm", 0.01), ("mm", 0.001),  # named
    ("0.5", 0.5),  # metres per unit (an SfM world)
    ("0.0254", 0.0254),  # inches
])
def test_parse_unit(text, metres):
    assert parse_unit(text) == metres


@pytest.mark.parametrize("text", ["km", "0", "-1", "nan", "1e9"])
def test_parse_unit_names_the_allowed_values(text):
    with pytest.raises(ImportFailure, match="--unit must be one of m, cm, mm"):
        parse_unit(text)


# (frame, site x, y, z axes written in source coordinates, handedness)
FRAMES = [
    (WorldFrame(), [[1, 0, 0], [0, 1, 0], [0, 0, 1]], 1),  # REP-103 already
    (WorldFrame(up="-y"), [[1, 0, 0], [0, 0, 1], [0, -1, 0]], 1),  # OpenCV: y down, z becomes the site's y
    (WorldFrame(up="+y"), [[1, 0, 0], [0, 0, -1], [0, 1, 0]], 1),  # graphics: y up
    (WorldFrame(up="-y", x_axis="+z"), [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], 1),  # another x
    (WorldFrame(up="+x"), [[0, 1, 0], [0, 0, 1], [1, 0, 0]], 1),  # x up: y becomes the site's x
    (WorldFrame(up="-z"), [[1, 0, 0], [0, -1, 0], [0, 0, -1]], 1),  # a board face up on the floor: z into it
    (WorldFrame(up="+y", x_axis="+x", y_axis="+z"), [[1, 0, 0], [0, 0, 1], [0, 1, 0]], -1),  # left-handed, Y up (WheresTheFellow)
]


@pytest.mark.parametrize("frame, M, hand", FRAMES)
def test_world_frame_axes(frame, M, hand):
    np.testing.assert_array_equal(frame.rotation, M)
    assert frame.handedness == hand


@pytest.mark.parametrize("frame, message", [
    (WorldFrame(up="-y", x_axis="+y"), "--x-axis must be across --up"),  # parallel to up
    (WorldFrame(up="+z", y_axis="+x"), "--y-axis must be across"),  # y along x
    (WorldFrame(up="down"), "--up must be one of"),  # not an axis
])
def test_world_frame_errors_name_the_flag(frame, message):
    with pytest.raises(ImportFailure, match=message):
        _ = frame.rotation


def test_points_unit_and_floor():
    """OpenCV's world in cm, y down, the floor at y = 150: a point on the floor is at z = 0."""
    f = WorldFrame(up="-y", unit_m=0.01, floor=150.0)
    np.testing.assert_allclose(f.points([[20.0, 150.0, 300.0], [0.0, -100.0, 0.0]]), [[0.2, 3.0, 0.0], [0.0, 0.0, 2.5]])
    assert "floor at source y = 150" in f.describe() and "0.01 m per source unit" in f.describe()


def test_camera_pose_inverts_opencv_extrinsics():
    pos, target = np.array([1.0, -2.0, 2.5]), np.array([0.0, 1.0, 1.0])
    Rw = look_at_rotation(pos, target)
    R, t = pose_to_extrinsics(Rw, pos)  # site world, metres
    rotation, position = WorldFrame().camera_pose(R, t)
    np.testing.assert_allclose(rotation, Rw, atol=1e-12)
    np.testing.assert_allclose(position, pos, atol=1e-12)


def test_camera_pose_refuses_a_handedness_mismatch():
    R = np.diag([1.0, 1.0, -1.0])  # det -1: a left-handed world's rotation
    with pytest.raises(ImportFailure, match="determinant -1.*--y-axis"):
        WorldFrame().camera_pose(R, np.zeros(3))


def test_opengl_to_opencv_flips_y_and_z():
    R, t = opengl_to_opencv(np.eye(3), np.array([1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(R, np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_array_equal(t, [1.0, -2.0, -3.0])
