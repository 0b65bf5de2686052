"""Calibration files written from a hand-made site, each in its source's own conventions, for the
import's tests to read back. Written here by hand (the maths spelled out per format), not with
edge.calibration's readers, so a round trip checks both directions independently.

Each writer returns the files and the flags that say how its world lies.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.site import Site

__all__ = ["dome_site", "level_cam0_site", "write_opencv", "write_colmap", "write_kalibr", "write_json", "write_left_handed", "extrinsics",
           "COLMAP_MODEL"]

# Intrinsics per camera of dome_site, each in the form one COLMAP model holds.
COLMAP_MODEL = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV")
_INTRINSICS = (  # fx, fy, cx, cy, dist
    (1400.0, 1400.0, 960.0, 540.0, ()),
    (1385.5, 1391.2, 955.3, 547.9, ()),
    (1410.0, 1410.0, 962.1, 538.4, (-0.08, 0.0, 0.0, 0.0)),
    (1395.0, 1395.0, 958.0, 541.0, (-0.11, 0.04, 0.0, 0.0)),
    (1402.3, 1398.7, 963.4, 536.2, (-0.12, 0.06, 0.0008, -0.0005)),
)


def _camera(cid: str, pos, target, intr, width=1920, height=1080, fps=30.0) -> Camera:
    fx, fy, cx, cy, dist = intr
    R = look_at_rotation(np.asarray(pos, dtype=np.float64), np.asarray(target, dtype=np.float64))
    return Camera(id=cid, width=width, height=height, fps=fps, fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(dist),
                  position=tuple(float(v) for v in pos), rotation=tuple(tuple(float(v) for v in r) for r in R))


def dome_site() -> Site:
    """Five HD cameras on a ring of radius 4 m around a dome's floor, 2.2-3.0 m up, each aimed at a
    point near the centre at 1 m (the issue's installation), REP-103 metres."""
    cams = []
    for i in range(5):
        a = np.radians(90 + 72 * i)
        pos = (4.0 * np.cos(a) + 0.5, 4.0 * np.sin(a) - 0.3, 2.2 + 0.2 * i)
        target = (0.5 + 0.3 * np.cos(a + 1.0), -0.3 + 0.3 * np.sin(a + 1.0), 1.0)
        cams.append(_camera(f"dome{i}", pos, target, _INTRINSICS[i]))
    return Site(name="dome", cameras=tuple(cams), floor=((-3.0, -3.0), (3.0, -3.0), (3.0, 3.0), (-3.0, 3.0)))


def level_cam0_site() -> Site:
    """A site whose world is camera 0's as Kalibr has it: camera 0 level at (0, 0, 1.6) looking
    along +y (its x to the world's +x), the others around the room."""
    c0 = Camera(id="cam0", width=1280, height=720, fps=30.0, fx=900.0, fy=900.0, cx=640.0, cy=360.0, dist=(-0.1, 0.03, 0.0, 0.0),
                position=(0.0, 0.0, 1.6), rotation=((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)))
    others = [_camera(f"cam{i}", pos, (0.3, 3.0, 0.9), (905.0, 903.0, 641.0, 358.0, (-0.09, 0.02, 0.001, 0.0)), 1280, 720)
              for i, pos in enumerate([(3.0, 0.5, 2.4), (3.2, 6.0, 2.5), (-2.8, 5.5, 2.3)], start=1)]
    return Site(name="level", cameras=(c0, *others), floor=((-2.0, 0.5), (2.5, 0.5), (2.5, 5.5), (-2.0, 5.5)))


def extrinsics(cam: Camera, A: np.ndarray, origin, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV extrinsics ``x_cam = R X_src + t`` (t in source units) in a source world whose points
    are ``X_src = scale * A (X - origin)`` for site points X."""
    # X = A^T X_src / scale + origin  (A orthonormal), so
    # x_cam[m] = R_cw (X - C) = R_cw A^T X_src / scale + R_cw (origin - C), and in source units:
    R_cw = cam.R.T
    return R_cw @ A.T, scale * R_cw @ (np.asarray(origin, dtype=np.float64) - cam.t)


# OpenCV: a board on a wall 1.5 m above the floor made the world: x along the wall, y down,
# z out of the wall (the site's +y); centimetres.
OPENCV_A = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
OPENCV_FLAGS = ["--unit", "cm", "--up", "-y", "--floor-at", "150"]


def write_opencv(site: Site, folder: Path, ext: str = "yaml", rotation: str = "R") -> tuple[list[Path], list[str]]:
    """One cv2.FileStorage file per camera (``camera_matrix``, ``distortion_coefficients``, ``R``
    or ``rvec``, ``tvec``, ``image_width``, ``image_height``), in centimetres, world y down."""
    paths = []
    for cam in site.cameras:
        R, t = extrinsics(cam, OPENCV_A, (0.0, 0.0, 1.5), 100.0)
        path = folder / f"{cam.id}.{ext}"
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", cam.width)
        fs.write("image_height", cam.height)
        fs.write("camera_matrix", cam.K)
        fs.write("distortion_coefficients", np.array(cam.dist if cam.dist else [0.0] * 5).reshape(-1, 1))
        if rotation == "R":
            fs.write("R", R)
        else:
            fs.write("rvec", cv2.Rodrigues(R)[0])
        fs.write("tvec", t.reshape(3, 1))
        fs.release()
        paths.append(path)
    return paths, OPENCV_FLAGS


# COLMAP: an SfM world at half a metre per unit, y down, z along the site's +x, origin 0.8 m
# under the floor's plane.
COLMAP_A = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
COLMAP_FLAGS = ["--unit", "0.5", "--up", "-y", "--x-axis", "+z", "--floor-at", "-1.6", "--fps", "30"]


def _colmap_params(model: str, cam: Camera) -> list[float]:
    cx, cy = cam.cx + 0.5, cam.cy + 0.5  # COLMAP's first pixel centre is at 0.5
    d = list(cam.dist) + [0.0] * (4 - len(cam.dist))
    return {
        "SIMPLE_PINHOLE": [cam.fx, cx, cy],
        "PINHOLE": [cam.fx, cam.fy, cx, cy],
        "SIMPLE_RADIAL": [cam.fx, cx, cy, d[0]],
        "RADIAL": [cam.fx, cx, cy, d[0], d[1]],
        "OPENCV": [cam.fx, cam.fy, cx, cy, *d[:4]],
    }[model]


def write_colmap(site: Site, folder: Path, models=COLMAP_MODEL) -> tuple[list[Path], list[str]]:
    """A COLMAP text model: cameras.txt (one model per camera) and images.txt (quaternion w, x, y, z
    of the world-to-camera rotation, and t), one image per camera, with and without points lines."""
    folder.mkdir(parents=True, exist_ok=True)
    cams = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    imgs = ["# Image list with two lines of data per image:", "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
            "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for i, (cam, model) in enumerate(zip(site.cameras, models), start=1):
        R, t = extrinsics(cam, COLMAP_A, (0.0, 0.0, -0.8), 2.0)
        x, y, z, w = (float(v) for v in Rotation.from_matrix(R).as_quat())
        t = [float(v) for v in t]
        cams.append(f"{i} {model} {cam.width} {cam.height} " + " ".join(repr(float(v)) for v in _colmap_params(model, cam)))
        imgs.append(f"{10 + i} {w!r} {x!r} {y!r} {z!r} {t[0]!r} {t[1]!r} {t[2]!r} {i} {cam.id}.jpg")
        imgs.append("" if i % 2 else "100.5 200.25 -1 300.0 400.0 7")
    (folder / "cameras.txt").write_text("\n".join(cams) + "\n")
    (folder / "images.txt").write_text("\n".join(imgs) + "\n")
    return [folder], COLMAP_FLAGS


def _T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _rows(T: np.ndarray, indent: str = "  ") -> str:
    return "".join(f"{indent}- [{', '.join(repr(float(v)) for v in row)}]\n" for row in T)


def write_kalibr(site: Site, folder: Path, world: bool = True) -> tuple[list[Path], list[str]]:
    """A Kalibr camchain (metres, T_cn_cnm1 chain from cam0) and, with ``world``, the site's world
    as T_cam0_world in a file of its own; without it the world is camera 0 (``level_cam0_site``)."""
    Tw = [_T(*extrinsics(cam, np.eye(3), (0.0, 0.0, 0.0), 1.0)) for cam in site.cameras]  # T_cn_world
    text = "# written by Kalibr's camchain format\n"
    for n, cam in enumerate(site.cameras):
        d = list(cam.dist)[:4]
        text += (f"cam{n}:\n  camera_model: pinhole\n  intrinsics: [{cam.fx!r}, {cam.fy!r}, {cam.cx!r}, {cam.cy!r}]\n"
                 f"  distortion_model: {'radtan' if d else 'none'}\n  distortion_coeffs: [{', '.join(repr(v) for v in (d or [0.0] * 4))}]\n")
        if n:
            text += "  T_cn_cnm1:\n" + _rows(Tw[n] @ np.linalg.inv(Tw[n - 1]))
        text += f"  T_cam_imu:\n{_rows(np.eye(4))}  timeshift_cam_imu: 0.0\n  rostopic: /cam{n}/image_raw\n"
        text += f"  resolution: [{cam.width}, {cam.height}]\n  cam_overlaps: [{(n + 1) % len(site.cameras)}]\n"
    path = folder / "camchain.yaml"
    path.write_text(text)
    if not world:
        # Camera 0 is level: its y points down, the floor 1.6 m under it.
        return [path], ["--up", "-y", "--floor-at", str(site.cameras[0].t[2]), "--fps", "30"]
    tpath = folder / "T_cam0_world.yaml"
    tpath.write_text("T_cam0_world:\n" + _rows(Tw[0]))
    return [path], ["--T-cam0-world", str(tpath), "--fps", "30"]


# A graphics tool's JSON: millimetres, world y up, each camera's pose (camera-to-world) with
# OpenGL camera axes (y up, z backward).
JSON_A = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
JSON_FLAGS = ["--format", "json", "--extrinsics", "camera-to-world", "--camera-axes", "opengl", "--unit", "mm", "--up", "+y"]


def write_json(site: Site, folder: Path) -> tuple[list[Path], list[str]]:
    """Plain JSON: {"cameras": [{"id", "K", "dist", "R", "t", "width", "height", "fps"}]}, R the
    camera's orientation in a y-up world (OpenGL camera axes), t its position in millimetres."""
    F = np.diag([1.0, -1.0, -1.0])
    out = {"cameras": [{
        "id": cam.id, "K": cam.K.tolist(), "dist": list(cam.dist), "width": cam.width, "height": cam.height, "fps": cam.fps,
        "R": (JSON_A @ cam.R @ F).tolist(), "t": (1000.0 * JSON_A @ cam.t).tolist(),
    } for cam in site.cameras]}
    path = folder / "cameras.json"
    path.write_text(json.dumps(out, indent=1))
    return [path], JSON_FLAGS


# A left-handed source world (as WheresTheFellow's): millimetres, Y up, Z the site's +y.
LEFT_A = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
LEFT_FLAGS = ["--format", "json", "--unit", "mm", "--up", "+y", "--x-axis", "+x", "--y-axis", "+z"]


def write_left_handed(site: Site, folder: Path) -> tuple[list[Path], list[str]]:
    """Plain JSON, world-to-camera (x_cam = R X + t, det R = -1) in a left-handed Y-up world, mm."""
    cams = {}
    for cam in site.cameras:
        R, t = extrinsics(cam, LEFT_A, (0.0, 0.0, 0.0), 1000.0)
        cams[cam.id] = {"K": cam.K.tolist(), "dist": list(cam.dist), "R": R.tolist(), "t": t.tolist(),
                        "image_size": [cam.width, cam.height], "fps": cam.fps}
    path = folder / "left.json"
    path.write_text(json.dumps({"cameras": cams}))
    return [path], LEFT_FLAGS
