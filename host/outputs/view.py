"""``superbody view``: a live 3D view of a site in Foxglove, served with the foxglove-sdk.

Subscribes to the site's PoseArrays and host status on Zenoh and serves a Foxglove WebSocket
(``ws://127.0.0.1:8765`` by default; in Foxglove: Open connection, Foxglove WebSocket) with:

- ``/superbody/scene`` (``foxglove.SceneUpdate``): the floor polygon, the obstacles, each camera's
  frustum (from the site file, re-sent every second for late joiners), each person as an
  arrow along their torso yaw with a label "id yaw" (each person lives 0.5 s unless renewed),
  and the host's health from its status: "host ok" or "host degraded" with the first reasons,
  above the floor, and under each camera its state and delivery delay, green when it is fine
  and red when not (``health_scene``).
- ``superbody/<site>/people``: the raw PoseArray (JSON, its JSON Schema).
- ``superbody/<site>/host/status``: the raw host status (JSON, its JSON Schema).

The scene's frame is the site's world frame, named after the site (REP-103: metres, z up).

    superbody view [--site SITE.toml] [--ws-port 8765] [--connect tcp/10.0.0.2:7447]
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time

import numpy as np
from numpy.typing import NDArray

from superbody.edge import transport
from superbody.edge.camera import Camera, pixel_to_ray
from superbody.edge.resources import json_schema
from superbody.edge.site import Site
from superbody.host.messages import pose as pose_msg
from superbody.host.messages import status as host_status

__all__ = ["SCENE_TOPIC", "frustum_points", "floor_points", "static_scene", "people_scene", "health_texts", "health_scene", "run_view"]

log = logging.getLogger("superbody.view")

SCENE_TOPIC = "/superbody/scene"
_FRUSTUM_DEPTH_M = 1.0  # how far the drawn frustum reaches from the optical centre
_PERSON_LIFETIME_NS = 500_000_000  # a person not renewed within this vanishes (left the room)
_ARROW_LENGTH_M = 0.6
_TORSO_HEIGHT_M = 1.2  # where the arrow is drawn: about a standing person's chest


def frustum_points(cam: Camera, depth: float = _FRUSTUM_DEPTH_M) -> NDArray[np.float64]:
    """A camera's viewing pyramid as line segments: 8 segments, shape (16, 3), world frame.

    Four edges from the optical centre through the image corners to ``depth`` metres along the
    optical axis, and the rectangle joining their ends.
    """
    corners = np.array([[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]], dtype=np.float64)  # (4, 2)
    origin, d = pixel_to_ray(corners, cam)  # (3,), (4, 3)
    axis = cam.R[:, 2]  # the optical axis in the world
    ends = origin + d * (depth / (d @ axis))[:, None]  # (4, 3) on the plane `depth` in front
    segs = [p for e in ends for p in (origin, e)]
    segs += [p for i in range(4) for p in (ends[i], ends[(i + 1) % 4])]
    return np.asarray(segs)  # (16, 3)


def floor_points(site: Site) -> NDArray[np.float64]:
    """The floor polygon as a closed loop on z = 0, shape (N, 3)."""
    xy = np.asarray(site.floor, dtype=np.float64)  # (N, 2)
    return np.hstack([xy, np.zeros((len(xy), 1))])


def _point(p):
    from foxglove.messages import Point3

    return Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _pose(x: float, y: float, z: float, yaw: float = 0.0):
    from foxglove.messages import Pose, Quaternion, Vector3

    # A rotation of `yaw` about +z: q = (0, 0, sin(yaw/2), cos(yaw/2)).
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def _stamp(ns: int):
    from foxglove.messages import Timestamp

    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def static_scene(site: Site, stamp_ns: int):
    """The site's fixed geometry as a ``foxglove.SceneUpdate``: floor, obstacles, camera frusta."""
    from foxglove.messages import (
        Color,
        CubePrimitive,
        LinePrimitive,
        LinePrimitiveLineType,
        SceneEntity,
        SceneUpdate,
        TextPrimitive,
        Vector3,
    )

    frame, ts = site.name, _stamp(stamp_ns)
    entities = [SceneEntity(timestamp=ts, frame_id=frame, id="floor", lines=[LinePrimitive(
        type=LinePrimitiveLineType.LineLoop, pose=_pose(0.0, 0.0, 0.0), thickness=0.03, points=[_point(p) for p in floor_points(site)],
        color=Color(r=0.6, g=0.6, b=0.6, a=1.0))])]
    for o in site.obstacles:
        lo, hi = np.asarray(o.min), np.asarray(o.max)
        c = (lo + hi) / 2
        entities.append(SceneEntity(timestamp=ts, frame_id=frame, id=f"obstacle-{o.name}", cubes=[CubePrimitive(
            pose=_pose(*map(float, c)), size=Vector3(x=float(hi[0] - lo[0]), y=float(hi[1] - lo[1]), z=float(hi[2] - lo[2])),
            color=Color(r=0.5, g=0.35, b=0.2, a=0.6))]))
    for cam in site.cameras:
        entities.append(SceneEntity(timestamp=ts, frame_id=frame, id=f"camera-{cam.id}", lines=[LinePrimitive(
            type=LinePrimitiveLineType.LineList, pose=_pose(0.0, 0.0, 0.0), thickness=0.02,
            points=[_point(p) for p in frustum_points(cam)], color=Color(r=0.2, g=0.6, b=1.0, a=1.0))],
            texts=[TextPrimitive(pose=_pose(*map(float, cam.position)), billboard=True, font_size=14.0, scale_invariant=True,
                                 color=Color(r=0.2, g=0.6, b=1.0, a=1.0), text=f"camera {cam.id}")]))
    return SceneUpdate(entities=entities)


def people_scene(arr: pose_msg.PoseArray):
    """Each person of a PoseArray as an arrow along their yaw with an "id, yaw" label."""
    from foxglove.messages import ArrowPrimitive, Color, Duration, SceneEntity, SceneUpdate, TextPrimitive

    ts, life = _stamp(arr.stamp_ns), Duration(0, _PERSON_LIFETIME_NS)
    entities = []
    for p in arr.people:
        entities.append(SceneEntity(
            timestamp=ts, frame_id=arr.site, id=f"person-{p.id}", lifetime=life,
            arrows=[ArrowPrimitive(pose=_pose(p.x, p.y, _TORSO_HEIGHT_M, p.yaw), shaft_length=_ARROW_LENGTH_M * 0.7, shaft_diameter=0.06,
                                   head_length=_ARROW_LENGTH_M * 0.3, head_diameter=0.15, color=Color(r=1.0, g=0.4, b=0.1, a=1.0))],
            texts=[TextPrimitive(pose=_pose(p.x, p.y, _TORSO_HEIGHT_M + 0.4), billboard=True, font_size=16.0, scale_invariant=True,
                                 color=Color(r=1.0, g=1.0, b=1.0, a=1.0), text=f"{p.id}  {math.degrees(p.yaw):.0f} deg")],
        ))
    return SceneUpdate(entities=entities)


def health_texts(site: Site, status: host_status.HostStatus) -> list[tuple[str, tuple[float, float, float], str, bool]]:
    """What ``health_scene`` draws: (entity id, where, text, fine) for the host's health (above the
    floor's centre: its state and first three reasons) and for each camera (under it: its state
    and median delivery delay)."""
    floor = np.asarray(site.floor, dtype=np.float64)
    cx, cy = floor.mean(axis=0) if len(floor) else (0.0, 0.0)
    health = status.health
    fine = health is None or health.state == "ok"
    out = [("host-health", (float(cx), float(cy), 2.8), "\n".join(["host ok" if fine else "host degraded", *(health.reasons[:3] if health else [])]),
            fine)]
    where = {c.id: c.position for c in site.cameras}
    for cam in status.cameras or ():
        if cam.id in where:
            delay = "" if cam.delay_ms.p50 is None else f" {cam.delay_ms.p50 / 1e3:.2f} s late"
            x, y, z = map(float, where[cam.id])
            out.append((f"camera-state-{cam.id}", (x, y, z - 0.25), f"{cam.state}{delay}", cam.state == "ok"))
    return out


def health_scene(site: Site, status: host_status.HostStatus, stamp_ns: int):
    """The host status's health as scene text (``health_texts``), green where fine and red where not."""
    from foxglove.messages import Color, SceneEntity, SceneUpdate, TextPrimitive

    ts = _stamp(stamp_ns)
    good, bad = Color(r=0.2, g=0.85, b=0.3, a=1.0), Color(r=1.0, g=0.25, b=0.2, a=1.0)
    return SceneUpdate(entities=[
        SceneEntity(timestamp=ts, frame_id=site.name, id=eid, texts=[TextPrimitive(
            pose=_pose(*xyz), billboard=True, font_size=14.0 if eid == "host-health" else 12.0, scale_invariant=True,
            color=good if fine else bad, text=text)])
        for eid, xyz, text, fine in health_texts(site, status)
    ])


def run_view(conf, site: Site, host: str, port: int, stop: threading.Event, ready: threading.Event | None = None) -> dict:
    """Serve the live view until ``stop`` is set; returns counts of what was forwarded."""
    import foxglove
    import zenoh
    from foxglove.channels import SceneUpdateChannel

    server = foxglove.start_server(name=f"superbody {site.name}", host=host, port=port)
    scene = SceneUpdateChannel(SCENE_TOPIC)
    people_topic, status_topic = transport.people_key(site.name), transport.host_status_key(site.name)
    people = foxglove.Channel(people_topic, schema=json.loads(json_schema("people")), message_encoding="json")
    status = foxglove.Channel(status_topic, schema=json.loads(json_schema("status")), message_encoding="json")
    counts = {"people": 0, "status": 0, "rejected": 0}

    def on_people(sample) -> None:
        raw = sample.payload.to_bytes()
        try:
            arr = pose_msg.decode(raw, expected_site=site.name)
        except pose_msg.PoseDecodeError as e:
            counts["rejected"] += 1
            if counts["rejected"] <= 3:
                log.warning("rejected PoseArray: %s", e)
            return
        now = time.time_ns()
        people.log(raw, log_time=now)
        scene.log(people_scene(arr), log_time=now)
        counts["people"] += 1

    def on_status(sample) -> None:
        raw, now = sample.payload.to_bytes(), time.time_ns()
        status.log(raw, log_time=now)
        counts["status"] += 1
        try:
            scene.log(health_scene(site, host_status.decode(raw), now), log_time=now)
        except ValueError as e:  # DecodeError: the raw status went out as it came; the scene skips it
            counts["rejected"] += 1
            if counts["rejected"] <= 3:
                log.warning("host status not shown in the scene: %s", e)

    try:
        with zenoh.open(conf) as session:
            subs = [session.declare_subscriber(people_topic, on_people), session.declare_subscriber(status_topic, on_status)]
            log.info("Foxglove live view of site %s on ws://%s:%d", site.name, host, server.port)
            if ready is not None:
                ready.set()
            while not stop.is_set():
                scene.log(static_scene(site, time.time_ns()))
                stop.wait(1.0)
            for s in subs:
                s.undeclare()
    finally:
        server.stop()
    return counts


