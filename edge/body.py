"""The COCO-17 body model: joint names, kinematic parents and left/right mirror pairs.

Defined once here; every other module refers to joints by these indices or names.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "KEYPOINTS",
    "NUM_KEYPOINTS",
    "INDEX",
    "PARENT",
    "BONES",
    "MIRROR",
    "MIRROR_PAIRS",
    "NOSE",
    "LEFT_SHOULDER",
    "RIGHT_SHOULDER",
    "LEFT_HIP",
    "RIGHT_HIP",
    "TORSO",
    "TYPICAL_HEIGHT_M",
    "WIDTH_RANGE_M",
]

KEYPOINTS: Final[tuple[str, ...]] = (
    "nose",            # 0
    "left_eye",        # 1
    "right_eye",       # 2
    "left_ear",        # 3
    "right_ear",       # 4
    "left_shoulder",   # 5
    "right_shoulder",  # 6
    "left_elbow",      # 7
    "right_elbow",     # 8
    "left_wrist",      # 9
    "right_wrist",     # 10
    "left_hip",        # 11
    "right_hip",       # 12
    "left_knee",       # 13
    "right_knee",      # 14
    "left_ankle",      # 15
    "right_ankle",     # 16
)
NUM_KEYPOINTS: Final[int] = len(KEYPOINTS)
INDEX: Final[dict[str, int]] = {name: i for i, name in enumerate(KEYPOINTS)}

NOSE, LEFT_SHOULDER, RIGHT_SHOULDER, LEFT_HIP, RIGHT_HIP = 0, 5, 6, 11, 12
TORSO: Final[tuple[int, ...]] = (LEFT_SHOULDER, RIGHT_SHOULDER, LEFT_HIP, RIGHT_HIP)

# Kinematic parent of each joint (-1 for the root). The tree is rooted at the nose; shoulders
# hang from the nose (through the neck, which COCO lacks), hips from the shoulders.
PARENT: Final[tuple[int, ...]] = (
    -1,  # 0 nose
    0,   # 1 left_eye <- nose
    0,   # 2 right_eye <- nose
    1,   # 3 left_ear <- left_eye
    2,   # 4 right_ear <- right_eye
    0,   # 5 left_shoulder <- nose
    0,   # 6 right_shoulder <- nose
    5,   # 7 left_elbow <- left_shoulder
    6,   # 8 right_elbow <- right_shoulder
    7,   # 9 left_wrist <- left_elbow
    8,   # 10 right_wrist <- right_elbow
    5,   # 11 left_hip <- left_shoulder
    6,   # 12 right_hip <- right_shoulder
    11,  # 13 left_knee <- left_hip
    12,  # 14 right_knee <- right_hip
    13,  # 15 left_ankle <- left_knee
    14,  # 16 right_ankle <- right_knee
)
BONES: Final[tuple[tuple[int, int], ...]] = tuple(
    (parent, child) for child, parent in enumerate(PARENT) if parent >= 0
)

# Left/right counterpart of each joint (itself for the nose).
MIRROR: Final[tuple[int, ...]] = (0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15)
MIRROR_PAIRS: Final[tuple[tuple[int, int], ...]] = tuple(
    (i, j) for i, j in enumerate(MIRROR) if i < j
)

# Height above the floor of each joint as a pose detector places it, for a standing adult of
# about 1.75 m with the arms down, in metres: the medians of the depth-measured joints in the
# WheresTheFellow recordings (OpenPifPaf keypoints; docs/dataset.md), arms from the unraised
# side. Used to place single-view joints in 3D and by the simulator's skeleton.
TYPICAL_HEIGHT_M: Final[tuple[float, ...]] = (
    1.59,  # 0 nose
    1.62,  # 1 left_eye
    1.62,  # 2 right_eye
    1.62,  # 3 left_ear
    1.62,  # 4 right_ear
    1.43,  # 5 left_shoulder
    1.43,  # 6 right_shoulder
    1.12,  # 7 left_elbow
    1.12,  # 8 right_elbow
    0.89,  # 9 left_wrist
    0.89,  # 10 right_wrist
    0.91,  # 11 left_hip
    0.91,  # 12 right_hip
    0.50,  # 13 left_knee
    0.50,  # 14 right_knee
    0.12,  # 15 left_ankle
    0.12,  # 16 right_ankle
)

# Width of the shoulder and hip lines as a pose detector places their joints, metres: the least
# and the most for adults. In the WheresTheFellow recordings (OpenPifPaf keypoints) the medians of
# their extent across the camera's line of sight, over the views within 37 deg of facing the camera
# or away from it, are 0.34 and 0.22 (each third of the recording and each camera within 0.02);
# the simulator's body has 0.38 and 0.20, scaled with height (1.5-2.0 m: 0.33-0.43 and 0.17-0.23)
# and build. Used to turn a line one camera saw (``host.estimation.analytic``).
WIDTH_RANGE_M: Final[dict[tuple[int, int], tuple[float, float]]] = {
    (LEFT_SHOULDER, RIGHT_SHOULDER): (0.28, 0.46),
    (LEFT_HIP, RIGHT_HIP): (0.16, 0.30),
}
