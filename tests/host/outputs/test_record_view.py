"""``superbody record`` and ``superbody view`` against a live loopback system.

Record: a router, three simulated camera processes and the host (analytic, for speed) run as
separate processes; ``superbody record`` (another process) writes an MCAP file that the ``mcap``
library reads back. View: ``superbody view`` (a process) is reached by a WebSocket client on the
Foxglove subprotocol; a PoseArray published on Zenoh comes out on its channels.
"""

from __future__ import annotations

import json
import struct
import threading
import time

import pytest
import zenoh

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.site import load_site
from superbody.host.messages import pose as pose_msg
from tests.conftest import WTF_SITE, free_port

SITE = str(WTF_SITE)


def _wait_for_status(session, site: str, predicate, timeout: float) -> bool:
    cv, seen = threading.Condition(), []

    def on_status(sample):
        with cv:
            seen.append(json.loads(sample.payload.to_bytes()))
            cv.notify_all()

    sub = session.declare_subscriber(transport.host_status_key(site), on_status)
    try:
        with cv:
            return cv.wait_for(lambda: any(predicate(s) for s in seen), timeout=timeout)
    finally:
        sub.undeclare()


def test_record_writes_every_camera_poses_and_status_with_schemas(processes, tmp_path):
    from mcap.reader import make_reader

    site = load_site(SITE)
    ep = f"tcp/127.0.0.1:{free_port()}"
    processes.start("router", "--listen", ep)
    processes.start("host", "run", "--site", SITE, "--estimator", "analytic", "--status-every", "0.5", "--connect", ep)
    for cam in site.camera_ids:
        processes.start("edge", "run", "--site", SITE, "--camera", cam, "--seed", "3", "--people", "2", "--connect", ep)
    with zenoh.open(transport.session_config("peer", connect=[ep])) as session:
        assert _wait_for_status(session, site.name, lambda s: s["cameras_alive"] == list(site.camera_ids) and s["published"] > 0, 60)
    out = tmp_path / "site.mcap"
    rec = processes.start("record", "--duration", "3", "--out", str(out), "--site", site.name, "--connect", ep)
    assert rec.wait(timeout=60) == 0, rec.stderr.read()

    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        by_topic: dict[str, list[bytes]] = {}
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "jsonschema", channel.topic  # a schema on every channel
            assert channel.message_encoding == "json"
            assert message.log_time >= message.publish_time - 10**9  # publish time: the capture stamp, before arrival
            by_topic.setdefault(channel.topic, []).append(message.data)
    schemas = {s.name: json.loads(s.data) for s in summary.schemas.values()}
    assert set(schemas) == {"superbody.observation", "superbody.people", "superbody.host_status"}
    assert all(v["$schema"].endswith("2020-12/schema") for v in schemas.values())
    # One channel per key: every camera's observations, the PoseArrays, the status.
    expected = {transport.observation_key(site.name, c) for c in site.camera_ids}
    expected |= {transport.people_key(site.name), transport.host_status_key(site.name)}
    assert set(by_topic) == expected, sorted(by_topic)
    for cam in site.camera_ids:
        obs = [wire.decode(d) for d in by_topic[transport.observation_key(site.name, cam)]]
        assert len(obs) >= 15 and all(o.camera == cam for o in obs)  # 15 fps for ~3 s
        assert [o.seq for o in obs] == sorted(o.seq for o in obs)
    arrays = [pose_msg.decode(d) for d in by_topic[transport.people_key(site.name)]]
    assert len(arrays) >= 10 and any(a.people for a in arrays)
    assert by_topic[transport.host_status_key(site.name)]


def test_record_rejects_a_bad_site_name(processes):
    p = processes.start("record", "--duration", "1", "--out", "x.mcap", "--site", "no such site")
    assert p.wait(timeout=30) == 2
    err = p.stderr.read()
    assert "superbody record: error: argument --site" in err and "Traceback" not in err


def _recv_json(ws, op: str, timeout: float) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = ws.recv(timeout=max(0.01, end - time.monotonic()))
        if isinstance(m, str) and json.loads(m).get("op") == op:
            return json.loads(m)
    raise TimeoutError(op)


def test_view_serves_the_scene_and_the_pose_array_to_a_foxglove_client(processes):
    from websockets.sync.client import connect

    site = load_site(SITE)
    zport, wsport = free_port(), free_port()
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{zport}"])
    with zenoh.open(conf) as session:
        view = processes.start("view", "--site", SITE, "--ws-port", str(wsport), "--connect", f"tcp/127.0.0.1:{zport}")
        ws = None
        for _ in range(300):  # the view process starts in a few seconds; bounded: 30 s
            try:
                ws = connect(f"ws://127.0.0.1:{wsport}", subprotocols=["foxglove.sdk.v1"], open_timeout=1)
                break
            except OSError:
                assert view.poll() is None, view.stderr.read()
                time.sleep(0.1)
        assert ws is not None, "the view never listened"
        with ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            _recv_json(ws, "serverInfo", 10)
            channels = {c["topic"]: c for c in _recv_json(ws, "advertise", 10)["channels"]}
            scene = channels["/superbody/scene"]
            assert scene["schemaName"] == "foxglove.SceneUpdate"
            people = channels[transport.people_key(site.name)]
            assert people["encoding"] == "json" and people["schemaEncoding"] == "jsonschema"
            assert json.loads(people["schema"])["$id"] == "superbody.people/2"
            assert transport.host_status_key(site.name) in channels
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": scene["id"]},
                                                                     {"id": 2, "channelId": people["id"]}]}))
            person = pose_msg.PersonPose(id=41, x=1.0, y=2.0, yaw=0.5, vx=0.0, vy=0.0, yaw_rate=0.0, cov=pose_msg.np.eye(3) * 0.01,
                                         confidence=0.9, cameras=("1",), stamp_ns=time.time_ns(), views=1, estimator="analytic")
            arr = pose_msg.PoseArray(site=site.name, seq=5, stamp_ns=time.time_ns(), people=(person,), latency_ns=1000,
                                     cameras_alive=("1",), estimator="analytic")
            pub = session.declare_publisher(transport.people_key(site.name))
            got: dict[int, bytes] = {}
            end = time.monotonic() + 30
            while not ({1, 2} <= set(got)) and time.monotonic() < end:
                pub.put(pose_msg.encode(arr))  # again until the view's subscriber has matched
                try:
                    m = ws.recv(timeout=0.3)
                except TimeoutError:
                    continue
                if isinstance(m, bytes) and m[0] == 1:  # messageData: opcode, subscription u32, log time u64, payload
                    sub_id = struct.unpack_from("<I", m, 1)[0]
                    if sub_id == 2 or b"person-41" in m:
                        got[sub_id] = m[13:]
            assert 2 in got and pose_msg.decode(got[2]).seq == 5  # the raw PoseArray, unchanged
            assert 1 in got and b"person-41" in got[1] and b"41  29 deg" in got[1]  # the arrow's entity and its label
    assert view.poll() is None  # still serving until stopped


@pytest.mark.parametrize("args, text", [
    (["--ws-port", "70000"], "--ws-port must be an integer in [0, 65535]"),  # out of range
    (["--site", "/nonexistent.toml"], "cannot read site file"),  # missing site file
])
def test_view_bad_arguments_are_one_line_errors(processes, args, text):
    p = processes.start("view", *args)
    assert p.wait(timeout=30) == 2
    err = p.stderr.read()
    assert text in err and "Traceback" not in err, err


def test_the_scene_shows_the_hosts_health_and_each_cameras_state():
    from superbody.host.messages import status as hs
    from superbody.host.outputs.view import health_scene, health_texts

    site = load_site(SITE)
    cams = [hs.CameraStatus(id=c.id, alive=True, state="ok", fps=15.0, delay_ms=hs.delay(0.12, 0.2), frames=10, fused=9, dropped={},
                            problems=[]) for c in site.cameras]
    cams[1] = hs.CameraStatus(id=cams[1].id, alive=True, state="too_late", fps=15.0, delay_ms=hs.delay(2.3, 2.5), frames=0, fused=0,
                              dropped={"too_late": 300}, problems=["too_late: frames arrive 2.50 s after capture (p95)"])
    status = hs.HostStatus(cameras_alive=[c.id for c in site.cameras], cameras_total=len(site.cameras), people=1, obs_per_s=45.0,
                           latency_ms=hs.latency(150.0, 200.0), rejected={}, queue_dropped=0, published=100,
                           health=hs.Health(state="degraded", reasons=[f"camera {cams[1].id}: {cams[1].problems[0]}"]), cameras=cams)
    texts = {eid: (text, fine) for eid, _, text, fine in health_texts(site, status)}
    assert texts["host-health"][0].startswith("host degraded\ncamera 2: too_late") and not texts["host-health"][1]
    assert texts["camera-state-2"] == ("too_late 2.30 s late", False)
    assert texts["camera-state-1"] == ("ok 0.12 s late", True)
    assert b"too_late 2.30 s late" in health_scene(site, status, time.time_ns()).encode()  # what Foxglove gets
    older = hs.HostStatus(**{f: getattr(status, f) for f in ("cameras_alive", "cameras_total", "people", "obs_per_s", "latency_ms",
                                                            "rejected", "queue_dropped", "published")})
    assert [t[:3:2] for t in health_texts(site, older)] == [("host-health", "host ok")]  # a host before issue 37
