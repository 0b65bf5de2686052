"""``superbody site import | check | floor-plot``: a site file from a calibration the installer has,
its checks, and its floor plan.

- ``import``: OpenCV (YAML/XML/JSON), plain JSON, COLMAP text or Kalibr camchain files to a site
  file (``edge.calibration.site_import``), checked, with what it assumed;
- ``check``: the same checks on any site file (``edge.site_check``);
- ``floor-plot``: the top view to draw the floor polygon by hand (``edge.floor_plot``).

Errors are one line on stderr naming the file, line or key and field, exit code 2; a check that
fails is exit code 2 too, and ``import`` then writes nothing.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from superbody.edge.cli_args import number_in

__all__ = ["register", "import_main", "check_main", "floor_plot_main"]

_EPILOG = """examples:
  superbody site import cams/*.yaml --unit cm --up -y --floor-at 150 --out deploy/sites/dome.toml
  superbody site import colmap/sparse/0 --unit 0.5 --up -y --out dome.toml --fps 30
  superbody site import camchain.yaml --T-cam0-world T.yaml --out dome.toml
  superbody site import cams.json --format json --extrinsics camera-to-world --unit mm --out dome.toml"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``site import``, ``site check`` and ``site floor-plot``."""
    site = sub.add_parser("site", help="site files: import a calibration, check a site, plot its floor")
    ssub = site.add_subparsers(dest="site_command", metavar="COMMAND", required=True)
    p = ssub.add_parser(
        "import", help="a site file from calibration files you already have (OpenCV, JSON, COLMAP, Kalibr)",
        description="Read the cameras of OpenCV (YAML, XML, JSON), plain JSON, COLMAP text or Kalibr camchain files, move them "
                    "into the site's world (REP-103: metres, z up, the floor at z = 0) as the flags say the source's world lies, "
                    "derive the floor the cameras see, check the result and write the site file.",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", type=Path, metavar="FILE", help="calibration files (COLMAP: the model folder or its two .txt files)")
    p.add_argument("--out", type=Path, required=True, metavar="SITE.toml", help="site file to write")
    p.add_argument("--format", default="auto", metavar="FORMAT", help="auto (default), opencv, json, colmap or kalibr")
    p.add_argument("--name", metavar="NAME", help="site name (default: the --out file's stem)")
    p.add_argument("--unit", default="m", metavar="UNIT", help="the source's length unit: m (default), cm, mm, or metres per unit")
    p.add_argument("--up", default="+z", metavar="AXIS", help="the source axis pointing up: +x, -x, +y, -y, +z (default), -z")
    p.add_argument("--x-axis", metavar="AXIS", help="the source axis that becomes the site's +x (default: +x, or +y when x is up)")
    p.add_argument("--y-axis", metavar="AXIS", help="the site's +y, for a left-handed source world only")
    p.add_argument("--floor-at", default="0", metavar="VALUE",
                   help="the floor's coordinate on the --up axis, source units, as the source writes it "
                        "(--up -y --floor-at 150: the floor is the plane y = 150; default 0)")
    p.add_argument("--extrinsics", default="world-to-camera", choices=("world-to-camera", "camera-to-world"),
                   help="opencv, json: R, t map world points into the camera (x_cam = R X + t, default) or are the camera's pose "
                        "(its orientation and position in the world)")
    p.add_argument("--camera-axes", default="opencv", choices=("opencv", "opengl"),
                   help="opencv, json: the camera frame: x right, y down, z forward (default) or OpenGL/Blender's y up, z backward")
    p.add_argument("--T-cam0-world", metavar="T", help="kalibr: where the world is: a file holding the 4 x 4 transform taking world "
                                                       "points to camera 0's coordinates, or its 16 numbers (default: the world is camera 0)")
    p.add_argument("--size", metavar="WxH", help="image size for cameras whose file has none, e.g. 1920x1080")
    p.add_argument("--fps", metavar="FPS", help="frames per second for cameras whose file has none (default 15)")
    p.add_argument("--cameras", metavar="ID,ID", help="import only these cameras")
    p.add_argument("--layout", default="auto", metavar="LAYOUT",
                   help="how the cameras stand, for the floor polygon: auto (default), wall, ring or ceiling")
    # "--up -y" as the issue writes it: argparse takes a value that starts with "-" for an option
    # unless it looks like a negative number, so a signed axis is made to look like one.
    p._negative_number_matcher = re.compile(r"^-(\d+|\d*\.\d+|[xyzXYZ])$")
    p.set_defaults(func=import_main)
    c = ssub.add_parser("check", help="check a site file's cameras and floor (above the floor, floor in view, plausible intrinsics)")
    c.add_argument("site", type=Path, metavar="SITE.toml")
    c.set_defaults(func=check_main)
    f = ssub.add_parser("floor-plot", help="draw a site's floor plan (cameras, their views, a grid) to read the floor polygon off",
                        description="Top view of the site: cameras, the outline of each camera's view on the floor, how many cameras "
                                    "see each place, the floor polygon and obstacles, on a labelled grid (needs matplotlib).")
    f.add_argument("site", type=Path, metavar="SITE.toml")
    f.add_argument("--out", type=Path, required=True, metavar="FLOOR.png", help="PNG to write")
    f.set_defaults(func=floor_plot_main)


def _fail(command: str, message: object) -> int:
    print(f"superbody site {command}: error: {message}", file=sys.stderr)
    return 2


def _number(text: str, flag: str, lo: float, hi: float) -> float:
    from superbody.edge.calibration.frames import ImportFailure

    return number_in(text, flag, lo, hi, ImportFailure)


def _size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or not all(16 <= int(v) <= 16384 for v in m.groups()):
        from superbody.edge.calibration.frames import ImportFailure

        raise ImportFailure(f"--size must be WIDTHxHEIGHT in pixels, each in [16, 16384], e.g. 1920x1080; got {text!r}")
    return int(m.group(1)), int(m.group(2))


def import_main(args: argparse.Namespace) -> int:
    from superbody.edge.calibration.frames import ImportFailure, WorldFrame, parse_unit
    from superbody.edge.calibration.kalibr import parse_transform
    from superbody.edge.calibration.site_import import import_site, read_calibration
    from superbody.edge.floor import LAYOUTS
    from superbody.edge.site import NAME_RE

    try:
        name = args.name or re.sub(r"[^A-Za-z0-9_-]+", "-", args.out.stem).strip("-")
        if not NAME_RE.fullmatch(name or ""):
            raise ImportFailure(f"--name must be 1-64 letters, digits, '_' or '-', got {name!r}")
        if args.layout not in ("auto", *LAYOUTS):
            raise ImportFailure(f"--layout must be one of auto, {', '.join(LAYOUTS)}, got {args.layout!r}")
        frame = WorldFrame(up=args.up, x_axis=args.x_axis, y_axis=args.y_axis, unit_m=parse_unit(args.unit),
                           floor=_number(args.floor_at, "--floor-at", -1e9, 1e9))
        _ = frame.rotation  # the axes' errors before any file is read
        fps = None if args.fps is None else _number(args.fps, "--fps", 0.1, 1000)
        size = _size(args.size)
        T = None if args.T_cam0_world is None else parse_transform(args.T_cam0_world)
        fmt, sources = read_calibration(args.inputs, args.format, extrinsics=args.extrinsics, camera_axes=args.camera_axes, T_cam0_world=T)
        if args.cameras:
            wanted = [c.strip() for c in args.cameras.split(",") if c.strip()]
            unknown = [c for c in wanted if c not in {s.id for s in sources}]
            if unknown:
                raise ImportFailure(f"--cameras: {', '.join(unknown)} not in the source; cameras: {', '.join(s.id for s in sources)}")
            sources = [s for s in sources if s.id in wanted]
        header = (f"Site {name}: imported by superbody site import from {', '.join(p.name for p in args.inputs)} ({fmt}).\n"
                  f"Source world: {frame.describe()}.\n"
                  "World: REP-103 (metres, z up, floor at z = 0); rotation is world-from-camera, position the optical centre.\n"
                  "The floor polygon was derived from the cameras (edge/floor.py); draw your own from superbody site floor-plot.")
        result = import_site(sources, frame, name=name, fps=fps, size=size, layout=args.layout, header=header, path=str(args.out))
    except ImportFailure as e:
        return _fail("import", e)
    print(f"read {len(sources)} camera(s) as {fmt} from {', '.join(str(p) for p in args.inputs)}")
    print("assumed:")
    for line in result.assumed:
        print(f"  {line}")
    if result.cameras:
        print("cameras:")
        for line in result.cameras:
            print(f"  {line}")
    print("checks:" + ("" if result.findings else " every camera above the floor, looking at it, plausible intrinsics; the floor seen"))
    for f in result.findings:
        print(f"  {f}")
    if not result.ok:
        errors = [f for f in result.findings if f.severity == "error"]
        hint = ""
        if len(errors) == len(result.site.cameras) and all("not above the floor" in f.message for f in errors):
            hint = " (every camera under the floor: is --up's sign the other way, or --floor-at on the other side?)"
        more = f" (and {len(errors) - 1} more above)" if len(errors) > 1 else ""
        return _fail("import", f"{errors[0].field}: {errors[0].message}{hint}{more}; {args.out} not written")
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(result.text, encoding="utf-8")
    except OSError as e:
        return _fail("import", f"{args.out}: cannot write ({e.strerror})")
    print(f"wrote {args.out}: {len(result.site.cameras)} cameras, floor for a {result.layout} layout; "
          f"check it on a plot: superbody site floor-plot {args.out} --out floor.png")
    return 0


def check_main(args: argparse.Namespace) -> int:
    from superbody.edge.site import SiteError, load_site
    from superbody.edge.site_check import check_site

    try:
        site = load_site(args.site)
    except SiteError as e:
        return _fail("check", e)
    findings = check_site(site)
    for f in findings:
        print(f)
    errors = [f for f in findings if f.severity == "error"]
    if errors:
        return _fail("check", f"{len(errors)} error(s) in {args.site}")
    print(f"{args.site}: {len(site.cameras)} cameras, {len(findings)} warning(s)")
    return 0


def floor_plot_main(args: argparse.Namespace) -> int:
    from superbody.edge.site import SiteError, load_site

    try:
        site = load_site(args.site)
    except SiteError as e:
        return _fail("floor-plot", e)
    try:
        from superbody.edge.floor_plot import plot_floor

        out = plot_floor(site, args.out)
    except ImportError as e:
        return _fail("floor-plot", f"needs matplotlib ({e}): pip install matplotlib")
    except OSError as e:
        return _fail("floor-plot", f"{args.out}: cannot write ({e.strerror})")
    print(out)
    return 0
