"""Kalibr camchain YAML (``camchain.yaml``) as ``SourceCamera`` s.

Per camera ``camN``: ``camera_model: pinhole``, ``intrinsics: [fu, fv, pu, pv]``,
``distortion_model: radtan`` (``distortion_coeffs: [k1, k2, r1, r2]``, OpenCV's k1, k2, p1, p2)
or ``none``, ``resolution: [width, height]``, and from cam1 on ``T_cn_cnm1``: the 4 x 4 transform
taking camera N-1's coordinates to camera N's (metres). The chain starts at camera 0, so the
world is camera 0's frame (x right, y down, z forward) unless ``T_cam0_world`` (world points to
camera 0's coordinates) says where the world is. ``T_cam_imu``, ``rostopic``, ``timeshift_cam_imu``
and ``cam_overlaps`` are not needed and are ignored. Omnidirectional, double-sphere and fisheye
(``equidistant``) models have no equivalent in the site's camera model and are refused.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from superbody.edge.calibration.formats import SourceCamera, line_of, matrix, read_tree
from superbody.edge.calibration.frames import ImportFailure

__all__ = ["DISTORTIONS", "read_kalibr", "parse_transform", "kalibr_projection"]

DISTORTIONS = ("radtan", "none")


def _transform(value: Any, where: str) -> NDArray[np.float64]:
    T = matrix(value, (4, 4), where, "a 4 x 4 transform [[R, t], [0, 0, 0, 1]]")
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-9:
        raise ImportFailure(f"{where}: the last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-4 or np.linalg.det(R) < 0:
        raise ImportFailure(f"{where}: the upper-left 3 x 3 must be a rotation (orthonormal, det +1); |R^T R - I| = {err:.2g}, "
                            f"det = {np.linalg.det(R):+.3f}")
    return T


def parse_transform(text: str, flag: str = "--T-cam0-world") -> NDArray[np.float64]:
    """A 4 x 4 transform from 16 (or 12: the top three rows) comma- or space-separated numbers, or
    from a YAML/JSON file holding it (bare, or under ``T_cam0_world``).

    Raises:
        ImportFailure: neither, or not a rigid transform.
    """
    path = Path(text)
    if path.is_file():
        tree, _ = read_tree(path)
        if isinstance(tree, dict):
            tree = tree.get("T_cam0_world", tree.get("T"))
        return _transform(tree, f"{flag} {path.name}")
    try:
        v = [float(x) for x in re.split(r"[,\s]+", text.strip()) if x]
    except ValueError:
        v = []
    if len(v) not in (12, 16):
        raise ImportFailure(f"{flag} must be a file holding a 4 x 4 matrix, or its 16 numbers row by row (12 without the last row), "
                            f"got {text!r}")
    if len(v) == 12:
        v += [0.0, 0.0, 0.0, 1.0]
    return _transform(np.reshape(v, (4, 4)), flag)


def kalibr_projection(T_cam_world: NDArray, intrinsics: NDArray, dist: NDArray) -> Callable[[NDArray], NDArray]:
    """Kalibr's pinhole-radtan projection of world points (N, 3): transform to the camera with the
    4 x 4 chain, normalise, radial-tangential distortion, then fu, fv, pu, pv."""
    fu, fv, pu, pv = intrinsics
    k1, k2, r1, r2 = dist if len(dist) else (0.0, 0.0, 0.0, 0.0)

    def project(p: NDArray) -> NDArray:
        ph = np.column_stack([np.asarray(p, dtype=np.float64).reshape(-1, 3), np.ones(len(p))])  # (N, 4)
        pc = ph @ T_cam_world.T
        x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
        mx2, my2, mxy = x * x, y * y, x * y
        rho2 = mx2 + my2
        rad = k1 * rho2 + k2 * rho2 * rho2
        xd = x + x * rad + 2.0 * r1 * mxy + r2 * (rho2 + 2.0 * mx2)
        yd = y + y * rad + 2.0 * r2 * mxy + r1 * (rho2 + 2.0 * my2)
        return np.column_stack([fu * xd + pu, fv * yd + pv])

    return project


def read_kalibr(path: Path, T_cam0_world: NDArray | None = None) -> list[SourceCamera]:
    """The cameras of a Kalibr camchain (see the module docstring).

    Raises:
        ImportFailure: no cam0, a camera model or distortion other than pinhole and ``DISTORTIONS``,
            a field of the wrong shape (file:line and key), a broken chain.
    """
    tree, text = read_tree(path)
    keys = sorted((k for k in (tree if isinstance(tree, dict) else {}) if re.fullmatch(r"cam\d+", k)), key=lambda k: int(k[3:]))
    if not keys or keys[0] != "cam0":
        raise ImportFailure(f"{path.name}: a Kalibr camchain has cam0, cam1, ... at the top level, got {', '.join(map(str, tree or {})) or 'none'}")
    if [int(k[3:]) for k in keys] != list(range(len(keys))):
        raise ImportFailure(f"{path.name}: cameras must be cam0, cam1, ... without gaps (each T_cn_cnm1 refers to the one before), got {', '.join(keys)}")
    T = np.eye(4) if T_cam0_world is None else np.asarray(T_cam0_world, dtype=np.float64)
    out = []
    for k in keys:
        cam = tree[k]
        line = line_of(text, k)

        def at(field: str, k: str = k, line: int = line) -> str:
            return f"{path.name}:{line}: {k}.{field}"

        if not isinstance(cam, dict):
            raise ImportFailure(f"{at('')[:-1]} must be a map of the camera's fields")
        model = cam.get("camera_model", "pinhole")
        if model != "pinhole":
            raise ImportFailure(f"{at('camera_model')} must be pinhole, got {model!r} (omni, ds and eucm have no equivalent in the site's "
                                "OpenCV camera model)")
        if "intrinsics" not in cam:
            raise ImportFailure(f"{at('intrinsics')} is missing: [fu, fv, pu, pv] in pixels")
        intr = matrix(cam["intrinsics"], (4,), at("intrinsics"), "[fu, fv, pu, pv] in pixels")
        dmodel = cam.get("distortion_model", "none")
        if dmodel not in DISTORTIONS:
            raise ImportFailure(f"{at('distortion_model')} must be one of {', '.join(DISTORTIONS)}, got {dmodel!r} "
                                "(equidistant, fov: fisheye models the site's camera model does not have)")
        dist = matrix(cam.get("distortion_coeffs", []), (4,), at("distortion_coeffs"), "[k1, k2, r1, r2]") if dmodel == "radtan" else np.zeros(0)
        width: int | None = None
        height: int | None = None
        if "resolution" in cam:
            wh = matrix(cam["resolution"], (2,), at("resolution"), "[width, height] in pixels")
            if not all(16 <= v <= 16384 and v == int(v) for v in wh):
                raise ImportFailure(f"{at('resolution')} must be [width, height], whole pixels in [16, 16384], got {wh.tolist()}")
            width, height = int(wh[0]), int(wh[1])
        if k != "cam0":
            if "T_cn_cnm1" not in cam:
                raise ImportFailure(f"{at('T_cn_cnm1')} is missing: the 4 x 4 transform from cam{int(k[3:]) - 1}'s coordinates to {k}'s")
            T = _transform(cam["T_cn_cnm1"], at("T_cn_cnm1")) @ T
        K = np.array([[intr[0], 0.0, intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
        out.append(SourceCamera(
            id=k, K=K, dist=tuple(float(v) for v in dist) if np.any(dist) else (), R=T[:3, :3].copy(), t=T[:3, 3].copy(),
            width=width, height=height, fps=None, where=f"{path.name}:{line} ({k})", project=kalibr_projection(T.copy(), intr, dist),
            notes=("world: camera 0's frame (x right, y down, z forward)",) if T_cam0_world is None and k == "cam0" else (),
        ))
    return out
