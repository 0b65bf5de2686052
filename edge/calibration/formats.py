"""Calibration files a site can be imported from, read into one form: ``SourceCamera``.

- ``opencv``: ``cv2.FileStorage`` YAML, XML or JSON (``camera_matrix`` or ``K``,
  ``distortion_coefficients``, ``R`` or ``rvec``, ``t``/``T``/``tvec``, ``image_width`` and
  ``image_height``), one camera per file or one per top-level key; also plain JSON of the same
  fields, with lists for matrices;
- ``json``: a plain JSON file of ``{"cameras": [{"id", "K", "dist", "R", "t", "width", "height",
  "fps"}, ...]}`` (or ``{id: {...}}``), whose extrinsics and camera axes are named by flags
  (``read_matrices``'s ``extrinsics`` and ``camera_axes``);
- ``colmap``: a text model's ``cameras.txt`` and ``images.txt`` (``edge.calibration.colmap``);
- ``kalibr``: a camchain YAML (``edge.calibration.kalibr``).

``edge.calibration.site_import.read_calibration`` picks the reader (``detect_format``).

Every reader keeps its source's world and unit (``edge.calibration.frames`` maps them onto the
site's) and gives each camera the source's own projection, so that the import can check the
converted camera against it. Errors are ``ImportFailure``, naming the file, the line where it can
and the key.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from superbody.edge.calibration.frames import ImportFailure, opengl_to_opencv, pose_to_extrinsics

__all__ = [
    "FORMATS", "SourceCamera", "read_tree", "line_of", "matrix", "camera_id", "read_matrices", "opencv_projection",
]

FORMATS = ("opencv", "json", "colmap", "kalibr")

# Field names as calibration tools write them, first the name errors use.
_K = ("camera_matrix", "K", "cameraMatrix", "intrinsic_matrix")
_DIST = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "dist", "D", "distortion")
_R = ("R", "rotation_matrix", "rmat", "rotation")
_RVEC = ("rvec", "rotation_vector", "rvecs")
_T = ("t", "T", "tvec", "translation", "translation_vector")
_SIZE = ("image_size", "imageSize", "resolution", "size")
_FPS = ("fps", "frame_rate", "framerate", "rate_hz")
_ID = ("id", "camera_name", "name")


@dataclass(frozen=True)
class SourceCamera:
    """One camera as its calibration file has it.

    Attributes:
        id: camera id for the site.
        K: (3, 3) intrinsics, pixels, in OpenCV's pixel convention (the first pixel's centre at 0, 0).
        dist: OpenCV distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), or empty.
        R: (3, 3) source-world-to-camera rotation, OpenCV camera axes: ``x_cam = R p + t``.
        t: (3,) translation in source units.
        width, height: image size in pixels, None where the source does not say.
        fps: frame rate, None where the source does not say.
        where: the file (and line) the camera came from, for messages.
        project: the source's own camera model: source-world points (N, 3) to its pixels (N, 2).
        pixel_offset: the source's pixel coordinates minus OpenCV's (COLMAP: 0.5).
        notes: what the reader assumed or converted for this camera.
    """

    id: str
    K: NDArray[np.float64]
    dist: tuple[float, ...]
    R: NDArray[np.float64]
    t: NDArray[np.float64]
    width: int | None
    height: int | None
    fps: float | None
    where: str
    project: Callable[[NDArray], NDArray] = field(repr=False)
    pixel_offset: float = 0.0
    notes: tuple[str, ...] = ()


def line_of(text: str, key: str, after: int = 0) -> int:
    """The 1-based line of the first ``key:`` (or ``"key":``) in a YAML or JSON text at or after
    line ``after``, else 0."""
    start = 0
    for _ in range(max(after - 1, 0)):
        start = text.find("\n", start) + 1
        if start == 0:
            return 0
    m = re.compile(rf'(?:^|[\s{{,-])"?{re.escape(key)}"?\s*:', re.MULTILINE).search(text, start)
    return text.count("\n", 0, m.end()) + 1 if m else 0


def _at(path: Path, text: str, key: str) -> str:
    """``file:line: key`` for a dotted key (``cam1.camera_matrix``: the field after its camera's line)."""
    *parents, last = key.split(".")
    after = line_of(text, parents[0]) if parents and "[" not in parents[0] else 0
    line = line_of(text, last, after)
    return f"{path.name}:{line}: {key}" if line else f"{path.name}: {key}"


def _yaml_block_lists(text: str) -> str:
    """YAML with block-list items written at their key's indentation (``T_cn_cnm1:\\n- [..]``, as
    Kalibr writes them) indented under the key, which OpenCV's YAML reader requires."""
    out, key_indent = [], None
    for line in text.splitlines():
        item = re.match(r"^(\s*)- ", line)
        if item and key_indent is not None and len(item.group(1)) == key_indent:
            line = "  " + line
        elif not item:
            key = re.match(r"^(\s*)[^\s#-][^:]*:\s*(#.*)?$", line)
            key_indent = len(key.group(1)) if key else None
        out.append(line)
    return "\n".join(out) + "\n"


def _node(n: Any) -> Any:
    """A cv2.FileNode as Python: dict, list, float, str, or an array for an OpenCV matrix."""
    if n.isMap():
        keys = n.keys()
        if {"rows", "cols", "dt", "data"} <= set(keys) and n.mat() is not None:  # an OpenCV matrix
            return np.asarray(n.mat(), dtype=np.float64)
        return _matrices({k: _node(n.getNode(k)) for k in keys})  # ROS's {rows, cols, data}
    if n.isSeq():
        return [_node(n.at(i)) for i in range(n.size())]
    if n.isInt() or n.isReal():
        return n.real()
    if n.isString():
        return n.string()
    return None


def _matrices(tree: Any) -> Any:
    """JSON matrices written as ``{"rows", "cols", "data"}`` (OpenCV's JSON, ROS's YAML) as arrays."""
    if isinstance(tree, dict):
        if {"rows", "cols", "data"} <= set(tree) and isinstance(tree["data"], list):
            try:
                return np.asarray(tree["data"], dtype=np.float64).reshape(int(tree["rows"]), int(tree["cols"]))
            except (TypeError, ValueError):
                return tree  # the field's own check names it
        return {k: _matrices(v) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_matrices(v) for v in tree]
    return tree


def read_tree(path: Path) -> tuple[Any, str]:
    """A YAML, XML or JSON file as Python values (matrices as arrays), and its text.

    Raises:
        ImportFailure: unreadable, or not YAML/XML/JSON (with the line the parser stopped at).
    """
    import cv2

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ImportFailure(f"{path}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    suffix = path.suffix.lower()
    if suffix == ".json" or (text.lstrip().startswith("{") and suffix not in (".yaml", ".yml", ".xml")):
        try:
            return _matrices(json.loads(text)), text
        except json.JSONDecodeError as e:
            raise ImportFailure(f"{path.name}:{e.lineno}: not valid JSON ({e.msg}, column {e.colno})") from None
    fmt = cv2.FILE_STORAGE_FORMAT_XML if text.lstrip().startswith("<") else cv2.FILE_STORAGE_FORMAT_YAML
    body = text if fmt == cv2.FILE_STORAGE_FORMAT_XML else _yaml_block_lists(text)
    try:
        fs = cv2.FileStorage(body, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY | fmt)
    except (cv2.error, SystemError) as e:
        cause = e.__cause__ if isinstance(e, SystemError) and e.__cause__ is not None else e
        m = re.search(r"\((\d+)\): (.*?)'?\s*$", str(cause).strip())
        why = f"{m.group(1)}: {m.group(2)}" if m else " ".join(str(cause).split())[-160:]
        raise ImportFailure(f"{path.name}:{why} (not a YAML or XML file OpenCV reads)") from None
    try:
        return _node(fs.root()), text
    finally:
        fs.release()


def matrix(value: Any, shape: tuple[int, ...], where: str, what: str = "") -> NDArray[np.float64]:
    """A finite array of exactly ``shape`` (a (3,) vector also from (3, 1) or (1, 3)), else ``ImportFailure``."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is not None and len(shape) == 1 and a.ndim == 2 and 1 in a.shape:
        a = a.reshape(-1)
    if a is None or a.shape != shape or not np.isfinite(a).all():
        got = "not numbers" if a is None else ("non-finite numbers" if a.shape == shape else f"shape {a.shape}")
        need = " x ".join(map(str, shape)) + (" matrix" if len(shape) == 2 else " numbers")
        raise ImportFailure(f"{where} must be {what or need}, got {got}")
    return a


def camera_id(text: str, fallback: str) -> str:
    """A site camera id (letters, digits, ``_``, ``-``; 1-64) from a file stem or a source's name."""
    cid = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-")[:64]
    return cid or fallback


def _get(cam: dict, names: Sequence[str]) -> tuple[str, Any]:
    for n in names:
        if n in cam:
            return n, cam[n]
    return names[0], None


def opencv_projection(K: NDArray, dist: Sequence[float], R: NDArray, t: NDArray) -> Callable[[NDArray], NDArray]:
    """OpenCV's own projection (``cv2.projectPoints``) of source-world points (N, 3) to pixels (N, 2).

    The points are moved into the camera first (``x_cam = R X + t``), so a left-handed source
    world's rotation (determinant -1, no Rodrigues vector) projects as well.
    """
    import cv2

    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(3)
    d = np.asarray(dist, dtype=np.float64) if len(dist) else np.zeros(4)

    def project(p: NDArray) -> NDArray:
        pc = np.asarray(p, dtype=np.float64).reshape(-1, 3) @ R.T + t
        uv, _ = cv2.projectPoints(pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, d)
        return uv.reshape(-1, 2)

    return project


def _dist(value: Any, where: str) -> tuple[float, ...]:
    if value is None:
        return ()
    try:
        d = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ImportFailure(f"{where} must be 0, 4, 5 or 8 numbers (k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {value!r}") from None
    if not np.isfinite(d).all() or len(d) not in (0, 4, 5, 8, 12, 14):
        raise ImportFailure(f"{where} must be 0, 4, 5 or 8 finite numbers (k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {len(d)}: {d.tolist()}")
    if len(d) > 8:
        if np.any(d[8:]):
            raise ImportFailure(f"{where}: thin-prism and tilt coefficients (s1..s4, tx, ty) are not supported; the site's model "
                                "takes at most 8 (k1, k2, p1, p2, k3, k4, k5, k6)")
        d = d[:8]
    return tuple(float(v) for v in d) if np.any(d) else ()


def _matrix_camera(cam: dict, cid: str, path: Path, text: str, key: str, extrinsics: str, camera_axes: str) -> SourceCamera:
    """One camera's fields (aliases above) as a ``SourceCamera``."""
    def at(name: str) -> str:
        return _at(path, text, f"{key}.{name}" if key else name)

    kname, kval = _get(cam, _K)
    if kval is None and all(k in cam for k in ("fx", "fy", "cx", "cy")):
        kval = [[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]]
    if kval is None:
        raise ImportFailure(f"{at(kname)} is missing: the 3 x 3 intrinsic matrix (also read as {', '.join(_K[1:])}, or fx, fy, cx, cy)")
    K = matrix(kval, (3, 3), at(kname))
    if K[0, 1] != 0 or K[1, 0] != 0 or np.any(K[2] != [0.0, 0.0, 1.0]):
        raise ImportFailure(f"{at(kname)} must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {K.tolist()}")
    dname, dval = _get(cam, _DIST)
    dist = _dist(dval, at(dname))
    rname, rval = _get(cam, _R)
    vname, vval = _get(cam, _RVEC)
    if rval is None and vval is None:
        raise ImportFailure(f"{at(rname)} is missing: the 3 x 3 rotation (or {vname}, a Rodrigues vector)")
    if rval is not None:
        R = matrix(rval, (3, 3), at(rname))
    else:
        import cv2

        R = np.asarray(cv2.Rodrigues(matrix(vval, (3,), at(vname)))[0], dtype=np.float64)
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-4 or abs(abs(np.linalg.det(R)) - 1) > 1e-4:
        raise ImportFailure(f"{at(rname if rval is not None else vname)} must be a rotation (orthonormal), |R^T R - I| = {err:.2g}")
    tname, tval = _get(cam, _T)
    if tval is None:
        raise ImportFailure(f"{at(tname)} is missing: the translation, 3 numbers (also read as {', '.join(_T[1:])})")
    t = matrix(tval, (3,), at(tname))
    notes = []
    if camera_axes == "opengl":
        R, t = opengl_to_opencv(R, t) if extrinsics == "world-to-camera" else (R @ np.diag([1.0, -1.0, -1.0]), t)
        notes.append("camera axes OpenGL (x right, y up, z backward), turned to OpenCV's")
    if extrinsics == "camera-to-world":
        R, t = pose_to_extrinsics(R, t)
    width = height = None
    if "image_width" in cam or "image_height" in cam or "width" in cam or "height" in cam:
        wname, wval = _get(cam, ("image_width", "width"))
        hname, hval = _get(cam, ("image_height", "height"))
        width, height = _pixels(wval, at(wname)), _pixels(hval, at(hname))
    else:
        sname, sval = _get(cam, _SIZE)
        if sval is not None:
            wh = matrix(sval, (2,), at(sname), "[width, height] in pixels")
            width, height = _pixels(wh[0], at(sname) + "[0]"), _pixels(wh[1], at(sname) + "[1]")
    fname, fval = _get(cam, _FPS)
    fps = None
    if fval is not None:
        if not isinstance(fval, (int, float)) or isinstance(fval, bool) or not 0.1 <= fval <= 1000:
            raise ImportFailure(f"{at(fname)} must be a number in [0.1, 1000], got {fval!r}")
        fps = float(fval)
    return SourceCamera(id=cid, K=K, dist=dist, R=R, t=t, width=width, height=height, fps=fps,
                        where=f"{path.name}" + (f" [{key}]" if key else ""), project=opencv_projection(K, dist, R, t), notes=tuple(notes))


def _pixels(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value) or not 16 <= value <= 16384:
        raise ImportFailure(f"{where} must be a whole number of pixels in [16, 16384], got {value!r}")
    return int(value)


def read_matrices(paths: Sequence[Path], extrinsics: str = "world-to-camera", camera_axes: str = "opencv") -> list[SourceCamera]:
    """OpenCV-style files (one camera each, or one per top-level key, or a ``cameras`` list/table).

    Args:
        paths: the files.
        extrinsics: ``"world-to-camera"`` (OpenCV's ``x_cam = R X + t``) or ``"camera-to-world"``
            (R the camera's orientation in the world, t its position).
        camera_axes: ``"opencv"`` (x right, y down, z forward) or ``"opengl"`` (x right, y up, z back).
    """
    cams: list[SourceCamera] = []
    for path in paths:
        tree, text = read_tree(path)
        if not isinstance(tree, dict):
            raise ImportFailure(f"{path.name}: must hold a map of fields (or of cameras), got {type(tree).__name__}")
        if any(k in tree for k in (*_K, *_R, *_RVEC, *_T, *_DIST, "fx", "image_width", "width")):  # the file is one camera
            entries: list[tuple[str, Any]] = [("", tree)]
        elif isinstance(tree.get("cameras"), list):
            entries = [(f"cameras[{i}]", c) for i, c in enumerate(tree["cameras"])]
        else:
            source = tree["cameras"] if isinstance(tree.get("cameras"), dict) else tree
            entries = [(str(k), c) for k, c in source.items() if isinstance(c, dict)]
        if not entries:
            raise ImportFailure(f"{path.name}: no camera found: a camera has {_K[0]} (or {', '.join(_K[1:])}), "
                                f"{_R[0]} or {_RVEC[0]}, and {_T[0]}; at the top level, in a 'cameras' list, or under a key per camera")
        for key, cam in entries:
            if not isinstance(cam, dict):
                raise ImportFailure(f"{_at(path, text, key)} must be a map of a camera's fields")
            cams.append(_matrix_camera(cam, _entry_id(cam, key, path, len(cams)), path, text, key, extrinsics, camera_axes))
    return cams


def _entry_id(cam: dict, key: str, path: Path, index: int) -> str:
    """A camera's id: its own id field, else its key, else the file's stem (and its place in a list)."""
    value = _get(cam, _ID)[1]
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, (str, int)) and not isinstance(value, bool):
        text = str(value)
    elif key.startswith("cameras["):
        text = f"{path.stem}-{key[8:-1]}"
    else:
        text = key or path.stem
    return camera_id(text, f"cam{index}")
