"""models/training/train.py pieces that the pipeline tests do not reach."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")  # the train extra, which `make test` installs

from superbody.models.nets import OUT_DIM  # noqa: E402
from superbody.models.training.train import _predict  # noqa: E402


def test_predicting_no_samples_gives_empty_arrays_of_the_output_width() -> None:
    # An empty validation split once raised NameError here (OUT_DIM was not imported).
    model = torch.nn.Linear(2, 2)
    out, y = _predict(model, lambda idx: pytest.fail("nothing to forward"), np.array([], dtype=np.intp), batch=8)
    assert out.shape == (0, OUT_DIM) and y.shape == (0, 4)
    assert model.training  # left in training mode, as after a non-empty prediction
