"""The host package's ``superbody`` subcommands: ``host run`` and ``demo``."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from dataclasses import replace

from superbody.edge import transport
from superbody.edge.cli_args import add_clock_args, clock_from_args, positive
from superbody.edge.site import SiteError, load_site

__all__ = ["register"]

log = logging.getLogger("superbody.host")

def _unit(text: str) -> float:
    v = float(text)
    if not 0 < v <= 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1], got {text}")
    return v


def _run_host(args: argparse.Namespace) -> int:
    from superbody.host.aggregator import Aggregator, HostConfig
    from superbody.host.estimation import build_estimator
    from superbody.host.estimation.estimator import ModelMismatchError
    from superbody.host.filtering.pose_filter import FilterConfig
    from superbody.host.memory import pin_mmap_threshold
    from superbody.host.service import run_host
    from superbody.host.tracking.config import TrackerConfig

    try:
        site = load_site(args.site)
        estimator, name = build_estimator(site, args.estimator, args.model)
        config = HostConfig(
            freshness_s=args.freshness, max_publish_hz=args.max_rate, status_every_s=args.status_every,
            tracker=replace(TrackerConfig(), d_max=args.d_max, use_geometry=not args.no_geometry),
            filter=replace(FilterConfig(), enabled=not args.no_filter),
        )
        clock = clock_from_args(args)
        conf = transport.config_from_args(args)
        sinks = []
        if args.serial:
            from superbody.host.outputs.serial_link import SerialLink

            sinks.append(SerialLink(args.serial, args.baud))
    except (SiteError, ValueError, ModelMismatchError, OSError) as e:
        print(f"superbody host run: error: {e}", file=sys.stderr)
        return 2
    pin_mmap_threshold()  # a burst of large messages must not raise the host's memory for good
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    ros2 = _open_ros2(args)
    if ros2 is False:
        return 2
    if ros2 is not None:
        sinks.append(ros2)
    try:
        result = run_host(conf, Aggregator(site, estimator, name, config), clock, stop, args.duration, sinks)
    finally:
        for sink in sinks:
            sink.close()
    log.info("host stopped: %s", result)
    return 0


def _open_ros2(args: argparse.Namespace):
    """``host run --ros2``: its ``host.outputs.ros2.Ros2Sink``, None without the flag, False after an error."""
    if not args.ros2:
        return None
    try:
        from superbody.host.outputs import ros2

        return ros2.open_from_args(args)
    except ImportError:
        print("superbody host run: error: --ros2 needs the rosbags package: pip install 'superbody[ros2]'", file=sys.stderr)
    except ValueError as e:
        print(f"superbody host run: error: {e}", file=sys.stderr)
    return False


def register(sub: argparse._SubParsersAction) -> None:
    """Add the host's commands (``host run``, ``demo``)."""
    host = sub.add_parser("host", help="host aggregator commands")
    host_sub = host.add_subparsers(dest="host_command", metavar="COMMAND", required=True)
    p = host_sub.add_parser("run", help="run the aggregator: observations in, people's poses out")
    p.add_argument("--site", required=True, help="site file (TOML)")
    from superbody.host.estimation import ESTIMATORS

    p.add_argument("--estimator", choices=ESTIMATORS, default="auto",
                   help="pose estimator (default auto: hybrid when the model carries a hybrid calibration, else the network alone)")
    p.add_argument("--model", help="ONNX model (default: the shipped models/<site>.fp32.onnx)")
    p.add_argument("--freshness", type=positive, default=0.5, help="seconds a camera's view stays in set S (default 0.5)")
    p.add_argument("--d-max", type=_unit, default=0.65, help="colour match threshold, Bhattacharyya distance (default 0.65)")
    p.add_argument("--no-geometry", action="store_true", help="match on colour only, as the paper (no ground-point gate)")
    p.add_argument("--no-filter", action="store_true", help="per-frame output: no temporal filtering")
    p.add_argument("--max-rate", type=float, default=0.0, help="publish at most this many times a second (default: after every batch)")
    p.add_argument("--status-every", type=positive, default=10.0, help="seconds between status lines (default 10)")
    p.add_argument("--serial", metavar="URL", help="also write poses to this serial port (pyserial URL, e.g. /dev/ttyUSB0)")
    p.add_argument("--baud", type=int, default=115200, help="serial baud rate (default 115200)")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many seconds")
    add_clock_args(p)
    transport.add_session_args(p)
    from superbody.host.outputs import ros2

    ros2.add_args(p)
    p.set_defaults(func=_run_host)

    from superbody.host import demo

    demo.register(sub)

    from superbody.host.outputs import record, view

    record.register(sub)
    view.register(sub)
