"""Inference speed of exported pose models: graphs/s on one core, fp32 vs int8, batch 1 and 64.

    python benchmarks/model_bench.py [--model models/wtf-apartment.int8.onnx] [--seconds 3]
                                     [--compare OTHER.onnx ...] [--json-out F]

Given an int8 model, its fp32 twin (same stem, .fp32.onnx) is measured beside it. Inputs are
real superbody graphs built from simulated people in the model's site. The models are timed in
interleaved rounds (fp32, int8, fp32, ...) and each figure is the median over the rounds, so
load from other processes on a shared machine hits them alike. Graph building (numpy,
host.graph.build_batch) is timed separately: the host pays both per tick.

``--json-out F`` writes ``{"fp32": {"1": graphs/s, "64": graphs/s}, "int8": {...}}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import onnxruntime as ort  # noqa: E402

from superbody.edge.resources import model_path, site_path  # noqa: E402
from superbody.edge.site import load_site  # noqa: E402
from superbody.host.estimator import META_READS_ADJ  # noqa: E402
from superbody.host.graph import GraphSpec, build_batch  # noqa: E402
from superbody.models.simdata import SimDataConfig, generate  # noqa: E402

BATCHES = (1, 64)
ROUNDS = 5


def _rate(fn, seconds: float) -> float:
    """Seconds per call of ``fn``, measured for about ``seconds``."""
    fn()  # warm up
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n


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
    sessions, feeds = {}, {}
    for kind, path in paths.items():
        if path.is_file():
            sessions[kind] = s = ort.InferenceSession(str(path), sess_opts, providers=["CPUExecutionProvider"])
            feeds[kind] = {b: {i.name: f[i.name] for i in s.get_inputs()} for b, f in batches.items()}
    per_call: dict[str, dict[int, list[float]]] = {k: {b: [] for b in BATCHES} for k in sessions}
    for _ in range(ROUNDS):  # interleaved: every model in every round
        for kind, sess in sessions.items():
            for b in BATCHES:
                per_call[kind][b].append(_rate(lambda: sess.run(None, feeds[kind][b]), seconds / ROUNDS))
    print(f"model {model.name} ({meta.get('graph.variant', '?')} variant, {spec.num_nodes} nodes x {spec.num_features} features), one core, "
          f"median of {ROUNDS} interleaved rounds")
    print(f"{'':>40} {'batch':>6} {'ms/call':>9} {'graphs/s':>10} {'size KB':>8} {'formulation':>12}")
    results: dict[str, dict[str, float]] = {}
    for kind, calls in per_call.items():
        m = sessions[kind].get_modelmeta().custom_metadata_map
        form = m.get("export.formulation", "dense") + ("" if m.get(META_READS_ADJ, "true") == "true" else ", mask")
        for b in BATCHES:
            t = float(np.median(calls[b]))
            if kind in ("fp32", "int8"):
                results.setdefault(kind, {})[str(b)] = b / t
            print(f"{kind:>40} {b:>6} {t * 1e3:9.3f} {b / t:10.0f} {paths[kind].stat().st_size / 1e3:8.0f} {form:>12}")
    if "fp32" in results and "int8" in results:
        print(f"int8 / fp32 at batch 64: {results['int8']['64'] / results['fp32']['64']:.2f}")
    for b in (1, 10, 64):
        for adj in (True, False):
            t = _rate(lambda: build_batch(views[:b], site, spec, adjacency=adj), seconds / 4)
            print(f"graph building, {b:>2} people{'' if adj else ', no edges (mask-only models)'}: {t * 1e3:.3f} ms")
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=model_path("wtf-apartment.int8.onnx"))
    p.add_argument("--site", type=Path, default=site_path("wtf-apartment"))
    p.add_argument("--seconds", type=float, default=3.0, help="time per model and batch size, all rounds together")
    p.add_argument("--compare", type=Path, action="append", default=[], help="another model of the same spec to time beside them (printed only)")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.model, a.site, a.seconds, a.json_out, a.compare))
