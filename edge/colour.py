"""The colour signature: a hue-saturation histogram of a person's region, and the
Bhattacharyya distance between two of them (as in the paper's tracker).

Images are OpenCV BGR uint8. Histograms are float32 arrays of shape ``HIST_BINS`` that sum to 1
(all zeros when the region had no usable pixel).
"""

from __future__ import annotations

from typing import Final

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["HIST_BINS", "hs_histogram", "bhattacharyya", "bhattacharyya_matrix"]

# 16 hue x 8 saturation bins: coarse enough to survive lighting changes between cameras,
# fine enough to tell clothing colours apart, and 128 numbers on the wire.
HIST_BINS: Final[tuple[int, int]] = (16, 8)
# OpenCV's 8-bit HSV: hue in [0, 180), saturation in [0, 256).
_RANGES: Final[list[float]] = [0.0, 180.0, 0.0, 256.0]


def hs_histogram(bgr: NDArray[np.uint8], mask: NDArray[np.uint8] | None = None, bins: tuple[int, int] = HIST_BINS) -> NDArray[np.float32]:
    """Normalised hue-saturation histogram of an image region.

    Args:
        bgr: region of interest, shape (H, W, 3), uint8 BGR.
        mask: optional (H, W) uint8; only pixels where it is non-zero count.
        bins: (hue bins, saturation bins).

    Returns:
        Histogram, shape ``bins``, float32, summing to 1 (zeros if no pixel counted).
    """
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
        raise ValueError(f"hs_histogram: bgr must be (H, W, 3) uint8, got {bgr.shape} {bgr.dtype}")
    if bgr.shape[0] == 0 or bgr.shape[1] == 0:
        return np.zeros(bins, dtype=np.float32)
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    hist = cv2.calcHist([hsv], [0, 1], mask, list(bins), _RANGES)  # (Hb, Sb) float32 counts
    total = float(hist.sum())
    return (hist / total).astype(np.float32) if total > 0 else np.zeros(bins, dtype=np.float32)


def bhattacharyya(h1: NDArray, h2: NDArray) -> float:
    """Bhattacharyya distance between two normalised histograms, in [0, 1] (0 = identical).

    d = sqrt(1 - sum_i sqrt(h1_i * h2_i)); an empty histogram is at distance 1 from anything.
    """
    return float(bhattacharyya_matrix(np.asarray(h1)[None], np.asarray(h2)[None])[0, 0])


def bhattacharyya_matrix(a: NDArray, b: NDArray) -> NDArray[np.float64]:
    """Pairwise Bhattacharyya distances.

    Args:
        a: histograms, shape (N, ...).
        b: histograms, shape (M, ...).

    Returns:
        Distances, shape (N, M), in [0, 1].
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    sa = np.sqrt(np.maximum(a.reshape(len(a), int(np.prod(a.shape[1:]))), 0.0))  # (N, B)
    sb = np.sqrt(np.maximum(b.reshape(len(b), int(np.prod(b.shape[1:]))), 0.0))  # (M, B)
    # Normalise so that histograms not summing to exactly 1 still compare on shape.
    na = np.linalg.norm(sa, axis=1, keepdims=True)
    nb = np.linalg.norm(sb, axis=1, keepdims=True)
    bc = (sa / np.where(na > 0, na, 1)) @ (sb / np.where(nb > 0, nb, 1)).T  # Bhattacharyya coefficient
    bc[(na[:, 0] == 0)[:, None] | (nb[:, 0] == 0)[None, :]] = 0.0
    return np.sqrt(np.clip(1.0 - bc, 0.0, 1.0))
