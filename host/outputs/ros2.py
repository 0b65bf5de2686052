"""The poses for ROS 2 users: ``geometry_msgs/msg/PoseArray`` published the way rmw_zenoh does.

A ROS 2 node running on ``rmw_zenoh_cpp`` (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``) receives these
without a relay and without ROS installed on the host: the payload is the message in CDR
(serialised by the pure-Python ``rosbags`` library), put on rmw_zenoh's key for the topic, with
the attachment rmw_zenoh's subscriptions read, and liveliness tokens that make the node and its
publisher appear in ``ros2 node list`` / ``ros2 topic list``. What was checked against rmw_zenoh's
source, and what could not be, is in ``docs/ros2.md``.

- Key: ``<domain>/<topic without leading slash>/geometry_msgs::msg::dds_::PoseArray_/<RIHS01 hash>``.
- Attachment (zenoh-ext serialisation): ``"sequence_number"``, int64 (from 1), ``"source_timestamp"``,
  int64 (ns at publication), ``"source_gid"``, 16 bytes (random per publisher).
- Message: ``header.stamp`` = the PoseArray's tick time, ``header.frame_id`` = the site's name
  (the site's world frame, REP-103), one ``Pose`` per person: position (x, y, 0), orientation the
  yaw about +z as a quaternion ``(0, 0, sin(yaw/2), cos(yaw/2))``. Ids, velocities and covariance
  do not fit a PoseArray: subscribe to ``superbody/<site>/people`` for them.

``superbody host run --ros2 [--ros2-topic /superbody/people] [--ros2-domain 0]``.
"""

from __future__ import annotations

import math
import os
import re
import struct
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from superbody.host.messages import pose as pose_msg

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "TYPE_NAME",
    "DDS_TYPE_NAME",
    "TYPE_HASH",
    "Ros2Config",
    "Ros2Publisher",
    "check_topic",
    "topic_key",
    "liveliness_keys",
    "attachment",
    "pose_array_cdr",
    "Ros2Sink",
]

TYPE_NAME = "geometry_msgs/msg/PoseArray"
DDS_TYPE_NAME = "geometry_msgs::msg::dds_::PoseArray_"  # rmw_zenoh: "<pkg>::msg::dds_::<Name>_"
# RIHS01 type hash of geometry_msgs/msg/PoseArray (ROS 2 Iron and later); tests recompute it with rosbags.
TYPE_HASH = "RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4c9ed328d3d5004aa0"
GID_SIZE = 16  # RMW_GID_STORAGE_SIZE (rmw/types.h, ROS 2 Iron and later)
_ADMIN_SPACE = "@ros2_lv"
# A topic name: absolute, tokens of letters, digits and '_' not starting with a digit.
_TOPIC_RE = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
_NODE_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,254}$")
_MAX_DOMAIN = 232  # the largest ROS_DOMAIN_ID ROS documents


@dataclass(frozen=True)
class Ros2Config:
    """Where the PoseArrays go.

    Attributes:
        topic: absolute ROS 2 topic name.
        domain_id: ROS_DOMAIN_ID, in [0, 232].
        node: the ROS node name the publisher appears under.
        depth: the KEEP_LAST history depth announced in the publisher's QoS.
    """

    topic: str = "/superbody/people"
    domain_id: int = 0
    node: str = "superbody_host"
    depth: int = 10

    def __post_init__(self) -> None:
        check_topic(self.topic)
        if not (isinstance(self.domain_id, int) and 0 <= self.domain_id <= _MAX_DOMAIN):
            raise ValueError(f"ROS 2 domain id must be an integer in [0, {_MAX_DOMAIN}], got {self.domain_id!r}")
        if not _NODE_RE.fullmatch(self.node):
            raise ValueError(f"ROS 2 node name must be letters, digits and '_' not starting with a digit, got {self.node!r}")
        if not 1 <= self.depth <= 10_000:
            raise ValueError(f"ROS 2 history depth must be in [1, 10000], got {self.depth!r}")


def check_topic(topic: str) -> str:
    """An absolute ROS 2 topic name (``/superbody/people``), else ValueError saying what is allowed."""
    if not (isinstance(topic, str) and _TOPIC_RE.fullmatch(topic)):
        raise ValueError(f"ROS 2 topic must be absolute, '/'-separated tokens of letters, digits and '_' "
                         f"not starting with a digit (e.g. /superbody/people), got {topic!r}")
    return topic


def topic_key(topic: str, domain_id: int = 0) -> str:
    """rmw_zenoh's Zenoh key for a PoseArray topic: ``<domain>/<topic>/<dds type>/<type hash>``."""
    return f"{domain_id}/{check_topic(topic).strip('/')}/{DDS_TYPE_NAME}/{TYPE_HASH}"


def _mangle(name: str) -> str:
    return name.replace("/", "%")  # rmw_zenoh: '/' in a key chunk becomes '%'


def _qos(depth: int) -> str:
    """The publisher's QoS as rmw_zenoh writes it into liveliness keys: fields equal to its
    defaults are left empty. Ours: reliable (default), volatile (2; the default is
    transient local), keep last (default), ``depth``, infinite deadline, lifespan and lease."""
    return f":2:,{depth}:,:,:,,"


def liveliness_keys(zid: str, config: Ros2Config, node_id: int = 0, publisher_id: int = 1) -> tuple[str, str]:
    """The node's (``NN``) and the publisher's (``MP``) liveliness token keys, in rmw_zenoh's layout
    ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP>/<enclave>/<namespace>/<node>[/<topic>/<type>/<hash>/<qos>]``
    (enclave and namespace "/" mangled to "%")."""
    base = f"{_ADMIN_SPACE}/{config.domain_id}/{zid}/{node_id}"
    node = f"{base}/{node_id}/NN/%/%/{config.node}"
    pub = f"{base}/{publisher_id}/MP/%/%/{config.node}/{_mangle(config.topic)}/{DDS_TYPE_NAME}/{TYPE_HASH}/{_qos(config.depth)}"
    return node, pub


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _z_str(s: str) -> bytes:
    b = s.encode()
    return _leb128(len(b)) + b


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's publication attachment in zenoh-ext serialisation: each string and byte buffer
    as a LEB128 length and its bytes, each int64 as 8 little-endian bytes."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"gid must be {GID_SIZE} bytes, got {len(gid)}")
    return (_z_str("sequence_number") + struct.pack("<q", sequence_number)
            + _z_str("source_timestamp") + struct.pack("<q", source_timestamp_ns)
            + _z_str("source_gid") + _leb128(GID_SIZE) + bytes(gid))


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def pose_array_cdr(arr: pose_msg.PoseArray, frame_id: str | None = None, store=None) -> bytes:
    """The poses as a ``geometry_msgs/msg/PoseArray`` in little-endian CDR with its 4-byte
    encapsulation header, as a ROS 2 subscription reads it.

    Args:
        arr: the host's PoseArray.
        frame_id: the header's frame (default: the site's name, its world frame).
        store: a rosbags typestore (default: ROS 2 Jazzy's).
    """
    ts = store or _typestore()
    T = ts.types
    Time, Header, Pose = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"], T["geometry_msgs/msg/Pose"]
    Point, Quaternion, PoseArray = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"], T[TYPE_NAME]
    poses = [Pose(position=Point(x=float(p.x), y=float(p.y), z=0.0),
                  # yaw about +z: q = (0, 0, sin(yaw/2), cos(yaw/2))
                  orientation=Quaternion(x=0.0, y=0.0, z=math.sin(p.yaw / 2), w=math.cos(p.yaw / 2)))
             for p in arr.people]
    stamp = Time(sec=arr.stamp_ns // 1_000_000_000, nanosec=arr.stamp_ns % 1_000_000_000)
    msg = PoseArray(header=Header(stamp=stamp, frame_id=frame_id if frame_id is not None else arr.site), poses=poses)
    return bytes(ts.serialize_cdr(msg, TYPE_NAME))


class Ros2Publisher:
    """Publishes PoseArrays on an open Zenoh session as rmw_zenoh would. Thread-safe.

    Args:
        session: an open Zenoh session reaching the ROS 2 graph (e.g. connected to rmw_zenohd).
        config: topic, domain, node name.
    """

    def __init__(self, session: zenoh.Session, config: Ros2Config = Ros2Config()):
        self.config = config
        self._store = _typestore()
        self._gid = os.urandom(GID_SIZE)
        self._seq = 1  # rmw_zenoh's publishers count from 1
        self._lock = threading.Lock()
        self.key = topic_key(config.topic, config.domain_id)
        node_key, pub_key = liveliness_keys(str(session.info.zid()), config)
        self._tokens = [session.liveliness().declare_token(node_key), session.liveliness().declare_token(pub_key)]
        self._pub = session.declare_publisher(self.key)

    def publish(self, arr: pose_msg.PoseArray) -> None:
        payload = pose_array_cdr(arr, store=self._store)
        with self._lock:
            att = attachment(self._seq, time.time_ns(), self._gid)
            self._seq += 1
            self._pub.put(payload, attachment=att)

    def close(self) -> None:
        self._pub.undeclare()
        for t in self._tokens:
            t.undeclare()


class Ros2Sink:
    """The host's ``--ros2`` output (a ``Sink``, host/outputs/): a ``Ros2Publisher`` on a session of
    its own; closing it closes both."""

    def __init__(self, session: zenoh.Session, publisher: Ros2Publisher) -> None:
        self.session, self.publisher = session, publisher

    def publish(self, arr: pose_msg.PoseArray) -> None:
        self.publisher.publish(arr)

    def close(self) -> None:
        self.publisher.close()
        self.session.close()


