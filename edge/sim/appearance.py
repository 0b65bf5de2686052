"""Simulated clothing and lighting, and the hue-saturation histogram a camera computes from them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.colour import hs_histogram

__all__ = ["Appearance", "Lighting"]


@dataclass(frozen=True)
class Appearance:
    """A person's body, clothing and what they carry. Colours are OpenCV HSV (hue 0-179,
    sat/val 0-255). ``carry`` (left, right): that forearm is held up in front of the chest
    (a phone, a cup, a tracker) instead of swinging, as the right arm in the real recordings."""

    height_m: float
    width_scale: float
    shirt_hsv: tuple[int, int, int]
    trousers_hsv: tuple[int, int, int]
    skin_hsv: tuple[int, int, int]
    carry: tuple[bool, bool] = (False, False)


@dataclass(frozen=True)
class Lighting:
    """One camera's view of colour: brightness gain, hue shift, saturation gain, background."""

    gain: float = 1.0
    hue_shift: float = 0.0
    sat_gain: float = 1.0
    background_hsv: tuple[int, int, int] = (20, 30, 160)


def _random_appearance(rng: np.random.Generator, height_m: float) -> Appearance:
    return Appearance(
        height_m=height_m,
        width_scale=float(np.clip(rng.normal(1.0, 0.08), 0.8, 1.25)),
        shirt_hsv=(int(rng.integers(0, 180)), int(rng.integers(90, 240)), int(rng.integers(90, 230))),
        trousers_hsv=(int(rng.integers(0, 180)), int(rng.integers(20, 200)), int(rng.integers(40, 180))),
        skin_hsv=(int(rng.integers(5, 20)), int(rng.integers(60, 150)), int(rng.integers(90, 220))),
        carry=(bool(rng.uniform() < 0.15), bool(rng.uniform() < 0.3)),
    )


def _distinct_hues(rng: np.random.Generator, n: int) -> list[int]:
    """Shirt hues spread around the colour wheel so that simulated people are told apart."""
    start = int(rng.integers(0, 180))
    return [(start + (180 * k) // max(n, 1)) % 180 for k in range(n)]


def _recolour(a: Appearance, hue: int, rng: np.random.Generator) -> Appearance:
    trousers_hue = (hue + int(rng.integers(30, 150))) % 180
    return Appearance(
        a.height_m, a.width_scale, (hue, int(rng.integers(140, 240)), a.shirt_hsv[2]),
        (trousers_hue, a.trousers_hsv[1], a.trousers_hsv[2]), a.skin_hsv, a.carry,
    )


def _person_histogram(a: Appearance, kp: NDArray, light: Lighting, rng: np.random.Generator) -> NDArray[np.float32]:
    """HS histogram of a synthetic 32-pixel-wide patch: head, shirt and trousers where their
    joints are visible, plus background at the sides, under the camera's lighting, through the
    real colour code."""
    vis = ~np.isnan(kp[:, 0])
    rows: list[tuple[tuple[int, int, int], int]] = []
    if vis[:5].any():
        rows.append((a.skin_hsv, 8))
    if vis[5:11].any():
        rows.append((a.shirt_hsv, 28))
    if vis[11:].any():
        rows.append((a.trousers_hsv, 28))
    h = sum(n for _, n in rows)
    patch = np.empty((h, 32, 3), dtype=np.float32)
    r = 0
    for colour, n in rows:
        patch[r : r + n] = colour
        r += n
    # Background shows at the sides of the box.
    patch[:, :3] = light.background_hsv
    patch[:, 29:] = light.background_hsv
    hsv = patch + rng.normal(size=patch.shape) * [3.0, 22.0, 20.0]  # texture, folds, shading
    hsv[..., 0] = np.mod(hsv[..., 0] + light.hue_shift, 180)
    hsv[..., 1] = np.clip(hsv[..., 1] * light.sat_gain, 0, 255)
    hsv[..., 2] = np.clip(hsv[..., 2] * light.gain, 0, 255)
    bgr = cast("NDArray[np.uint8]", cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2BGR))  # cv2 stubs: any MatLike
    return hs_histogram(bgr)
