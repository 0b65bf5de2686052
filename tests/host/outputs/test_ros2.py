"""geometry_msgs/PoseArray for ROS 2 on rmw_zenoh's key and attachment (host/outputs/ros2.py).

No ROS here: the CDR is read back with rosbags, the attachment with zenoh's own deserialiser
(an implementation independent of ours), the keys are checked against the layout read in
rmw_zenoh's source (docs/ros2.md), and ``host run --ros2`` is run as a process."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
import zenoh
import zenoh.ext

from superbody.edge import transport
from superbody.host.messages import pose as pose_msg
from superbody.host.outputs import ros2
from tests.conftest import WTF_SITE, free_port


def _arr(yaws=(0.0, 1.0, -2.5), stamp_ns=1_718_000_000_123_456_789) -> pose_msg.PoseArray:
    people = tuple(pose_msg.PersonPose(id=i, x=0.5 * i, y=-1.0 + i, yaw=y, vx=0.0, vy=0.0, yaw_rate=0.0, cov=np.eye(3) * 0.01,
                                       confidence=0.9, cameras=("1",), stamp_ns=stamp_ns, views=1, estimator="analytic")
                   for i, y in enumerate(yaws))
    return pose_msg.PoseArray(site="wtf-apartment", seq=3, stamp_ns=stamp_ns, people=people, latency_ns=0,
                              cameras_alive=("1",), estimator="analytic")


def _store():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def test_type_hash_is_the_one_rosbags_computes():
    assert _store().hash_rihs01(ros2.TYPE_NAME) == ros2.TYPE_HASH
    # rosbags' hashing against a value published by others: std_msgs/msg/String in rmw_zenoh examples.
    assert _store().hash_rihs01("std_msgs/msg/String") == "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


@pytest.mark.parametrize("yaws", [(), (0.0,), (0.0, 1.0, -2.5, math.pi)])  # empty room included
def test_cdr_round_trip(yaws):
    arr = _arr(yaws)
    cdr = ros2.pose_array_cdr(arr)
    assert cdr[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    msg = _store().deserialize_cdr(cdr, ros2.TYPE_NAME)
    assert msg.header.frame_id == "wtf-apartment"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_718_000_000, 123_456_789)
    assert len(msg.poses) == len(yaws)
    for p, q in zip(arr.people, msg.poses):
        assert (q.position.x, q.position.y, q.position.z) == (p.x, p.y, 0.0)
        o = q.orientation
        assert abs(o.x) + abs(o.y) == 0 and math.isclose(o.x**2 + o.y**2 + o.z**2 + o.w**2, 1.0)
        assert math.isclose(math.atan2(2 * o.w * o.z, 1 - 2 * o.z**2), p.yaw, abs_tol=1e-9) or math.isclose(abs(p.yaw), math.pi)


def test_attachment_reads_back_with_zenohs_deserialiser():
    gid = bytes(range(16))
    raw = ros2.attachment(7, 1_718_000_000_000_000_001, gid)
    got = zenoh.ext.z_deserialize(tuple[str, zenoh.ext.Int64, str, zenoh.ext.Int64, str, bytes], zenoh.ZBytes(raw))
    assert got == ("sequence_number", 7, "source_timestamp", 1_718_000_000_000_000_001, "source_gid", gid)
    with pytest.raises(ValueError, match="16 bytes"):
        ros2.attachment(1, 0, b"short")


def test_keys_follow_rmw_zenoh():
    cfg = ros2.Ros2Config(topic="/superbody/people", domain_id=3)
    assert ros2.topic_key(cfg.topic, 3) == f"3/superbody/people/geometry_msgs::msg::dds_::PoseArray_/{ros2.TYPE_HASH}"
    node, pub = ros2.liveliness_keys("abc123", cfg)
    assert node == "@ros2_lv/3/abc123/0/0/NN/%/%/superbody_host"
    assert pub == f"@ros2_lv/3/abc123/0/1/MP/%/%/superbody_host/%superbody%people/geometry_msgs::msg::dds_::PoseArray_/{ros2.TYPE_HASH}/:2:,10:,:,:,,"


# (bad config, what the error names)
BAD = [
    (dict(topic="superbody/people"), "absolute"),  # relative
    (dict(topic="/superbody-people"), "ROS 2 topic"),  # '-' is not allowed in ROS names
    (dict(topic="/1st"), "ROS 2 topic"),  # a token starting with a digit
    (dict(topic="/a//b"), "ROS 2 topic"),  # empty token
    (dict(domain_id=233), "[0, 232]"),
    (dict(node="my node"), "node name"),
]


@pytest.mark.parametrize("kwargs, text", BAD)
def test_bad_config_is_rejected(kwargs, text):
    with pytest.raises(ValueError, match=text.replace("[", r"\[").replace("]", r"\]")):
        ros2.Ros2Config(**kwargs)


def test_host_run_ros2_publishes_cdr_with_the_attachment(processes):
    """The host as a process with --ros2 and simulated cameras; a plain Zenoh subscriber on
    rmw_zenoh's key (what an rmw_zenoh subscription declares) gets CDR PoseArrays."""
    port = free_port()
    site = "wtf-apartment"
    conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    got, cv = [], threading.Condition()

    def on_sample(sample):
        with cv:
            got.append((sample.payload.to_bytes(), sample.attachment.to_bytes() if sample.attachment is not None else None))
            cv.notify_all()

    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(ros2.topic_key("/people_test", 5), on_sample)
        ep = f"tcp/127.0.0.1:{port}"
        processes.start("host", "run", "--site", str(WTF_SITE), "--estimator", "analytic", "--connect", ep,
                        "--ros2", "--ros2-topic", "/people_test", "--ros2-domain", "5")
        for cam in ("1", "2", "3"):
            processes.start("edge", "run", "--site", str(WTF_SITE), "--camera", cam, "--seed", "3", "--people", "2", "--connect", ep)
        with cv:
            assert cv.wait_for(lambda: any(len(_store().deserialize_cdr(p, ros2.TYPE_NAME).poses) >= 1 for p, _ in got), timeout=60)
        tokens = [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/5/**", timeout=5) if r.ok is not None]
        sub.undeclare()
    assert any(t.endswith("/NN/%/%/superbody_host") for t in tokens), tokens
    assert any("/MP/%/%/superbody_host/%people_test/" in t for t in tokens), tokens
    seqs = []
    for payload, att in got:
        msg = _store().deserialize_cdr(payload, ros2.TYPE_NAME)
        assert msg.header.frame_id == site
        name, seq, _, stamp, _, gid = zenoh.ext.z_deserialize(tuple[str, zenoh.ext.Int64, str, zenoh.ext.Int64, str, bytes], zenoh.ZBytes(att))
        assert name == "sequence_number" and len(gid) == 16 and abs(stamp - time.time_ns()) < 120e9
        seqs.append(seq)
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # counts up by one per PoseArray
