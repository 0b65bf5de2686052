"""``superbody calibrate board``, ``intrinsics`` and ``oak-intrinsics``: a camera's calibration.

- ``board``: one image of the board lying face up on the floor at a measured place gives the
  camera's pose in the world (its intrinsics come from the site file).
- ``intrinsics``: several images of the board from varied angles give a webcam's K and
  distortion;
- ``oak-intrinsics``: an OAK device's own factory calibration for its NN-sized frames.

The geometry is in ``superbody.edge.calibration.board``; this module parses and checks the arguments,
reads the images and writes the results. Errors are one line on stderr, exit code 2.
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import cast

from superbody.edge.cli_args import number_in

__all__ = ["register"]

_BOARD_FLAGS_HELP = {
    "squares": "squares of the board, COLUMNSxROWS along its x and y axes (e.g. 5x7)",
    "square": "side of a chessboard square in metres, as measured on the print",
    "marker": "side of an ArUco marker in metres, as measured on the print",
    "dict": "OpenCV ArUco dictionary of the board (default: %(default)s)",
}


def register(csub: argparse._SubParsersAction) -> None:
    """Add ``board``, ``intrinsics`` and ``oak-intrinsics`` to the ``calibrate`` subcommands."""
    b = csub.add_parser(
        "board",
        help="a camera's pose in the world from one image of a ChArUco board on the floor",
        description=(
            "Detect a ChArUco board lying face up on the floor in one image from the camera and solve the "
            "camera's pose in the world, with the camera's intrinsics from the site file. Board frame: "
            "OpenCV's CharucoBoard (origin at the board's outer top-left corner as printed, x along the "
            "first row, y down the print); world = (X, Y, 0) + Rz(yaw) (x, -y, 0)."
        ),
    )
    b.add_argument("--site", type=Path, required=True, metavar="SITE.toml", help="site file with the camera's intrinsics")
    b.add_argument("--camera", required=True, metavar="ID", help="camera id in the site")
    b.add_argument("--image", type=Path, required=True, metavar="IMG.png", help="image of the board from that camera")
    _add_board_flags(b)
    b.add_argument("--origin", required=True, metavar="X,Y",
                   help="the board's origin corner on the floor, world metres (write --origin=-1.5,2 when X is negative)")
    b.add_argument("--yaw", required=True, metavar="DEG", help="direction of the board's x axis, degrees counter-clockwise from world +x")
    b.add_argument("--out", type=Path, metavar="SITE.toml", help="write the site with this camera's pose replaced (may be --site)")
    b.add_argument("--json-out", type=Path, metavar="F",
                   help='write {"camera", "position_m", "rotation" (world-from-camera), "reprojection_px", "corners"}')
    b.set_defaults(func=_run_board)

    k = csub.add_parser(
        "intrinsics",
        help="a webcam's intrinsics (K, distortion) from images of a ChArUco board",
        description=(
            "Detect a ChArUco board in several images from one camera (the board seen from varied angles and "
            "distances, filling different parts of the image) and fit K and the distortion coefficients "
            "(k1, k2, p1, p2, k3) with OpenCV's calibrateCamera."
        ),
    )
    k.add_argument("--images", required=True, metavar="'DIR/*.png'", help="glob of the images (quote it)")
    _add_board_flags(k)
    k.add_argument("--site", type=Path, metavar="SITE.toml", help="site file holding the camera (with --camera and --out)")
    k.add_argument("--camera", metavar="ID", help="camera id in the site")
    k.add_argument("--out", type=Path, metavar="SITE.toml", help="write the site with this camera's intrinsics replaced")
    k.add_argument("--json-out", type=Path, metavar="F",
                   help='write {"width", "height", "fx", "fy", "cx", "cy", "dist", "rms_px", "views", "skipped"}')
    k.set_defaults(func=_run_intrinsics)
    _add_calibrate_oak_intrinsics(csub)


def _add_board_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--squares", required=True, metavar="CxR", help=_BOARD_FLAGS_HELP["squares"])
    p.add_argument("--square", required=True, metavar="M", help=_BOARD_FLAGS_HELP["square"])
    p.add_argument("--marker", required=True, metavar="M", help=_BOARD_FLAGS_HELP["marker"])
    p.add_argument("--dict", default="DICT_5X5_100", metavar="DICT", help=_BOARD_FLAGS_HELP["dict"])


class _ArgError(ValueError):
    """A bad argument; the message names it."""


def _fail(command: str, message: str) -> int:
    print(f"superbody {command}: error: {message}", file=sys.stderr)
    return 2


def _spec(args: argparse.Namespace):
    from superbody.edge.calibration.board import DICTIONARIES, BoardError, BoardSpec, parse_squares

    try:
        nx, ny = parse_squares(args.squares)
    except BoardError as e:
        raise _ArgError(f"--{e}") from None
    square = number_in(args.square, "--square", 0.001, 10.0, _ArgError)
    marker = number_in(args.marker, "--marker", 0.001, 10.0, _ArgError)
    if not marker < square:
        raise _ArgError(f"--marker must be smaller than --square ({square:g}), got {marker:g}")
    if args.dict.upper() not in {n.upper() for n in DICTIONARIES}:
        raise _ArgError(f"--dict must be one of {', '.join(DICTIONARIES)}; got {args.dict!r}")
    try:
        return BoardSpec(nx, ny, square, marker, args.dict)
    except BoardError as e:
        raise _ArgError(str(e)) from None


def _origin(text: str) -> tuple[float, float]:
    parts = text.split(",")
    if len(parts) != 2:
        raise _ArgError(f"--origin must be X,Y in metres (e.g. 0.5,-1.2), got {text!r}")
    return tuple(number_in(p.strip(), "--origin", -1e4, 1e4, _ArgError) for p in parts)  # type: ignore[return-value]


def _read_image(path: Path, flag: str):
    import cv2

    if not path.is_file():
        raise _ArgError(f"{flag} {path}: no such file")
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise _ArgError(f"{flag} {path}: not an image OpenCV can read")
    return image


def _header(site_path: Path) -> list[str]:
    """The leading comment lines of a site file, without their '# '."""
    lines = []
    for line in site_path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[2:] if line.startswith("# ") else line[1:])
    return lines


def _write_site(site, source: Path, out: Path, note: str) -> None:
    """Write the site (header of ``source`` plus ``note``), checked before it replaces anything."""
    import tomllib

    from superbody.edge.site import dump_site, parse_site

    # A newer calibration of the same camera replaces the note of the older one.
    kept = [line for line in _header(source) if not line.startswith(note.split(" from ")[0] + " from superbody calibrate")]
    text = dump_site(site, header="\n".join([*kept, note]))
    parse_site(tomllib.loads(text), path=str(out))  # SiteError here leaves every file as it was
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)  # --out may be --site: never leave it half written


def _rotation_deg(Ra, Rb) -> float:
    import numpy as np

    c = (np.trace(Ra @ Rb.T) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, float(c)))))


# --- calibrate board ----------------------------------------------------------------------------


def _run_board(args: argparse.Namespace) -> int:
    command = "calibrate board"
    from superbody.edge.site import SiteError, load_site

    try:
        spec = _spec(args)
        origin = _origin(args.origin)
        yaw_deg = number_in(args.yaw, "--yaw", -360.0, 360.0, _ArgError)
        site = load_site(args.site)
        try:
            cam = site.camera(args.camera)
        except KeyError as e:
            raise _ArgError(f"--camera: {e.args[0]}") from None
        image = _read_image(args.image, "--image")
    except (_ArgError, SiteError) as e:
        return _fail(command, str(e))

    import numpy as np

    from superbody.edge.calibration.board import BoardError, calibrate_pose

    try:
        fit = calibrate_pose(image, spec, cam, origin, math.radians(yaw_deg))
    except BoardError as e:
        return _fail(command, f"{args.image}: {e}")
    moved_m = float(np.linalg.norm(fit.position - cam.t))
    turned_deg = _rotation_deg(fit.rotation, cam.R)
    position = [float(v) for v in fit.position]
    rotation = [[float(v) for v in row] for row in fit.rotation]
    try:
        if args.out is not None:
            new_cam = replace(cam, position=cast("tuple[float, float, float]", tuple(position)),
                              rotation=cast("tuple[tuple[float, float, float], ...]", tuple(tuple(r) for r in rotation)))
            new_site = replace(site, cameras=tuple(new_cam if c.id == cam.id else c for c in site.cameras))
            note = (
                f"camera {cam.id}: pose from superbody calibrate board --image {args.image} --squares {args.squares} "
                f"--square {args.square} --marker {args.marker} --dict {args.dict} --origin {args.origin} --yaw {args.yaw} "
                f"(RMS {fit.reprojection_px:.3f} px over {fit.corners} corners)"
            )
            _write_site(new_site, args.site, args.out, note)
        if args.json_out is not None:
            doc = {
                "camera": cam.id, "position_m": position, "rotation": rotation,
                "reprojection_px": float(fit.reprojection_px), "corners": int(fit.corners),
            }
            args.json_out.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    except (_ArgError, SiteError) as e:
        return _fail(command, str(e))
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    pos = ", ".join(f"{v:.3f}" for v in position)
    print(
        f"camera {cam.id}: position [{pos}] m, RMS {fit.reprojection_px:.3f} px over {fit.corners} corners, "
        f"board seen {fit.oblique_deg:.0f} deg from its normal; {moved_m:.3f} m and {turned_deg:.2f} deg from the site's pose"
    )
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0


# --- calibrate intrinsics -----------------------------------------------------------------------


def _run_intrinsics(args: argparse.Namespace) -> int:
    command = "calibrate intrinsics"
    from superbody.edge.site import SiteError, load_site

    try:
        spec = _spec(args)
        given = [args.site is not None, args.camera is not None]
        if args.out is not None and not all(given):
            raise _ArgError("--out needs --site and --camera (the site whose camera gets the intrinsics)")
        if any(given) and not all(given):
            raise _ArgError("--site and --camera go together")
        cam = site = None
        if args.site is not None:
            site = load_site(args.site)
            try:
                cam = site.camera(args.camera)
            except KeyError as e:
                raise _ArgError(f"--camera: {e.args[0]}") from None
        paths = sorted(Path(p) for p in glob.glob(os.path.expanduser(args.images)))
        paths = [p for p in paths if p.is_file()]
        if not paths:
            raise _ArgError(f"--images {args.images!r}: no file matches")
        images = [_read_image(p, "--images") for p in paths]
        h, w = images[0].shape[:2]
        if cam is not None and (w, h) != (cam.width, cam.height):
            raise _ArgError(f"--images: {paths[0]} is {w}x{h} but camera {cam.id!r} is {cam.width}x{cam.height} in the site")
    except (_ArgError, SiteError) as e:
        return _fail(command, str(e))

    from superbody.edge.calibration.board import BoardError, calibrate_intrinsics

    try:
        fit = calibrate_intrinsics(images, spec)
    except BoardError as e:
        return _fail(command, f"--images: {_name_images(str(e), paths)}")
    K, dist = fit.K, [float(v) for v in fit.dist]
    doc = {
        "width": w, "height": h, "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
        "dist": dist, "rms_px": fit.rms_px, "views": fit.views, "skipped": [str(paths[i]) for i in fit.skipped],
    }
    if cam is not None:
        doc = {"camera": cam.id, **doc}
    try:
        if args.out is not None:
            assert cam is not None and site is not None  # --out needs --site and --camera (checked above)
            new_cam = replace(cam, fx=doc["fx"], fy=doc["fy"], cx=doc["cx"], cy=doc["cy"], dist=tuple(dist))
            new_site = replace(site, cameras=tuple(new_cam if c.id == cam.id else c for c in site.cameras))
            note = (
                f"camera {cam.id}: intrinsics from superbody calibrate intrinsics --images '{args.images}' "
                f"({fit.views} views, RMS {fit.rms_px:.3f} px)"
            )
            _write_site(new_site, args.site, args.out, note)
        if args.json_out is not None:
            args.json_out.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    except (_ArgError, SiteError) as e:
        return _fail(command, str(e))
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    print(
        f"{fit.views} views of {len(paths)} images ({w}x{h}): fx {doc['fx']:.2f} fy {doc['fy']:.2f} "
        f"cx {doc['cx']:.2f} cy {doc['cy']:.2f} dist [{', '.join(f'{v:.4f}' for v in dist)}], RMS {fit.rms_px:.3f} px"
    )
    for i in fit.skipped:
        print(f"skipped {paths[i]}: too few corners")
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0


def _name_images(message: str, paths: list[Path]) -> str:
    """Replace 'image i' in a BoardError by the file's path."""
    import re

    return re.sub(r"image (\d+)", lambda m: str(paths[int(m.group(1))]) if int(m.group(1)) < len(paths) else m.group(0), message)


def _add_calibrate_oak_intrinsics(csub: argparse._SubParsersAction) -> None:
    o = csub.add_parser(
        "oak-intrinsics",
        help="take a camera's intrinsics from its OAK device's calibration",
        description=(
            "Read the intrinsics and distortion of an OAK's colour camera for the NN frame the OAK source "
            "uses (the site camera's size, or --size; centre crop) from the device's calibration, print them "
            "beside the site's, and with --out write the site with them."
        ),
    )
    o.add_argument("--site", type=Path, required=True, metavar="SITE.toml", help="site file")
    o.add_argument("--camera", required=True, metavar="ID", help="camera id in the site")
    o.add_argument("--device", default=None, metavar="DEVICE_ID", help="OAK MX id / serial, IP or USB path (default: the first found)")
    o.add_argument("--size", default=None, metavar="WxH", help="NN frame size (default: the site camera's width x height)")
    o.add_argument("--out", type=Path, default=None, metavar="SITE.toml", help="write the site with this camera's intrinsics here")
    o.set_defaults(func=_run_calibrate_oak_intrinsics)


def _frame_size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or not (16 <= int(w) <= 16384 and 16 <= int(h) <= 16384):
        raise ValueError(f"--size must be WIDTHxHEIGHT with each in [16, 16384], e.g. 512x288, got {text!r}")
    return int(w), int(h)


def _leading_comments(path: Path) -> str:
    """The comment lines at the top of a file, without their '# ' (dump_site writes them back)."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[1:].removeprefix(" "))
    return "\n".join(lines)


def _run_calibrate_oak_intrinsics(args: argparse.Namespace) -> int:
    import numpy as np

    from superbody.edge.site import SiteError, dump_site, load_site
    from superbody.edge.sources import oak
    from superbody.edge.sources.oak_convert import camera_with_intrinsics, site_with_camera
    from superbody.edge.sources.source import SourceError

    command = "calibrate oak-intrinsics"
    try:
        site = load_site(args.site)
        cam = site.camera(args.camera)
        width, height = _frame_size(args.size) if args.size else (cam.width, cam.height)
        K, dist, device_id = oak.read_device_intrinsics(args.device, width, height)
        new = camera_with_intrinsics(cam, K, dist, width, height)
        print(f"OAK {device_id}, {width}x{height} NN frame (site camera {cam.id!r}: {cam.width}x{cam.height})")
        print(f"{'':>4} {'site':>12} {'device':>12}")
        for name in ("fx", "fy", "cx", "cy"):
            print(f"{name:>4} {getattr(cam, name):>12.3f} {getattr(new, name):>12.3f}")
        print(f"dist site {list(cam.dist)}, device {list(new.dist)}")
        if args.out is not None:
            header = _leading_comments(args.site)
            note = f"Camera {cam.id} intrinsics from OAK {device_id} ({width}x{height}): superbody calibrate oak-intrinsics"
            text = dump_site(site_with_camera(site, new), header="\n".join(filter(None, (header, note))))
            args.out.write_text(text, encoding="utf-8")
            back = load_site(args.out).camera(cam.id)
            fields = lambda c: [c.width, c.height, c.fx, c.fy, c.cx, c.cy, *c.dist]  # noqa: E731
            if len(back.dist) != len(new.dist) or not np.allclose(fields(back), fields(new), rtol=0, atol=1e-6):
                return _fail(command, f"{args.out}: the site file read back differs from the one written")
            print(f"wrote {args.out}")
    except KeyError as e:
        return _fail(command, str(e.args[0]))
    except (SiteError, SourceError, ValueError) as e:
        return _fail(command, str(e))
    except OSError as e:
        return _fail(command, f"{e.filename}: {e.strerror or e}")
    return 0
