"""The temporal filter's acceleration noise against the live error, on simulated recordings.

    python benchmarks/filter_tuning.py [--model models/wtf-apartment.int8.onnx | --analytic]
        [--accel 1.5,2,2.5,3,4,6] [--recordings 8] [--duration 30] [--json-out F]

Each recording is one simulated person walking in the shipped WheresTheFellow site, captured
like dev.json (``models.temporal.simulated_recording``: unsynchronised cameras at 8 Hz, the
truth exact and on the cameras' clock). Each is replayed through the host's aggregator
(``models.temporal.replay``: tracker, estimator, filter) once per ``FilterConfig.accel_std_mps2``,
all else at the host's defaults, and scored at each sample's capture time. The figure per value
is the mean over recordings of the x / y MAE (mm) and of the sample-to-sample jitter of the
position error (``models.temporal.jitter``, mm): less noise means more lag, and the other way round.
This is how ``FilterConfig``'s default was chosen (the least position error); the real-data check
is ``superbody crossval --split space --temporal`` (models/MODEL_CARD.md).
``--json-out F`` writes ``{"accel_std_mps2": [...], "x_mm": [...], "y_mm": [...], "yaw_deg": [...],
"jitter_mm": [...], "recordings", "duration_s", "estimator"}``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from superbody.edge.angles import wrap_angle
from superbody.edge.resources import site_path
from superbody.edge.site import load_site
from superbody.host.aggregator import HostConfig
from superbody.host.filtering.pose_filter import FilterConfig
from superbody.models.evaluation.evaluate import predict
from superbody.models.evaluation.temporal import replay, simulated_recording
from superbody.models.evaluation.temporal_scores import jitter

ROOT = Path(__file__).resolve().parents[1]


def _floats(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--accel must be comma-separated numbers, got {text!r}") from None
    for v in values:
        try:
            FilterConfig(accel_std_mps2=v)  # the filter's own range check names the field and the range
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return values


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", type=Path, default=ROOT / "models" / "wtf-apartment.int8.onnx", help="ONNX model, run as the host's hybrid")
    p.add_argument("--analytic", action="store_true", help="use the analytic estimator instead of --model")
    p.add_argument("--accel", type=_floats, default=[1.5, 2.0, 2.5, 3.0, 4.0, 6.0], help="accel_std_mps2 values, comma-separated")
    p.add_argument("--recordings", type=int, default=8, help="simulated recordings, seeds 0..N-1 (1-100)")
    p.add_argument("--duration", type=float, default=30.0, help="seconds per recording (1-600)")
    p.add_argument("--json-out", type=Path)
    args = p.parse_args(argv)
    if not 1 <= args.recordings <= 100 or not 1 <= args.duration <= 600:
        p.error(f"--recordings must be in [1, 100] and --duration in [1, 600], got {args.recordings}, {args.duration}")
    if not args.analytic and not args.model.is_file():
        p.error(f"--model {args.model}: no such file")
    site = load_site(site_path("wtf-apartment"))
    if args.analytic:
        from superbody.host.estimation.analytic import AnalyticEstimator

        est, name = AnalyticEstimator(site), "analytic"
    else:
        from superbody.host.estimation.estimator import OnnxEstimator
        from superbody.host.estimation.hybrid import HybridEstimator

        est, name = HybridEstimator(OnnxEstimator(args.model, site), site), f"hybrid:{args.model.name}"
    base = HostConfig()
    err = np.zeros((len(args.accel), args.recordings, 4))  # x mm, y mm, yaw deg, jitter mm
    for r in range(args.recordings):
        samples, stamps = simulated_recording(site, duration_s=args.duration, seed=r)
        truth = np.array([s.truth for s in samples])
        per_frame = predict(samples, est)
        for i, a in enumerate(args.accel):
            cfg = dataclasses.replace(base, filter=dataclasses.replace(base.filter, accel_std_mps2=a))
            pose = replay(samples, stamps, per_frame, site, est, name, config=cfg).poses
            e = np.abs(pose - truth)
            err[i, r] = (e[:, 0].mean() * 1000, e[:, 1].mean() * 1000, np.degrees(np.abs(wrap_angle(pose[:, 2] - truth[:, 2]))).mean(),
                         jitter(pose, truth)["position_mm"])
        print(f"recording {r + 1}/{args.recordings} replayed", file=sys.stderr, flush=True)
    mean = err.mean(axis=1)
    print(f"{name} on {args.recordings} simulated recordings of {args.duration:g} s (site wtf-apartment), live at each capture time")
    print("accel_std_mps2    x mm    y mm  yaw deg  jitter mm")
    for a, (x, y, yaw, jit) in zip(args.accel, mean):
        mark = "  <- default" if a == FilterConfig().accel_std_mps2 else ""
        print(f"{a:14g}  {x:6.1f}  {y:6.1f}  {yaw:7.2f}  {jit:9.1f}{mark}")
    if args.json_out:
        args.json_out.write_text(json.dumps({"accel_std_mps2": args.accel, "x_mm": mean[:, 0].tolist(), "y_mm": mean[:, 1].tolist(),
                                             "yaw_deg": mean[:, 2].tolist(), "jitter_mm": mean[:, 3].tolist(),
                                             "recordings": args.recordings, "duration_s": args.duration, "estimator": name}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
