"""COLMAP text models (``cameras.txt`` + ``images.txt``) as ``SourceCamera`` s.

``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS...``; ``images.txt``: per image a line
``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` (the world-to-camera rotation as a unit
quaternion, scalar first, and the translation: ``x_cam = R(q) X + t``) and a line of its 2D
points (ignored). Each image is one camera of the site (a fixed camera, photographed once), named
by its file name. COLMAP puts the first pixel's centre at (0.5, 0.5), OpenCV at (0, 0): the
principal point moves by half a pixel.

Camera models (``MODELS``), their parameters and their OpenCV distortion:

- ``SIMPLE_PINHOLE``: f, cx, cy; ``PINHOLE``: fx, fy, cx, cy (no distortion);
- ``SIMPLE_RADIAL``: f, cx, cy, k (k1 = k); ``RADIAL``: f, cx, cy, k1, k2;
- ``OPENCV``: fx, fy, cx, cy, k1, k2, p1, p2; ``FULL_OPENCV``: ... k1, k2, p1, p2, k3, k4, k5, k6.

The fisheye and other models have no OpenCV equivalent in the site's camera model and are refused.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from superbody.edge.calibration.formats import SourceCamera, camera_id
from superbody.edge.calibration.frames import ImportFailure

__all__ = ["MODELS", "PIXEL_OFFSET", "read_colmap", "quaternion_matrix", "colmap_projection"]

# Model name -> parameter names, in COLMAP's order.
MODELS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
PIXEL_OFFSET = 0.5  # COLMAP pixel coordinates minus OpenCV's


def quaternion_matrix(q: NDArray) -> NDArray[np.float64]:
    """(3, 3) rotation of a unit quaternion (w, x, y, z), Hamilton convention."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _rotate(q: NDArray, p: NDArray) -> NDArray[np.float64]:
    """Points (N, 3) turned by a unit quaternion (w, x, y, z): q p q*, as COLMAP's Eigen does."""
    w, v = q[0], q[1:]
    t = 2.0 * np.cross(v, p)  # (N, 3)
    return p + w * t + np.cross(v, t)


def _intrinsics(model: str, params: NDArray) -> tuple[float, float, float, float, NDArray]:
    """fx, fy, cx, cy (COLMAP's pixels) and the 8 OpenCV distortion coefficients of a model."""
    d = np.zeros(8)
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cx, cy = params[:3]
        fx, fy = f, f
        d[: len(params) - 3] = params[3:]  # k1[, k2]
    else:
        fx, fy, cx, cy = params[:4]
        d[: len(params) - 4] = params[4:]
    return float(fx), float(fy), float(cx), float(cy), d


def colmap_projection(model: str, params: NDArray, q: NDArray, t: NDArray) -> Callable[[NDArray], NDArray]:
    """COLMAP's own projection of world points (N, 3) to its pixels (N, 2), model by model
    (``WorldToImage``: normalise, add the distortion's offsets, scale and shift)."""
    params = np.asarray(params, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    t = np.asarray(t, dtype=np.float64)

    def project(p: NDArray) -> NDArray:
        pc = _rotate(q, np.asarray(p, dtype=np.float64).reshape(-1, 3)) + t
        u, v = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
        uu, vv, uv = u * u, v * v, u * v
        r2 = uu + vv
        if model == "SIMPLE_RADIAL":
            du, dv = u * params[3] * r2, v * params[3] * r2
        elif model == "RADIAL":
            radial = params[3] * r2 + params[4] * r2 * r2
            du, dv = u * radial, v * radial
        elif model in ("OPENCV", "FULL_OPENCV"):
            k1, k2, p1, p2 = params[4:8]
            if model == "OPENCV":
                radial = k1 * r2 + k2 * r2 * r2
            else:
                k3, k4, k5, k6 = params[8:12]
                r4, r6 = r2 * r2, r2 * r2 * r2
                radial = (1 + k1 * r2 + k2 * r4 + k3 * r6) / (1 + k4 * r2 + k5 * r4 + k6 * r6) - 1
            du = u * radial + 2 * p1 * uv + p2 * (r2 + 2 * uu)
            dv = v * radial + 2 * p2 * uv + p1 * (r2 + 2 * vv)
        else:
            du = dv = np.zeros_like(u)
        if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
            fx = fy = params[0]
            cx, cy = params[1], params[2]
        else:
            fx, fy, cx, cy = params[:4]
        return np.column_stack([fx * (u + du) + cx, fy * (v + dv) + cy])

    return project


def _lines(path: Path) -> list[tuple[int, str]]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ImportFailure(f"{path}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    return [(i + 1, line.rstrip("\r")) for i, line in enumerate(text.split("\n"))]


def _numbers(tokens: Sequence[str], where: str, what: str) -> NDArray[np.float64]:
    try:
        v = np.array([float(x) for x in tokens])
    except ValueError:
        raise ImportFailure(f"{where}: {what} must be numbers, got {' '.join(tokens)!r}") from None
    if not np.isfinite(v).all():
        raise ImportFailure(f"{where}: {what} must be finite, got {' '.join(tokens)!r}")
    return v


def _files(paths: Sequence[Path]) -> tuple[Path, Path]:
    """cameras.txt and images.txt from a model folder or the two files."""
    found: dict[str, Path] = {}
    for p in paths:
        if p.is_dir():
            for sub in (p, p / "sparse" / "0", p / "0"):
                for name in ("cameras.txt", "images.txt"):
                    if (sub / name).is_file():
                        found.setdefault(name, sub / name)
        else:
            found[p.name] = p
    missing = [n for n in ("cameras.txt", "images.txt") if n not in found]
    if missing:
        raise ImportFailure(f"--format colmap needs cameras.txt and images.txt (a text model: colmap model_converter --output_type TXT); "
                            f"missing: {', '.join(missing)} in {', '.join(str(p) for p in paths)}")
    return found["cameras.txt"], found["images.txt"]


def _cameras(path: Path) -> dict[int, tuple[str, int, int, NDArray, str]]:
    """CAMERA_ID -> (model, width, height, params, where)."""
    out = {}
    for n, line in _lines(path):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{path.name}:{n}"
        tok = line.split()
        if len(tok) < 4:
            raise ImportFailure(f"{where}: a camera line is CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., got {line.strip()!r}")
        model = tok[1].upper()
        if model not in MODELS:
            raise ImportFailure(f"{where}: camera model must be one of {', '.join(MODELS)}, got {tok[1]!r} "
                                "(fisheye and other models have no equivalent in the site's OpenCV camera model)")
        if len(tok) - 4 != len(MODELS[model]):
            raise ImportFailure(f"{where}: {model} takes {len(MODELS[model])} parameters ({', '.join(MODELS[model])}), got {len(tok) - 4}")
        try:
            cid, width, height = int(tok[0]), int(tok[2]), int(tok[3])
        except ValueError:
            raise ImportFailure(f"{where}: CAMERA_ID, WIDTH and HEIGHT must be whole numbers, got {' '.join(tok[:4])!r}") from None
        if not (16 <= width <= 16384 and 16 <= height <= 16384):
            raise ImportFailure(f"{where}: WIDTH and HEIGHT must be in [16, 16384] pixels, got {width} x {height}")
        out[cid] = (model, width, height, _numbers(tok[4:], where, "PARAMS"), where)
    return out


def _is_points(line: str) -> bool:
    """A line of 2D points (X Y POINT3D_ID ..., all numbers; empty when none), not the next image's
    line (whose NAME is not a number): hand-written models often leave the points lines out."""
    try:
        [float(x) for x in line.split()]
    except ValueError:
        return False
    return True


def read_colmap(paths: Sequence[Path]) -> list[SourceCamera]:
    """Every image of a COLMAP text model as a camera (see the module docstring).

    Raises:
        ImportFailure: a missing file, a malformed line (file:line), an unknown camera id or model.
    """
    cam_file, img_file = _files(paths)
    cameras = _cameras(cam_file)
    out: list[SourceCamera] = []
    lines = [(n, line) for n, line in _lines(img_file)]
    i = 0
    while i < len(lines) and (lines[i][1].lstrip().startswith("#") or not lines[i][1].strip()):
        i += 1
    ids: set[str] = set()
    while i < len(lines):
        n, line = lines[i]
        if not line.strip():  # between or after images
            i += 1
            continue
        where = f"{img_file.name}:{n}"
        tok = line.split()
        if len(tok) < 10:
            raise ImportFailure(f"{where}: an image line is IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {line.strip()[:80]!r}")
        q = _numbers(tok[1:5], where, "QW QX QY QZ")
        t = _numbers(tok[5:8], where, "TX TY TZ")
        if abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise ImportFailure(f"{where}: QW QX QY QZ must be a unit quaternion, |q| = {np.linalg.norm(q):.4f}")
        try:
            cam_id = int(tok[8])
        except ValueError:
            raise ImportFailure(f"{where}: CAMERA_ID must be a whole number, got {tok[8]!r}") from None
        if cam_id not in cameras:
            raise ImportFailure(f"{where}: CAMERA_ID {cam_id} is not in {cam_file.name} (cameras: {', '.join(map(str, sorted(cameras)))})")
        model, width, height, params, cam_where = cameras[cam_id]
        name = " ".join(tok[9:])
        cid = camera_id(Path(name).with_suffix("").as_posix(), f"image{tok[0]}")
        if cid in ids:
            cid = camera_id(f"image{tok[0]}", f"image{len(out)}")
        ids.add(cid)
        fx, fy, cx, cy, d = _intrinsics(model, params)
        K = np.array([[fx, 0.0, cx - PIXEL_OFFSET], [0.0, fy, cy - PIXEL_OFFSET], [0.0, 0.0, 1.0]])
        dist = () if not d.any() else tuple(float(v) for v in (d if d[4:].any() else d[:4]))
        out.append(SourceCamera(
            id=cid, K=K, dist=dist, R=quaternion_matrix(q), t=t, width=width, height=height, fps=None,
            where=f"{where} ({name}, camera {cam_id} {model} at {cam_where})", project=colmap_projection(model, params, q, t),
            pixel_offset=PIXEL_OFFSET, notes=(f"COLMAP {model}; principal point moved by -0.5 px (COLMAP's first pixel centre is 0.5, OpenCV's 0)",),
        ))
        i += 1 + (i + 1 < len(lines) and _is_points(lines[i + 1][1]))  # the image line and its line of 2D points, if there
    if not out:
        raise ImportFailure(f"{img_file.name}: no image: each is a line IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME and a line of 2D points")
    return out
