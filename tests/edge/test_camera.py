"""Camera model: projection, rays and plane intersection."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from superbody.edge.camera import Camera, intersect_plane, look_at_rotation, pixel_to_ray, project


def _camera(dist=()) -> Camera:
    R = look_at_rotation(np.array([0.0, -3.0, 2.5]), np.array([0.0, 1.0, 0.8]))
    return Camera(
        id="c", width=1280, height=720, fps=15.0, fx=900.0, fy=910.0, cx=641.5, cy=358.0, dist=tuple(dist),
        position=(0.0, -3.0, 2.5), rotation=tuple(map(tuple, R)),
    )


CAMERAS = {
    "pinhole": _camera(),
    "barrel": _camera((-0.28, 0.09, 0.001, -0.0005, -0.012)),  # a wide-angle webcam
    "pincushion": _camera((0.12, -0.05, 0.0, 0.0, 0.0)),
    "rational": _camera((0.2, -0.1, 0.0005, 0.0005, 0.01, 0.25, -0.08, 0.02)),  # 8-coefficient model
}


@pytest.mark.parametrize("name", sorted(CAMERAS))
@settings(max_examples=300, deadline=None)
@given(u=st.floats(0, 1279), v=st.floats(0, 719), depth=st.floats(0.3, 30))
def test_project_inverts_pixel_to_ray(name, u, v, depth):
    cam = CAMERAS[name]
    origin, d = pixel_to_ray(np.array([[u, v]]), cam)
    uv, z = project(origin + depth * d, cam)
    assert z[0] > 0
    np.testing.assert_allclose(uv[0], [u, v], atol=1e-6, rtol=0)


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_grid_across_whole_image(name):
    cam = CAMERAS[name]
    uu, vv = np.meshgrid(np.linspace(0, cam.width - 1, 33), np.linspace(0, cam.height - 1, 19))
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    origin, d = pixel_to_ray(uv, cam)
    back, _ = project(origin + 4.0 * d, cam)
    assert np.abs(back - uv).max() < 1e-6


def test_projection_matrix_matches_project_without_distortion():
    cam = CAMERAS["pinhole"]
    pts = np.array([[0.5, 1.0, 1.2], [-1.0, 2.0, 0.0], [0.0, 0.0, 1.7]])
    h = np.hstack([pts, np.ones((3, 1))]) @ cam.projection_matrix.T
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], project(pts, cam)[0], atol=1e-9)


def test_points_behind_camera_have_negative_depth():
    cam = CAMERAS["pinhole"]
    _, z = project(np.array([[0.0, -6.0, 2.5]]), cam)  # 3 m behind the camera
    assert z[0] < 0


def test_look_at_centres_the_target_with_image_up_towards_sky():
    cam = CAMERAS["pinhole"]
    uv, _ = project(np.array([[0.0, 1.0, 0.8]]), cam)
    np.testing.assert_allclose(uv[0], [cam.cx, cam.cy], atol=1e-9)
    above, _ = project(np.array([[0.0, 1.0, 1.8]]), cam)
    assert above[0, 1] < cam.cy  # higher in the world = smaller v
    with pytest.raises(ValueError, match="parallel"):
        look_at_rotation(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.0, 0.0]))


# (ray direction, plane height, expected point or None when the plane is not ahead)
PLANE_CASES = [
    ((0.0, 0.0, -1.0), 0.0, (1.0, 2.0, 0.0)),  # straight down to the floor
    ((1.0, 0.0, -1.0), 1.0, (3.0, 2.0, 1.0)),  # 45 degrees down to z = 1
    ((0.0, 1.0, 0.0), 0.0, None),  # parallel to the floor
    ((0.0, 0.0, 1.0), 0.0, None),  # pointing away from the plane
]


@pytest.mark.parametrize("direction,height,expected", PLANE_CASES)
def test_intersect_plane(direction, height, expected):
    origin = np.array([1.0, 2.0, 3.0])
    d = np.array([direction], dtype=float)
    d /= np.linalg.norm(d)
    pts, valid = intersect_plane(origin, d, height)
    if expected is None:
        assert not valid[0] and np.isnan(pts[0]).all()
    else:
        assert valid[0]
        np.testing.assert_allclose(pts[0], expected, atol=1e-12)


def test_intersect_plane_empty():
    pts, valid = intersect_plane(np.zeros(3), np.zeros((0, 3)))
    assert pts.shape == (0, 3) and valid.shape == (0,)


def test_floor_point_round_trip():
    cam = CAMERAS["barrel"]
    floor = np.array([[0.3, 1.5, 0.0], [-1.2, 0.4, 0.0], [1.0, 3.0, 0.0]])
    uv, _ = project(floor, cam)
    origin, d = pixel_to_ray(uv, cam)
    back, valid = intersect_plane(origin, d, 0.0)
    assert valid.all()
    np.testing.assert_allclose(back, floor, atol=1e-8)
