"""Camera calibration: a camera's pose (and a webcam's intrinsics) from a ChArUco board
(board.py), the board drawn as a camera sees it for tests (render.py), and the
``superbody calibrate board | intrinsics | oak-intrinsics`` commands (cli.py). The cameras of a
WheresTheFellow recording are recovered from its data by models/dataset_calibration.py."""

from superbody.edge.calibration.board import BoardError, BoardSpec, calibrate_intrinsics, calibrate_pose

__all__ = ["BoardError", "BoardSpec", "calibrate_intrinsics", "calibrate_pose"]
