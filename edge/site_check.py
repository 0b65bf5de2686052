"""Checks a site's cameras and floor for what a loadable file can still get wrong.

``edge.site`` refuses what cannot be (a negative focal length, a principal point outside the
image); this module looks for what is possible but wrong, the marks of a calibration read in the
wrong unit or with the wrong up axis: a camera below the floor, a camera that sees no floor, a
field of view no lens has, a floor no camera sees. Each finding names the field; errors are what
the product cannot work with, warnings what deserves a look.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from superbody.edge.camera import Camera, distort, normalised_to_rays, undistort
from superbody.edge.floor import floor_points, seen_by, views_at
from superbody.edge.site import Site

__all__ = ["Finding", "check_camera", "check_site", "pitch_deg", "fov_deg", "HEIGHT_M", "HFOV_DEG", "ASPECT"]

HEIGHT_M = (0.3, 15.0)  # plausible camera heights above the floor; at or below 0: an error
HFOV_DEG = ((2.0, 170.0), (20.0, 130.0))  # horizontal field of view: possible (else an error), usual (else a warning)
ASPECT = ((0.5, 2.0), (0.9, 1.1))  # fx / fy: possible, usual
CENTRE_OFF = 0.15  # principal point off the image centre by more than this share of the size: a warning


@dataclass(frozen=True)
class Finding:
    """One thing a check found: ``severity`` ``error`` or ``warning``, the field, and what is wrong."""

    severity: Literal["error", "warning"]
    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.severity}: {self.field}: {self.message}"


def pitch_deg(cam: Camera) -> float:
    """Degrees the optical axis points below the horizon (negative: above)."""
    return math.degrees(math.asin(float(np.clip(-cam.R[2, 2], -1.0, 1.0))))


def fov_deg(cam: Camera) -> tuple[float, float]:
    """Horizontal and vertical field of view of the pinhole (without distortion), degrees."""
    return 2 * math.degrees(math.atan(cam.width / (2 * cam.fx))), 2 * math.degrees(math.atan(cam.height / (2 * cam.fy)))


def _image_rays(cam: Camera, n: int = 9) -> np.ndarray:
    """(n * n, 3) world directions through a grid of pixels over the whole image."""
    u, v = np.meshgrid(np.linspace(0, cam.width - 1, n), np.linspace(0, cam.height - 1, n))
    xn = undistort(np.column_stack([u.ravel(), v.ravel()]), cam)
    return normalised_to_rays(xn, cam.R)


def _folds(cam: Camera) -> bool:
    """Whether the distortion turns back inside the image (radius not growing with the angle):
    a fisheye lens fitted with OpenCV's polynomial, valid only near the centre."""
    if not np.any(cam.D):
        return False
    corner = max(np.hypot(x, y) for x in ((0 - cam.cx) / cam.fx, (cam.width - cam.cx) / cam.fx)
                 for y in ((0 - cam.cy) / cam.fy, (cam.height - cam.cy) / cam.fy))
    r = np.linspace(0.0, corner * 1.05, 200)
    for a in np.linspace(0.0, math.pi / 2, 5):
        xn = np.column_stack([r * math.cos(a), r * math.sin(a)])
        rd = np.hypot(*distort(xn, cam.D).T)
        if np.any(np.diff(rd) <= 0):
            return True
    return False


def check_camera(cam: Camera, index: int) -> list[Finding]:
    """A camera's pose and intrinsics: above the floor, the floor in view, a plausible lens."""
    where = f"cameras[{index}] ({cam.id})"
    out: list[Finding] = []
    z = float(cam.t[2])
    if z <= 0.0:
        out.append(Finding("error", f"{where}.position", f"z = {z:.3f} m is not above the floor; a camera must be above it (z > 0)"))
    elif not HEIGHT_M[0] <= z <= HEIGHT_M[1]:
        out.append(Finding("warning", f"{where}.position", f"z = {z:.2f} m above the floor; usual: {HEIGHT_M[0]:g}-{HEIGHT_M[1]:g} m "
                                                          "(the unit or the floor's place?)"))
    if z > 0.0:
        d = _image_rays(cam)
        if not np.any(d[:, 2] < -1e-3):
            out.append(Finding("error", f"{where}.rotation",
                               f"no pixel sees the floor in front of the camera: its optical axis points {-pitch_deg(cam):.0f} deg above "
                               "the horizon; a camera must look down at the floor (the up axis or its sign?)"))
    hfov, _ = fov_deg(cam)
    (lo, hi), (ulo, uhi) = HFOV_DEG
    if not lo <= hfov <= hi:
        out.append(Finding("error", f"{where}.fx", f"fx = {cam.fx:g} px gives a {hfov:.1f} deg horizontal field of view over {cam.width} px; "
                                                   f"possible: {lo:g}-{hi:g} deg (intrinsics for another image size?)"))
    elif not ulo <= hfov <= uhi:
        out.append(Finding("warning", f"{where}.fx", f"a {hfov:.0f} deg horizontal field of view; usual: {ulo:g}-{uhi:g} deg"))
    aspect = cam.fx / cam.fy
    (alo, ahi), (aulo, auhi) = ASPECT
    if not alo <= aspect <= ahi:
        out.append(Finding("error", f"{where}.fy", f"fx / fy = {aspect:.3f}; possible: {alo:g}-{ahi:g}"))
    elif not aulo <= aspect <= auhi:
        out.append(Finding("warning", f"{where}.fy", f"fx / fy = {aspect:.3f}; usual (square pixels): {aulo:g}-{auhi:g}"))
    off = max(abs(cam.cx - cam.width / 2) / cam.width, abs(cam.cy - cam.height / 2) / cam.height)
    if off > CENTRE_OFF:
        out.append(Finding("warning", f"{where}.cx", f"principal point ({cam.cx:.1f}, {cam.cy:.1f}) is {100 * off:.0f}% of the image off "
                                                     f"its centre ({cam.width} x {cam.height}): is the image size the calibration's?"))
    if _folds(cam):
        out.append(Finding("warning", f"{where}.dist", "the distortion turns back inside the image (a fisheye lens?): "
                                                       "the model is not valid near the image's corners"))
    return out


def check_site(site: Site, cell_m: float = 0.25) -> list[Finding]:
    """Every camera (``check_camera``) and the floor: each camera sees some of it, every part of
    it is seen by some camera."""
    out = [f for i, cam in enumerate(site.cameras) for f in check_camera(cam, i)]
    if any(f.severity == "error" for f in out):
        return out  # the floor's findings would only repeat them
    xy = floor_points(site.floor, cell_m)
    if len(xy) == 0:
        return out
    for i, cam in enumerate(site.cameras):
        if not seen_by(cam, xy).any():
            out.append(Finding("warning", f"cameras[{i}] ({cam.id})", "sees none of the floor polygon"))
    blind = float(np.mean(views_at(site.cameras, xy) == 0))
    if blind > 0.1:
        out.append(Finding("warning", "floor.polygon", f"{100 * blind:.0f}% of the floor is seen by no camera"))
    return out
