"""Where a person stands on the floor, from one camera's 2D view.

A joint of known height above the floor (edge.body.TYPICAL_HEIGHT_M) and a calibrated camera
give a point: the pixel's ray meets the horizontal plane at that height. Each body part gives
one candidate (a level):

    ankles (mean of the visible ones; one ankle is anywhere in a walker's step) at 0.12 m,
    hips at 0.91 m, shoulders at 1.43 m,
    the torso: the range at which the shoulders sit 0.52 m above the hips,
    and, only where none of those gives a point, the knees (as the ankles) at 0.50 m

and the candidate with the smallest uncertainty is used. From a wall-mounted camera that is
the lowest visible joint: the lower the joint, the further it is (vertically) from the camera
and the less an error in its assumed height moves the point. From a camera mounted at about
hip height (1 m) the hips' rays graze their plane and a 5 cm error in a person's hip height
moves the point by metres; there the ankles, the torso's length or the shoulders decide.

The knees are the last resort: in the WheresTheFellow recording (OpenPifPaf keypoints) the points
of the knees that the ankles' error model would have chosen over the hips came out 1.48 times
their sigma off (rms; the ankles' 1.17, the hips' 1.30), and so chosen they cost dev.json's live
position (y 69.8 -> 72.4 mm). They place views that show nothing else (two wrists and a knee).

A level whose ray misses its plane in front of the camera, or meets it farther than
``max_range_m`` away, gives no candidate. A view without ankles, knees, hips or shoulders has no
ground point: the detector's box is not used (its bottom edge is a table's or a sofa's as often
as the feet, and a box around a head alone puts the "feet" metres away).

The uncertainty is a 1-sigma distance in metres, mostly along the viewing direction. For a
joint's plane:

    sigma^2 = body^2 + (r * dz / dh)^2 + (dtheta * (r^2 + dh^2) / dh)^2

with r the horizontal range, dh the camera's height above the plane, dz the spread of the
joint's real height (people differ, knees bend), dtheta the pixel noise as an angle, and body
how far that part sits from the point between the feet. It grows with range and as the joint
comes nearer the camera's height. The torso's range is r = L / (tan e_s - tan e_h), with e_s
and e_h the elevations of the shoulders' and hips' rays and L the torso's vertical length; it
needs no camera height, and

    sigma^2 = body^2 + (r * dL / L)^2 + (dtheta * r^2 / L)^2 * ((1 + tan^2 e_s)^2 + (1 + tan^2 e_h)^2)

with dL the spread of L between people and postures.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import INDEX, LEFT_HIP, LEFT_SHOULDER, RIGHT_HIP, RIGHT_SHOULDER, TYPICAL_HEIGHT_M
from superbody.edge.camera import Camera, intersect_plane, pixel_to_ray
from superbody.edge.messages.observation import PersonView

__all__ = ["MAX_RANGE_M", "JOINT_PIXEL_STD", "LEVELS", "Level", "ground_point", "ground_points", "torso_range"]

MAX_RANGE_M: Final[float] = 30.0


class Level(NamedTuple):
    """One body part the ground point can come from, with its error model (and the detector's
    pixel noise, ``JOINT_PIXEL_STD``, the same for every joint)."""

    name: str
    joints: tuple[int, ...]  # COCO-17 indices averaged in the image
    height_m: float  # height of that part above the floor (the torso: shoulders' height above the hips)
    height_std_m: float  # how much that height varies between people and poses
    body_std_m: float  # how far that part sits, horizontally, from the point between the feet


_LEFT_ANKLE, _RIGHT_ANKLE = INDEX["left_ankle"], INDEX["right_ankle"]
_LEFT_KNEE, _RIGHT_KNEE = INDEX["left_knee"], INDEX["right_knee"]
# The pose detector's noise on a joint's pixel, 1 sigma: one number for every joint.
JOINT_PIXEL_STD: Final[float] = 4.0
_TORSO_M: Final[float] = TYPICAL_HEIGHT_M[LEFT_SHOULDER] - TYPICAL_HEIGHT_M[LEFT_HIP]

# The index into LEVELS is what ground_points reports as "level". The last is the torso's
# length; the others are planes at a height.
LEVELS: Final[tuple[Level, ...]] = (
    Level("ankles", (_LEFT_ANKLE, _RIGHT_ANKLE), TYPICAL_HEIGHT_M[_LEFT_ANKLE], 0.05, 0.10),
    # The last resort (module docstring), with the ankles' error model.
    Level("knees", (_LEFT_KNEE, _RIGHT_KNEE), TYPICAL_HEIGHT_M[_LEFT_KNEE], 0.05, 0.10),
    Level("hips", (LEFT_HIP, RIGHT_HIP), TYPICAL_HEIGHT_M[LEFT_HIP], 0.08, 0.10),
    Level("shoulders", (LEFT_SHOULDER, RIGHT_SHOULDER), TYPICAL_HEIGHT_M[LEFT_SHOULDER], 0.10, 0.12),
    # Shoulder-to-hip length: ~8% between adults (stature alone varies ~4%) and with posture.
    Level("torso", (LEFT_SHOULDER, RIGHT_SHOULDER, LEFT_HIP, RIGHT_HIP), _TORSO_M, 0.04, 0.10),
)
_PLANES: Final[int] = 4  # LEVELS[:_PLANES] meet a plane; the torso is LEVELS[_PLANES]
_KNEES, _HIPS, _SHOULDERS, _TORSO = 1, 2, 3, 4
_LEGS = (0, _KNEES)  # the ankles and the knees
# A walker's ankles are up to half a step (about 0.35 m) ahead of and behind their centre: the
# ankles' mean is near the centre, one ankle anywhere in that span (a spread of +-0.35 m has a
# 1-sigma of 0.2 m). It replaces the legs' ``body_std_m`` where one ankle (or one knee) is seen.
_ONE_ANKLE_STD_M: Final[float] = 0.20
# Below this height difference the ray grazes the plane and the point means nothing.
_MIN_DH_M: Final[float] = 0.05
# The plane levels' joints as one (levels, 2) table, and each level's error model as (L,) arrays.
_JOINTS = np.array([lv.joints for lv in LEVELS[:_PLANES]])  # (P, 2)
_HEIGHT = np.array([lv.height_m for lv in LEVELS[:_PLANES]])  # (P,)
_HEIGHT_STD = np.array([lv.height_std_m for lv in LEVELS[:_PLANES]])
_BODY_STD = np.array([lv.body_std_m for lv in LEVELS[:_PLANES]])


def ground_points(
    keypoints: NDArray[np.float32],
    cam: Camera,
    max_range_m: float = MAX_RANGE_M,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int8]]:
    """Ground points of many views from one camera, in one pass.

    Args:
        keypoints: (N, 17, 3) COCO-17 (u, v, score) per view; NaN rows for missing joints.
        cam: the camera that saw them.
        max_range_m: farthest accepted horizontal distance from the camera.

    Returns:
        ``(xy, sigma, level)``: floor points (N, 2) in metres, their 1-sigma uncertainty (N,)
        in metres, and the index into ``LEVELS`` used (N,), -1 where none worked (those rows
        of ``xy`` and ``sigma`` are NaN).
    """
    kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, 17, 3)  # (N, 17, 3)
    n, p = len(kp), _PLANES
    dh, sigma_fixed, sigma_range, sigma_pixel = _camera_terms(cam)  # (P,) each
    t = cam.t  # (3,)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Pixel of each plane level: the mean of its visible joints, NaN where there is none.
        pts = kp[:, _JOINTS, :2]  # (N, P, 2, 2)
        seen = ~np.isnan(pts[..., 0])  # (N, P, 2)
        uv = np.where(seen[..., None], pts, 0.0).sum(axis=2) / seen.sum(axis=2)[..., None]  # (N, P, 2)

        # One batch of rays; where each level's ray meets its plane z = h.
        flat = uv.reshape(-1, 2)  # (N P, 2)
        usable = ~np.isnan(flat).any(axis=1)
        d: NDArray[np.float64] = np.full((len(flat), 3), np.nan)
        if usable.any():
            d[usable] = pixel_to_ray(flat[usable], cam)[1]
        d = d.reshape(n, p, 3)  # (N, P, 3)
        hit, valid = intersect_plane(t, d.reshape(-1, 3), np.tile(_HEIGHT, n))
        points = np.empty((n, p + 1, 2))
        points[:, :p], valid = hit[:, :2].reshape(n, p, 2), valid.reshape(n, p)  # (N, P, 2), (N, P)
        r = np.hypot(points[:, :p, 0] - t[0], points[:, :p, 1] - t[1])  # (N, P) horizontal range
        valid &= (r <= max_range_m) & (dh >= _MIN_DH_M)
        # sigma^2 = body^2 + (r dz / dh)^2 + (dtheta (r^2 + dh^2) / dh)^2
        sigma = np.full((n, p + 1), np.inf)
        one_leg = (seen.sum(axis=2) == 1) & np.isin(np.arange(p), _LEGS)  # (N, P): anywhere in a step
        body2 = np.where(one_leg, _ONE_ANKLE_STD_M**2, sigma_fixed)  # (N, P)
        sigma[:, :p] = np.sqrt(body2 + (r * sigma_range) ** 2 + (sigma_pixel * (r * r + dh**2)) ** 2)
        points[:, p], sigma[:, p] = _torso(d[:, _HIPS], d[:, _SHOULDERS], cam, max_range_m)
    sigma[:, :p][~valid] = np.inf
    others = np.isfinite(np.delete(sigma, _KNEES, axis=1)).any(axis=1)  # (N,) another level placed it
    sigma[others, _KNEES] = np.inf

    level = np.argmin(sigma, axis=1)  # (N,) the most certain candidate
    rows = np.arange(n)
    best = sigma[rows, level]
    found = np.isfinite(best)
    xy = np.where(found[:, None], points[rows, level], np.nan)
    return xy, np.where(found, best, np.nan), np.where(found, level, -1).astype(np.int8)


def torso_range(hips: NDArray, shoulders: NDArray) -> NDArray[np.float64]:
    """(N,) horizontal ranges (m) at which the shoulders' rays (N, 3) pass a typical torso's
    length (``_TORSO_M``) above the hips' rays (N, 3) from the same camera: NaN without both rays,
    0 or less where they do not part upwards."""
    tan_h = hips[:, 2] / np.hypot(hips[:, 0], hips[:, 1])  # (N,) elevation tangents
    tan_s = shoulders[:, 2] / np.hypot(shoulders[:, 0], shoulders[:, 1])
    return np.asarray(_TORSO_M / (tan_s - tan_h), dtype=np.float64)


def _torso(hips: NDArray, shoulders: NDArray, cam: Camera, max_range_m: float) -> tuple[NDArray, NDArray]:
    """Floor points (N, 2) and sigmas (N,; inf where none) from the torso's length: the range
    at which the shoulders' ray passes ``_TORSO_M`` above the hips' (see the module docstring)."""
    lv = LEVELS[_TORSO]
    flat_h, flat_s = np.hypot(hips[:, 0], hips[:, 1]), np.hypot(shoulders[:, 0], shoulders[:, 1])  # (N,)
    tan_h, tan_s = hips[:, 2] / flat_h, shoulders[:, 2] / flat_s  # (N,) elevation tangents
    r = torso_range(hips, shoulders)  # (N,) NaN without both rays
    ahead = hips[:, :2] / flat_h[:, None] + shoulders[:, :2] / flat_s[:, None]  # (N, 2) the person's direction
    ahead /= np.linalg.norm(ahead, axis=1, keepdims=True)
    dtheta = JOINT_PIXEL_STD / (0.5 * (cam.fx + cam.fy))
    sigma = np.sqrt(lv.body_std_m**2 + (r * lv.height_std_m / lv.height_m) ** 2
                    + (dtheta * r * r / lv.height_m) ** 2 * ((1 + tan_s**2) ** 2 + (1 + tan_h**2) ** 2))
    ok = (r > 0) & (r <= max_range_m)  # False for NaN
    return cam.t[:2] + r[:, None] * ahead, np.where(ok, sigma, np.inf)


@lru_cache(maxsize=256)
def _camera_terms(cam: Camera) -> tuple[NDArray[np.float64], ...]:
    """Per plane level (P,): the camera's height above its plane dh, and the error model's terms
    body^2, dz / dh and dtheta / dh (see the module docstring)."""
    dh = np.abs(cam.t[2] - _HEIGHT)  # (L,)
    dtheta = JOINT_PIXEL_STD / (0.5 * (cam.fx + cam.fy))  # pixel noise as an angle
    with np.errstate(divide="ignore"):
        return dh, _BODY_STD**2, _HEIGHT_STD / dh, dtheta / dh


def ground_point(view: PersonView, cam: Camera, max_range_m: float = MAX_RANGE_M) -> tuple[NDArray[np.float64], float] | None:
    """Where the person in ``view`` stands on the floor, seen from ``cam``.

    Args:
        view: one detected person.
        cam: the camera that saw them.
        max_range_m: farthest accepted horizontal distance from the camera.

    Returns:
        ``(xy, sigma)``: the floor point (2,) in metres (REP-103) and its 1-sigma uncertainty
        in metres; ``None`` when no body part gives a point in front of the camera within range.
    """
    xy, sigma, level = ground_points(view.keypoints[None], cam, max_range_m)
    if level[0] < 0:
        return None
    return xy[0], float(sigma[0])
