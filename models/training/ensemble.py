"""Ensembles: several pose networks trained alike, their estimates combined into one.

Members differ in their simulated training data (``--sim-seed``), their shuffling (``--seed``)
and, where given, the simulation-only checkpoint they were fine-tuned from. For K members with
poses (x_k, y_k, yaw_k) and 1-sigmas (sx_k, sy_k, syaw_k), with u_k = (sin yaw_k, cos yaw_k):

- x, y: the mean of the members';
- yaw: the direction of the mean of the u_k (circular mean);
- 1-sigma: that of the equal mixture of the members' Gaussians,
  sqrt(mean(s_k^2) + mean(d_k^2)), d_k the member's distance from the combined estimate: for yaw
  the chord |u_k - u| to the combined heading's unit vector u (the angle between them, for the
  few degrees members differ by; at most 2 where the angle is pi).

``combine`` does it on arrays (held-out predictions of cross-validations, one per member).
``models.training.export.export_onnx`` given several networks does the same sums inside one ONNX graph
with the single model's interface (pose (B, 4) = x, y, and the mean unit heading vector as sin,
cos: yaw = atan2; pose_std (B, 3)), so the host runs an ensemble like any model.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["combine", "load_member", "calibration_graphs"]

_EPS = 1e-9


def combine(pose: NDArray, std: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Combine K members' estimates of B people.

    Args:
        pose: (K, B, 3) x, y (m), yaw (rad) per member.
        std: (K, B, 3) their 1-sigmas.

    Returns:
        ``(pose, std)``, (B, 3) each; yaw in (-pi, pi]. A person any member could not estimate
        (a non-finite row) gets NaN.
    """
    pose = np.asarray(pose, dtype=np.float64)
    std = np.asarray(std, dtype=np.float64)
    if pose.ndim != 3 or pose.shape[-1] != 3 or std.shape != pose.shape or len(pose) < 1:
        raise ValueError(f"combine: pose and std must both have shape (K >= 1, B, 3), got {pose.shape} and {std.shape}")
    u = np.stack([np.sin(pose[..., 2]), np.cos(pose[..., 2])], axis=-1)  # (K, B, 2)
    mean_u = u.mean(0)  # (B, 2)
    unit = mean_u / np.maximum(np.linalg.norm(mean_u, axis=-1, keepdims=True), _EPS)  # (B, 2)
    xy = pose[..., :2].mean(0)  # (B, 2)
    spread = np.concatenate([(pose[..., :2] - xy) ** 2, ((u - unit) ** 2).sum(-1, keepdims=True)], axis=-1)  # (K, B, 3)
    out_std = np.sqrt((std**2).mean(0) + spread.mean(0))
    yaw = np.arctan2(mean_u[:, 0], mean_u[:, 1])
    yaw = np.where(yaw <= -np.pi, np.pi, yaw)
    out = np.column_stack([xy, yaw])
    bad = ~(np.isfinite(pose).all(axis=(0, 2)) & np.isfinite(std).all(axis=(0, 2)))
    out[bad] = np.nan
    out_std[bad] = np.nan
    return out, out_std


def load_member(path: str | Path):
    """A trained network from a ``superbody train`` checkpoint (.pt), with its training config.

    Returns:
        ``(model, spec, site, train_config)``.

    Raises:
        ValueError: not such a checkpoint (the message names the file and what is missing).
    """
    import torch

    from superbody.edge.site import SiteError, load_site
    from superbody.host.estimation.graph import GraphSpec
    from superbody.models.nets import build_model

    path = Path(path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
        cfg, hparams = dict(state["config"]), dict(state["model"])
        site = load_site(cfg["site"])
        spec = GraphSpec.for_site(site, variant=cfg["variant"], use_3d=cfg["use_3d"], max_views=cfg["max_views"], geometry=cfg["geometry"])
        arch = hparams.pop("arch")
        hparams["origin"] = tuple(hparams.get("origin", (0.0, 0.0)))
        model = build_model(arch, spec, **hparams)
        model.load_state_dict(state["state_dict"])
    except (OSError, KeyError, TypeError, RuntimeError, SiteError, pickle.UnpicklingError) as e:
        raise ValueError(f"{path}: not a superbody train checkpoint ({type(e).__name__}: {e})") from None
    model.eval()
    return model, spec, site, cfg


def calibration_graphs(site, spec, samples: int = 512, seed: int = 0) -> list:
    """Graph batches of ``samples`` people simulated in the site, for int8 calibration."""
    from superbody.host.estimation.graph import build_batch
    from superbody.models.data.simdata import SimDataConfig, generate

    sim = generate(site, SimDataConfig(samples=samples, seed=seed, depth=spec.use_3d), progress=False)
    views = [s.views for s in sim]
    return [build_batch(views[i : i + 128], site, spec) for i in range(0, len(views), 128)]


