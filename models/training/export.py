"""ONNX export and int8 quantisation of the pose networks.

The exported model (what ``host.estimation.estimator.OnnxEstimator`` runs)::

    inputs   x    (batch, N, F)     float32   node features      (host.estimation.graph.build_batch)
             adj  (batch, R, N, N)  float32   0/1 per relation
             mask (batch, N)        float32   1 = node present
    outputs  pose (batch, 4)        float32   (x, y, sin yaw, cos yaw), x and y in metres
             pose_std (batch, 3)    float32   the network's own 1-sigma: x, y (m), yaw (rad)

The network's normalised output is scaled back to metres inside the graph; ``pose[:, :2]`` is
in the frame named by the metadata key ``pose.frame``: "world" for "site" models (the origin
is baked in too), "floor_centre" for "rays" models (add the serving site's
``host.estimation.graph.floor_centre``). sin and cos are the network's raw outputs (not renormalised);
yaw = atan2(sin, cos).

Metadata (``metadata_props``, all strings): the GraphSpec (``graph.*``), ``pose.frame``,
``pose.scale``, ``pose.origin`` (JSON [x, y]), ``model.config`` (JSON: arch, hyper-parameters,
normalisation), ``train.config`` (JSON: the training run's config), ``ensemble.members`` for
an ensemble (several networks combined in the graph, ``models.training.ensemble``), and for int8 models
``quant.*`` (format, node-name fragments kept in fp32 and how many products they kept and
quantised, calibration size, source file, and ``quant.drift``:
how far the int8 poses are from the fp32 ones on the calibration graphs).
"""

from __future__ import annotations

import json
import tempfile
import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import onnx
import onnxruntime as ort
import torch
import torch.nn as nn
from numpy.typing import NDArray
from onnxruntime.quantization import CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process

from superbody.host.estimation.estimator import (
    INPUT_NAMES,
    META_MODEL_CONFIG,
    META_POSE_FRAME,
    META_POSE_ORIGIN,
    META_POSE_SCALE,
    META_READS_ADJ,
    META_TRAIN_CONFIG,
    OUTPUT_NAME,
    STD_OUTPUT_NAME,
)
from superbody.host.estimation.graph import GraphBatch, GraphSpec
from superbody.models.fast_gat import FastGAT
from superbody.models.nets import GAT, PoseNet, build_model

# How the network was written out: "fast_gat" (models.fast_gat) or "dense" (the training graph).
META_EXPORT_FORMULATION = "export.formulation"
# How many networks an ensemble model combines (absent: one).
META_ENSEMBLE = "ensemble.members"

__all__ = ["export_onnx", "quantize_int8", "read_metadata", "load_onnx_model", "reexport", "GraphBatchReader", "QUANTIZED_OPS", "KEEP_FP32",
           "META_EXPORT_FORMULATION", "META_ENSEMBLE"]

# Only the products are quantised: they hold the arithmetic. Quantising every op (softmax,
# the -1e9 attention mask, residual adds) wrecked a trained GAT (position error x9).
QUANTIZED_OPS: tuple[str, ...] = ("MatMul", "Gemm")
# Per architecture, node-name fragments kept in fp32 by default: the layer that reads the raw
# features (their columns mix scales, one-hots, pixels and metres, so one int8 range per tensor
# blurs the fine ones) and the GNNs' first message-passing layer. Measured on models trained
# on simulated graphs (600 steps), position / yaw MAE int8 vs fp32: everything quantised,
# "rays" GAT +4.6% / +4.7%, "site" RGCN +6.7%; with these kept in fp32 every model of both
# variants stayed within +2.5% / +0.5%, at about the same speed.
# A GAT exported as the fast GAT (the default) names its nodes after models.fast_gat: its input
# layer "/body/embed/", its first layer's projection "/body/lin/", and its attention products
# (activations times activations, every layer) "/body/MatMul*". The dense names alone matched
# none of them, so every product was quantised. Measured on dev.json with the simulation-only
# model (never trained on it), x / y / yaw MAE int8 against fp32: all quantised +8.2% / +0.2% /
# +7.1%; these kept in fp32 +1.0% / -1.8% / +3.2% (yaw drift from fp32 1.8 -> 0.9 deg mean).
KEEP_FP32: dict[str, tuple[str, ...]] = {
    "gat": ("/net/embed/", "/net/layers.0/", "/body/embed/", "/body/lin/", "/body/MatMul"),
    "rgcn": ("/net/embed/", "/net/layers.0/"),
    "mlp": ("/net/slot/slot.0/",),
}


# Weights as uint8, not int8: onnxruntime multiplies uint8 activations by int8 weights with
# VPMADDUBSW on x86 CPUs without VNNI (AVX2, AVX-512 before Cascade Lake), which adds two
# products in 16 bits and saturates. The same int8 file then gives other poses on such a CPU:
# measured on this repository's test GAT (256 unseen graphs, mean / max position difference from
# fp32) 7 / 25 mm on an AVX-512 VNNI Xeon and 33 / 109 mm on an emulated Haswell (qemu-x86_64
# -cpu Haswell); with everything quantised 9 / 23 mm and 140 / 280 mm. uint8 x uint8 never
# saturates: 9 / 38 mm and 6 / 23 mm on both CPUs, bit for bit the same poses.
WEIGHT_TYPE = QuantType.QUInt8


class _ExportedPose(nn.Module):
    """The network plus its output denormalisation: normalised (B, 7) -> pose in metres (B, 4)
    and its 1-sigma (B, 3) (x, y metres, yaw radians). With ``fast``, a GAT runs as
    ``models.fast_gat.FastGAT`` (same outputs, a fraction of the work)."""

    gain: torch.Tensor  # buffers, registered in __init__
    offset: torch.Tensor
    std_gain: torch.Tensor

    def __init__(self, net: PoseNet, fast: bool = False):
        super().__init__()
        self.net = net
        self.body: nn.Module = FastGAT(net) if fast and isinstance(net, GAT) else net
        s = net.scale
        ox, oy = net.origin if net.spec.variant == "site" else (0.0, 0.0)
        self.register_buffer("gain", torch.tensor([s, s, 1.0, 1.0]))
        self.register_buffer("offset", torch.tensor([ox, oy, 0.0, 0.0]))
        self.register_buffer("std_gain", torch.tensor([s, s, 1.0]))

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.body(x, adj, mask)  # (B, 7)
        pose = out[:, :4] * self.gain + self.offset  # (B, 4)
        std = torch.exp(out[:, 4:7].clamp(-12.0, 4.0)) * self.std_gain  # (B, 3)
        return pose, std


class _ExportedEnsemble(nn.Module):
    """Several ``_ExportedPose`` as one: the members' poses and sigmas combined as
    ``models.training.ensemble.combine`` does (mean position, circular-mean yaw as a unit (sin, cos), the
    sigma of the members' equal mixture)."""

    def __init__(self, members: Sequence[_ExportedPose]):
        super().__init__()
        self.members = nn.ModuleList(members)

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        outs = [m(x, adj, mask) for m in self.members]
        pose = torch.stack([o[0] for o in outs])  # (K, B, 4)
        std = torch.stack([o[1] for o in outs])  # (K, B, 3)
        u = pose[..., 2:4] / pose[..., 2:4].norm(dim=-1, keepdim=True).clamp_min(1e-9)  # (K, B, 2) unit (sin, cos)
        mean_u = u.mean(0)  # (B, 2)
        unit = mean_u / mean_u.norm(dim=-1, keepdim=True).clamp_min(1e-9)
        xy = pose[..., :2].mean(0)  # (B, 2)
        spread = torch.cat([(pose[..., :2] - xy) ** 2, ((u - unit) ** 2).sum(-1, keepdim=True)], dim=-1)  # (K, B, 3)
        return torch.cat([xy, mean_u], dim=-1), torch.sqrt((std**2).mean(0) + spread.mean(0))


def _metadata(model: PoseNet, spec: GraphSpec, config: Mapping) -> dict[str, str]:
    meta = dict(spec.to_metadata())
    site_model = spec.variant == "site"
    meta[META_POSE_FRAME] = "world" if site_model else "floor_centre"
    meta[META_POSE_SCALE] = repr(model.scale)
    meta[META_POSE_ORIGIN] = json.dumps(list(model.origin) if site_model else [0.0, 0.0])
    meta[META_MODEL_CONFIG] = json.dumps(model.config(), sort_keys=True)
    meta[META_TRAIN_CONFIG] = json.dumps(dict(config), sort_keys=True, default=str)
    return meta


def _set_metadata(proto: onnx.ModelProto, meta: Mapping[str, str]) -> None:
    keep = [p for p in proto.metadata_props if p.key not in meta]
    del proto.metadata_props[:]
    proto.metadata_props.extend(keep)
    for key, value in meta.items():
        proto.metadata_props.add(key=key, value=value)


def read_metadata(path: str | Path) -> dict[str, str]:
    """The metadata_props of an ONNX file."""
    return {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}


def _declare_all_inputs(proto: onnx.ModelProto, spec: GraphSpec) -> None:
    """Keep the (x, adj, mask) interface for models that ignore an input (the MLP's adj):
    the exporter drops unused inputs, onnxruntime accepts declared-but-unused ones."""
    shapes: dict[str, list[str | int]] = {
        "x": ["batch", spec.num_nodes, spec.num_features],
        "adj": ["batch", spec.num_relations, spec.num_nodes, spec.num_nodes],
        "mask": ["batch", spec.num_nodes],
    }
    present = {i.name: i for i in proto.graph.input}
    inputs = [present.get(n) or onnx.helper.make_tensor_value_info(n, onnx.TensorProto.FLOAT, shapes[n]) for n in INPUT_NAMES]
    del proto.graph.input[:]
    proto.graph.input.extend(inputs)


def export_onnx(model: PoseNet | Sequence[PoseNet], spec: GraphSpec, config: Mapping, path: str | Path, opset: int = 17, fast: bool = True) -> Path:
    """Write the model as fp32 ONNX with a dynamic batch axis and its metadata.

    Args:
        model: a network from ``models.nets.build_model``, or several alike (same spec, scale
            and origin): an ensemble, combined inside the graph as ``models.training.ensemble.combine``
            does (metadata ``ensemble.members``: how many).
        spec: the graph spec it was built for (must equal ``model.spec``).
        config: the training config to store (JSON-able; other values are stored as str()).
        path: the .onnx file to write.
        opset: ONNX opset.
        fast: export a GAT as ``models.fast_gat.FastGAT``: the same outputs on the graphs
            ``host.estimation.graph.build_batch`` makes, 3-5x faster; it reads the graph's edges from
            ``mask`` (``adj`` stays an input, unread: metadata ``model.reads_adj`` "false").
            Other architectures export as they are.

    Returns:
        The path written.
    """
    models = [model] if isinstance(model, PoseNet) else list(model)
    if not models:
        raise ValueError("export_onnx: no model given")
    for m in models:
        if m.spec != spec:
            raise ValueError(f"export_onnx: the model was built for {m.spec}, not {spec}")
        if (m.arch, m.scale, tuple(m.origin)) != (models[0].arch, models[0].scale, tuple(models[0].origin)):
            raise ValueError("export_onnx: an ensemble's members must share arch, output scale and origin")
    model = models[0]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    was_training = [m.training for m in models]
    members = [_ExportedPose(m, fast=fast).eval() for m in models]
    wrapper = members[0] if len(members) == 1 else _ExportedEnsemble(members).eval()
    formulation = "fast_gat" if isinstance(members[0].body, FastGAT) else "dense"
    B = 2  # any size: the batch axis is exported as dynamic
    example = (
        torch.rand(B, spec.num_nodes, spec.num_features),
        (torch.rand(B, spec.num_relations, spec.num_nodes, spec.num_nodes) > 0.5).float(),
        torch.ones(B, spec.num_nodes),
    )
    batch_axis = {n: {0: "batch"} for n in (*INPUT_NAMES, OUTPUT_NAME, STD_OUTPUT_NAME)}
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # The TorchScript exporter is deprecated; the dynamo one needs onnxscript, which is
            # not a dependency. This one is exact for these plain dense models.
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(
                wrapper, example, str(path), dynamo=False, opset_version=opset,
                input_names=list(INPUT_NAMES), output_names=[OUTPUT_NAME, STD_OUTPUT_NAME], dynamic_axes=batch_axis,
                do_constant_folding=True,
            )
    finally:
        for m, t in zip(models, was_training):
            m.train(t)
    proto = onnx.load(str(path))
    _declare_all_inputs(proto, spec)
    proto.producer_name = "superbody"
    proto.doc_string = (f"superbody {model.arch} pose network; output pose (batch, 4) = x, y (m, frame: metadata pose.frame), "
                        "sin yaw, cos yaw; pose_std (batch, 3) = predicted 1-sigma of x, y (m) and yaw (rad)")
    meta = _metadata(model, spec, config)
    if len(models) > 1:
        proto.doc_string += f"; an ensemble of {len(models)} networks (models.training.ensemble)"
        meta[META_ENSEMBLE] = str(len(models))
    meta[META_EXPORT_FORMULATION] = formulation
    meta[META_READS_ADJ] = "false" if formulation == "fast_gat" or model.arch == "mlp" else "true"
    _set_metadata(proto, meta)
    onnx.checker.check_model(proto)
    onnx.save(proto, str(path))
    return path


class GraphBatchReader(CalibrationDataReader):
    """Feeds graph batches to onnxruntime's calibrator, one batch per call."""

    def __init__(self, batches: Iterable[GraphBatch | Mapping[str, NDArray[np.float32]]]):
        self._it: Iterator = iter(batches)
        self.count = 0

    def get_next(self) -> dict[str, NDArray[np.float32]] | None:
        b = next(self._it, None)
        if b is None:
            return None
        self.count += 1
        feeds = b.feeds() if isinstance(b, GraphBatch) else dict(b)
        return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in feeds.items()}


def quantize_int8(
    fp32_path: str | Path,
    int8_path: str | Path,
    calibration_batches: Iterable[GraphBatch | Mapping[str, NDArray[np.float32]]],
    per_channel: bool = True,
    keep_fp32: Sequence[str] | None = None,
    activations: Literal["uint8", "uint16"] = "uint8",
) -> Path:
    """Static quantisation (QDQ) of an exported model: 8-bit weights, keeping its metadata.

    Weights are uint8 (``WEIGHT_TYPE``; per output channel with ``per_channel``); activations
    are uint8 (or uint16, ``activations``) with ranges from MinMax calibration on ``calibration_batches``
    (graph batches built from training samples: a few hundred graphs is enough; they are held
    in memory). Only MatMul/Gemm are quantised (``QUANTIZED_OPS``), except nodes whose name
    contains one of ``keep_fp32``; by default, the architecture's ``KEEP_FP32`` (the input
    layer, the GNNs' first message-passing layer and the fast GAT's attention products: the
    most sensitive to int8).

    The int8 model's drift from the fp32 one on the calibration graphs (position: metres;
    yaw: degrees; mean and max) is stored in the metadata as ``quant.drift`` (JSON).

    Returns:
        The path written.
    """
    fp32_path, int8_path = Path(fp32_path), Path(int8_path)
    meta = read_metadata(fp32_path)
    spec = GraphSpec.from_metadata(meta)
    batches = [b.feeds() if isinstance(b, GraphBatch) else dict(b) for b in calibration_batches]
    if not batches:
        raise ValueError("quantize_int8: calibration_batches is empty; give a few hundred training graphs")
    if activations not in ("uint8", "uint16"):
        raise ValueError(f"quantize_int8: activations must be 'uint8' or 'uint16', got {activations!r}")
    if keep_fp32 is None:
        keep_fp32 = KEEP_FP32.get(json.loads(meta.get(META_MODEL_CONFIG, "{}")).get("arch", ""), ())
    with tempfile.TemporaryDirectory() as tmp:
        pre = Path(tmp) / "pre.onnx"
        # Shape inference and graph optimisation first, as onnxruntime recommends.
        quant_pre_process(str(fp32_path), str(pre), skip_symbolic_shape=True)
        nodes = [n.name for n in onnx.load(str(pre)).graph.node if n.op_type in QUANTIZED_OPS]
        kept = [n for n in nodes if any(k in n for k in keep_fp32)]
        quantize_static(
            str(pre), str(int8_path), GraphBatchReader(batches),
            quant_format=QuantFormat.QDQ, per_channel=per_channel,
            activation_type=QuantType.QUInt8 if activations == "uint8" else QuantType.QUInt16,
            weight_type=WEIGHT_TYPE,
            op_types_to_quantize=list(QUANTIZED_OPS), calibrate_method=CalibrationMethod.MinMax,
            nodes_to_exclude=kept,
        )
    proto = onnx.load(str(int8_path))
    _declare_all_inputs(proto, spec)
    meta.update({
        "quant.format": f"QDQ, uint8 weights, {activations} activations, MinMax calibration",
        "quant.ops": ",".join(QUANTIZED_OPS),
        "quant.keep_fp32": json.dumps(list(keep_fp32)),
        "quant.fp32_nodes": str(len(kept)),  # how many of the products those fragments kept in fp32
        "quant.int8_nodes": str(len(nodes) - len(kept)),
        "quant.per_channel": "true" if per_channel else "false",
        "quant.calibration_batches": str(len(batches)),
        "quant.calibration_graphs": str(sum(len(b["x"]) for b in batches)),
        "quant.source": fp32_path.name,
    })
    _set_metadata(proto, meta)
    onnx.save(proto, str(int8_path))
    meta["quant.drift"] = json.dumps(_drift(fp32_path, int8_path, batches))
    _set_metadata(proto, meta)
    onnx.save(proto, str(int8_path))
    return int8_path


def _drift(fp32_path: Path, int8_path: Path, batches: list[dict[str, NDArray[np.float32]]]) -> dict[str, float]:
    """How far the int8 model's poses are from the fp32 model's on the same graphs."""
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    runs = []
    for path in (fp32_path, int8_path):
        s = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        names = [i.name for i in s.get_inputs()]
        runs.append(np.concatenate([s.run([OUTPUT_NAME], {n: b[n] for n in names})[0] for b in batches]).astype(np.float64))
    ref, out = runs  # (G, 4) each
    pos = np.linalg.norm(out[:, :2] - ref[:, :2], axis=1)  # (G,)
    yaw = np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(out[:, 2], out[:, 3]) - np.arctan2(ref[:, 2], ref[:, 3]))))))  # (G,)
    return {
        "graphs": int(len(ref)),
        "pos_mean_m": round(float(pos.mean()), 5), "pos_max_m": round(float(pos.max()), 5),
        "yaw_mean_deg": round(float(yaw.mean()), 3), "yaw_max_deg": round(float(yaw.max()), 3),
    }


def load_onnx_model(path: str | Path, check_batch: GraphBatch | None = None) -> PoseNet:
    """The PyTorch network inside an exported fp32 model (any formulation), from its metadata
    (``model.config``, ``graph.*``) and weights, e.g. to export it again in another form.

    Parameters come from the initializers of the same name, or, for the linear layers the
    exporter turned into a bare MatMul, from that MatMul's weight (transposed). The result is
    checked against the file under onnxruntime on ``check_batch`` (or a batch of random
    present-node graphs): ``ValueError`` if they differ by more than 1e-4.
    """
    path = Path(path)
    proto = onnx.load(str(path))
    meta = {p.key: p.value for p in proto.metadata_props}
    spec = GraphSpec.from_metadata(meta)
    if META_ENSEMBLE in meta:
        raise ValueError(f"{path}: an ensemble of {meta[META_ENSEMBLE]} networks; export its members' checkpoints again instead")
    cfg = json.loads(meta.get(META_MODEL_CONFIG, "{}"))
    arch = cfg.pop("arch", None)
    if arch is None:
        raise ValueError(f"{path}: no {META_MODEL_CONFIG} metadata with an arch")
    cfg["origin"] = tuple(cfg.get("origin", (0.0, 0.0)))
    net = build_model(arch, spec, **cfg)
    inits = {i.name: onnx.numpy_helper.to_array(i) for i in proto.graph.initializer}
    matmul_weight = {}  # module path -> the MatMul's weight (in, out)
    for node in proto.graph.node:
        if node.op_type == "MatMul":
            w = [i for i in node.input if i in inits]
            if len(w) == 1:
                matmul_weight[node.name.replace("/", ".")] = inits[w[0]]
    state = {}
    for key, param in net.state_dict().items():
        found = [v for n, v in inits.items() if n == f"net.{key}" or n.endswith(f".net.{key}")]
        if not found and key.endswith(".weight"):
            module = "." + key[: -len(".weight")] + "."
            found = [w.T for n, w in matmul_weight.items() if module in n + "."]
            found = found[:1] if all(np.array_equal(found[0], f) for f in found) else found
        if len(found) != 1 or tuple(found[0].shape) != tuple(param.shape):
            raise ValueError(f"{path}: cannot find parameter {key!r} {tuple(param.shape)} in the ONNX initializers")
        state[key] = torch.from_numpy(np.array(found[0], dtype=np.float32))
    net.load_state_dict(state)
    net.eval()
    _check_against(net, path, spec, check_batch)
    return net


def _check_against(net: PoseNet, path: Path, spec: GraphSpec, batch: GraphBatch | None) -> None:
    if batch is None:
        rng = np.random.default_rng(0)
        mask = (rng.uniform(size=(16, spec.num_nodes)) > 0.3).astype(np.float32)
        mask[:, 0] = 1.0
        mask[:, 1 :: 18] = 1.0  # body nodes present
        x = (rng.normal(size=(16, spec.num_nodes, spec.num_features)) * mask[:, :, None]).astype(np.float32)
        from superbody.host.estimation.graph import masked_adjacency

        batch = GraphBatch(x=x, adj=masked_adjacency(spec, mask), mask=mask)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    feeds = batch.feeds()
    ref = sess.run([OUTPUT_NAME], {i.name: feeds[i.name] for i in sess.get_inputs()})[0]
    with torch.no_grad():
        out = _ExportedPose(net)(*(torch.from_numpy(feeds[n]) for n in INPUT_NAMES))[0].numpy()
    err = float(np.abs(out - ref).max())
    if not err <= 1e-4:
        raise ValueError(f"{path}: the network rebuilt from the file differs from it by {err:.2g} (> 1e-4)")


def reexport(src: str | Path, dst: str | Path, fast: bool = True, opset: int = 17) -> Path:
    """Export an exported fp32 model again (``export_onnx``, e.g. as the fast GAT), keeping
    every metadata entry of the source (training config, calibrations) but the export's own."""
    src, dst = Path(src), Path(dst)
    meta = read_metadata(src)
    net = load_onnx_model(src)
    config = json.loads(meta.get(META_TRAIN_CONFIG, "{}"))
    tmp = dst.with_name(dst.name + ".tmp")
    export_onnx(net, net.spec, config, tmp, opset=opset, fast=fast)
    proto = onnx.load(str(tmp))
    fresh = {p.key: p.value for p in proto.metadata_props}
    _set_metadata(proto, {**meta, **{k: fresh[k] for k in (META_EXPORT_FORMULATION, META_READS_ADJ)}})
    onnx.save(proto, str(dst))
    tmp.unlink()
    return dst


if __name__ == "__main__":
    # python -m superbody.models.training.export models/wtf-apartment.fp32.onnx [...]: re-export shipped
    # fp32 models in place (e.g. as the fast GAT), keeping their metadata.
    import argparse
    import sys

    p = argparse.ArgumentParser(description="Export fp32 pose models again (as the fast GAT by default), in place, keeping their metadata.")
    p.add_argument("models", nargs="+", type=Path, help="fp32 .onnx files written by export_onnx")
    p.add_argument("--dense", action="store_true", help="the training graph instead of the fast GAT")
    a = p.parse_args()
    for m in a.models:
        if not m.is_file():
            print(f"superbody export: error: {m}: no such file", file=sys.stderr)
            sys.exit(2)
        reexport(m, m, fast=not a.dense)
        print(f"{m}: {read_metadata(m)[META_EXPORT_FORMULATION]}")
