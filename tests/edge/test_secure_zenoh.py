"""The secured deployment of deploy/zenoh/ over real Zenoh on loopback (issue 11 #7): the router
with TLS, mutual TLS, user/password and the ACL, every node a client with its own certificate.

Certificates and configs come from ``deploy/zenoh/make-certs.sh`` into a temporary folder, as a
site's installer would make them. What it shows: a peer without a certificate gets nothing in;
a certified camera cannot publish another camera's keys nor fake PoseArrays; the legitimate
system (router, host, three camera processes) still delivers poses to a certified app.
"""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time

import pytest
import zenoh

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.messages import pose as pose_msg
from tests.conftest import ROOT, WTF_SITE, free_port

SITE = load_site(WTF_SITE)
MARK = 987_654_321  # the seq of every forged message


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    out = tmp_path_factory.mktemp("zenoh-site")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    env = dict(os.environ, ZENOH_LISTEN=endpoint, ZENOH_CONNECT=endpoint)
    subprocess.run([str(ROOT / "deploy" / "zenoh" / "make-certs.sh"), str(out), SITE.name, *SITE.camera_ids],
                   check=True, env=env, timeout=120, capture_output=True)
    return out, endpoint


def test_the_configs_load_and_are_what_the_readme_says(certs):
    out, endpoint = certs
    router = zenoh.Config.from_file(str(out / "router.json5"))
    assert json.loads(router.get_json("access_control/enabled")) is True
    assert json.loads(router.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(router.get_json("listen/endpoints")) == [endpoint]
    assert json.loads(router.get_json("transport/shared_memory/enabled")) is False  # see edge/transport.py
    for name in ("host", "app", *(f"camera-{c}" for c in SITE.camera_ids)):
        node = zenoh.Config.from_file(str(out / f"{name}.json5"))
        assert json.loads(node.get_json("mode")) == "client"
        assert json.loads(node.get_json("scouting/multicast/enabled")) is False
        assert json.loads(node.get_json("transport/auth/usrpwd/user")) == name
        assert json.loads(node.get_json("transport/shared_memory/enabled")) is False
    for f in ("loopback/router.json5", "loopback/node.json5"):
        conf = zenoh.Config.from_file(str(ROOT / "deploy" / "zenoh" / f))
        assert all("127.0.0.1" in e for e in json.loads(conf.get_json("listen/endpoints")) + json.loads(conf.get_json("connect/endpoints")))


class _Seen:
    def __init__(self) -> None:
        self.cv = threading.Condition()
        self.people: list[pose_msg.PoseArray] = []
        self.forged: list[str] = []
        self.cam2 = 0

    def on_people(self, sample) -> None:
        with self.cv:
            try:
                arr = pose_msg.decode(sample.payload.to_bytes())
            except pose_msg.PoseDecodeError:
                self.forged.append("undecodable people")
                return
            if arr.seq == MARK or arr.estimator == "forged":
                self.forged.append("fake PoseArray")
            self.people.append(arr)
            self.cv.notify_all()

    def on_cam2(self, sample) -> None:
        with self.cv:
            if json.loads(sample.payload.to_bytes()).get("seq") == MARK:
                self.forged.append("camera 2 key from camera 1")
            self.cam2 += 1
            self.cv.notify_all()

    def wait(self, predicate, timeout: float) -> bool:
        with self.cv:
            return self.cv.wait_for(predicate, timeout=timeout)


def _forged_pose_array() -> bytes:
    fake = pose_msg.PersonPose(id=1, x=0.0, y=0.0, yaw=0.0, vx=0.0, vy=0.0, yaw_rate=0.0, cov=[[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]],
                               confidence=1.0, cameras=("1",), stamp_ns=time.time_ns(), views=1)
    return pose_msg.encode(pose_msg.PoseArray(SITE.name, MARK, time.time_ns(), (fake,), estimator="forged"))


@pytest.mark.slow
def test_acl_and_mutual_tls_keep_intruders_out_and_the_system_working(certs, processes):
    out, endpoint = certs
    site_file = str(WTF_SITE)
    router = processes.start("router", "--config", str(out / "router.json5"))
    processes.start("host", "run", "--site", site_file, "--estimator", "analytic", "--config", str(out / "host.json5"))
    for cam in SITE.camera_ids:
        processes.start("edge", "run", "--site", site_file, "--camera", cam, "--seed", "3", "--people", "2",
                        "--config", str(out / f"camera-{cam}.json5"))
    seen = _Seen()
    with zenoh.open(zenoh.Config.from_file(str(out / "app.json5"))) as app:
        subs = [app.declare_subscriber(transport.people_key(SITE.name), seen.on_people),
                app.declare_subscriber(transport.observation_key(SITE.name, "2"), seen.on_cam2)]
        # The legitimate system delivers poses of people to a certified app.
        assert seen.wait(lambda: sum(bool(a.people) for a in seen.people) >= 10 and seen.cam2 >= 10, timeout=60), \
            (len(seen.people), seen.cam2, router.poll())

        # A peer without a certificate (and without a password) gets nothing in: no link at all.
        rogue = zenoh.Config()
        rogue.insert_json5("mode", '"client"')
        rogue.insert_json5("connect/endpoints", json.dumps([endpoint]))
        rogue.insert_json5("connect/timeout_ms", "3000")
        rogue.insert_json5("scouting/multicast/enabled", "false")
        rogue.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(out / "ca.pem")))
        with pytest.raises(zenoh.ZError):
            zenoh.open(rogue)

        # A certified camera 1 tries to speak for camera 2 and to publish fake poses.
        obs = SimCamera(World(SITE, 2, seed=3), "2").observe(time.time_ns())[0]
        forged_obs = json.loads(wire.encode(obs))
        forged_obs["seq"] = MARK
        with zenoh.open(zenoh.Config.from_file(str(out / "camera-1.json5"))) as cam1:
            for _ in range(20):  # bounded
                cam1.put(transport.observation_key(SITE.name, "2"), json.dumps(forged_obs))
                cam1.put(transport.people_key(SITE.name), _forged_pose_array())
                time.sleep(0.02)
            n_people, n_cam2 = len(seen.people), seen.cam2
            # Real traffic keeps flowing past the forgeries; none of them arrives.
            assert seen.wait(lambda: len(seen.people) >= n_people + 20 and seen.cam2 >= n_cam2 + 20, timeout=20)
        assert seen.forged == []
        assert all(a.estimator == "analytic" for a in seen.people)
        for s in subs:
            s.undeclare()
