"""A calibration's world in the site's: which way is up, the unit, where the floor is.

Calibration tools each have their own world: OpenCV's is whatever the board or the first camera
made it (a board on a wall gives y down, centimetres or millimetres), COLMAP's is arbitrary up to
scale, Kalibr's is camera 0. A site's world is REP-103: metres, z up, the floor at z = 0
(``edge.camera``). ``WorldFrame`` names how one maps onto the other:

- ``up``: the source axis that points up, against gravity (``"-y"`` for OpenCV's y-down worlds);
- ``x_axis``: the source axis that becomes the site's +x (default: the first of +x, +y, +z
  across ``up``); the site's y then completes a right-handed frame, unless ``y_axis`` names it
  too (a left-handed source world: its rotations have determinant -1);
- ``unit_m``: metres per source unit (``UNITS``: m, cm, mm);
- ``floor``: the floor's coordinate on the up axis, in source units, as the source writes it
  (``up="-y", floor=150``: the floor is the plane y = 150).

A site point is then ``p = unit_m * M p_src + (0, 0, -unit_m * sign(up) * floor)``, with ``M``
(``rotation``) the site's axes written in the source's. Extrinsics convert from OpenCV's
``x_cam = R p_src + t`` to the camera's pose in the site (``camera_pose``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "AXES", "UNITS", "ImportFailure", "WorldFrame", "parse_axis", "parse_unit", "opengl_to_opencv", "pose_to_extrinsics",
]

AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


class ImportFailure(ValueError):
    """A calibration that cannot become a site: the message names the file, the line or key where
    it can, the field and what is allowed."""


def parse_axis(text: str, flag: str) -> NDArray[np.float64]:
    """A signed axis name (``+x``, ``-y``, ``z``...) as a unit vector (3,).

    Raises:
        ImportFailure: not one of ``AXES``, naming ``flag``.
    """
    t = text.strip().lower()
    t = t if t[:1] in "+-" else "+" + t
    if t not in AXES:
        raise ImportFailure(f"{flag} must be one of {', '.join(AXES)}, got {text!r}")
    v = np.zeros(3)
    v["xyz".index(t[1])] = 1.0 if t[0] == "+" else -1.0
    return v


def parse_unit(text: str, flag: str = "--unit") -> float:
    """Metres per source unit from ``m``, ``cm``, ``mm`` or a positive number (metres per unit)."""
    t = text.strip().lower()
    if t in UNITS:
        return UNITS[t]
    try:
        v = float(t)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and 1e-6 <= v <= 1e3):
        raise ImportFailure(f"{flag} must be one of {', '.join(UNITS)} or metres per unit in [1e-06, 1000], got {text!r}")
    return v


def _name(v: NDArray) -> str:
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "-") + "xyz"[i]


@dataclass(frozen=True)
class WorldFrame:
    """How a source world maps onto the site's (see the module docstring)."""

    up: str = "+z"
    x_axis: str | None = None
    y_axis: str | None = None
    unit_m: float = 1.0
    floor: float = 0.0

    @property
    def rotation(self) -> NDArray[np.float64]:
        """(3, 3) ``M``: row i is the site's axis i written in source coordinates.

        Raises:
            ImportFailure: an unknown axis name, or axes that are not perpendicular.
        """
        z = parse_axis(self.up, "--up")
        if self.x_axis is None:
            x = next(a for a in (np.eye(3)[k] for k in range(3)) if abs(a @ z) < 0.5)
        else:
            x = parse_axis(self.x_axis, "--x-axis")
            if abs(x @ z) > 0.5:
                raise ImportFailure(f"--x-axis must be across --up ({self.up}), got {self.x_axis}; allowed: "
                                    f"{', '.join(a for a in AXES if a[1] != _name(z)[1])}")
        if self.y_axis is None:
            y = np.cross(z, x)
        else:
            y = parse_axis(self.y_axis, "--y-axis")
            if abs(y @ z) > 0.5 or abs(y @ x) > 0.5:
                raise ImportFailure(f"--y-axis must be across --up ({self.up}) and --x-axis ({_name(x)}), got {self.y_axis}")
        return np.stack([x, y, z])

    @property
    def handedness(self) -> int:
        """+1 for a right-handed source world, -1 for a left-handed one."""
        return 1 if np.linalg.det(self.rotation) > 0 else -1

    @property
    def z_offset_m(self) -> float:
        """Metres added to a point's height: the floor goes to z = 0."""
        return -self.unit_m * float(parse_axis(self.up, "--up").sum()) * self.floor

    def describe(self) -> str:
        """One line: the mapping, e.g. ``site x = +x, y = +z, z = -y (up); 0.01 m per unit; floor at y = 150``."""
        M = self.rotation
        names = [_name(r) for r in M]
        hand = "" if self.handedness > 0 else " (a left-handed source world)"
        return (f"site x = source {names[0]}, y = {names[1]}, z = {names[2]} (up){hand}; {self.unit_m:g} m per source unit; "
                f"floor at source {names[2][1]} = {self.floor:g}")

    def points(self, p_src: NDArray) -> NDArray[np.float64]:
        """Source points (N, 3) in source units to site points (N, 3) in metres."""
        p = np.asarray(p_src, dtype=np.float64).reshape(-1, 3)
        return self.unit_m * p @ self.rotation.T + np.array([0.0, 0.0, self.z_offset_m])

    def camera_pose(self, R: NDArray, t: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """A camera's pose in the site from OpenCV extrinsics in the source world.

        Args:
            R: (3, 3) source-world-to-camera rotation: ``x_cam = R p_src + t``.
            t: (3,) translation, source units.

        Returns:
            ``(rotation, position)``: world-from-camera (3, 3) and the optical centre (3,), metres.

        Raises:
            ImportFailure: the rotation and the axes disagree on the source world's handedness.
        """
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(3)
        M = self.rotation
        # A camera ray d_cam is R^T d_cam in the source world and M R^T d_cam in the site's.
        rotation = M @ R.T
        if np.linalg.det(rotation) < 0:
            hand = "right" if self.handedness > 0 else "left"
            raise ImportFailure(f"the rotation has determinant {np.linalg.det(R):+.0f} but the axes make the source world {hand}-handed: "
                                "a left-handed world needs --y-axis as well as --up and --x-axis, a right-handed one neither")
        centre = -R.T @ t  # the optical centre in the source world: R c + t = 0
        return rotation, self.points(centre)[0]


def opengl_to_opencv(R: NDArray, t: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World-to-camera extrinsics of an OpenGL/Blender camera (x right, y up, z backward) for the
    same camera in OpenCV's axes (x right, y down, z forward)."""
    F = np.diag([1.0, -1.0, -1.0])
    return F @ np.asarray(R, dtype=np.float64), F @ np.asarray(t, dtype=np.float64).reshape(3)


def pose_to_extrinsics(rotation: NDArray, position: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A camera's pose (world-from-camera rotation, optical centre) as world-to-camera ``(R, t)``."""
    Rw = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
    return Rw.T, -Rw.T @ np.asarray(position, dtype=np.float64).reshape(3)
