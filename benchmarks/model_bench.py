"""Inference speed of exported pose models: graphs/s on one core, fp32 vs int8, batch 1 and 64.

    python -m benchmarks.model_bench [--model models/wtf-apartment.int8.onnx] [--seconds 2]
                                     [--compare OTHER.onnx ...] [--json-out F]

(from the repository; ``python benchmarks/model_bench.py`` works too.)

Given an int8 model, its fp32 twin (same stem, .fp32.onnx) is measured beside it. Inputs are
real superbody graphs built from simulated people in the model's site. The models are timed in
interleaved rounds (fp32, int8, fp32, ...) and each figure is the median over the rounds, so
load from other processes on a shared machine hits them alike. Graph building (numpy,
host.graph.build_batch) is timed separately: the host pays both per tick.

Absolute rates on shared machines move 2-3x between runs and machines, so the same rounds also
time a reference: the single fast GAT, one untrained GAT of the model's own architecture
(``model.config``: heads, hidden, layers), exported as the shipped networks are (fp32, the fast
GAT formulation of ``models.fast_gat``; weights do not change its speed). Each model's graphs/s
is also given over the reference's at the same batch size (``graphs_per_s_over_fast_gat``): an
ensemble of three such networks runs at about a third. Building the reference needs torch (the
``train`` extra); without it the ratio is left out and said so.

``--json-out F`` writes ``{"fp32": {"1": graphs/s, "64": graphs/s}, "int8": {...},
"fast_gat": {...}, "graphs_per_s_over_fast_gat": {"fp32": {"1": ratio, "64": ratio}, "int8": {...}}}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import onnxruntime as ort

from superbody.edge.resources import model_path, site_path
from superbody.edge.site import load_site
from superbody.host.estimation.estimator import META_READS_ADJ
from superbody.host.estimation.graph import GraphSpec, build_batch
from superbody.models.data.simdata import SimDataConfig, generate

BATCHES = (1, 64)
ROUNDS = 5
REFERENCE = "fast_gat"  # the single fast GAT's key in the results


def _rate(fn, seconds: float) -> float:
    """Seconds per call of ``fn``, measured for about ``seconds``."""
    fn()  # warm up
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n


def fast_gat_reference(meta: Mapping[str, str], spec: GraphSpec, out_dir: Path) -> Path | None:
    """The single fast GAT: one untrained GAT of the model's architecture (its ``model.config``;
    another architecture's model gets the default GAT), exported as ``models.export`` exports the
    shipped networks (fp32, fast GAT). None, said on stderr, where torch is not installed."""
    try:
        import torch

        from superbody.models.nets import build_model
        from superbody.models.training.export import export_onnx
    except ImportError as e:
        print(f"model_bench: no single fast GAT reference, so no ratios: {e} (install the train extra)", file=sys.stderr)
        return None
    cfg = json.loads(meta.get("model.config", "{}"))
    if cfg.pop("arch", "gat") != "gat":
        cfg = {k: v for k, v in cfg.items() if k in ("origin", "scale")}
    if "origin" in cfg:
        cfg["origin"] = tuple(cfg["origin"])
    torch.manual_seed(0)
    torch.set_num_threads(1)
    net = build_model("gat", spec, **cfg)
    return export_onnx(net, spec, {"purpose": "model_bench reference, untrained"}, out_dir / "fast-gat-reference.fp32.onnx")


def main(model: Path, site_path: Path, seconds: float, json_out: str | None, compare: list[Path] = ()) -> int:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    site = load_site(site_path)
    sess_opts = ort.SessionOptions()
    sess_opts.intra_op_num_threads = 1
    sess_opts.inter_op_num_threads = 1
    sess_opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL  # as the host runs them
    meta = ort.InferenceSession(str(model), sess_opts, providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
    spec = GraphSpec.from_metadata(meta)
    samples = generate(site, SimDataConfig(samples=256, seed=99), workers=1, progress=False)
    views = [s.views for s in samples]
    batches = {b: build_batch(views[:b], site, spec).feeds() for b in BATCHES}
    paths = {"fp32": model.with_name(model.name.replace(".int8.onnx", ".fp32.onnx")), "int8": model}
    paths.update({p.name: p for p in compare})
    with tempfile.TemporaryDirectory(prefix="model-bench-") as tmp:
        reference = fast_gat_reference(meta, spec, Path(tmp))
        if reference is not None:
            paths[REFERENCE] = reference
        sessions, feeds = {}, {}
        for kind, path in paths.items():
            if path.is_file():
                sessions[kind] = s = ort.InferenceSession(str(path), sess_opts, providers=["CPUExecutionProvider"])
                feeds[kind] = {b: {i.name: f[i.name] for i in s.get_inputs()} for b, f in batches.items()}
        sizes = {kind: paths[kind].stat().st_size for kind in sessions}
    per_call: dict[str, dict[int, list[float]]] = {k: {b: [] for b in BATCHES} for k in sessions}
    for _ in range(ROUNDS):  # interleaved: every model in every round, the reference too
        for kind, sess in sessions.items():
            for b in BATCHES:
                per_call[kind][b].append(_rate(lambda s=sess, f=feeds[kind][b]: s.run(None, f), seconds / ROUNDS))
    rate = {kind: {b: b / float(np.median(calls[b])) for b in BATCHES} for kind, calls in per_call.items()}
    ref = rate.get(REFERENCE)
    print(f"model {model.name} ({meta.get('graph.variant', '?')} variant, {spec.num_nodes} nodes x {spec.num_features} features), one core, "
          f"median of {ROUNDS} interleaved rounds; x fast GAT = graphs/s over the single fast GAT's (untrained, same architecture) in these rounds")
    print(f"{'':>40} {'batch':>6} {'ms/call':>9} {'graphs/s':>10} {'x fast GAT':>10} {'size KB':>8} {'formulation':>12}")
    results: dict[str, dict[str, float]] = {}
    ratios: dict[str, dict[str, float]] = {}
    for kind in per_call:
        m = sessions[kind].get_modelmeta().custom_metadata_map
        form = m.get("export.formulation", "dense") + ("" if m.get(META_READS_ADJ, "true") == "true" else ", mask")
        for b in BATCHES:
            g = rate[kind][b]
            r = g / ref[b] if ref else None
            if kind in ("fp32", "int8", REFERENCE):
                results.setdefault(kind, {})[str(b)] = g
            if kind in ("fp32", "int8") and r is not None:
                ratios.setdefault(kind, {})[str(b)] = r
            shown = "ref" if kind == REFERENCE else (f"{r:.2f}" if r is not None else "-")
            print(f"{kind:>40} {b:>6} {b / g * 1e3:9.3f} {g:10.0f} {shown:>10} {sizes[kind] / 1e3:8.0f} {form:>12}")
    if ratios:
        results["graphs_per_s_over_fast_gat"] = ratios  # type: ignore[assignment]
    if "fp32" in results and "int8" in results:
        print(f"int8 / fp32 at batch 64: {results['int8']['64'] / results['fp32']['64']:.2f}")
    for b in (1, 10, 64):
        for adj in (True, False):
            t = _rate(lambda v=views[:b], a=adj: build_batch(v, site, spec, adjacency=a), seconds / 4)
            print(f"graph building, {b:>2} people{'' if adj else ', no edges (mask-only models)'}: {t * 1e3:.3f} ms")
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=model_path("wtf-apartment.int8.onnx"))
    p.add_argument("--site", type=Path, default=site_path("wtf-apartment"))
    p.add_argument("--seconds", type=float, default=2.0, help="time per model and batch size, all rounds together (default 2)")
    p.add_argument("--compare", type=Path, action="append", default=[], help="another model of the same spec to time beside them (printed only)")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.model, a.site, a.seconds, a.json_out, a.compare))
