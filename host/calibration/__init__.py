"""Calibration kept true from the people walking by: each camera's joints against the others'
(residuals.py: leave-one-out triangulation), the health monitor over a sliding window
(health.py), bundle adjustment of cameras over people's joints (bundle.py), a recording's
people's views through the host's tracker (collect.py), and ``superbody calibrate people`` (cli.py)."""

from superbody.host.calibration.bundle import CameraChange, Refinement, pose_change, refine_cameras
from superbody.host.calibration.residuals import Instant, instant_from_views, instant_residuals

__all__ = ["Instant", "instant_from_views", "instant_residuals", "refine_cameras", "Refinement", "CameraChange", "pose_change"]
