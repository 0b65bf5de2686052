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


def test_the_time_limit_stops_training_inside_an_epoch(capsys) -> None:
    # Before: the limit was checked only at the end of an epoch, so a run whose epoch takes
    # longer than its limit went on for the whole epoch (the documented 15-minute command took
    # 17.2 min). Here one epoch is 1350 steps of one graph each (3-200 ms a step: 4 s to
    # minutes), against a limit of 2.4 s; the old code took 12.5 s here (one whole epoch).
    from superbody.models.training.train import TrainConfig, train
    from tests.conftest import WTF_SITE

    tiny = {"hidden": 16, "heads": 2, "layers": 2}
    train(TrainConfig(site=str(WTF_SITE), sim_samples=40, epochs=1, hparams=tiny, threads=1), progress=False)  # torch's lazy imports (seconds)
    cfg = TrainConfig(site=str(WTF_SITE), sim_samples=1500, epochs=3, batch_size=1, hparams=tiny, threads=1, max_minutes=0.04)
    capsys.readouterr()
    result = train(cfg, progress=True)
    seconds, data_seconds = 60 * result.minutes, 60 * result.data_minutes
    assert result.stop == "time limit" and len(result.history) == 1
    assert result.history[0]["steps"] < 1350  # stopped inside the first epoch
    # within a step and a validation pass (100 graphs) of the limit, or of the data where
    # building them took longer than the limit (the run then trains one step)
    assert seconds < max(60 * cfg.max_minutes, data_seconds) + 2.0, (seconds, data_seconds, result.history)
    # the stopped epoch's weights were validated and kept (the only ones): the result is scored
    assert result.best_epoch == 1 and result.val == {k: result.history[0][k] for k in ("mae_x_m", "mae_y_m", "yaw_mae_deg")}
    # the progress bar shows the time spent against the limit
    assert "/0.04 min" in capsys.readouterr().err
