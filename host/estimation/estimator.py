"""Estimators: the views of each person -> (x, y, yaw) on the floor, one batched call per tick.

``OnnxEstimator`` runs an exported pose network (``models/training/export.py``) with onnxruntime, on
the superbody graphs of ``host.estimation.graph``. numpy and onnxruntime only: the host never imports
torch.

The model's output ``pose`` (B, 4) is (x, y, sin yaw, cos yaw) with x, y in metres in the frame
its metadata names (``pose.frame``):

- ``"world"``: the site's world frame ("site" variant models).
- ``"floor_centre"``: relative to the serving site's floor centre (``host.estimation.graph.floor_centre``),
  world axes ("rays" variant models, whose features are floor-centred too).

yaw = atan2(sin, cos), wrapped to (-pi, pi] (REP-103: counter-clockwise from +x).

Memory: onnxruntime's CPU arena grows to the largest batch it has run and never gives that
back, so one call with 64 people (a peer flooding 64 copies of a person) would raise the host's
resident memory for good (measured: +45 MB at 64 people against 10, 6 cameras, int8 model).
``OnnxEstimator`` therefore runs at most ``max_batch`` people per onnxruntime call (the rest in
further calls) and, when it is built, runs ``max_batch`` people seen whole by every camera, so its
buffers have their largest size from the start and later input, hostile or not, cannot grow them.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol, runtime_checkable

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.host.estimation.graph import GraphSpec, Variant, build_batch, floor_centre

__all__ = [
    "Estimator",
    "Estimates",
    "DetailedEstimator",
    "detailed",
    "estimate_detailed",
    "OnnxEstimator",
    "ModelMismatchError",
    "decode_output",
    "META_POSE_FRAME",
    "META_POSE_SCALE",
    "META_POSE_ORIGIN",
    "META_MODEL_CONFIG",
    "META_TRAIN_CONFIG",
    "POSE_FRAMES",
    "INPUT_NAMES",
    "OUTPUT_NAME",
    "STD_OUTPUT_NAME",
    "META_STD_SCALE",
    "META_READS_ADJ",
    "MAX_BATCH",
]

# The exported models' interface and metadata keys (written by models/training/export.py).
INPUT_NAMES: Final[tuple[str, ...]] = ("x", "adj", "mask")
OUTPUT_NAME: Final[str] = "pose"
STD_OUTPUT_NAME: Final[str] = "pose_std"  # optional (B, 3): the network's 1-sigma of x, y (m) and yaw (rad)
META_STD_SCALE: Final[str] = "pose.std_scale"  # JSON [kx, ky, kyaw], or a row per camera count 1, 2, 3+: pose_std calibrated on held-out real data
META_POSE_FRAME: Final[str] = "pose.frame"  # "world" | "floor_centre"
META_POSE_SCALE: Final[str] = "pose.scale"  # metres per unit of the network's raw output (informative)
META_POSE_ORIGIN: Final[str] = "pose.origin"  # JSON [x, y]: origin of the raw output (informative)
META_MODEL_CONFIG: Final[str] = "model.config"  # JSON: arch and hyper-parameters
META_TRAIN_CONFIG: Final[str] = "train.config"  # JSON: the training run's config
META_READS_ADJ: Final[str] = "model.reads_adj"  # "false": the model takes its edges from mask (adj may be all zero); absent = "true"
POSE_FRAMES: Final[tuple[str, ...]] = ("world", "floor_centre")
# People per onnxruntime call: above a site's usual crowd (10), and bounds the arena (see above).
MAX_BATCH: Final[int] = 16

log = logging.getLogger("superbody.host")


@dataclass(frozen=True, eq=False)
class Estimates:
    """What an estimator says about a batch of people.

    Attributes:
        pose: (B, 3) x, y (m), yaw (rad, (-pi, pi]); NaN rows where nothing could be estimated.
        std: (B, 3) 1-sigma of each (m, m, rad); NaN where the estimator gives none.
        source: per person, which estimator produced the pose ("onnx", "analytic", "hybrid").
    """

    pose: NDArray[np.float64]
    std: NDArray[np.float64]
    source: tuple[str, ...]


@runtime_checkable
class DetailedEstimator(Protocol):
    """An estimator that gives each pose its sigma and its source: what the host calls, once per step."""

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates: ...


class _PosesOnly:
    """A plain ``Estimator`` as a ``DetailedEstimator``: its poses, no sigmas, one source for all."""

    def __init__(self, estimator: Estimator, source: str) -> None:
        self._estimator, self._source = estimator, source

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates:
        pose = np.asarray(self._estimator.estimate(view_sets), dtype=np.float64).reshape(-1, 3)
        return Estimates(pose, np.full(pose.shape, np.nan), (self._source,) * len(pose))


def detailed(estimator: Estimator, source: str) -> DetailedEstimator:
    """The estimator itself when it gives sigmas and sources (``estimate_detailed``), else it
    wrapped to give its poses with no sigmas and ``source`` for every person. The host adapts its
    estimator once, then reaches it by one call."""
    return estimator if isinstance(estimator, DetailedEstimator) else _PosesOnly(estimator, source)


def estimate_detailed(estimator: Estimator, view_sets: Sequence[Mapping[str, PersonView]], source: str) -> Estimates:
    """``detailed(estimator, source).estimate_detailed(view_sets)``."""
    return detailed(estimator, source).estimate_detailed(view_sets)


class ModelMismatchError(ValueError):
    """The model cannot serve this site (cameras, variant or input shapes differ)."""


@runtime_checkable
class Estimator(Protocol):
    """Anything that turns people's views into poses, so the host can swap implementations."""

    def estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> NDArray[np.float64]:
        """Poses (B, 3) = (x, y, yaw) in REP-103 for B people (camera id -> view each)."""
        ...


def decode_output(pose: NDArray, origin: NDArray) -> NDArray[np.float64]:
    """Model output (B, 4) (x, y, sin, cos) + the frame's origin (2,) -> (B, 3) (x, y, yaw).

    yaw = atan2(sin, cos) wrapped to (-pi, pi].
    """
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 4)
    yaw = np.arctan2(pose[:, 2], pose[:, 3])  # [-pi, pi]
    yaw = np.where(yaw <= -np.pi, np.pi, yaw)
    return np.column_stack([pose[:, :2] + np.asarray(origin, dtype=np.float64), yaw])


class OnnxEstimator:
    """A pose network exported to ONNX, for one site.

    Args:
        model_path: the .onnx file (fp32 or int8) with superbody metadata.
        site: the site it serves.
        providers: onnxruntime execution providers, in order of preference.
        intra_op_threads: threads onnxruntime may use inside one call.
        variant: if given, the graph variant the caller expects the model to have.
        max_batch: people per onnxruntime call, in [1, 1024]; larger batches are split. The
            arena is sized for it at construction (one warm-up call), so memory does not grow
            with the number of people later.

    Raises:
        ValueError: ``max_batch`` out of range.
        ModelMismatchError: the model lacks superbody metadata, or its cameras (and their
            order, "site" variant), view slots ("rays"), variant or input shapes do not fit.
    """

    def __init__(
        self,
        model_path: str | Path,
        site: Site,
        providers: Sequence[str] = ("CPUExecutionProvider",),
        intra_op_threads: int = 1,
        variant: Variant | None = None,
        max_batch: int = MAX_BATCH,
    ):
        if not (isinstance(max_batch, int) and 1 <= max_batch <= 1024):
            raise ValueError(f"max_batch must be an integer in [1, 1024], got {max_batch!r}")
        self.max_batch = max_batch
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = intra_op_threads
        opts.inter_op_num_threads = 1
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.path = Path(model_path)
        self.session = ort.InferenceSession(str(self.path), opts, providers=list(providers))
        self.metadata: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        try:
            self.spec = GraphSpec.from_metadata(self.metadata)
        except ValueError as e:
            raise ModelMismatchError(f"{self.path}: {e}") from None
        self.site = site
        self.frame = self.metadata.get(META_POSE_FRAME, "")
        if self.frame not in POSE_FRAMES:
            raise ModelMismatchError(f"{self.path}: metadata {META_POSE_FRAME} must be one of {', '.join(POSE_FRAMES)}, got {self.frame!r}")
        self._check(site, variant)
        self.origin = floor_centre(site) if self.frame == "floor_centre" else np.zeros(2)
        self._inputs = [i.name for i in self.session.get_inputs()]
        # A model that takes its edges from the mask is fed an all-zero adj: one reused buffer.
        self.reads_adj = self.metadata.get(META_READS_ADJ, "true") != "false"
        self._zero_adj = np.zeros((0, self.spec.num_relations, self.spec.num_nodes, self.spec.num_nodes), np.float32)
        self.has_std = STD_OUTPUT_NAME in [o.name for o in self.session.get_outputs()]
        try:
            # [kx, ky, kyaw] for every person, or one such row per camera count 1, 2, 3+.
            scale = np.asarray(json.loads(self.metadata.get(META_STD_SCALE, "[1, 1, 1]")), dtype=np.float64)
            std_scale = np.broadcast_to(scale, (3, 3)).copy() if scale.shape in ((3,), (3, 3)) else None
            if std_scale is None or not (np.all(np.isfinite(std_scale)) and np.all(std_scale > 0)):
                raise ValueError
            self.std_scale: NDArray[np.float64] = std_scale
        except (ValueError, TypeError):
            raise ModelMismatchError(f"{self.path}: metadata {META_STD_SCALE} must be 3 positive numbers or 3 rows of them "
                                     f"(cameras 1, 2, 3+), got {self.metadata.get(META_STD_SCALE)!r}") from None
        self._warm_up()

    def _warm_up(self) -> None:
        """Calls at ``max_batch`` people seen whole by every camera, then at every smaller batch (output unused): the buffers' final size, now.

        The whole path (graph building and onnxruntime) with plausible input: all-zero graphs of
        the same shape left the arena measurably smaller than real ones did.
        """
        kp = np.empty((17, 3), np.float32)
        kp[:, 0] = np.linspace(0.3, 0.7, 17)
        kp[:, 2] = 1.0
        views = {}
        for cam in self.site.cameras:
            u = kp.copy()
            u[:, 0] *= cam.width
            u[:, 1] = np.linspace(0.2, 0.8, 17) * cam.height
            views[cam.id] = PersonView(u, np.array([0.3 * cam.width, 0.2 * cam.height, 0.7 * cam.width, 0.8 * cam.height], np.float32),
                                       np.full(HIST_BINS, 1.0 / np.prod(HIST_BINS), np.float32))
        for _ in range(2):
            self.estimate_with_std([views] * self.max_batch)
        # onnxruntime also keeps a memory pattern per input shape it has run (up to max_batch of
        # them): made now, they cannot grow the host's memory later, e.g. when a flood of fake
        # people first brings batch sizes a quiet site never had (0.7 MB of a flood's 4.5 MB step, measured).
        for b in range(self.max_batch - 1, 0, -1):
            self.estimate_with_std([views] * b)

    def _check(self, site: Site, variant: Variant | None) -> None:
        spec, where = self.spec, str(self.path)
        if variant is not None and variant != spec.variant:
            raise ModelMismatchError(f"{where}: expected a {variant!r} variant model, this one is {spec.variant!r}")
        if spec.variant == "site" and spec.camera_ids != site.camera_ids:
            missing = [c for c in spec.camera_ids if c not in site.camera_ids]
            extra = [c for c in site.camera_ids if c not in spec.camera_ids]
            detail = (
                f"model cameras missing from the site: {missing or 'none'}; site cameras unknown to the model: {extra or 'none'}"
                if missing or extra
                else "same cameras in a different order"
            )
            raise ModelMismatchError(
                f"{where}: the model was trained for cameras {list(spec.camera_ids)} (in that order), "
                f"site {site.name!r} has {list(site.camera_ids)}: {detail}"
            )
        if spec.variant == "rays" and len(site.cameras) > spec.max_views:
            # Not an error: build_batch keeps the max_views views with the most detected joints.
            log.info("%s: site %r has %d cameras; each person's %d best views are used", where, site.name, len(site.cameras), spec.max_views)
        expected = {
            "x": [spec.num_nodes, spec.num_features],
            "adj": [spec.num_relations, spec.num_nodes, spec.num_nodes],
            "mask": [spec.num_nodes],
        }
        inputs = {i.name: i.shape for i in self.session.get_inputs()}
        for name in inputs:
            if name not in expected:
                raise ModelMismatchError(f"{where}: unexpected model input {name!r}; inputs are {', '.join(INPUT_NAMES)}")
            if list(inputs[name][1:]) != expected[name]:
                raise ModelMismatchError(
                    f"{where}: input {name!r} has shape {inputs[name]}, the metadata's graph spec implies [batch, {', '.join(map(str, expected[name]))}]"
                )
        outputs = [o.name for o in self.session.get_outputs()]
        if outputs not in ([OUTPUT_NAME], [OUTPUT_NAME, STD_OUTPUT_NAME]):
            raise ModelMismatchError(f"{where}: model outputs are {outputs}, expected [{OUTPUT_NAME!r}] or [{OUTPUT_NAME!r}, {STD_OUTPUT_NAME!r}]")

    @property
    def config(self) -> dict:
        """The model's architecture config, from its metadata (empty if absent)."""
        return json.loads(self.metadata.get(META_MODEL_CONFIG, "{}"))

    def estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> NDArray[np.float64]:
        """Poses of a batch of people, in one onnxruntime call.

        Args:
            view_sets: per person, camera id -> that camera's view of them (1 or more).

        Returns:
            (B, 3) float64 (x, y, yaw): metres in the world frame, yaw in (-pi, pi].

        Raises:
            ValueError: a view set is empty or names a camera the model does not know.
        """
        return self.estimate_with_std(view_sets)[0]

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates:
        """Poses, the network's calibrated sigmas, and the source "onnx" for every person."""
        pose, std = self.estimate_with_std(view_sets)
        return Estimates(pose, std, ("onnx",) * len(pose))

    def estimate_with_std(self, view_sets: Sequence[Mapping[str, PersonView]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Poses (B, 3) and their 1-sigma (B, 3) (x m, y m, yaw rad), ``max_batch`` people a call.

        The sigma is the network's own (``pose_std``) times the calibration in the metadata
        (``pose.std_scale``); NaN for a model without an uncertainty output.
        """
        if len(view_sets) == 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        names = [OUTPUT_NAME, STD_OUTPUT_NAME] if self.has_std else [OUTPUT_NAME]
        chunks = []
        for i in range(0, len(view_sets), self.max_batch):  # graphs built per chunk too: bounded buffers
            part = view_sets[i:i + self.max_batch]
            feeds = build_batch(part, self.site, self.spec, adjacency=self.reads_adj).feeds()
            if not self.reads_adj:
                B = len(part)
                if len(self._zero_adj) < B:
                    self._zero_adj = np.zeros((self.max_batch, *self._zero_adj.shape[1:]), np.float32)  # once: B <= max_batch
                feeds["adj"] = self._zero_adj[:B]
            chunks.append(self.session.run(names, {name: feeds[name] for name in self._inputs}))
        outs = [np.concatenate([c[k] for c in chunks]) for k in range(len(names))]
        pose = decode_output(outs[0], self.origin)
        if self.has_std:
            cams = np.minimum(np.fromiter(map(len, view_sets), np.intp, len(view_sets)), 3) - 1  # a view set has 1 view or more
            std = np.asarray(outs[1], np.float64) * self.std_scale[cams]  # (B, 3)
        else:
            std = np.full((len(pose), 3), np.nan)
        return pose, std
