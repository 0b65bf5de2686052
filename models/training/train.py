"""Training: simulated samples from a site (and optionally real ones) -> a pose network ->
fp32 and int8 ONNX, with the whole config stored in the model.

    superbody train --site deploy/sites/wtf-apartment.toml --arch gat --out build/models --name wtf-gat

Data: ``sim_samples`` samples simulated in the site (DS2-like; the "rays" variant can instead
use ``random_sites`` random rooms, so the model never sees the serving layout), plus, if
``real`` is given, the samples of a WheresTheFellow file, repeated ``real_repeat`` times per
epoch (DS1-like mix), and with ``real_subset_repeat`` every proper subset of a real sample's views
as well (one real frame seen by three cameras is also three real single-view frames and three
two-view frames, with the same truth: real detector noise for the hard camera counts, in the
places the multi-camera frames were taken). Real ground truth is converted to the torso centre the product reports
(models.data.wtf.truth_to_torso). ``real_exclude`` holds out a contiguous range of the real file
(cross-validation folds).

Graphs are built once, keeping x and mask only; each mini-batch rebuilds its adjacency from
the spec's template. Validation: a random ``val_fraction`` of the training data; the best
epoch by validation loss is kept (early stopping with ``patience``).

Time limit: ``max_minutes`` counts from the start of ``train``, so it covers building the
training data (simulation, graphs) and the training itself. It is checked after every batch:
once it is reached, the epoch stops there, its weights are validated like a whole epoch's, and
the best weights so far are kept. What runs after ``train`` (ONNX export, int8 quantisation,
``superbody train --calibrate-sim``) is outside it; the command prints each stage's time.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from superbody.edge.angles import wrap_angle
from superbody.edge.site import Site, load_site
from superbody.host.estimation.graph import GraphBatch, GraphSpec, adjacency_template, build_batch, floor_centre, masked_adjacency
from superbody.models.data.samples import Sample

if TYPE_CHECKING:
    import torch

    from superbody.models.nets import PoseNet

__all__ = ["TrainConfig", "TrainResult", "train", "prepare", "view_subsets"]

log = logging.getLogger("superbody.train")

ARCH_DEFAULTS: dict[str, dict] = {
    "gat": {"hidden": 48, "heads": 4, "layers": 3},
    "rgcn": {"hidden": 48, "bases": 4, "layers": 3},
    "mlp": {"hidden": 128, "slot_dim": 64},
}


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on; stored in the exported model's metadata."""

    site: str
    arch: str = "gat"
    variant: str = "site"
    use_3d: bool = False
    max_views: int = 4
    geometry: bool = False
    hparams: dict = field(default_factory=dict)
    sim_samples: int = 30_000
    sim_seed: int = 0
    random_sites: int = 0
    real: str | None = None
    real_exclude: tuple[int, int] | None = None
    real_holdout: tuple[int, ...] = ()
    real_repeat: int = 20
    real_subset_repeat: int = 0
    epochs: int = 40
    batch_size: int = 128
    lr: float = 2e-3
    weight_decay: float = 1e-4
    patience: int = 6
    val_fraction: float = 0.1
    yaw_weight: float = 1.0
    nll_weight: float = 0.01
    seed: int = 0
    max_minutes: float = 15.0
    threads: int = 2
    init: str | None = None

    def __post_init__(self) -> None:
        if self.arch not in ARCH_DEFAULTS:
            raise ValueError(f"arch must be one of {', '.join(ARCH_DEFAULTS)}, got {self.arch!r}")
        if self.variant not in ("site", "rays"):
            raise ValueError(f"variant must be 'site' or 'rays', got {self.variant!r}")
        if self.random_sites and self.variant != "rays":
            raise ValueError("random_sites needs variant 'rays' (a 'site' model is tied to its site's cameras)")
        lo: float  # integer bounds first, then float ones
        hi: float
        for name, lo, hi in (("sim_samples", 0, 5_000_000), ("random_sites", 0, 10_000), ("max_views", 1, 16), ("real_repeat", 1, 1000),
                             ("real_subset_repeat", 0, 1000), ("epochs", 1, 10_000), ("batch_size", 1, 65_536), ("patience", 1, 10_000), ("threads", 1, 256)):
            v = getattr(self, name)
            if not (isinstance(v, int) and lo <= v <= hi):
                raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {v!r}")
        for name, lo, hi in (("lr", 1e-6, 1.0), ("weight_decay", 0.0, 1.0), ("val_fraction", 0.0, 0.5),
                             ("yaw_weight", 0.0, 100.0), ("nll_weight", 0.0, 100.0), ("max_minutes", 0.01, 10_000.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and lo <= v <= hi):
                raise ValueError(f"{name} must be in [{lo}, {hi}], got {v!r}")
        if self.sim_samples == 0 and not self.real:
            raise ValueError("nothing to train on: sim_samples is 0 and no real data is given")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["real_exclude"] = list(self.real_exclude) if self.real_exclude else None
        d["real_holdout"] = list(self.real_holdout)
        return d


@dataclass
class TrainResult:
    """What a run produced.

    Attributes:
        minutes: the whole run (data and training), what ``max_minutes`` limits.
        data_minutes: of which building the training data (simulation, graphs).
        stop: why training stopped: ``"epochs"`` (all done), ``"early stop"`` (no better
            validation loss for ``patience`` epochs) or ``"time limit"``.
    """

    model: PoseNet
    spec: GraphSpec
    history: list[dict]
    best_epoch: int
    minutes: float
    val: dict
    calibration: list[GraphBatch]
    data_minutes: float = 0.0
    stop: str = "epochs"


# -- data ------------------------------------------------------------------------------------------


def prepare(samples: list[Sample], site: Site, spec: GraphSpec, model, chunk: int = 2048) -> tuple[NDArray, NDArray, NDArray]:
    """Graphs and targets of samples seen in one site.

    Returns:
        x (S, N, F) float32, mask (S, N) float32, targets (S, 4) float32.
    """
    xs, ms = [], []
    for i in range(0, len(samples), chunk):
        b = build_batch([s.views for s in samples[i : i + chunk]], site, spec)
        xs.append(b.x)
        ms.append(b.mask)
    truth = np.array([s.truth for s in samples]).reshape(-1, 3)
    N, F = spec.num_nodes, spec.num_features
    return (np.concatenate(xs) if xs else np.zeros((0, N, F), np.float32),
            np.concatenate(ms) if ms else np.zeros((0, N), np.float32),
            model.targets(truth, site))


def _datasets(cfg: TrainConfig, site: Site, spec: GraphSpec, model, progress: bool) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Training arrays and a per-sample weight of 'real' (1) or simulated (0)."""
    from superbody.models.data.simdata import SimDataConfig, generate, random_site

    parts: list[tuple[NDArray, NDArray, NDArray, NDArray]] = []
    if cfg.sim_samples:
        if cfg.random_sites:
            rng = np.random.default_rng([cfg.sim_seed, 0x517E])
            per = max(1, cfg.sim_samples // cfg.random_sites)
            for k in tqdm(range(cfg.random_sites), desc="random sites", unit="site", disable=not progress):
                rs = random_site(np.random.default_rng(rng.integers(0, 2**63)), name=f"random{k}")
                samples = generate(rs, SimDataConfig(samples=per, seed=cfg.sim_seed * 100_003 + k, depth=cfg.use_3d), progress=False)
                x, m, y = prepare(samples, rs, spec, model)
                parts.append((x, m, y, np.zeros(len(x), np.float32)))
        else:
            samples = generate(site, SimDataConfig(samples=cfg.sim_samples, seed=cfg.sim_seed, depth=cfg.use_3d), progress=progress)
            x, m, y = prepare(samples, site, spec, model)
            parts.append((x, m, y, np.zeros(len(x), np.float32)))
    if cfg.real:
        from superbody.models.data.wtf import load_wtf, truth_to_torso

        real = load_wtf(cfg.real, site=site if cfg.use_3d else None)
        drop = set(cfg.real_holdout)
        if cfg.real_exclude:
            drop |= set(range(*cfg.real_exclude))
        real = [s for i, s in enumerate(real) if i not in drop]
        real = [Sample(s.views, truth_to_torso(s.truth)[0], s.stamp_ns) for s in real]
        groups = [(real, cfg.real_repeat)] + ([(view_subsets(real), cfg.real_subset_repeat)] if cfg.real_subset_repeat else [])
        for group, repeat in groups:
            x, m, y = prepare(group, site, spec, model)
            parts.append((np.repeat(x, repeat, 0), np.repeat(m, repeat, 0), np.repeat(y, repeat, 0), np.ones(len(x) * repeat, np.float32)))
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(4))  # type: ignore[return-value]


def view_subsets(samples: list[Sample]) -> list[Sample]:
    """Every proper, non-empty subset of each sample's views, as samples with the same truth
    (a sample seen by k cameras gives 2^k - 2 of them; a single-view sample gives none)."""
    out: list[Sample] = []
    for s in samples:
        cams = sorted(s.views)
        for k in range(1, len(cams)):
            out.extend(Sample({c: s.views[c] for c in sub}, s.truth, s.stamp_ns) for sub in itertools.combinations(cams, k))
    return out


# -- training ---------------------------------------------------------------------------------------


def _metrics(out: NDArray, y: NDArray, scale: float) -> dict:
    pos = np.abs(out[:, :2] - y[:, :2]) * scale  # (S, 2) metres
    yaw = np.abs(wrap_angle(np.arctan2(out[:, 2], out[:, 3]) - np.arctan2(y[:, 2], y[:, 3])))
    return {"mae_x_m": float(pos[:, 0].mean()), "mae_y_m": float(pos[:, 1].mean()), "yaw_mae_deg": float(np.degrees(np.mean(yaw)))}


def train(cfg: TrainConfig, progress: bool = True) -> TrainResult:
    """Train a model as ``cfg`` says; returns it with its history (no files written)."""
    import torch

    from superbody.models.nets import build_model, pose_nll

    t0 = time.monotonic()
    deadline = t0 + 60.0 * cfg.max_minutes  # checked after every batch: data building counts too
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    site = load_site(cfg.site)
    spec = GraphSpec.for_site(site, variant=cfg.variant, use_3d=cfg.use_3d, max_views=cfg.max_views, geometry=cfg.geometry)  # type: ignore[arg-type]
    hparams = {**ARCH_DEFAULTS[cfg.arch], **cfg.hparams}
    if cfg.variant == "site":
        hparams["origin"] = tuple(float(v) for v in floor_centre(site))
    model = build_model(cfg.arch, spec, **hparams)  # type: ignore[arg-type]
    if cfg.init:
        state = torch.load(cfg.init, map_location="cpu", weights_only=False)
        model.load_state_dict(state["state_dict"])
        log.info("starting from %s", cfg.init)
    X, M, Y, R = _datasets(cfg, site, spec, model, progress)
    data_minutes = (time.monotonic() - t0) / 60
    log.info("training data: %d graphs (%d real), %d nodes x %d features, built in %.1f s",
             len(X), int(R.sum()), spec.num_nodes, spec.num_features, 60 * data_minutes)
    if time.monotonic() >= deadline:
        log.warning("the time limit of %g min was spent building the training data (%.1f min): one training step only; "
                    "raise --max-minutes or lower --sim-samples", cfg.max_minutes, data_minutes)
    order = rng.permutation(len(X))
    n_val = int(round(cfg.val_fraction * len(X)))
    val, tr = order[:n_val], order[n_val:]
    T = torch.from_numpy(np.array(adjacency_template(spec)))  # (R, N, N), a writable copy
    Xt, Mt, Yt = torch.from_numpy(X), torch.from_numpy(M), torch.from_numpy(Y)
    w = torch.tensor([1.0, 1.0, cfg.yaw_weight, cfg.yaw_weight])

    def forward(idx: NDArray) -> tuple[torch.Tensor, torch.Tensor]:
        ii = torch.from_numpy(idx)
        m = Mt[ii]  # (B, N)
        adj = T[None] * m[:, None, :, None] * m[:, None, None, :]  # (B, R, N, N)
        return model(Xt[ii], adj, m), Yt[ii]

    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = max(1, math.ceil(len(tr) / cfg.batch_size))
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=cfg.epochs * steps_per_epoch, pct_start=0.1)
    # (val loss, epoch, state, validation metrics) of the best epoch so far
    best: tuple[float, int, dict[str, torch.Tensor] | None, dict] = (math.inf, -1, None, {})
    history: list[dict] = []
    stale = 0
    stop = "epochs"
    limit = f"{cfg.max_minutes:g} min"
    for epoch in range(cfg.epochs):
        model.train()
        perm = rng.permutation(tr)
        total, steps = 0.0, 0
        bar = tqdm(range(steps_per_epoch), desc=f"epoch {epoch + 1}/{cfg.epochs}", unit="step", leave=False, disable=not progress)
        for s in bar:
            out, y = forward(perm[s * cfg.batch_size : (s + 1) * cfg.batch_size])
            # The pose's squared error, plus the uncertainty head's likelihood (means detached).
            loss = (((out[:, :4] - y) ** 2) * w).mean() + pose_nll(out, y).mean() * cfg.nll_weight
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item()
            steps = s + 1
            now = time.monotonic()
            if s % 20 == 0:
                bar.set_postfix(loss=f"{total / steps:.4f}", time=f"{(now - t0) / 60:.1f}/{limit}")
            if now >= deadline:  # within the epoch: an epoch can take minutes
                stop = "time limit"
                break
        bar.close()
        val_out, val_y = _predict(model, forward, val, cfg.batch_size)
        # Early stopping on the pose alone: the uncertainty must not choose the epoch.
        val_loss = float((((val_out[:, :4] - val_y) ** 2) * w.numpy()).mean()) if len(val) else total / steps
        metrics = _metrics(val_out, val_y, model.scale) if len(val) else {}
        row = {"epoch": epoch + 1, "steps": steps, "train_loss": total / steps, "val_loss": val_loss, "minutes": (time.monotonic() - t0) / 60,
               **metrics}
        history.append(row)
        log.info("epoch %d%s: train %.4f val %.4f | val MAE x %.0f mm y %.0f mm yaw %.1f deg | %.1f of %s", epoch + 1,
                 f" ({steps} of {steps_per_epoch} steps)" if steps < steps_per_epoch else "", row["train_loss"], val_loss,
                 1000 * row.get("mae_x_m", math.nan), 1000 * row.get("mae_y_m", math.nan), row.get("yaw_mae_deg", math.nan), row["minutes"], limit)
        if val_loss < best[0]:
            best, stale = (val_loss, epoch + 1, {k: v.detach().clone() for k, v in model.state_dict().items()}, metrics), 0
        else:
            stale += 1
        if stop == "time limit" or time.monotonic() >= deadline:
            stop = "time limit"
            log.info("time limit of %s reached in epoch %d (%d of %d steps): keeping epoch %d's weights", limit, epoch + 1, steps,
                     steps_per_epoch, best[1])
            break
        if stale >= cfg.patience:
            stop = "early stop"
            log.info("early stop: no better validation loss for %d epochs", stale)
            break
    model.load_state_dict(best[2])  # type: ignore[arg-type]  # None only if no epoch beat inf (NaN losses): it raises TypeError, as before
    model.eval()
    calib_idx = rng.choice(tr, size=min(512, len(tr)), replace=False)
    chunks = [calib_idx[i : i + 128] for i in range(0, len(calib_idx), 128)]
    calibration = [GraphBatch(x=X[c], adj=masked_adjacency(spec, M[c]), mask=M[c]) for c in chunks]
    return TrainResult(model=model, spec=spec, history=history, best_epoch=best[1], minutes=(time.monotonic() - t0) / 60,
                       val=best[3], calibration=calibration, data_minutes=data_minutes, stop=stop)


def _predict(model, forward, idx: NDArray, batch: int) -> tuple[NDArray, NDArray]:
    import torch

    from superbody.models.nets import OUT_DIM

    model.eval()
    outs, ys = [], []
    with torch.no_grad():
        for i in range(0, len(idx), batch * 4):
            o, y = forward(idx[i : i + batch * 4])
            outs.append(o.numpy())
            ys.append(y.numpy())
    model.train()
    if not outs:
        return np.zeros((0, OUT_DIM), np.float32), np.zeros((0, 4), np.float32)
    return np.concatenate(outs), np.concatenate(ys)


def save(result: TrainResult, cfg: TrainConfig, out_dir: str | Path, name: str, quantize: bool = True) -> dict[str, Path]:
    """Write <name>.pt (state and config), <name>.fp32.onnx, <name>.int8.onnx and <name>.train.json."""
    import torch

    from superbody.models.training.export import export_onnx, quantize_int8

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"checkpoint": out / f"{name}.pt", "fp32": out / f"{name}.fp32.onnx", "report": out / f"{name}.train.json"}
    config = {**cfg.to_json(), "best_epoch": result.best_epoch, "minutes": round(result.minutes, 2), "val": result.val}
    torch.save({"state_dict": result.model.state_dict(), "config": config, "model": result.model.config()}, paths["checkpoint"])
    export_onnx(result.model, result.spec, config, paths["fp32"])
    if quantize:
        paths["int8"] = out / f"{name}.int8.onnx"
        quantize_int8(paths["fp32"], paths["int8"], result.calibration)
    paths["report"].write_text(json.dumps({"config": config, "history": result.history}, indent=1) + "\n")
    return paths


# -- command line ---------------------------------------------------------------------------------


def _search(cfg: TrainConfig, n: int, progress: bool) -> TrainConfig:
    """The paper's small random hyper-parameter search: ``n`` short runs, keep the best by validation loss."""
    rng = np.random.default_rng(cfg.seed + 1)
    space = {
        "gat": lambda: {"hidden": int(rng.choice([32, 48, 64])), "heads": int(rng.choice([2, 4])), "layers": int(rng.integers(2, 5))},
        "rgcn": lambda: {"hidden": int(rng.choice([32, 48, 64])), "bases": int(rng.choice([2, 4, 8])), "layers": int(rng.integers(2, 5))},
        "mlp": lambda: {"hidden": int(rng.choice([64, 128, 256])), "slot_dim": int(rng.choice([32, 64, 128]))},
    }[cfg.arch]
    trials = []
    for k in range(n):
        hp = space()
        lr = float(10 ** rng.uniform(-3.3, -2.3))
        short = dataclasses.replace(cfg, hparams=hp, lr=lr, sim_samples=min(cfg.sim_samples, 8000), epochs=min(cfg.epochs, 6),
                                    max_minutes=cfg.max_minutes / (n + 1))
        r = train(short, progress=progress)
        loss = min(h["val_loss"] for h in r.history)
        trials.append((loss, hp, lr))
        log.info("search %d/%d: %s lr %.2g -> val loss %.4f", k + 1, n, hp, lr, loss)
    loss, hp, lr = min(trials, key=lambda t: t[0])
    log.info("search: best %s lr %.2g (val loss %.4f)", hp, lr, loss)
    return dataclasses.replace(cfg, hparams=hp, lr=lr)


