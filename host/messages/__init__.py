"""The host's messages: the PoseArray (pose_types.py in memory, pose_rules.py its rule table,
pose.py its codec, pose_check.py its validator), the host status (status.py), and the JSON
Schemas generated from the typed messages (schemas.py)."""

from superbody.host.messages.pose_types import PersonPose, PoseArray
from superbody.host.messages.status import HostStatus

__all__ = ["PersonPose", "PoseArray", "HostStatus"]
