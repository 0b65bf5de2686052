"""The host package's ``superbody`` subcommands: ``host run``, ``demo``, ``record`` and ``view``.

Every command-line option of the host's commands is defined here; the modules they run take
plain arguments."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

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
from superbody.edge.delivery import MAX_DELAY_S, MAX_JITTER_S
from superbody.edge.resources import site_path
from superbody.edge.site import NAME_RE, SiteError, load_site
from superbody.host.aggregator import HostConfig
from superbody.host.demo import DEFAULT_SITE, DEMO_PORT, DemoConfig, run_demo
from superbody.host.outputs.record import record
from superbody.host.outputs.ros2 import _MAX_DOMAIN, Ros2Config, Ros2Publisher, Ros2Sink, _typestore, check_topic
from superbody.host.outputs.view import run_view
from superbody.host.tracking.config import TrackerConfig

__all__ = ["register"]

log = logging.getLogger("superbody.host")

def _unit(text: str) -> float:
    v = float(text)
    if not 0 < v <= 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1], got {text}")
    return v


def _run_host(args: argparse.Namespace) -> int:
    from superbody.host.aggregator import Aggregator
    from superbody.host.estimation import build_estimator
    from superbody.host.estimation.estimator import ModelMismatchError
    from superbody.host.memory import pin_mmap_threshold
    from superbody.host.service import run_host
    from superbody.host.settings import host_config

    try:
        site = load_site(args.site)
        estimator, name = build_estimator(site, args.estimator, args.model)
        config = host_config(
            site, freshness_s=args.freshness, max_delay_s=args.max_delay, max_publish_hz=args.max_rate, status_every_s=args.status_every,
            tracker={k: v for k, v in (("d_max", args.d_max), ("use_geometry", False if args.no_geometry else None)) if v is not None},
            filter={"enabled": False} if args.no_filter else {},
        )
        clock = clock_from_args(args)
        conf = config_from_args(args)
        sinks = []
        if args.serial:
            from superbody.host.outputs.serial_link import SerialLink

            sinks.append(SerialLink(args.serial, args.baud))
    except (SiteError, ValueError, ModelMismatchError, OSError) as e:
        print(f"superbody host run: error: {e}", file=sys.stderr)
        return 2
    pin_mmap_threshold()  # a burst of large messages must not raise the host's memory for good
    stop = stop_on_signals()
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
        return _open_ros2_sink(args)
    except ImportError:
        print("superbody host run: error: --ros2 needs the rosbags package: pip install 'superbody[ros2]'", file=sys.stderr)
    except ValueError as e:
        print(f"superbody host run: error: {e}", file=sys.stderr)
    return False


def register(sub: argparse._SubParsersAction) -> None:
    """Add the host's commands: ``host run``, ``demo``, ``record``, ``view``."""
    host = sub.add_parser("host", help="host aggregator commands")
    host_sub = host.add_subparsers(dest="host_command", metavar="COMMAND", required=True)
    p = host_sub.add_parser("run", help="run the aggregator: observations in, people's poses out")
    p.add_argument("--site", required=True, help="site file (TOML)")
    from superbody.host.estimation import ESTIMATORS

    p.add_argument("--estimator", choices=ESTIMATORS, default="auto",
                   help="pose estimator (default auto: hybrid when the model carries a hybrid calibration, else the network alone)")
    p.add_argument("--model", help="ONNX model (default: the shipped models/<site>.fp32.onnx)")
    p.add_argument("--max-delay", type=float_in(0.0, 1.9, "--max-delay"), default=None, metavar="S",
                   help="longest the host waits for a camera's frames after their capture: poses are published this much in the past "
                        f"at most, and a camera that delivers later is left out and reported (default: [host] max_delay_s, else {HostConfig.max_delay_s})")
    p.add_argument("--freshness", type=float_in(0.01, 60.0, "--freshness"), default=None, metavar="S",
                   help="a camera's view stays in a person's set S while captured at most this long before the instant the host fuses "
                        f"(default: [host] freshness_s, else {HostConfig.freshness_s})")
    p.add_argument("--d-max", type=_unit, default=None,
                   help=f"colour match threshold, Bhattacharyya distance (default: [host.tracker] d_max, else {TrackerConfig.d_max})")
    p.add_argument("--no-geometry", action="store_true", help="match on colour only, as the paper (no ground-point gate)")
    p.add_argument("--no-filter", action="store_true", help="per-frame output: no temporal filtering")
    p.add_argument("--max-rate", type=float, default=None,
                   help="publish at most this many times a second (default: [host] max_publish_hz, else after every batch)")
    p.add_argument("--status-every", type=positive, default=None,
                   help=f"seconds between status lines (default: [host] status_every_s, else {HostConfig.status_every_s:g})")
    p.add_argument("--serial", metavar="URL", help="also write poses to this serial port (pyserial URL, e.g. /dev/ttyUSB0)")
    p.add_argument("--baud", type=int, default=115200, help="serial baud rate (default 115200)")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many seconds")
    add_clock_args(p)
    add_session_args(p)
    _add_ros2_args(p)
    p.set_defaults(func=_run_host)
    _register_demo(sub)
    _register_record(sub)
    _register_view(sub)


def _site_name(text: str) -> str:
    if not NAME_RE.fullmatch(text):
        raise argparse.ArgumentTypeError(f"must be a site name (1-64 of A-Z a-z 0-9 _ -), got {text!r}")
    return text


def _run_record(args: argparse.Namespace) -> int:
    try:
        conf = config_from_args(args)
        out = Path(args.out)
        if not out.parent.is_dir():
            raise ValueError(f"--out {out}: folder {out.parent} does not exist")
    except (ValueError, OSError) as e:
        print(f"superbody record: error: {e}", file=sys.stderr)
        return 2
    stop = stop_on_signals()
    counts = record(conf, out, args.duration, args.site, stop)
    print(f"superbody record: wrote {out}: " + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "no messages"))
    return 0


def _register_record(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a site's observations, poses and status into an MCAP file")
    p.add_argument("--out", required=True, metavar="F.mcap", help="MCAP file to write")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many seconds (default: Ctrl-C)")
    p.add_argument("--site", type=_site_name, default=None, help="record only this site (its name; default: every site)")
    add_session_args(p)
    p.set_defaults(func=_run_record)


def _int_arg(flag: str, lo: int, hi: int):
    """argparse type: an integer in [lo, hi]; anything else is ``FLAG must be an integer in [lo, hi]``."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = lo - 1
        if not lo <= n <= hi:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer in [{lo}, {hi}], got {text!r}")
        return n

    return parse


def _run_view(args: argparse.Namespace) -> int:
    try:
        site = load_site(args.site)
        conf = config_from_args(args)
        import foxglove  # noqa: F401  (the `view` extra)
    except ImportError:
        print("superbody view: error: needs the foxglove-sdk package: pip install 'superbody[view]'", file=sys.stderr)
        return 2
    except (SiteError, ValueError) as e:
        print(f"superbody view: error: {e}", file=sys.stderr)
        return 2
    stop = stop_on_signals()
    try:
        counts = run_view(conf, site, args.ws_host, args.ws_port, stop)
    except RuntimeError as e:  # e.g. the port is taken
        print(f"superbody view: error: cannot serve on {args.ws_host}:{args.ws_port} ({e})", file=sys.stderr)
        return 1
    log.info("view stopped: %s", counts)
    return 0


def _register_view(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="live 3D view of a site in Foxglove (floor, cameras, people as arrows)")
    p.add_argument("--site", default=str(site_path()), help="site file (default: the shipped wtf-apartment, the demo's)")
    p.add_argument("--ws-port", type=_int_arg("--ws-port", 0, 65535), default=8765, help="Foxglove WebSocket port (default 8765, Foxglove's default; 0: any free port)")
    p.add_argument("--ws-host", default="127.0.0.1", help="address to serve on (default 127.0.0.1; 0.0.0.0 for other machines)")
    add_session_args(p)
    p.set_defaults(func=_run_view)


def _topic(text: str) -> str:
    try:
        return check_topic(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _add_ros2_args(parser: argparse.ArgumentParser) -> None:
    """``--ros2``, ``--ros2-topic``, ``--ros2-domain`` for ``host run``."""
    g = parser.add_argument_group("ROS 2 (rmw_zenoh)")
    g.add_argument("--ros2", action="store_true", help="also publish the poses as geometry_msgs/msg/PoseArray for ROS 2 nodes on rmw_zenoh")
    g.add_argument("--ros2-topic", type=_topic, default=Ros2Config.topic, help="ROS 2 topic (default %(default)s)")
    env = os.environ.get("ROS_DOMAIN_ID", "")
    default = int(env) if env.isdigit() and int(env) <= _MAX_DOMAIN else 0
    g.add_argument("--ros2-domain", type=_int_arg("--ros2-domain", 0, _MAX_DOMAIN), default=default, help="ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID, else 0)")


def _open_ros2_sink(args: argparse.Namespace) -> Ros2Sink:
    """The ``Ros2Sink`` of ``host run --ros2``: its own Zenoh session with the host's mode,
    endpoints and config file, listening nowhere (the host's session keeps its listeners)."""
    import zenoh

    from superbody.edge import transport

    config = Ros2Config(topic=args.ros2_topic, domain_id=args.ros2_domain)
    _typestore()  # rosbags present (ImportError) before any session is opened
    conf = transport.session_config("peer" if args.mode == "router" else args.mode, args.connect or args.listen, [], args.config,
                                    getattr(args, "cfg", None))
    session = zenoh.open(conf)
    try:
        return Ros2Sink(session, Ros2Publisher(session, config))
    except BaseException:
        session.close()
        raise


def _print_summary(s: dict) -> None:
    print("\nsuperbody demo summary")
    print(f"  people simulated / confirmed: {s['people_simulated']} / {s['people_confirmed']}  (tracks published: {s['tracks']})")
    print(f"  identity switches:            {s['id_switches']}")
    pm, ym = s["position_mae_mm"], s["yaw_mae_deg"]
    print(f"  position MAE vs truth:        {'-' if pm is None else f'{pm:.0f} mm'}")
    print(f"  yaw MAE vs truth:             {'-' if ym is None else f'{ym:.1f} deg'}")
    print(f"  capture-to-publish p50 / p99: {s['latency_ms']['p50']:.2f} / {s['latency_ms']['p99']:.2f} ms  (the age of what the host publishes)")
    print(f"  pose arrays published:        {s['poses_published']}")
    timing = s.get("camera_timing", {})
    if any(t["delay_s"] or t["jitter_s"] or t["fps"] is not None for t in timing.values()):
        print("  camera timing:                " + "; ".join(
            f"{cam}: {t['delay_s']:g} s late (sd {t['jitter_s']:g} s)" + ("" if t["fps"] is None else f", {t['fps']:g} fps")
            for cam, t in timing.items()))
    if s["confirm_delay_s"]:
        print("  confirmed after appearing:    " + ", ".join(f"person {k}: {v:.1f} s" for k, v in sorted(s["confirm_delay_s"].items())))
    print(f"  logs:                         {s['log_dir']}")


def _camera_value(flag: str, lo: float, hi: float, unit: str):
    """argparse type: ``CAMERA=VALUE`` with VALUE a number in [lo, hi]; the error names the flag and range
    (the camera id is checked against the site once it is loaded)."""
    number = float_in(lo, hi, flag)

    def parse(text: str) -> tuple[str, float]:
        cam, sep, value = text.partition("=")
        if not (sep and cam.strip()):
            raise argparse.ArgumentTypeError(f"{flag} must be CAMERA={unit} with {unit} in [{lo:g}, {hi:g}], got {text!r}")
        try:
            return cam.strip(), number(value)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(f"{flag} {cam.strip()}=...: {unit} must be a number in [{lo:g}, {hi:g}], got {value!r}") from None
    return parse


def _run_demo(args: argparse.Namespace) -> int:
    cfg = DemoConfig(site=args.site, people=args.people, seed=args.seed, duration_s=args.duration, clock_scale=args.clock_scale,
                     port=args.port, estimator=args.estimator, model=args.model, kill_camera=args.kill_camera,
                     kill_at_s=args.kill_at, table=not args.no_table, delay_s=args.delay, camera_delay_s=dict(args.camera_delay or ()),
                     jitter_s=args.jitter, camera_fps=dict(args.camera_fps or ()))
    try:
        site = load_site(cfg.site)
        cfg.check_cameras(site)
        if cfg.kill_camera is not None:
            site.camera(cfg.kill_camera)
    except (SiteError, KeyError) as e:
        print(f"superbody demo: error: {e.args[0] if e.args else e}", file=sys.stderr)
        return 2
    stop = stop_on_signals()
    try:
        summary = run_demo(cfg, stop)
    except RuntimeError as e:
        print(f"superbody demo: error: {e}", file=sys.stderr)
        return 1
    _print_summary(summary)
    if args.json_summary:
        keys = ("people_simulated", "people_confirmed", "tracks", "confirm_delay_s", "id_switches", "position_mae_mm", "yaw_mae_deg",
                "latency_ms", "poses_published", "camera_timing")
        Path(args.json_summary).write_text(json.dumps({k: summary[k] for k in keys}, indent=1) + "\n")
    return 0


def _register_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the whole system on simulated cameras and people, with a live table")
    p.add_argument("--site", default=str(DEFAULT_SITE), help="site file (default: the paper's apartment)")
    p.add_argument("--people", type=int_in(1, 10, "--people"), default=3, help="simulated people (default 3)")
    p.add_argument("--seed", type=int, default=7, help="simulator seed (default 7)")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many simulated seconds (default: Ctrl-C)")
    p.add_argument("--clock-scale", type=positive, default=1.0, help="simulated seconds per wall second (default 1)")
    p.add_argument("--port", type=int_in(0, 65535, "--port"), default=DEMO_PORT,
                   help=f"loopback port of the demo's Zenoh router (default {DEMO_PORT}, not zenohd's 7447; 0: any free port)")
    p.add_argument("--estimator", choices=("auto", "hybrid", "onnx", "analytic"), default="auto",
                   help="pose estimator (default auto: the shipped fp32 model, fused with geometry when it carries a hybrid calibration)")
    p.add_argument("--model", help="ONNX model (default: models/<site>.fp32.onnx)")
    p.add_argument("--kill-camera", metavar="ID", help="kill this camera's process mid-run (fault injection)")
    p.add_argument("--kill-at", type=positive, default=10.0, help="simulated second at which to kill it (default 10)")
    p.add_argument("--no-table", action="store_true", help="no live table, only the summary")
    p.add_argument("--json-summary", metavar="F", help="write the summary as JSON")
    t = p.add_argument_group("camera timing (as real nodes: late, jittered, each at its own rate; stamps stay capture times)")
    t.add_argument("--delay", type=float_in(0.0, MAX_DELAY_S, "--delay"), default=0.0, metavar="S",
                   help=f"every camera publishes each observation S seconds after its capture (0-{MAX_DELAY_S:g}; default 0)")
    t.add_argument("--camera-delay", type=_camera_value("--camera-delay", 0.0, MAX_DELAY_S, "SECONDS"), action="append",
                   metavar="ID=S", help="this camera's delay instead of --delay (repeatable), e.g. --camera-delay 1=0.8")
    t.add_argument("--jitter", type=float_in(0.0, MAX_JITTER_S, "--jitter"), default=0.0, metavar="S",
                   help=f"standard deviation of a normal spread of every camera's delay, clipped at 0 (0-{MAX_JITTER_S:g}; default 0)")
    t.add_argument("--camera-fps", type=_camera_value("--camera-fps", 0.1, 1000.0, "FPS"), action="append", metavar="ID=F",
                   help="this camera captures at F fps instead of the site's (repeatable), e.g. --camera-fps 3=5")
    p.set_defaults(func=_run_demo)
