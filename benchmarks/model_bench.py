"""Inference speed of exported pose models: graphs/s on one core, fp32 vs int8, batch 1 and 64.

    python benchmarks/model_bench.py [--model models/wtf-apartment.int8.onnx] [--seconds 3]

Given an int8 model, its fp32 twin (same stem, .fp32.onnx) is measured beside it. Inputs are
real superbody graphs built from simulated people in the model's site. Graph building (numpy,
host.graph.build_batch) is timed separately: the host pays both per tick.
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

import onnxruntime as ort  # noqa: E402

from superbody.edge.resources import model_path, site_path  # noqa: E402
from superbody.edge.site import load_site  # noqa: E402
from superbody.host.graph import GraphSpec, build_batch  # noqa: E402
from superbody.models.simdata import SimDataConfig, generate  # noqa: E402


def _rate(fn, seconds: float) -> tuple[float, int]:
    fn()  # warm up
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n, n


def main(model: Path, site_path: Path, seconds: float, json_out: str | None) -> int:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    site = load_site(site_path)
    sess_opts = ort.SessionOptions()
    sess_opts.intra_op_num_threads = 1
    sess_opts.inter_op_num_threads = 1
    meta = ort.InferenceSession(str(model), sess_opts, providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
    spec = GraphSpec.from_metadata(meta)
    samples = generate(site, SimDataConfig(samples=256, seed=99), workers=1, progress=False)
    views = [s.views for s in samples]
    batches = {b: build_batch(views[:b], site, spec).feeds() for b in (1, 64)}
    results = {}
    paths = {"fp32": model.with_name(model.name.replace(".int8.onnx", ".fp32.onnx")), "int8": model}
    print(f"model {model.name} ({meta.get('graph.variant', '?')} variant, {spec.num_nodes} nodes x {spec.num_features} features), one core")
    print(f"{'':>6} {'batch':>6} {'ms/call':>9} {'graphs/s':>10} {'size MB':>8}")
    for kind, path in paths.items():
        if not path.is_file():
            continue
        sess = ort.InferenceSession(str(path), sess_opts, providers=["CPUExecutionProvider"])
        for b, feeds in batches.items():
            per_call, _ = _rate(lambda: sess.run(None, feeds), seconds)
            results[f"{kind}_b{b}"] = {"ms_per_call": per_call * 1e3, "graphs_per_s": b / per_call}
            print(f"{kind:>6} {b:>6} {per_call * 1e3:9.3f} {b / per_call:10.0f} {path.stat().st_size / 1e6:8.2f}")
    for b in (1, 10, 64):
        per_call, _ = _rate(lambda: build_batch(views[:b], site, spec), seconds / 2)
        results[f"build_b{b}"] = {"ms_per_call": per_call * 1e3}
        print(f"graph building, {b:>2} people: {per_call * 1e3:.3f} ms")
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=model_path("wtf-apartment.int8.onnx"))
    p.add_argument("--site", type=Path, default=site_path("wtf-apartment"))
    p.add_argument("--seconds", type=float, default=3.0, help="time per measurement")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.model, a.site, a.seconds, a.json_out))
