"""What a real 2D detector does to a view: which joints it reports by where the person faces,
pixel noise, left/right swaps, spurious people (the detector noise model)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["FACING_VISIBILITY", "facing_factor", "NoiseModel"]


# How often a real detector reports each joint by where the person faces, relative to its
# average over all directions: measured on WheresTheFellow's dev.json (500 views; the truth's
# yaw against the direction to the camera, 8 bins of 45 degrees centred on -157.5 ... 157.5;
# each view counted twice, as itself and mirrored left-right, so the table is symmetric).
# `python scripts/sim_vs_dataset.py` prints it again. From the back the nose and eyes vanish
# but the ears stay; side-on the far eye, ear, elbow and wrist are hidden.
FACING_VISIBILITY: Final[tuple[tuple[float, ...], ...]] = (
    (0.01, 1.28, 1.55, 1.47, 1.47, 1.55, 1.28, 0.01),  # nose
    (0.04, 2.10, 2.26, 2.07, 1.90, 0.34, 0.00, 0.00),  # left_eye
    (0.00, 0.00, 0.34, 1.90, 2.07, 2.26, 2.10, 0.04),  # right_eye
    (1.47, 1.81, 1.64, 0.89, 0.73, 0.00, 0.06, 1.18),  # left_ear
    (1.18, 0.06, 0.00, 0.73, 0.89, 1.64, 1.81, 1.47),  # right_ear
    (1.10, 1.10, 0.97, 1.01, 0.92, 0.86, 1.09, 0.94),  # left_shoulder
    (0.94, 1.09, 0.86, 0.92, 1.01, 0.97, 1.10, 1.10),  # right_shoulder
    (1.35, 1.41, 1.24, 1.31, 1.18, 0.23, 0.10, 1.09),  # left_elbow
    (1.09, 0.10, 0.23, 1.18, 1.31, 1.24, 1.41, 1.35),  # right_elbow
    (0.85, 1.64, 1.57, 1.71, 1.56, 0.24, 0.02, 0.65),  # left_wrist
    (0.65, 0.02, 0.24, 1.56, 1.71, 1.57, 1.64, 0.85),  # right_wrist
    (1.01, 1.08, 0.97, 1.04, 1.02, 0.97, 1.00, 0.94),  # left_hip
    (0.94, 1.00, 0.97, 1.02, 1.04, 0.97, 1.08, 1.01),  # right_hip
    (1.02, 1.07, 0.98, 1.08, 1.05, 0.90, 0.99, 0.94),  # left_knee
    (0.94, 0.99, 0.90, 1.05, 1.08, 0.98, 1.07, 1.02),  # right_knee
    (0.98, 0.98, 1.00, 1.14, 1.10, 0.97, 0.96, 0.91),  # left_ankle
    (0.91, 0.96, 0.97, 1.10, 1.14, 1.00, 0.98, 0.98),  # right_ankle
)


def facing_factor(table: tuple[tuple[float, ...], ...] | NDArray, rel: float) -> NDArray[np.float64]:
    """(17,) factors of a facing-visibility table (17, K) at a relative facing angle.

    Args:
        table: per joint, K factors at angles -pi + (k + 0.5) 2 pi / K (``FACING_VISIBILITY``).
        rel: the person's facing relative to the direction from them to the camera, radians
            (0: facing the camera; positive: turned counter-clockwise, the camera sees the
            person's right side).

    Returns:
        (17,) factors, linearly interpolated around the circle.
    """
    t = np.asarray(table, dtype=np.float64)
    k = t.shape[1]
    u = (rel + math.pi) / (2 * math.pi / k) - 0.5
    k0 = math.floor(u)
    f = u - k0
    return (1.0 - f) * t[:, k0 % k] + f * t[:, (k0 + 1) % k]


@dataclass(frozen=True)
class NoiseModel:
    """What a real 2D pose detector does to the truth. Defaults tuned against WheresTheFellow
    (``scripts/sim_vs_dataset.py`` prints the comparison).

    Whether a joint is reported and the confidence it is reported with are drawn separately:
    in the real data often-missed joints (wrists, faces) still come with high scores.

    Attributes:
        pixel_noise_px: std of Gaussian pixel noise at 3 m; grows as the person comes closer.
        joint_rate: per-joint probability (COCO order) that a clearly visible joint is reported.
        view_quality_std: std of a detection-probability change shared by all joints of a view
            (blur, lighting, pose): views are good or bad as a whole.
        facing_visibility: per joint (COCO order), the factor on its detection probability by
            where the person faces relative to the camera, at 8 angles 45 degrees apart from
            -157.5 (the camera behind the person's right shoulder) through 0 (facing the camera)
            to 157.5, interpolated between; ``None``: the same in every direction.
        distance_drop: detection probability lost per metre beyond 3 m.
        border_px: joints within this many pixels of the image border are found less often.
        occluded_keep: probability that a joint hidden by an obstacle or a person is still
            reported (detectors hallucinate plausible joints), for a person reported at all:
            one with at least one joint found in plain view.
        score_mean, score_std: the reported confidence of a detected joint, before clipping to
            [score_threshold, 1].
        score_threshold: nothing below this confidence is reported (OpenPifPaf used 0.5).
        swap_prob: probability that a view has its left and right joints swapped. Measured
            without labels (``models.data.simstats.lr_disagreement``: pairs of views whose rays
            meet better with one view's sides swapped): dev.json 2 of 246 view pairs (0.008);
            the simulator 0.004 at 0, 0.015 at 0.005, 0.024 at 0.01 and 0.057 at 0.03 (the
            earlier guess, which made geometry's yaw fail 3-5 times as often as it does on
            dev.json). Two disagreements pin it loosely: 0.002, at most ~0.013 (95%).
        spurious_prob: probability per frame of a spurious partial person.
        view_miss_prob: probability that the detector misses a person entirely in a view.
        truncated_miss_prob: extra miss probability for a person whose joints are all out of
            the image, scaled by the fraction that is out.
        min_joints: a person is reported only with at least this many joints.
        depth_noise_m: std of the depth noise of 3D points, per metre of depth.
    """

    pixel_noise_px: float = 2.5
    joint_rate: tuple[float, ...] = (0.66, 0.5, 0.5, 0.56, 0.56, 1.0, 1.0, 0.86, 0.86, 0.66, 0.66, 1.0, 1.0, 0.99, 0.99, 0.95, 0.95)
    view_quality_std: float = 0.06
    facing_visibility: tuple[tuple[float, ...], ...] | None = FACING_VISIBILITY
    distance_drop: float = 0.05
    border_px: float = 12.0
    occluded_keep: float = 0.15
    score_mean: float = 0.805
    score_std: float = 0.105
    score_threshold: float = 0.5
    swap_prob: float = 0.005
    spurious_prob: float = 0.01
    view_miss_prob: float = 0.2
    truncated_miss_prob: float = 0.3
    min_joints: int = 1
    depth_noise_m: float = 0.01
