"""A site file from a calibration the installer already has (``superbody site import``).

The cameras are read (``read_calibration``, the format told or recognised by ``detect_format``) in their source's form (``edge.calibration.formats``), moved into the site's
world (``edge.calibration.frames.WorldFrame``), written as a site (``edge.site.dump_site``) and read
back, then checked:

- each camera, as read back from the site text, projects test points in front of it to the
  pixels the source's own camera model gives (``MAX_REPROJECTION_PX``);
- every camera above the floor, the floor in its view, plausible intrinsics
  (``edge.site_check``);
- the floor polygon (``edge.floor.visible_floor`` for the cameras' layout) seen by the cameras.

What the source does not say (image size, fps) comes from the flags or a default, and the report
says which.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from superbody.edge.calibration.colmap import read_colmap
from superbody.edge.calibration.formats import FORMATS, SourceCamera, read_matrices
from superbody.edge.calibration.frames import ImportFailure, WorldFrame
from superbody.edge.calibration.kalibr import read_kalibr
from superbody.edge.camera import Camera, project
from superbody.edge.floor import LAYOUTS, floor_points, guess_layout, polygon_area, views_at, visible_floor
from superbody.edge.site import Site, SiteError, dump_site, parse_site
from superbody.edge.site_check import Finding, check_camera, check_site, fov_deg, pitch_deg

__all__ = ["DEFAULT_FPS", "MAX_REPROJECTION_PX", "TEST_DEPTHS_M", "ImportResult", "import_site", "reprojection_px", "detect_format",
           "read_calibration"]

DEFAULT_FPS = 15.0  # a camera node's pose-detector rate when the source has none (as calibrate from-dataset)
MAX_REPROJECTION_PX = 0.01
TEST_DEPTHS_M = (1.0, 3.0, 8.0)  # test points in front of each camera, metres along its axis


@dataclass
class ImportResult:
    """The site, its text, and what the import found and assumed."""

    site: Site
    text: str
    layout: str
    assumed: list[str] = field(default_factory=list)
    cameras: list[str] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(f.severity == "error" for f in self.findings)


def reprojection_px(src: SourceCamera, cam: Camera, frame: WorldFrame) -> float:
    """The largest pixel distance between the source's own projection of test points and the
    site camera's (``edge.camera.project``) of the same points in the site's world.

    The test points: a 5 x 5 grid over the image (5%-95%) at ``TEST_DEPTHS_M`` in front of the
    camera, built in the source's world from its extrinsics.
    """
    w, h = cam.width, cam.height
    u, v = np.meshgrid(np.linspace(0.05 * w, 0.95 * w, 5), np.linspace(0.05 * h, 0.95 * h, 5))
    rays = np.column_stack([u.ravel(), v.ravel(), np.ones(u.size)]) @ np.linalg.inv(src.K).T  # (25, 3) z = 1
    x_cam = np.concatenate([rays * (d / frame.unit_m) for d in TEST_DEPTHS_M])  # (75, 3) source units
    p_src = (x_cam - src.t) @ src.R  # R^T (x_cam - t), row-wise
    theirs = src.project(p_src) - src.pixel_offset
    ours, _ = project(frame.points(p_src), cam)
    return float(np.max(np.linalg.norm(theirs - ours, axis=1)))


def _size(src: SourceCamera, size: tuple[int, int] | None) -> tuple[int, int, str]:
    if src.width is not None and src.height is not None:
        note = "" if size is None or size == (src.width, src.height) else f"; --size {size[0]}x{size[1]} not used"
        return src.width, src.height, f"from {src.where.split(' ')[0]}{note}"
    if size is None:
        raise ImportFailure(f"{src.where}: camera {src.id} has no image size in its file; give --size WIDTHxHEIGHT "
                            "(the image size the camera was calibrated at, in pixels)")
    return size[0], size[1], "from --size"


def _fps(src: SourceCamera, fps: float | None) -> tuple[float, str]:
    if src.fps is not None:
        note = "" if fps is None or fps == src.fps else f"; --fps {fps:g} not used"
        return src.fps, f"from {src.where.split(' ')[0]}{note}"
    if fps is None:
        return DEFAULT_FPS, f"the default {DEFAULT_FPS:g} fps; --fps sets it"
    return fps, "from --fps"


def _camera_doc(src: SourceCamera, frame: WorldFrame, width: int, height: int, fps: float) -> dict:
    rotation, position = frame.camera_pose(src.R, src.t)
    return {
        "id": src.id, "width": width, "height": height, "fps": fps,
        "fx": float(src.K[0, 0]), "fy": float(src.K[1, 1]), "cx": float(src.K[0, 2]), "cy": float(src.K[1, 2]),
        "dist": list(src.dist), "position": position.tolist(), "rotation": rotation.tolist(),
    }


def import_site(
    sources: Sequence[SourceCamera], frame: WorldFrame, *, name: str, fps: float | None = None, size: tuple[int, int] | None = None,
    layout: str = "auto", header: str = "", path: str = "site.toml",
) -> ImportResult:
    """The site of the source cameras, and its checks (see the module docstring).

    Args:
        sources: the cameras as read (``read_calibration``).
        frame: the source world in the site's.
        name: the site's name.
        fps: frames per second for cameras whose source has none (None: ``DEFAULT_FPS``).
        size: (width, height) for cameras whose source has none.
        layout: the cameras' layout for the floor (``edge.floor.LAYOUTS``, or ``"auto"``).
        header: comment lines for the site file's top.
        path: the site file's name, for messages.

    Returns:
        The result: the site, its TOML text, the findings (``ok`` when there is no error).

    Raises:
        ImportFailure: a field the site cannot take (naming the camera, its source and the field),
            or no floor for the layout.
    """
    if not sources:
        raise ImportFailure("no camera to import")
    if not 1 <= len(sources) <= 64:
        raise ImportFailure(f"a site has 1 to 64 cameras, the source has {len(sources)}: choose with --cameras ID,ID,...")
    ids = [s.id for s in sources]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ImportFailure(f"camera ids must be unique, repeated: {', '.join(dupes)} (one file per camera needs distinct file names)")
    result_cams, docs = [], []
    for src in sources:
        width, height, size_from = _size(src, size)
        cam_fps, fps_from = _fps(src, fps)
        docs.append(_camera_doc(src, frame, width, height, cam_fps))
        result_cams.append((size_from, fps_from))
    doc = {"site": {"name": name}, "floor": {"polygon": [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]}, "cameras": docs}
    try:
        site = parse_site(doc, path=path)
    except SiteError as e:
        raise ImportFailure(_which_source(str(e), sources)) from None
    early = [f for i, c in enumerate(site.cameras) for f in _pose_errors(site, i)]
    chosen = guess_layout(site.cameras) if layout == "auto" else layout
    assumed = [f"world: {frame.describe()}", _tally("image size", [f for f, _ in result_cams]),
               _tally("fps", [f for _, f in result_cams]), f"floor: {'guessed' if layout == 'auto' else '--layout'} layout {chosen}"]
    if early:  # no floor can be derived for cameras under it
        return ImportResult(site, "", chosen, assumed, [], early)
    try:
        floor = visible_floor(site.cameras, layout=chosen)
    except ValueError as e:
        raise ImportFailure(f"{e}; give --layout ({', '.join(LAYOUTS)}) or draw the floor by hand "
                            "(superbody site floor-plot)") from None
    site = replace(site, floor=floor)
    text = dump_site(site, header=header)
    site = parse_site(tomllib.loads(text), path=path)  # what a node and the host will read
    result = ImportResult(site, text, chosen, assumed)
    for src, cam, (size_from, fps_from) in zip(sources, site.cameras, result_cams):
        err = reprojection_px(src, cam, frame)
        hfov, _ = fov_deg(cam)
        result.cameras.append(
            f"{cam.id}: at ({cam.t[0]:.3f}, {cam.t[1]:.3f}, {cam.t[2]:.3f}) m, looking {pitch_deg(cam):.0f} deg down, heading "
            f"{np.degrees(np.arctan2(cam.R[1, 2], cam.R[0, 2])):.0f} deg; {cam.width} x {cam.height} px ({size_from}), "
            f"{cam.fps:g} fps ({fps_from}); fx {cam.fx:.1f}, {hfov:.0f} deg wide; reprojection against the source {err:.1e} px"
            + "".join(f"; {n}" for n in src.notes))
        if not err < MAX_REPROJECTION_PX:
            result.findings.append(Finding("error", f"cameras[{len(result.cameras) - 1}] ({cam.id})",
                                           f"projects test points {err:.3g} px away from the source's own model (at most {MAX_REPROJECTION_PX} px)"))
    result.findings += check_site(site)
    grid = floor_points(site.floor, 0.1)
    two = float(np.mean(views_at(site.cameras, grid) >= 2)) if len(grid) else 0.0
    result.assumed.append(f"floor polygon: {len(site.floor)} corners, {polygon_area(site.floor):.1f} m^2, {100 * two:.0f}% of it seen by "
                          "two or more cameras")
    return result


def _tally(what: str, sources: Sequence[str]) -> str:
    """``image size: from the files for 4 cameras, from --size for 1``: where a field came from."""
    counts: dict[str, int] = {}
    for src in sources:
        key = "from the files" if src.startswith("from ") and not src.startswith(("from --",)) else src.split(";")[0]
        counts[key] = counts.get(key, 0) + 1
    return f"{what}: " + ", ".join(f"{k} for {n} camera{'s' if n > 1 else ''}" for k, n in counts.items())


def _pose_errors(site: Site, index: int) -> list[Finding]:
    """The errors of a camera's pose (below the floor, no floor in view): no floor can be derived then."""
    return [f for f in check_camera(site.cameras[index], index) if f.severity == "error" and f.field.endswith((".position", ".rotation"))]


def _which_source(message: str, sources: Sequence[SourceCamera]) -> str:
    """A site error about ``cameras[i]`` with the source file of camera i."""
    m = re.search(r"cameras\[(\d+)\]", message)
    if m and int(m.group(1)) < len(sources):
        src = sources[int(m.group(1))]
        return f"{message} (camera {src.id} from {src.where})"
    return message


def detect_format(paths: Sequence[Path]) -> str:
    """The format of the input files, from their names and first lines (``FORMATS``).

    Raises:
        ImportFailure: no file, or a file that is missing.
    """
    if not paths:
        raise ImportFailure("no calibration file given")
    for p in paths:
        if not p.exists():
            raise ImportFailure(f"{p}: no such file or directory")
    names = {p.name for p in paths}
    if any(p.is_dir() for p in paths) or names & {"cameras.txt", "images.txt"}:
        return "colmap"
    text = paths[0].read_text(encoding="utf-8", errors="replace")[:20000]
    if re.search(r"^cam\d+\s*:", text, re.MULTILINE) and re.search(r"^\s+(intrinsics|T_cn_cnm1|camera_model)\s*:", text, re.MULTILINE):
        return "kalibr"
    if paths[0].suffix.lower() == ".json" and '"cameras"' in text and "opencv-matrix" not in text:
        return "json"
    return "opencv"


def read_calibration(paths: Sequence[Path], fmt: str = "auto", *, extrinsics: str = "world-to-camera", camera_axes: str = "opencv",
                     T_cam0_world: NDArray | None = None) -> tuple[str, list[SourceCamera]]:
    """Every camera of the input files, and the format they were read as.

    Raises:
        ImportFailure: an unknown format (naming the valid ones), or anything a reader refuses.
    """
    if fmt == "auto":
        fmt = detect_format(paths)
    if fmt not in FORMATS:
        raise ImportFailure(f"--format must be one of auto, {', '.join(FORMATS)}, got {fmt!r}")
    if fmt in ("colmap", "kalibr") and (extrinsics != "world-to-camera" or camera_axes != "opencv"):
        raise ImportFailure(f"--extrinsics and --camera-axes are for --format opencv and json; {fmt} says its own")
    if T_cam0_world is not None and fmt != "kalibr":
        raise ImportFailure(f"--T-cam0-world is for --format kalibr, not {fmt}")
    if fmt == "colmap":
        return fmt, read_colmap(paths)
    if fmt == "kalibr":
        if len(paths) != 1:
            raise ImportFailure(f"--format kalibr reads one camchain YAML, got {len(paths)} files")
        return fmt, read_kalibr(paths[0], T_cam0_world)
    return fmt, read_matrices(paths, extrinsics, camera_axes)
