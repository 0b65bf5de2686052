"""The host's own output: each PoseArray encoded (host/messages/pose.py) and put on
``superbody/<site>/people``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from superbody.edge import transport
from superbody.host.messages import pose as pose_msg

if TYPE_CHECKING:
    import zenoh

__all__ = ["ZenohSink"]


class ZenohSink:
    """Publishes PoseArrays on ``superbody/<site>/people`` of an open session.

    ``publish`` raises ``ValueError`` (from ``pose_msg.encode``) for a PoseArray no subscriber
    would accept, before anything is sent.
    """

    def __init__(self, session: zenoh.Session, site: str) -> None:
        self.key = transport.people_key(site)
        self._pub = session.declare_publisher(self.key, encoding=pose_msg.zenoh_encoding())

    def publish(self, poses: pose_msg.PoseArray) -> None:
        self._pub.put(pose_msg.encode(poses))

    def close(self) -> None:
        self._pub.undeclare()
