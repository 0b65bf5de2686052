"""The ``superbody`` console script, and the edge package's commands (``edge run``, ``router``).

One program, subcommands contributed by each package: every entry point in the
``superbody.commands`` group is a ``register(subparsers)`` function that adds its commands and
sets ``func`` on each parser. ``func(args)`` returns the exit code.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import re
import sys
from importlib.metadata import entry_points

from superbody.edge import site_cli, transport
from superbody.edge.cli_args import (
    add_clock_args,
    add_session_args,
    clock_from_args,
    config_from_args,
    float_in,
    int_in,
    positive,
    stop_on_signals,
)
from superbody.edge.delivery import MAX_DELAY_S, MAX_JITTER_S, DeliveryModel
from superbody.edge.detectors import DETECTOR_FORMS, DetectorSpec, parse_detector
from superbody.edge.detectors.base import DetectorError
from superbody.edge.node import DEFAULT_OAK_MODEL, FPS_SOURCES, SOURCE_FORMS, START_SOURCES, SourceSpec, open_source, parse_source, run_node
from superbody.edge.router import run_router
from superbody.edge.site import Site, SiteError, load_site
from superbody.edge.sources.source import SourceError

log = logging.getLogger("superbody.edge")

__all__ = ["main", "register", "build_parser"]


def _version() -> str:
    from superbody.edge.resources import package_version

    return package_version()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="superbody", description="Multi-camera torso pose appliance.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.add_argument("--version", action="version", version=f"superbody {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for ep in sorted(entry_points(group="superbody.commands"), key=lambda e: e.name):
        ep.load()(sub)
    return parser


def _init_zenoh_log() -> None:
    """Zenoh's own (Rust) logging from the environment, as its examples do: RUST_LOG=debug shows it."""
    try:
        import zenoh
    except ImportError:  # a broken install: the command itself will say so
        return
    init = getattr(zenoh, "init_log_from_env_or", None)
    if init is not None:
        init("error")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _init_zenoh_log()
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as e:
        # Zenoh's errors (a port already in use, an unreachable TLS file) are raised as ZError
        # from inside its Rust core: one line naming the cause, not a traceback.
        if type(e).__name__ != "ZError":
            raise
        why = re.sub(r" at \S+\.rs:\d+\.?", "", " ".join(str(e).split()))[:300]  # drop Rust source paths
        print(f"superbody {args.command}: error: zenoh: {why}", file=sys.stderr)
        return 2


def register(sub: argparse._SubParsersAction) -> None:
    """Add the edge package's commands: ``edge run``, ``router``, ``site``."""
    _register_node(sub)
    _register_router(sub)
    site_cli.register(sub)


if __name__ == "__main__":
    sys.exit(main())


def _source_arg(text: str) -> SourceSpec:
    try:
        return parse_source(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _detector_arg(text: str) -> DetectorSpec:
    try:
        return parse_detector(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _check_options(args: argparse.Namespace) -> None:
    """Options that only some sources take; ``ValueError`` naming the option otherwise."""
    spec: SourceSpec = args.source
    if spec.needs_detector and args.detector is None:
        raise ValueError(f"--source {spec} needs --detector, one of {', '.join(DETECTOR_FORMS)}")
    if not spec.needs_detector and args.detector is not None:
        raise ValueError(f"--detector is for video, webcam and RTSP sources; --source {spec} detects people itself")
    only = {
        "sim": [("--seed", args.seed), ("--people", args.people)],
        "oak": [("--nn-archive", args.nn_archive), ("--oak-model", args.oak_model)],
        "video": [("--fast", args.fast or None)],
        "replay": [("--replay-start-ns", args.replay_start_ns)],
    }
    for kind, options in only.items():
        for name, value in options:
            if value is not None and spec.kind != kind:
                raise ValueError(f"{name} is for --source {kind}, not --source {spec}")
    if args.loop and spec.kind not in ("video", "replay"):
        raise ValueError(f"--loop is for --source video and replay, not --source {spec}")
    if args.depth and spec.kind not in ("sim", "oak"):
        raise ValueError(f"--depth is for --source sim and oak, not --source {spec}")
    if spec.kind != "sim" and (args.clock_scale != 1.0 or args.clock_anchor_ns != 0):
        raise ValueError(f"--clock-scale and --clock-anchor-ns are for simulated sources; --source {spec} runs on the wall clock")
    if args.fps is not None and spec.kind not in FPS_SOURCES:
        raise ValueError(f"--fps is for --source {', '.join(FPS_SOURCES)}, not --source {spec} (it captures at its own rate)")
    if args.start_at is not None and spec.kind not in START_SOURCES:
        raise ValueError(f"--start-at is for --source {' and '.join(START_SOURCES)}, not --source {spec}")
    if args.start_at is not None and args.replay_start_ns is not None:
        raise ValueError("--start-at and --replay-start-ns say the same thing: give one")
    if args.fast and (args.delay or args.jitter):
        raise ValueError("--delay and --jitter are for sources paced in real time; --fast reads the file as fast as the detector goes")


def _sized_for_site(spec: DetectorSpec, site: Site, camera_id: str) -> DetectorSpec:
    """MoveNet without ``@SHORT``: the input size at which it finds a standing person on most of
    the floor this camera sees (``movenet.short_side_for``); other detectors as they are."""
    if spec.kind != "movenet" or spec.size is not None:
        return spec
    from superbody.edge.detectors.movenet import DEFAULT_SHORT_SIDE, PERSON_INPUT_PX, PERSON_PERCENTILES, network_size, short_side_for

    cam = site.camera(camera_id)
    choice = short_side_for(cam, site.floor)
    if choice is None:
        log.warning("camera %s sees none of site %s's floor: MoveNet runs at its default input short side %d px", camera_id, site.name,
                    DEFAULT_SHORT_SIDE)
        return spec
    w, h = network_size(cam.width, cam.height, choice.short_side)
    seen = f"seen whole (on {100 * choice.whole:.0f}% of the floor it sees)" if choice.whole else "(seen whole nowhere: the part it sees)"
    log.info("camera %s: MoveNet input %d x %d: a standing person %s is %.0f-%.0f px tall in the image (%.0f-%.0fth percentile), "
             "%.0f-%.0f px in %d x %d; found between %.0f and %.0f px on %.0f%% of the floor it sees; movenet@SHORT sets another size",
             camera_id, w, h, seen, *choice.person_px, *PERSON_PERCENTILES, *(v * choice.short_side / min(cam.width, cam.height) for v in choice.person_px),
             w, h, *PERSON_INPUT_PX, 100 * choice.share)
    return dataclasses.replace(spec, size=choice.short_side)


def _run_node(args: argparse.Namespace) -> int:
    def error(message: object, code: int = 2) -> int:
        print(f"superbody edge run: error: {message}", file=sys.stderr)
        return code

    try:
        site = load_site(args.site)
        site.camera(args.camera)
        _check_options(args)
        clock = clock_from_args(args)
        conf = config_from_args(args)
    except (SiteError, KeyError, ValueError) as e:
        return error(e.args[0] if e.args else e)
    spec: SourceSpec = args.source
    try:
        source = open_source(spec, site, args.camera, seed=args.seed or 0, people=3 if args.people is None else args.people,
                             depth=args.depth, clock=clock, nn_archive=args.nn_archive,
                             oak_model=args.oak_model or DEFAULT_OAK_MODEL, realtime=not args.fast, loop=args.loop,
                             replay_start_ns=args.replay_start_ns, fps=args.fps,
                             start_ns=None if args.start_at is None else round(args.start_at * 1e9))
    except (SourceError, ValueError) as e:
        return error(e)
    detector = None
    if args.detector is not None:
        from superbody.edge.detectors import open_detector

        try:
            detector = open_detector(_sized_for_site(args.detector, site, args.camera))
        except DetectorError as e:
            source.close()
            return error(f"--detector {args.detector}: {e}")
    stop = stop_on_signals()
    try:
        run_node(conf, site, args.camera, source, clock, args.duration, stop, detector=detector,
                 delivery=DeliveryModel(args.delay, args.jitter))
    except (SourceError, DetectorError) as e:
        return error(e, 1)
    finally:
        if detector is not None:
            detector.close()
    return 0


def _register_node(sub: argparse._SubParsersAction) -> None:
    edge = sub.add_parser("edge", help="camera-node commands")
    edge_sub = edge.add_subparsers(dest="edge_command", metavar="COMMAND", required=True)
    p = edge_sub.add_parser("run", help="run a camera node: capture, detect, publish Observations")
    p.add_argument("--site", required=True, help="site file (TOML)")
    p.add_argument("--camera", required=True, help="camera id in the site file")
    p.add_argument("--source", type=_source_arg, default=SourceSpec("sim"), metavar="SOURCE",
                   help=f"frame source: {', '.join(SOURCE_FORMS)} (default: sim)")
    p.add_argument("--detector", type=_detector_arg, default=None, metavar="DETECTOR",
                   help=f"host pose detector for video, webcam and RTSP sources: {', '.join(DETECTOR_FORMS)}")
    p.add_argument("--seed", type=int, default=None, help="sim: seed; nodes with the same seed see the same people (default 0)")
    p.add_argument("--people", type=int_in(0, 64, "--people"), default=None, help="sim: simulated people (default 3)")
    p.add_argument("--depth", action="store_true", help="sim: simulate a depth camera; oak: stereo depth per keypoint")
    p.add_argument("--nn-archive", default=None, metavar="PATH", help="oak: a local NN archive instead of the model zoo's")
    p.add_argument("--oak-model", default=None, metavar="NAME", help=f"oak: model zoo name (default {DEFAULT_OAK_MODEL})")
    p.add_argument("--fast", action="store_true", help="video: read frames as fast as the detector goes, not in real time")
    p.add_argument("--loop", action="store_true", help="video, replay: start the file again at its end")
    p.add_argument("--replay-start-ns", type=int_in(0, 2**63 - 1, "--replay-start-ns"), default=None, metavar="NS",
                   help="replay: wall time (UNIX ns) at which the recording's first observation is replayed; "
                        "give every camera replayed from one file the same (default: when the node starts); "
                        "--start-at says the same in seconds")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many seconds of world time")
    t = p.add_argument_group("timing (docs/commands.md#camera-timing); every observation keeps its capture stamp")
    t.add_argument("--fps", type=float_in(0.1, 1000.0, "--fps"), default=None, metavar="F",
                   help="capture rate: sim captures at F instead of the site camera's fps; video and replay are thinned to F "
                        "(at most their own rate)")
    t.add_argument("--start-at", type=float_in(0.0, 9.2e9, "--start-at"), default=None, metavar="UNIX_SECONDS",
                   help="video, replay: the wall time of the file's first frame; nodes given the same start share one capture "
                        "clock (frame k of every file at the same instant), e.g. $(( $(date +%%s) + 5 ))")
    t.add_argument("--delay", type=float_in(0.0, MAX_DELAY_S, "--delay"), default=0.0, metavar="S",
                   help=f"publish each observation S seconds after its capture, in order (0-{MAX_DELAY_S:g}; default 0)")
    t.add_argument("--jitter", type=float_in(0.0, MAX_JITTER_S, "--jitter"), default=0.0, metavar="S",
                   help=f"standard deviation of a normal spread of that delay, clipped at 0 (0-{MAX_JITTER_S:g}; default 0)")
    add_clock_args(p)
    add_session_args(p)
    p.set_defaults(func=_run_node)


def _run_router(args: argparse.Namespace) -> int:
    stop = stop_on_signals()
    try:
        run_router(args.listen or ([] if args.config else [transport.DEFAULT_ENDPOINT]), stop, args.config, args.cfg)
    except transport.ConfigError as e:
        print(f"superbody router: error: {e}", file=sys.stderr)
        return 2
    return 0


def _register_router(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="run a Zenoh router (loopback by default)")
    p.add_argument("-l", "--listen", action="append", metavar="ENDPOINT", help=f"endpoint to listen on (default {transport.DEFAULT_ENDPOINT})")
    p.add_argument("-c", "--config", metavar="FILE", help="Zenoh JSON5 configuration file")
    p.add_argument("--cfg", action="append", metavar="KEY:VALUE", help="a Zenoh config setting, JSON5 value, applied last (repeatable)")
    p.set_defaults(func=_run_router)
