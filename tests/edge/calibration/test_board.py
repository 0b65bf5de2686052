"""The ChArUco floor board: frames, pose solve, and calibration from boards rendered by known cameras."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from superbody.edge.calibration.board import (
    DICTIONARIES,
    MAX_OBLIQUE_DEG,
    MIN_CORNERS,
    BoardError,
    BoardSpec,
    Corners,
    board_to_world,
    calibrate_intrinsics,
    calibrate_pose,
    camera_pose_in_world,
    detect_corners,
    make_board,
    parse_squares,
    pose_from_corners,
    solve_board_pose,
)
from superbody.edge.calibration.render import board_texture, placement_in_front, render_board
from superbody.edge.camera import Camera, look_at_rotation, project
from superbody.edge.site import load_site
from tests.conftest import WTF_SITE

SPEC = BoardSpec(5, 7, 0.16, 0.12, "DICT_5X5_100")
# The accuracy target for a board 2.5 m in front of each apartment camera.
MAX_POSITION_M = 0.03
MAX_ANGLE_DEG = 0.5


def _angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip((np.trace(Ra @ Rb.T) - 1.0) / 2.0, -1.0, 1.0)))


def _camera(position, target, *, R=None, fx=617.0, fy=617.0, cx=320.0, cy=240.0, width=640, height=480, dist=()) -> Camera:
    R = look_at_rotation(np.array(position, float), np.array(target, float)) if R is None else np.asarray(R)
    return Camera(id="c", width=width, height=height, fps=15.0, fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(dist),
                  position=tuple(map(float, position)), rotation=tuple(map(tuple, R)))


def _errors(fit, cam: Camera) -> tuple[float, float]:
    return float(np.linalg.norm(fit.position - cam.t)), _angle_deg(fit.rotation, cam.R)


# --- the spec -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("5x7", (5, 7)),
        ("5X7", (5, 7)),  # either case
        (" 8 x 11 ", (8, 11)),  # spaces
        ("5", None),  # one number
        ("5x", None),
        ("1x7", None),  # a board needs 2 squares each way
        ("5x65", None),  # too many
        ("axb", None),
        ("5x7x2", None),
    ],
)
def test_parse_squares(text, expected):
    if expected is None:
        with pytest.raises(BoardError, match="squares must be"):
            parse_squares(text)
    else:
        assert parse_squares(text) == expected


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        # (fields different from SPEC, text of the error)
        ({"squares_x": 1}, "squares_x must be an integer in [2, 64]"),
        ({"squares_y": 7.0}, "squares_y must be an integer"),
        ({"square_m": 0.0}, "square_m must be metres"),
        ({"marker_m": math.nan}, "marker_m must be metres"),
        ({"marker_m": 0.16}, "marker_m must be smaller than square_m"),
        ({"dictionary": "DICT_5X5_99"}, "dictionary must be one of DICT_4X4_100"),
        ({"squares_x": 20, "squares_y": 20, "dictionary": "DICT_4X4_50"}, "needs 200 markers but DICT_4X4_50 has 50"),
    ],
)
def test_board_spec_rejects(kwargs, message):
    fields = {"squares_x": 5, "squares_y": 7, "square_m": 0.16, "marker_m": 0.12, "dictionary": "DICT_5X5_100", **kwargs}
    with pytest.raises(BoardError) as e:
        BoardSpec(**fields)
    assert message in str(e.value)


def test_spec_geometry_and_dictionaries():
    assert SPEC.size_m == pytest.approx((0.8, 1.12)) and SPEC.n_corners == 24
    assert "DICT_5X5_100" in DICTIONARIES and "DICT_APRILTAG_36h11" in DICTIONARIES
    assert "DICT_APRILTAG_36H11" not in DICTIONARIES  # one spelling of each
    assert BoardSpec(5, 7, 0.16, 0.12, "dict_apriltag_36H11").dictionary == "DICT_APRILTAG_36h11"  # any case
    assert len(make_board(SPEC).getChessboardCorners()) == SPEC.n_corners


def test_texture_is_the_board_as_printed():
    img, scale = board_texture(SPEC, px_per_m=1000.0, margin_m=0.02)
    assert scale == pytest.approx(1000.0) and img.shape == (1120 + 40, 800 + 40)
    assert (img[:20] == 255).all() and (img[:, -20:] == 255).all()  # the white margin
    # OpenCV's board frame: the top-left square is black, the next one along x white with a marker.
    assert img[20 + 80, 20 + 80] == 0 and img[20 + 80, 20 + 160 + 5] == 255


# --- frames -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("origin", "yaw_deg", "board_point", "world_point"),
    [
        # the board's x runs along yaw, its y 90 degrees clockwise of it, its z into the floor
        ((0.0, 0.0), 0.0, (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        ((0.0, 0.0), 0.0, (0.0, 1.0, 0.0), (0.0, -1.0, 0.0)),
        ((0.0, 0.0), 0.0, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)),
        ((1.0, 2.0), 90.0, (0.5, 0.0, 0.0), (1.0, 2.5, 0.0)),
        ((1.0, 2.0), 90.0, (0.0, 0.5, 0.0), (1.5, 2.0, 0.0)),
        ((-3.0, 0.5), 180.0, (0.2, 0.3, 0.0), (-3.2, 0.8, 0.0)),
        ((0.0, 0.0), -45.0, (math.sqrt(2), 0.0, 0.0), (1.0, -1.0, 0.0)),
    ],
)
def test_board_to_world(origin, yaw_deg, board_point, world_point):
    R, t = board_to_world(origin, math.radians(yaw_deg))
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R @ np.array(board_point) + t, world_point, atol=1e-12)


def test_placement_puts_the_board_centre_in_front_of_the_camera():
    cam = load_site(WTF_SITE).camera("2")
    origin, yaw = placement_in_front(cam, SPEC, 2.5)
    R, t = board_to_world(origin, yaw)
    centre = R @ np.array([0.4, 0.56, 0.0]) + t
    heading = cam.R[:2, 2] / np.linalg.norm(cam.R[:2, 2])
    assert np.allclose(centre[:2], cam.t[:2] + 2.5 * heading, atol=1e-12) and centre[2] == 0.0
    assert R[:2, 0] @ heading == pytest.approx(0.0, abs=1e-12)  # x across the line of sight
    assert R[:2, 1] @ heading == pytest.approx(-1.0)  # y (down the print) towards the camera
    assert (cam.R[:, 0] @ R[:, 0]) > 0.9  # x to the camera's right


# --- the pose solve on exact points -------------------------------------------------------------


@pytest.mark.parametrize(
    ("position", "target", "dist"),
    [
        # (camera position, where it looks, distortion)
        ((0.4, -2.0, 2.2), (0.4, 0.6, 0.0), ()),
        ((-1.5, 1.0, 1.0), (0.4, 0.6, 0.0), ()),  # low and oblique
        ((0.9, -1.0, 3.0), (0.4, 0.5, 0.0), (-0.2, 0.05, 0.001, -0.002, 0.0)),  # barrel distortion
    ],
)
def test_solve_board_pose_on_exact_corners(position, target, dist):
    cam = _camera(position, target, dist=dist)
    origin, yaw = (0.1, 1.2), math.radians(20.0)
    obj = make_board(SPEC).getChessboardCorners().astype(np.float64)
    R_wb, t_wb = board_to_world(origin, yaw)
    uv, depth = project(obj @ R_wb.T + t_wb, cam)
    assert (depth > 0).all()
    pose = solve_board_pose(obj, uv, cam)
    assert pose.reprojection_px < 1e-6 and pose.corners == len(obj)
    rotation, position_w = camera_pose_in_world(pose, origin, yaw)
    assert np.allclose(position_w, cam.t, atol=1e-7) and _angle_deg(rotation, cam.R) < 1e-5


def test_solve_board_pose_drops_corners_that_fit_much_worse():
    cam = _camera((0.4, -2.0, 2.2), (0.4, 0.6, 0.0))
    obj = make_board(SPEC).getChessboardCorners().astype(np.float64)
    R_wb, t_wb = board_to_world((0.0, 0.0), 0.0)
    uv, _ = project(obj @ R_wb.T + t_wb, cam)
    uv[[3, 17]] += [[1.5, -0.8], [-1.0, 1.2]]  # two corners pulled by a blurred marker border
    pose = solve_board_pose(obj, uv, cam)
    assert pose.corners == len(obj) - 2 and pose.reprojection_px < 1e-6
    rotation, position = camera_pose_in_world(pose, (0.0, 0.0), 0.0)
    assert np.allclose(position, cam.t, atol=1e-7)
    # With only MIN_CORNERS corners nothing is dropped: the error shows in the RMS instead.
    few = solve_board_pose(obj[:MIN_CORNERS], np.vstack([uv[:3], uv[3:MIN_CORNERS]]), cam)
    assert few.corners == MIN_CORNERS and few.reprojection_px > 0.1


def _exact_corners(cam: Camera, origin, yaw, ids=None, noise_px: float = 0.0) -> Corners:
    obj = make_board(SPEC).getChessboardCorners().astype(np.float64)
    ids = np.arange(len(obj)) if ids is None else np.asarray(ids)
    R_wb, t_wb = board_to_world(origin, yaw)
    uv, _ = project(obj[ids] @ R_wb.T + t_wb, cam)
    uv += np.random.default_rng(0).normal(0.0, noise_px, uv.shape) if noise_px else 0.0
    return Corners(ids.astype(np.int32), uv, obj[ids], markers=17)


CORNER_FAILURES = [
    # (name, camera position, corner ids kept, pixel noise, text of the error)
    ("grazing view: camera 0.3 m up, board 2.4 m away", (0.4, -3.0, 0.3), None, 0.0, "deg from its normal, allowed <= 80"),
    ("five corners", (0.4, -2.0, 2.2), [0, 1, 2, 5, 9], 0.0, "found 5 ChArUco corners (17 markers), need at least 6"),
    ("corners on one row", (0.4, -2.0, 2.2), [0, 1, 2, 3], 0.0, "need at least 6"),
    ("corners on one column", (0.4, -2.0, 2.2), [1, 5, 9, 13, 17, 21], 0.0, "lie on one line"),
    ("corners 6 px off: wrong intrinsics or board", (0.4, -2.0, 2.2), None, 6.0, "reproject with RMS"),
]


@pytest.mark.parametrize(("name", "position", "ids", "noise", "message"), CORNER_FAILURES, ids=[c[0] for c in CORNER_FAILURES])
def test_pose_from_corners_refuses(name, position, ids, noise, message):
    cam = _camera(position, (0.4, 0.6, 0.0))
    with pytest.raises(BoardError) as e:
        pose_from_corners(_exact_corners(cam, (0.0, 0.0), 0.0, ids, noise), SPEC, cam, (0.0, 0.0), 0.0)
    assert message in str(e.value)


def test_pose_from_corners_reports_the_viewing_angle():
    cam = _camera((0.4, -2.0, 2.2), (0.4, 0.6, 0.0))
    fit = pose_from_corners(_exact_corners(cam, (0.0, 0.0), 0.0), SPEC, cam, (0.0, 0.0), 0.0)
    # The line of sight to the board's centre (0.4, -0.56, 0) against the floor's normal.
    expected = math.degrees(math.atan2(math.hypot(0.0, -0.56 + 2.0), 2.2))
    assert fit.oblique_deg == pytest.approx(expected, abs=1e-6) and fit.oblique_deg < MAX_OBLIQUE_DEG
    assert np.allclose(fit.position, cam.t, atol=1e-7) and fit.corners == SPEC.n_corners


# --- rendered boards ----------------------------------------------------------------------------


def test_rendered_corners_are_where_the_camera_model_projects_them():
    # A camera straight above the board's centre, image x along the board's x: no solve involved,
    # so this pins the renderer, the board frame and the detector to the same convention.
    origin, yaw = (-0.3, 0.9), math.radians(30.0)
    R_wb, t_wb = board_to_world(origin, yaw)
    centre = R_wb @ np.array([0.4, 0.56, 0.0]) + t_wb
    cam = _camera(centre + [0.0, 0.0, 1.8], None, R=R_wb, fx=400.0, fy=400.0, width=480, height=480, cx=240.0, cy=240.0)
    img = render_board(SPEC, cam, origin, yaw, seed=3)
    corners = detect_corners(img, SPEC, cam)
    assert len(corners) == SPEC.n_corners
    uv, _ = project(corners.object_points @ R_wb.T + t_wb, cam)
    err = np.linalg.norm(uv - corners.pixels, axis=1)
    assert err.max() < 0.25, err


@pytest.mark.parametrize("camera_id", ["1", "2", "3"])
def test_apartment_camera_pose_from_a_board_2_5_m_in_front(camera_id):
    cam = load_site(WTF_SITE).camera(camera_id)
    origin, yaw = placement_in_front(cam, SPEC, 2.5)
    img = render_board(SPEC, cam, origin, yaw, seed=int(camera_id))
    fit = calibrate_pose(img, SPEC, cam, origin, yaw)
    dp, da = _errors(fit, cam)
    assert dp < MAX_POSITION_M and da < MAX_ANGLE_DEG, (dp, da)
    assert fit.corners >= 12 and fit.reprojection_px < 0.5


_DISTORTED = _camera((1.0, -2.5, 2.3), (0.3, 0.5, 0.0), fx=480.0, fy=482.0, cx=330.0, cy=236.0,
                     dist=(-0.25, 0.08, 0.0005, -0.0007, -0.01))

POSE_CASES = [
    # (name, camera, distance in front m, board yaw offset deg, sideways shift m)
    ("board turned 45 deg", "2", 2.5, 45.0, 0.0),
    ("board turned 90 deg (long side across)", "2", 2.5, 90.0, 0.0),
    ("board turned 180 deg (origin near the camera)", "1", 2.5, 180.0, 0.0),
    ("board 0.6 m to the side", "1", 2.5, 0.0, 0.6),
    ("board close, 1.8 m", "2", 1.8, -30.0, 0.0),
    ("board far, 3.5 m", "2", 3.5, 0.0, 0.0),
    ("wide-angle camera with strong distortion", _DISTORTED, 2.3, 15.0, -0.3),
]


@pytest.mark.parametrize(("name", "camera", "distance", "yaw_offset", "shift"), POSE_CASES, ids=[c[0] for c in POSE_CASES])
def test_pose_cases(name, camera, distance, yaw_offset, shift):
    cam = load_site(WTF_SITE).camera(camera) if isinstance(camera, str) else camera
    origin, yaw = placement_in_front(cam, SPEC, distance, math.radians(yaw_offset))
    right = cam.R[:2, 0] / np.linalg.norm(cam.R[:2, 0])
    origin = tuple(np.asarray(origin) + shift * right)
    img = render_board(SPEC, cam, origin, yaw, seed=11)
    fit = calibrate_pose(img, SPEC, cam, origin, yaw)
    dp, da = _errors(fit, cam)
    assert dp < MAX_POSITION_M and da < MAX_ANGLE_DEG, (dp, da)


def test_wrong_origin_moves_the_camera_by_the_same_amount():
    cam = load_site(WTF_SITE).camera("2")
    origin, yaw = placement_in_front(cam, SPEC, 2.5)
    img = render_board(SPEC, cam, origin, yaw, seed=5)
    fit = calibrate_pose(img, SPEC, cam, (origin[0] + 0.5, origin[1] - 0.25), yaw)
    assert np.allclose(fit.position - cam.t, [0.5, -0.25, 0.0], atol=MAX_POSITION_M)


FAILURES = [
    # (name, how the image is made, text of the error)
    ("too oblique: board 9 m away", "far", "ChArUco corners"),
    ("no board: it lies behind the camera", "behind", "found 0 ChArUco corners"),
    ("another dictionary than the print's", "dictionary", "found 0 ChArUco corners"),
    ("image of another size than the site's camera", "size", "image is 320x240 but camera '1' is 640x480"),
    ("a blank image", "blank", "found 0 ChArUco corners (0 markers)"),
]


@pytest.mark.parametrize(("name", "case", "message"), FAILURES, ids=[f[0] for f in FAILURES])
def test_unusable_views_fail_with_a_clear_error(name, case, message):
    cam = load_site(WTF_SITE).camera("1")
    spec = SPEC
    distance = {"far": 9.0, "behind": -2.0}.get(case, 2.5)
    origin, yaw = placement_in_front(cam, SPEC, distance)
    img = render_board(SPEC, cam, origin, yaw, seed=2)
    if case == "dictionary":
        spec = BoardSpec(5, 7, 0.16, 0.12, "DICT_6X6_100")
    elif case == "size":
        img = img[::2, ::2].copy()
    elif case == "blank":
        img = np.full_like(img, 128)
    with pytest.raises(BoardError) as e:
        calibrate_pose(img, spec, cam, origin, yaw)
    assert message in str(e.value)
    if "ChArUco corners" in message:
        assert f"need at least {MIN_CORNERS}" in str(e.value)


# --- intrinsics ---------------------------------------------------------------------------------


def intrinsics_views(cam: Camera, spec: BoardSpec, n: int = 8) -> list[np.ndarray]:
    """``n`` renders of the board by one camera from around it, tilted 20-40 degrees, the board
    filling different parts of the image (shared with the CLI test)."""
    w_m, h_m = spec.size_m
    R_wb, t_wb = board_to_world((0.0, 0.0), 0.0)
    centre = R_wb @ np.array([w_m / 2, h_m / 2, 0.0]) + t_wb
    images = []
    for k in range(n):
        a = 2 * math.pi * k / n
        tilt = math.radians(20.0 + 20.0 * (k % 2))
        distance = 1.6 * max(w_m, h_m) * (1.0 + 0.15 * (k % 3))
        position = centre + distance * np.array([math.sin(tilt) * math.cos(a), math.sin(tilt) * math.sin(a), math.cos(tilt)])
        # Aim beside the board so that it falls in different parts of the image.
        target = centre + 0.3 * max(w_m, h_m) * np.array([math.cos(3 * a), math.sin(3 * a), 0.0])
        view = replace(cam, position=tuple(position), rotation=tuple(map(tuple, look_at_rotation(position, target))))
        images.append(render_board(spec, view, (0.0, 0.0), 0.0, seed=k))
    return images


SMALL = BoardSpec(9, 6, 0.03, 0.022, "DICT_4X4_50")  # an A4 sheet


def test_intrinsics_from_rendered_views():
    truth = _camera((0, 0, 1), (0, 1, 1), fx=600.0, fy=605.0, cx=322.0, cy=238.0, dist=(-0.2, 0.05, 0.0, 0.0, 0.0))
    fit = calibrate_intrinsics(intrinsics_views(truth, SMALL, n=6), SMALL)
    assert fit.views == 6 and fit.skipped == () and fit.image_size == (640, 480)
    assert fit.rms_px < 0.2
    assert fit.K[0, 0] == pytest.approx(600.0, rel=0.01) and fit.K[1, 1] == pytest.approx(605.0, rel=0.01), fit.K
    assert fit.K[0, 2] == pytest.approx(322.0, abs=4.0) and fit.K[1, 2] == pytest.approx(238.0, abs=4.0)
    assert fit.dist[0] == pytest.approx(-0.2, abs=0.03)


def test_intrinsics_needs_enough_views():
    truth = _camera((0, 0, 1), (0, 1, 1))
    views = intrinsics_views(truth, SMALL, n=4)
    blank = np.full_like(views[0], 128)
    with pytest.raises(BoardError, match="3 of 6 images show at least 6 corners, need at least 4"):
        calibrate_intrinsics(views[:3] + [blank] * 3, SMALL)
    with pytest.raises(BoardError, match="image 1 is 320x240, the first is 640x480"):
        calibrate_intrinsics([views[0], views[1][::2, ::2]], SMALL)
    with pytest.raises(BoardError, match="no images"):
        calibrate_intrinsics([], SMALL)
