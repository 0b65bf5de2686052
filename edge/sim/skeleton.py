"""A person's 17 COCO joints in the world from their torso pose, gait phase and body size."""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge import body

__all__ = ["skeleton"]


# Lateral (left-positive), forward and height offsets of each joint for a 1.75 m person
# standing still, in metres. Arms and legs are recomputed with the gait.
_LATERAL: Final = np.array([0.0, 0.032, -0.032, 0.075, -0.075, 0.19, -0.19, 0.21, -0.21, 0.2, -0.2, 0.1, -0.1, 0.1, -0.1, 0.1, -0.1])


_FORWARD: Final = np.array([0.1, 0.075, 0.075, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.03, 0.03, 0.0, 0.0, 0.02, 0.02, 0.0, 0.0])


_HEIGHT: Final = np.asarray(body.TYPICAL_HEIGHT_M)


_LEFT: Final = np.array([i for i, n in enumerate(body.KEYPOINTS) if n.startswith("left_")])


_RIGHT: Final = np.array([body.MIRROR[i] for i in _LEFT])


def skeleton(x: float, y: float, yaw: float, phase: float, walk: float, height_m: float = 1.75, width_scale: float = 1.0,
             carry: tuple[bool, bool] = (False, False)) -> NDArray[np.float64]:
    """3D COCO-17 joints of a person standing or walking.

    Args:
        x, y, yaw: torso pose on the floor.
        phase: gait phase in radians (one stride per 2 pi).
        walk: 0 standing still .. 1 walking at full stride.
        height_m: body height; all lengths scale with it.
        width_scale: lateral scale (build).
        carry: (left, right) forearm held up in front of the chest.

    Returns:
        Joints, shape (17, 3), world frame.
    """
    s = height_m / 1.75
    f = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # facing
    left = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    base = np.array([x, y, 0.0])
    lateral = _LATERAL * s * width_scale
    forward = _FORWARD * s
    j = base + lateral[:, None] * left + forward[:, None] * f + (_HEIGHT * s)[:, None] * z  # (17, 3)
    leg_amp, arm_amp = 0.38 * walk, 0.32 * walk
    leg = (_HEIGHT[11] - _HEIGHT[15]) * s  # hip to ankle
    thigh, shin, upper, fore = 0.52 * leg, 0.48 * leg, 0.31 * s, 0.27 * s
    for side, held, (hip, knee, ankle, sh, elb, wri) in ((0.0, carry[0], (11, 13, 15, 5, 7, 9)), (math.pi, carry[1], (12, 14, 16, 6, 8, 10))):
        theta = leg_amp * math.sin(phase + side)  # leg swing, forward positive
        bend = walk * 0.5 * max(0.0, math.cos(phase + side))  # knee flexes in the swing phase
        j[knee] = j[hip] + thigh * (math.sin(theta) * f - math.cos(theta) * z)
        j[ankle] = j[knee] + shin * (math.sin(theta - bend) * f - math.cos(theta - bend) * z)
        alpha = -arm_amp * math.sin(phase + side)  # arms swing against the legs
        beta = 0.15 + 0.35 * walk * max(0.0, math.sin(-(phase + side)))  # elbow flex
        if held:  # upper arm a little forward, forearm raised: the wrist at chest height
            alpha, beta = 0.35 + 0.05 * math.sin(phase), 1.8
        j[elb] = j[sh] + upper * (math.sin(alpha) * f - math.cos(alpha) * z) + 0.02 * s * left * (1 if side == 0 else -1)
        j[wri] = j[elb] + fore * (math.sin(alpha + beta) * f - math.cos(alpha + beta) * z)
    # The stance foot carries the body: keep the lowest ankle at its standing height.
    j[:, 2] += _HEIGHT[15] * s - min(j[15, 2], j[16, 2])
    return j
