"""The site file: one TOML per installation, holding everything that is per-site.

Example::

    [site]
    name = "wtf-apartment"

    [floor]
    polygon = [[-2.0, -2.0], [3.0, -2.0], [3.0, 4.0], [-2.0, 4.0]]   # metres, REP-103 x, y

    [[obstacles]]          # optional, axis-aligned boxes
    name = "table"
    min = [0.5, 0.5, 0.0]
    max = [1.3, 1.1, 0.75]

    [[cameras]]
    id = "1"
    width = 640
    height = 480
    fps = 15.0
    fx = 617.0
    fy = 617.0
    cx = 320.0
    cy = 240.0
    dist = [0.0, 0.0, 0.0, 0.0, 0.0]     # optional, OpenCV order
    position = [2.9, -1.8, 2.4]          # optical centre in the world, metres
    rotation = [[...], [...], [...]]     # world-from-camera, row-major
    # or, instead of rotation:  look_at = [0.0, 0.0, 1.0]

``load_site`` returns frozen dataclasses; any invalid file raises ``SiteError`` naming the
field and what is allowed. Every field, what it is for, its unit and range, and example sites
for wall, ring and ceiling layouts: docs/install.md, "Site files". A calibration from another
tool becomes a site with ``superbody site import`` (edge/calibration/site_import.py).
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast, overload

import numpy as np

from superbody.edge.camera import Camera, look_at_rotation

__all__ = ["Site", "Obstacle", "SiteError", "load_site", "parse_site", "dump_site", "NAME_RE", "obstacles_hide"]

# Site and camera ids become Zenoh key chunks: keep them to a safe alphabet.
NAME_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
_MAX_DESCRIPTION = 10_000


class SiteError(ValueError):
    """An invalid site file; the message names the field and what is allowed."""


@dataclass(frozen=True)
class Obstacle:
    """An axis-aligned box that people cannot walk through and that hides what is behind it."""

    name: str
    min: tuple[float, float, float]
    max: tuple[float, float, float]


def obstacles_hide(origin: Any, points: Any, obstacles: Any, before: float = 1.0) -> np.ndarray:
    """(N,) whether the segment from ``origin`` (3,) to each point (N, 3) passes through one of the
    obstacle boxes before the fraction ``before`` of its length (slab test on origin + s d)."""
    origin = np.asarray(origin, dtype=np.float64)
    d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - origin  # (N, 3)
    hidden = np.zeros(len(d), dtype=bool)
    for o in obstacles:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (np.asarray(o.min) - origin) / d
            t2 = (np.asarray(o.max) - origin) / d
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
        hidden |= (tmax >= np.maximum(tmin, 0.0)) & (tmin < before)
    return hidden


@dataclass(frozen=True)
class Site:
    """One installation: its cameras, floor area and obstacles."""

    name: str
    cameras: tuple[Camera, ...]
    floor: tuple[tuple[float, float], ...]
    obstacles: tuple[Obstacle, ...] = ()
    source: str = ""
    description: str = ""  # [site].description: free text for people, kept by dump_site
    # [host] (and its [host.tracker], [host.filter]): the host's settings for this site, as JSON
    # text (hashable, compared as written); the host reads and checks them (host.settings), the
    # edge does not know their fields. "" when the file has none.
    host_json: str = ""

    @property
    def host(self) -> dict[str, Any]:
        """The site file's ``[host]`` table (empty when it has none)."""
        return json.loads(self.host_json) if self.host_json else {}

    @property
    def camera_ids(self) -> tuple[str, ...]:
        return tuple(c.id for c in self.cameras)

    def camera(self, camera_id: str) -> Camera:
        """The camera with this id; ``KeyError`` listing the valid ids otherwise."""
        for c in self.cameras:
            if c.id == camera_id:
                return c
        raise KeyError(f"camera {camera_id!r} is not in site {self.name!r}; cameras: {', '.join(self.camera_ids)}")

    def camera_index(self, camera_id: str) -> int:
        """Position of the camera in the site's order (used for one-hot features)."""
        return self.camera_ids.index(camera_id)

    @property
    def floor_bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the floor polygon."""
        p = np.asarray(self.floor)
        return float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max())


def _where(path: str, field: str) -> str:
    return f"{path}: {field}" if path else field


def _number(value: Any, field: str, lo: float = -math.inf, hi: float = math.inf, *, path: str = "", integer: bool = False) -> float:
    ok_type = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok_type:
        kind = "an integer" if integer else "a number"
        raise SiteError(f"{_where(path, field)} must be {kind} in [{lo}, {hi}], got {value!r}")
    if not math.isfinite(value) or not lo <= value <= hi:
        raise SiteError(f"{_where(path, field)} must be in [{lo}, {hi}], got {value!r}")
    return value


@overload
def _vector(value: Any, field: str, n: Literal[2], *, path: str = "", lo: float = -1e4, hi: float = 1e4) -> tuple[float, float]: ...
@overload
def _vector(value: Any, field: str, n: Literal[3], *, path: str = "", lo: float = -1e4, hi: float = 1e4) -> tuple[float, float, float]: ...
def _vector(value: Any, field: str, n: int, *, path: str = "", lo: float = -1e4, hi: float = 1e4) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise SiteError(f"{_where(path, field)} must be a list of {n} numbers, got {value!r}")
    return tuple(float(_number(v, f"{field}[{i}]", lo, hi, path=path)) for i, v in enumerate(value))


def _name(value: Any, field: str, *, path: str = "") -> str:
    if not isinstance(value, str) or not NAME_RE.fullmatch(value):
        raise SiteError(f"{_where(path, field)} must be 1-64 characters of letters, digits, '_' or '-', got {value!r}")
    return value


def _table(doc: dict, key: str, *, path: str, required: bool = True) -> dict:
    value = doc.get(key)
    if value is None and not required:
        return {}
    if not isinstance(value, dict):
        raise SiteError(f"{_where(path, f'[{key}]')} must be a table" + (" (missing)" if value is None else ""))
    return value


def _unknown(table: dict, allowed: set[str], where: str, *, path: str) -> None:
    extra = sorted(set(table) - allowed)
    if extra:
        raise SiteError(f"{_where(path, where)}: unknown field(s) {', '.join(extra)}; allowed: {', '.join(sorted(allowed))}")


_CAMERA_FIELDS = {"id", "width", "height", "fps", "fx", "fy", "cx", "cy", "dist", "position", "rotation", "look_at"}


def _camera(c: Any, i: int, *, path: str) -> Camera:
    where = f"cameras[{i}]"
    if not isinstance(c, dict):
        raise SiteError(f"{_where(path, where)} must be a table")
    _unknown(c, _CAMERA_FIELDS, where, path=path)
    for req in ("id", "width", "height", "fps", "fx", "fy", "cx", "cy", "position"):
        if req not in c:
            raise SiteError(f"{_where(path, f'{where}.{req}')} is missing")
    cid = _name(c["id"], f"{where}.id", path=path)
    width = int(_number(c["width"], f"{where}.width", 16, 16384, path=path, integer=True))
    height = int(_number(c["height"], f"{where}.height", 16, 16384, path=path, integer=True))
    fps = float(_number(c["fps"], f"{where}.fps", 0.1, 1000, path=path))
    fx = float(_number(c["fx"], f"{where}.fx", 1, 1e6, path=path))
    fy = float(_number(c["fy"], f"{where}.fy", 1, 1e6, path=path))
    cx = float(_number(c["cx"], f"{where}.cx", 0, width, path=path))
    cy = float(_number(c["cy"], f"{where}.cy", 0, height, path=path))
    dist = c.get("dist", [])
    if not isinstance(dist, list) or len(dist) not in (0, 4, 5, 8):
        raise SiteError(f"{_where(path, f'{where}.dist')} must be a list of 0, 4, 5 or 8 numbers (OpenCV order), got {dist!r}")
    dist_t = tuple(float(_number(v, f"{where}.dist[{k}]", -100, 100, path=path)) for k, v in enumerate(dist))
    position = _vector(c["position"], f"{where}.position", 3, path=path)
    if ("rotation" in c) == ("look_at" in c):
        raise SiteError(f"{_where(path, where)} needs exactly one of 'rotation' (3x3 world-from-camera) or 'look_at' ([x, y, z])")
    if "rotation" in c:
        rows = c["rotation"]
        if not isinstance(rows, list) or len(rows) != 3:
            raise SiteError(f"{_where(path, f'{where}.rotation')} must be 3 rows of 3 numbers")
        R = np.array([_vector(r, f"{where}.rotation[{k}]", 3, path=path, lo=-1.0001, hi=1.0001) for k, r in enumerate(rows)])
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        if err > 1e-4 or np.linalg.det(R) < 0:
            raise SiteError(
                f"{_where(path, f'{where}.rotation')} must be a proper rotation (orthonormal, det +1); "
                f"|R^T R - I| = {err:.2g}, det = {np.linalg.det(R):.3f}"
            )
        # Re-orthonormalise so downstream maths sees an exact rotation.
        u, _, vt = np.linalg.svd(R)
        R = u @ vt
    else:
        target = np.array(_vector(c["look_at"], f"{where}.look_at", 3, path=path))
        try:
            R = look_at_rotation(np.array(position), target)
        except ValueError:
            raise SiteError(f"{_where(path, f'{where}.look_at')} must not be straight above or below the camera") from None
    return Camera(
        id=cid, width=width, height=height, fps=fps, fx=fx, fy=fy, cx=cx, cy=cy, dist=dist_t,
        position=position, rotation=cast("tuple[tuple[float, float, float], ...]", tuple(tuple(float(v) for v in row) for row in R)),
    )


def parse_site(doc: dict, *, path: str = "") -> Site:
    """Validate a parsed TOML document and build the ``Site``."""
    _unknown(doc, {"site", "floor", "obstacles", "cameras", "host"}, "top level", path=path)
    site_t = _table(doc, "site", path=path)
    _unknown(site_t, {"name", "description"}, "[site]", path=path)
    name = _name(site_t.get("name"), "site.name", path=path)
    description = site_t.get("description", "")
    if not isinstance(description, str) or len(description) > _MAX_DESCRIPTION:
        raise SiteError(f"{_where(path, 'site.description')} must be a string of at most {_MAX_DESCRIPTION} characters, got {type(description).__name__}"
                        + (f" of {len(description)}" if isinstance(description, str) else ""))

    floor_t = _table(doc, "floor", path=path)
    _unknown(floor_t, {"polygon"}, "[floor]", path=path)
    poly = floor_t.get("polygon")
    if not isinstance(poly, list) or len(poly) < 3:
        raise SiteError(f"{_where(path, 'floor.polygon')} must be a list of at least 3 [x, y] points, got {poly!r}")
    floor = tuple(_vector(p, f"floor.polygon[{i}]", 2, path=path) for i, p in enumerate(poly))
    pts = np.asarray(floor)
    area = 0.5 * abs(np.dot(pts[:, 0], np.roll(pts[:, 1], 1)) - np.dot(pts[:, 1], np.roll(pts[:, 0], 1)))
    if area < 0.25:
        raise SiteError(f"{_where(path, 'floor.polygon')} must enclose at least 0.25 m^2, encloses {area:.3f}")

    obstacles = []
    obs_list = doc.get("obstacles", [])
    if not isinstance(obs_list, list):
        raise SiteError(f"{_where(path, 'obstacles')} must be an array of tables ([[obstacles]])")
    for i, o in enumerate(obs_list):
        where = f"obstacles[{i}]"
        if not isinstance(o, dict):
            raise SiteError(f"{_where(path, where)} must be a table")
        _unknown(o, {"name", "min", "max"}, where, path=path)
        lo = _vector(o.get("min"), f"{where}.min", 3, path=path)
        hi = _vector(o.get("max"), f"{where}.max", 3, path=path)
        if not all(a < b for a, b in zip(lo, hi)):
            raise SiteError(f"{_where(path, where)}: min must be below max on every axis, got min={lo} max={hi}")
        oname = o.get("name", f"obstacle{i}")
        if not isinstance(oname, str):
            raise SiteError(f"{_where(path, f'{where}.name')} must be a string")
        obstacles.append(Obstacle(oname, lo, hi))

    cams = doc.get("cameras")
    if not isinstance(cams, list) or not 1 <= len(cams) <= 64:
        raise SiteError(f"{_where(path, 'cameras')} must be an array of 1 to 64 tables ([[cameras]])")
    cameras = tuple(_camera(c, i, path=path) for i, c in enumerate(cams))
    ids = [c.id for c in cameras]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise SiteError(f"{_where(path, 'cameras')}: camera ids must be unique, repeated: {', '.join(dupes)}")
    host = _table(doc, "host", path=path, required=False)
    return Site(name=name, cameras=cameras, floor=floor, obstacles=tuple(obstacles), source=path, description=description,
                host_json=json.dumps(host, sort_keys=True) if host else "")


def load_site(path: str | Path) -> Site:
    """Load and validate a site file.

    Raises:
        SiteError: the file is missing, not TOML, or any field is invalid.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise SiteError(f"{path}: cannot read site file ({e.strerror})") from None
    except UnicodeDecodeError as e:
        line = _text_line(path, e.start)
        raise SiteError(f"{path}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}, line {line}); "
                        "site files are UTF-8 TOML") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SiteError(f"{path}: not valid TOML ({e})") from None
    return parse_site(doc, path=str(path))


def _text_line(path: Path, offset: int) -> int:
    """The 1-based line of byte ``offset`` in the file (for error messages)."""
    try:
        return path.read_bytes()[:offset].count(b"\n") + 1
    except OSError:
        return 0


def _fmt(v: float) -> str:
    return repr(float(round(v, 9)))


def _str(text: str) -> str:
    """A TOML string literal, quoted and escaped by tomli-w (quotes, backslashes, control characters)."""
    import tomli_w

    return tomli_w.dumps({"s": text})[len("s = "):].rstrip("\n")


def dump_site(site: Site, header: str = "") -> str:
    """The site as TOML text that ``load_site`` reads back to an equal ``Site``.

    Numbers are written compactly (rounded to 1e-9, arrays on one line); every string (the
    description, an obstacle named ``Bob's "big" table``) goes through tomli-w, so it is quoted
    and escaped as TOML requires. ``header`` becomes ``#`` comment lines on top.
    """
    out = [f"# {line}" if line else "#" for line in header.splitlines()]
    out += ["[site]", f"name = {_str(site.name)}"]
    if site.description:
        out.append(f"description = {_str(site.description)}")
    out += ["", "[floor]"]
    out.append("polygon = [" + ", ".join(f"[{_fmt(x)}, {_fmt(y)}]" for x, y in site.floor) + "]")
    for o in site.obstacles:
        out += ["", "[[obstacles]]", f"name = {_str(o.name)}", f"min = [{', '.join(map(_fmt, o.min))}]", f"max = [{', '.join(map(_fmt, o.max))}]"]
    for c in site.cameras:
        out += [
            "", "[[cameras]]", f"id = {_str(c.id)}", f"width = {c.width}", f"height = {c.height}", f"fps = {_fmt(c.fps)}",
            f"fx = {_fmt(c.fx)}", f"fy = {_fmt(c.fy)}", f"cx = {_fmt(c.cx)}", f"cy = {_fmt(c.cy)}",
            f"dist = [{', '.join(map(_fmt, c.dist))}]",
            f"position = [{', '.join(map(_fmt, c.position))}]",
            "rotation = [" + ", ".join("[" + ", ".join(map(_fmt, row)) + "]" for row in c.rotation) + "]",
        ]
    if site.host_json:
        import tomli_w

        out += ["", tomli_w.dumps({"host": site.host}).rstrip("\n")]
    return "\n".join(out) + "\n"
