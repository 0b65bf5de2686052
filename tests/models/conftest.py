"""Fixtures shared by the models tests."""

import pytest

from superbody.models.data.wtf import RawSample, load_wtf_raw


@pytest.fixture(scope="module")
def raw(dev_json) -> list[RawSample]:
    """dev.json's samples, as the calibration and the dataset reader see them."""
    return load_wtf_raw(dev_json)
