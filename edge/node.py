"""The camera-node process: a frame source, its detector, and a Zenoh publisher.

``superbody edge run --site SITE.toml --camera ID --source sim --seed 7`` publishes one
Observation per frame on ``superbody/<site>/cameras/<camera>/observations`` at the camera's fps
and holds a liveliness token on ``superbody/<site>/cameras/<camera>/alive`` while it runs.

Frames are captured on a grid of the world clock (frame k at k / fps plus a per-camera phase),
so simulated nodes started with the same site and seed see the same people at the same instants.
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import threading
import time
from typing import Protocol

from superbody.edge import transport, wire
from superbody.edge.cli import int_in, positive
from superbody.edge.clock import WorldClock, add_clock_args, clock_from_args
from superbody.edge.observation import Observation
from superbody.edge.site import Site, SiteError, load_site

__all__ = ["Source", "SimSource", "make_source", "run_node", "register", "SOURCES"]

log = logging.getLogger("superbody.edge")

SOURCES = ("sim",)


class Source(Protocol):
    """A frame source with its detector: the Observation captured at a given time."""

    def observe(self, stamp_ns: int) -> Observation: ...


class SimSource:
    """Simulated people seen by one camera of a site (edge/simulator.py)."""

    def __init__(self, site: Site, camera_id: str, seed: int, people: int = 3, depth: bool = False):
        from superbody.edge.simulator import SimCamera, World

        self._cam = SimCamera(World(site, people, seed), camera_id, depth=depth)

    def observe(self, stamp_ns: int) -> Observation:
        return self._cam.observe(stamp_ns)[0]


def make_source(name: str, site: Site, camera_id: str, **options) -> Source:
    """A source by name; ``ValueError`` listing the valid names otherwise."""
    if name == "sim":
        return SimSource(site, camera_id, options.get("seed", 0), options.get("people", 3), options.get("depth", False))
    raise ValueError(f"unknown source {name!r}; valid sources: {', '.join(SOURCES)}")


def run_node(
    conf,
    site: Site,
    camera_id: str,
    source: Source,
    clock: WorldClock = WorldClock(),
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    status_every_s: float = 10.0,
) -> int:
    """Publish the source's Observations until ``stop`` is set or ``duration_s`` (world time) passes.

    Returns:
        The number of Observations published.
    """
    import zenoh

    cam = site.camera(camera_id)
    stop = stop or threading.Event()
    period_ns = 1e9 / cam.fps
    # Cameras are not synchronised: spread their capture instants over the frame period.
    phase_ns = period_ns * site.camera_index(camera_id) / max(len(site.cameras), 1)
    published = skipped = people = rejected = 0
    with zenoh.open(conf) as session:
        token = session.liveliness().declare_token(transport.camera_alive_key(site.name, camera_id))
        pub = session.declare_publisher(transport.observation_key(site.name, camera_id), encoding=wire.zenoh_encoding())
        start = clock.now_ns()
        end = None if duration_s is None else start + int(duration_s * 1e9)
        k = math.ceil((start - phase_ns) / period_ns)
        last_status = time.monotonic()
        log.info("camera %s of site %s publishing at %.1f fps on %s", camera_id, site.name, cam.fps, transport.observation_key(site.name, camera_id))
        while not stop.is_set():
            t_ns = int(k * period_ns + phase_ns)
            if end is not None and t_ns > end:
                break
            clock.sleep_until(t_ns)
            obs = source.observe(t_ns)
            try:
                payload = wire.encode(obs)
            except ValueError as e:  # a source produced something no subscriber would accept
                rejected += 1
                if rejected <= 3 or rejected % 1000 == 0:
                    log.error("camera %s: frame %d not published (%d so far): %s", camera_id, obs.seq, rejected, e)
                k += 1
                continue
            pub.put(payload)
            published += 1
            people += len(obs.people)
            # If we fell behind (slow machine), skip to the next frame in the future.
            k_now = math.floor((clock.now_ns() - phase_ns) / period_ns)
            if k_now > k + 1:
                skipped += k_now - k - 1
                k = k_now
            k += 1
            if time.monotonic() - last_status > status_every_s:
                last_status = time.monotonic()
                log.info("camera %s: %d frames published, %d skipped, %.2f people/frame", camera_id, published, skipped, people / max(published, 1))
        pub.undeclare()
        token.undeclare()
    log.info("camera %s stopped after %d frames (%d skipped)", camera_id, published, skipped)
    return published


def _run(args: argparse.Namespace) -> int:
    try:
        site = load_site(args.site)
        site.camera(args.camera)
        source = make_source(args.source, site, args.camera, seed=args.seed, people=args.people, depth=args.depth)
        clock = clock_from_args(args)
        conf = transport.config_from_args(args)
    except (SiteError, KeyError, ValueError) as e:
        print(f"superbody edge run: error: {e.args[0] if e.args else e}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    run_node(conf, site, args.camera, source, clock, args.duration, stop)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    edge = sub.add_parser("edge", help="camera-node commands")
    edge_sub = edge.add_subparsers(dest="edge_command", metavar="COMMAND", required=True)
    p = edge_sub.add_parser("run", help="run a camera node: capture, detect, publish Observations")
    p.add_argument("--site", required=True, help="site file (TOML)")
    p.add_argument("--camera", required=True, help="camera id in the site file")
    p.add_argument("--source", default="sim", choices=SOURCES, help="frame source (default: sim)")
    p.add_argument("--seed", type=int, default=0, help="simulator seed: nodes with the same seed see the same people")
    p.add_argument("--people", type=int_in(0, 64, "--people"), default=3, help="simulated people (default 3)")
    p.add_argument("--depth", action="store_true", help="simulate a depth camera (3D joints in the Observations)")
    p.add_argument("--duration", type=positive, default=None, help="stop after this many seconds of world time")
    add_clock_args(p)
    transport.add_session_args(p)
    p.set_defaults(func=_run)
