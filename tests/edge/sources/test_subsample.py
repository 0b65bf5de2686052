"""Frames thinned to a lower rate (edge/sources/subsample.py): which frames ``--fps`` keeps."""

from __future__ import annotations

import numpy as np
import pytest

from superbody.edge.sources.subsample import Subsampler, subsample

T0 = 1_700_000_000 * 10**9


def _grid(fps: float, n: int) -> np.ndarray:
    """n stamps of a source at ``fps``, truncated to the ns as video.py computes them."""
    return np.array([int(T0 + k * 1e9 / fps) for k in range(n)], np.int64)


# (source fps, asked fps, frames of the source, indices kept)
RATE_CASES = [
    (10.0, 10.0, 6, [0, 1, 2, 3, 4, 5]),  # the source's own rate: every frame
    (10.0, 5.0, 9, [0, 2, 4, 6, 8]),  # half: every other frame
    (10.0, 4.0, 11, [0, 3, 5, 8, 10]),  # the first frame at or after each 0.25 s: 0, 0.3, 0.5, 0.8, 1.0 s
    (30.0, 7.5, 13, [0, 4, 8, 12]),  # a quarter of 30 fps
    (29.97, 10.0, 10, [0, 3, 6, 9]),  # NTSC: 0.1 s lands 0.1 ms before frame 3: kept at frame 3, not 4
    (15.0, 0.5, 61, [0, 30, 60]),  # one frame every 2 s
    (10.0, 4.0, 0, []),  # no frames
]


@pytest.mark.parametrize("src,fps,n,kept", RATE_CASES)
def test_the_first_frame_at_or_after_each_instant_of_the_rate_is_kept(src, fps, n, kept):
    assert np.flatnonzero(subsample(_grid(src, n), fps)).tolist() == kept


def test_a_gap_is_passed_over_not_made_up_in_a_burst():
    # 10 fps with frames 3-9 missing, thinned to 5 fps: after the gap the grid resumes at the next instant.
    stamps = np.delete(_grid(10.0, 16), range(3, 10))  # 0, 0.1, 0.2, 1.0, 1.1, ..., 1.5 s
    kept = stamps[subsample(stamps, 5.0)]
    assert ((kept - T0) / 1e8).round().astype(int).tolist() == [0, 2, 10, 12, 14]


def test_the_rate_is_reached_over_a_long_run():
    kept = subsample(_grid(25.0, 2500), 10.0)  # 100 s
    assert kept.sum() == 1000


@pytest.mark.parametrize("fps", [0.0, -1.0, float("nan"), float("inf")])
def test_a_rate_must_be_positive(fps):
    with pytest.raises(ValueError, match="fps must be a positive number"):
        Subsampler(fps)
