"""Where the host's PoseArrays go: one interface, ``Sink``, for every output.

The host loop (host/service.py) hands each PoseArray to its sinks in order and knows nothing
else about them. Sinks, chosen on the ``host run`` command line:

- ``ZenohSink`` (always, first): ``superbody/<site>/people`` on the host's session; a PoseArray
  it cannot encode raises ``ValueError`` and goes to no sink (counted as ``unpublishable``);
- ``SerialLink`` (``--serial URL``): length-prefixed frames to a robot controller
  (host/outputs/serial_link.py);
- ``Ros2Sink`` (``--ros2``): ``geometry_msgs/PoseArray`` for rmw_zenoh (host/outputs/ros2.py);
- ``CallbackSink``: a function (tests, the demo).

The Foxglove live view and the MCAP recorder (host/outputs/view.py, record.py) are processes of
their own that subscribe to the host's Zenoh output, so they see every host of a site.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from superbody.host.messages.pose_types import PoseArray

__all__ = ["Sink", "CallbackSink"]


class Sink(Protocol):
    """An output of the host: ``publish`` takes each PoseArray (on the host loop's thread; it must
    not block for long), ``close`` releases what the sink holds."""

    def publish(self, poses: PoseArray) -> None: ...

    def close(self) -> None: ...


class CallbackSink:
    """A sink that calls ``fn(poses)``; closing it does nothing."""

    def __init__(self, fn: Callable[[PoseArray], None]) -> None:
        self._fn = fn

    def publish(self, poses: PoseArray) -> None:
        self._fn(poses)

    def close(self) -> None:
        pass
