"""Temporal filtering of each person's pose: the Kalman filter, once (kalman.py), and the pose
filter built on it (pose_filter.py)."""

from superbody.host.filtering.pose_filter import FilterConfig, FilteredPose, PoseFilter, predict_many, update_many

__all__ = ["FilterConfig", "FilteredPose", "PoseFilter", "predict_many", "update_many"]
