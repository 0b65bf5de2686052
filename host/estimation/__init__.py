"""Pose estimators: a person's views in, floor position and torso yaw out.

- ``estimator.py``: the ``Estimator`` protocol and the network on onnxruntime (``OnnxEstimator``);
- ``graph.py``: the superbody graph the network reads;
- ``analytic.py``: geometry alone (triangulated ground point, shoulder and hip lines);
- ``hybrid.py``: the network fused with geometry, as the model's calibration says.

This module is the registry: ``build_estimator(site, name, model)`` by name, and
``default_model(site)``, the shipped model of a site.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

from superbody.edge.site import Site

if TYPE_CHECKING:
    from superbody.host.estimation.hybrid import HybridCalibration

__all__ = ["ESTIMATORS", "default_model", "build_estimator", "geometry_sigmas", "no_model_message"]

log = logging.getLogger("superbody.host")

ESTIMATORS = ("auto", "hybrid", "onnx", "analytic")


def default_model(site: Site) -> Path | None:
    """The shipped model for the site (package data), if there is one: ``models/<site>.fp32.onnx``,
    else ``models/<site>.int8.onnx``. The fp32 file is the default because it is both exact and
    the fastest (exported as the fast GAT, models.fast_gat; int8 costs more than it saves on
    these small products: docs/scaling.md)."""
    from superbody.edge.resources import model_path

    return model_path(f"{site.name}.fp32.onnx") or model_path(f"{site.name}.int8.onnx")


def build_estimator(site: Site, kind: str = "auto", model: str | Path | None = None):
    """The estimator by name, and the name reported in PoseArrays.

    Kinds: ``"hybrid"`` (the network fused with geometry, host.estimation.hybrid; the model must carry a
    hybrid calibration), ``"onnx"`` (the network alone), ``"analytic"`` (geometry alone), and
    ``"auto"``: hybrid when the model carries a calibration, else the network alone; for a site
    with no model (a new site, nothing trained yet) geometry alone, said once as a warning
    (``no_model_message``: how to train one).

    Raises:
        ValueError: unknown kind (listing the valid ones), or no model for the site with
            ``"hybrid"`` or ``"onnx"``.
        host.estimation.estimator.ModelMismatchError: the model does not fit the site.
    """
    if kind == "analytic":
        from superbody.host.estimation.analytic import AnalyticEstimator

        return AnalyticEstimator(site, geometry_sigmas(site, model)), "analytic"
    if kind not in ESTIMATORS:
        raise ValueError(f"unknown estimator {kind!r}; valid estimators: {', '.join(ESTIMATORS)}")
    path = Path(model) if model else default_model(site)
    if path is None and kind == "auto":
        from superbody.host.estimation.analytic import AnalyticEstimator

        log.warning("%s", no_model_message(site))
        return AnalyticEstimator(site), "analytic"
    if path is None:
        raise ValueError(f"--estimator {kind}: {no_model_message(site)}")
    if not path.is_file():
        raise ValueError(f"--model {path}: no such file")
    from superbody.host.estimation.estimator import ModelMismatchError, OnnxEstimator
    from superbody.host.estimation.hybrid import META_HYBRID, HybridEstimator

    try:
        net = OnnxEstimator(path, site)
    except ModelMismatchError:
        raise
    except Exception as e:  # onnxruntime's own errors: an empty, truncated or non-ONNX file
        why = " ".join(str(e).split())[:200]
        raise ValueError(f"--model {path}: not a loadable ONNX model ({path.stat().st_size} bytes): {why}") from None
    if kind == "hybrid" or (kind == "auto" and net.has_std and META_HYBRID in net.metadata):
        return HybridEstimator(net, site), f"hybrid:{path.name}"
    return net, f"onnx:{path.name}"


def geometry_sigmas(site: Site, model: str | Path | None = None) -> HybridCalibration | None:
    """The geometry's 1-sigmas per camera count from the hybrid calibration of ``model`` (else of
    the site's shipped model): fitted on real data, or on simulation of the site (``superbody
    train --calibrate-sim``). None, with a log line, when there is no such model or it cannot
    serve the site: the analytic estimator then reports no sigmas and the filter uses its defaults.
    """
    path = Path(model) if model else default_model(site)
    if path is None or not path.is_file():
        return None
    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.host.estimation.hybrid import META_HYBRID, calibration_of

    try:
        net = OnnxEstimator(path, site)
        cal = calibration_of(net) if META_HYBRID in net.metadata else None
    except Exception as e:  # a model for another site, or an unreadable file: geometry needs neither
        log.warning("geometry alone without sigmas: %s: %s", path.name, " ".join(str(e).split())[:200])
        return None
    if cal is None:
        log.info("geometry alone without sigmas: %s has no %s", path.name, META_HYBRID)
        return None
    log.info("geometry sigmas from %s's hybrid calibration (%s)", path.name, cal.source or "no source recorded")
    return cal


def no_model_message(site: Site) -> str:
    """What a host on a site without a model runs, the command that trains the site one (with its
    site file, when the site was loaded from one) and the page that explains it."""
    import shlex

    site_file = shlex.quote(site.source) if site.source else "<site file>"
    return (f"site {site.name!r} has no model (no --model, no shipped models/{site.name}.fp32.onnx): running geometry alone "
            f"(--estimator analytic: every pose triangulated from the views; no network). To train one from the site file, run: "
            f"superbody train --site {site_file} --geometry --calibrate-sim --name {site.name} (simulation of the site only, no labelled "
            f"data; the hybrid calibrated on simulated people of the site), then pass --model build/models/{site.name}.fp32.onnx "
            f"(see docs/install.md#train-a-model-for-the-site)")
