"""Camera calibration: a camera's pose (and a webcam's intrinsics) from a ChArUco board
(board.py), the board drawn as a camera sees it for tests (render.py), and the
``superbody calibrate board | intrinsics | oak-intrinsics`` commands (cli.py). The cameras of a
WheresTheFellow recording are recovered from its data by models/dataset_calibration.py.

A calibration the installer already has becomes a site file (``superbody site import``,
edge/site_cli.py): read from OpenCV, plain JSON, COLMAP or Kalibr files (formats.py, colmap.py,
kalibr.py), moved from the source's world into the site's (frames.py), written and checked
(site_import.py)."""

from superbody.edge.calibration.board import BoardError, BoardSpec, calibrate_intrinsics, calibrate_pose

__all__ = ["BoardError", "BoardSpec", "calibrate_intrinsics", "calibrate_pose"]
