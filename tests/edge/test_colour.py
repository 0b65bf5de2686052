"""Colour signature: HS histograms and the Bhattacharyya distance."""

import cv2
import numpy as np
import pytest

from superbody.edge.colour import HIST_BINS, bhattacharyya, bhattacharyya_matrix, hs_histogram


def _patch(h: int, s: int, v: int, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    hsv = np.full((40, 20, 3), (h, s, v), dtype=np.float64) + rng.normal(size=(40, 20, 3)) * noise
    hsv = np.clip(hsv, 0, [179, 255, 255]).astype(np.uint8)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def test_histogram_shape_and_normalisation():
    hist = hs_histogram(_patch(100, 200, 150, noise=10))
    assert hist.shape == HIST_BINS and hist.dtype == np.float32
    assert hist.sum() == pytest.approx(1.0, abs=1e-5)


def test_mask_and_empty_region():
    img = _patch(100, 200, 150)
    assert hs_histogram(img, mask=np.zeros(img.shape[:2], np.uint8)).sum() == 0
    assert hs_histogram(img[:0]).sum() == 0
    with pytest.raises(ValueError, match="uint8"):
        hs_histogram(img.astype(np.float32))


# (colour a, colour b, expected relation of the distance)
CASES = [
    ((100, 200, 150), (100, 200, 150), "same"),  # identical colour, different noise
    ((100, 200, 150), (10, 200, 150), "far"),  # blue vs orange shirt
    ((100, 200, 150), (100, 40, 150), "far"),  # saturated vs washed out
    ((100, 200, 150), (100, 200, 90), "same"),  # same colour, darker lighting: HS ignores V
]


@pytest.mark.parametrize("a,b,relation", CASES)
def test_bhattacharyya_separates_colours(a, b, relation):
    d = bhattacharyya(hs_histogram(_patch(*a, noise=8, seed=1)), hs_histogram(_patch(*b, noise=8, seed=2)))
    assert 0.0 <= d <= 1.0
    assert d < 0.35 if relation == "same" else d > 0.65


def test_distance_properties():
    h = hs_histogram(_patch(30, 180, 200, noise=10))
    z = np.zeros(HIST_BINS, np.float32)
    assert bhattacharyya(h, h) == pytest.approx(0.0, abs=1e-6)
    assert bhattacharyya(h, z) == 1.0  # nothing to compare: as far as can be
    m = bhattacharyya_matrix(np.stack([h, z]), np.stack([h, h, z]))
    assert m.shape == (2, 3)
    # Agrees with OpenCV's definition for normalised histograms.
    g = hs_histogram(_patch(60, 120, 200, noise=20))
    assert bhattacharyya(h, g) == pytest.approx(cv2.compareHist(h, g, cv2.HISTCMP_BHATTACHARYYA), abs=1e-4)
    assert bhattacharyya_matrix(np.zeros((0, *HIST_BINS)), np.stack([h])).shape == (0, 1)
