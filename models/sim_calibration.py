"""Calibrating the hybrid estimator on simulation: a site with no labelled real data.

    superbody calibrate hybrid-sim --site S --model M.fp32.onnx [--model M.int8.onnx] [--samples 4000]
    superbody train --site S --geometry --calibrate-sim ...        (the same, right after training)

``superbody calibrate hybrid`` fits the hybrid (``host.estimation.hybrid``) on a cross-validation
of real, labelled data. A new site has none. Here the held-out data is simulated instead: people
in the site's own cameras (``models.data.simdata.generate``, the detector noise model as
measured on a real detector, not jittered as for training; a seed the training never used), the model and geometry run on
them, and the same fit (``models.hybrid_fit.fit_calibration``: the network's sigma scale per
camera count, geometry's sigmas, the trust per camera count and axis) written into each model.
Every constant then comes from simulation and physics, none from a recording.

Simulation flatters geometry (its cameras are calibrated exactly and its bodies match the
analytic estimator's model), so the fit leans on geometry wherever geometry is good, and on the
network where views are poor (one camera, few joints): what a new site needs from it. And the
network earns trust on an axis of a camera count only where, alone, it beats geometry alone
(``fit_trust``'s ``must_win_alone``): a gain from averaging two estimates of equal quality rests
on the simulation's independent errors and exact sigmas, which a real site does not share. The fit
is also scored on the simulated samples, each of five floor regions with the calibration fitted
on the others (``leave_one_fold_out``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from superbody.edge.site import Site
from superbody.host.estimation.hybrid import HybridCalibration
from superbody.models.data.samples import Sample

__all__ = ["DEFAULT_SAMPLES", "DEFAULT_SEED", "calibrate_on_simulation", "geometry_calibration", "format_fits"]

DEFAULT_SAMPLES = 4000
DEFAULT_SEED = 7_2026  # never a training seed (training uses 0-9 by default)


class _HeldOut(NamedTuple):
    """Simulated people of a site with geometry run on them: what both fits score against."""

    data: list[Sample]
    truth: NDArray[np.float64]  # (N, 3)
    cams: NDArray[np.int64]  # (N,) views per person
    analytic: NDArray[np.float64]  # (N, 3)
    pair: NDArray[np.bool_]  # (N,)
    source: str


def _held_out(site: Site, samples: int, seed: int, progress: bool) -> _HeldOut:
    """People in the site's own cameras, the detector as measured, not jittered: training widens
    the noise for robustness, but the fit must see the errors the site's detector makes (with
    training's swap rates, up to 6% of views, geometry's 3-camera yaw failed so often that the
    fit trusted the network there, 7.6 deg on dev.json against geometry's 5.8)."""
    from superbody.models import hybrid_fit
    from superbody.models.data.simdata import SimDataConfig, generate

    data = generate(site, SimDataConfig(samples=samples, seed=seed, randomise_noise=False), progress=progress)
    analytic, pair = hybrid_fit.analytic_with_pairs(data, site)
    return _HeldOut(data, np.array([s.truth for s in data]), np.array([len(s.views) for s in data], dtype=np.int64), analytic, pair,
                    f"simulation of site {site.name}: {len(data)} samples, seed {seed}")


def geometry_calibration(site: Site, samples: int = DEFAULT_SAMPLES, seed: int = DEFAULT_SEED, progress: bool = False) -> HybridCalibration:
    """The geometry's sigmas per camera count on simulated people of the site (the detector as
    measured), as ``calibrate_on_simulation`` fits them for the hybrid: what
    ``host.estimation.analytic.AnalyticEstimator`` reports with its poses on a site whose model
    was calibrated on simulation.

    Returns:
        The calibration's ``analytic_std`` and ``analytic_yaw_std_no_pair``; no network trust.
    """
    from superbody.models import hybrid_fit

    h = _held_out(site, samples, seed, progress)
    return hybrid_fit.fit_analytic(h.analytic, h.pair, h.truth, h.cams, source=h.source)


def calibrate_on_simulation(site: Site, models: Sequence[Path], samples: int = DEFAULT_SAMPLES, seed: int = DEFAULT_SEED,
                            progress: bool = False, write: bool = True) -> dict[str, Any]:
    """Fit the hybrid calibration of each model on simulated samples of its site, and write it in.

    Args:
        site: the site the models are for.
        models: ONNX models with a ``pose_std`` output (each fitted on its own predictions: an int8
            model errs differently from its fp32 twin).
        samples: simulated people (view sets) to fit on.
        seed: the simulation's seed.
        progress: progress bars.
        write: write the calibration into each model (False: only fit and score).

    Returns:
        Per model path: ``{"std_scale", "calibration", "samples_by_cameras", "reports"}``:
        ``samples_by_cameras`` per camera count 1..N of the site (N its cameras) the samples the
        trust was fitted on (``hybrid_fit.trust_samples``); reports (hybrid with each floor region
        held out, network, analytic) as ``models.evaluation.evaluate.summarise`` gives them, on
        the simulated samples, by camera count 1..N.

    Raises:
        host.estimation.estimator.ModelMismatchError: a model does not fit the site or has no
            uncertainty output.
    """
    from superbody.host.estimation.estimator import ModelMismatchError, OnnxEstimator
    from superbody.models import hybrid_fit
    from superbody.models.evaluation.crossval import spatial_folds
    from superbody.models.evaluation.evaluate import summarise

    data, truth, cams, analytic, pair, source = _held_out(site, samples, seed, progress)
    views = [s.views for s in data]
    fold = np.zeros(len(data), np.int64)
    for k, (held, _) in enumerate(spatial_folds(truth[:, :2], 5, seed=seed)):
        fold[held] = k + 1
    out: dict[str, Any] = {}
    for path in models:
        net = OnnxEstimator(path, site)
        if not net.has_std:
            raise ModelMismatchError(f"{path}: the hybrid needs a model with a pose_std output (retrain it)")
        net.std_scale = np.ones((3, 3))  # the network's own sigmas: the scale is what is fitted
        pred, std = net.estimate_with_std(views)
        scale, cal = hybrid_fit.fit_calibration(pred, std, analytic, pair, truth, cams, source=source, must_win_alone=True)
        lofo = hybrid_fit.leave_one_fold_out(pred, std, analytic, pair, truth, cams, fold, site, must_win_alone=True)[0]
        counts = range(1, len(site.cameras) + 1)  # every camera count of the site, those with no samples too
        reports = {name: summarise(p, truth, cams, 0.0, counts) for name, p in (("hybrid (held-out regions)", lofo), ("network", pred),
                                                                               ("analytic", analytic))}
        if write:
            hybrid_fit.write_calibration(path, scale, cal)
        out[str(path)] = {"std_scale": scale.tolist(), "calibration": cal,
                          "samples_by_cameras": hybrid_fit.trust_samples(pred, analytic, cams, len(site.cameras)), "reports": reports}
    return out


def format_fits(fits: dict[str, Any]) -> str:
    """What ``calibrate_on_simulation`` fitted, and how it scores on the simulation, as lines of
    text: every camera count of the site, those with too few samples or none said so."""
    from superbody.models.hybrid_fit import format_trust

    lines = []
    for path, f in fits.items():
        cal = f["calibration"]
        lines.append(f"{path}: hybrid calibrated on {cal.source}")
        lines += ["  " + line for line in format_trust(cal, f["samples_by_cameras"])]
        lines.append("  scored on the simulation (x / y MAE, yaw MAE), all and by cameras:")
        for name, r in f["reports"].items():
            by = [f"{k} cam " + (f"{b['position_mae_mm']['x']:.0f} / {b['position_mae_mm']['y']:.0f} mm, {b['yaw_mae_deg']:.1f} deg"
                                 if b["samples"] else "no samples") for k, b in r["by_cameras"].items()]
            lines.append(f"  {name:<26} x / y {r['position_mae_mm']['x']:.0f} / {r['position_mae_mm']['y']:.0f} mm, "
                         f"yaw {r['yaw_mae_deg']:.1f} deg; " + "; ".join(by))
    return "\n".join(lines)
