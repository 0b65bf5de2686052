"""What the analytic estimator's error on a WheresTheFellow recording is made of, in the body's frame.

    python benchmarks/truth_budget.py [--dataset dev.json] [--site deploy/sites/wtf-apartment.toml] [--json-out F]

The scoring (``models.evaluate.summarise``) moves each torso-centre estimate ``TRUTH_OFFSET_M``
forward along its yaw, to where the dataset's chest-worn tracker should be. The analytic
estimator (``host.estimation.analytic``) has nothing fitted to that truth, so its errors describe the truth
and the images rather than a model. Per camera count, its position error along the truth's
heading (forward) and across it (left) is fitted to the truth's own velocity in those directions
(central differences over +-0.1 s of the track, ``models.temporal.truth_track``):

    error_forward = offset_forward - lag_forward * speed_forward
    error_left    = offset_left    - lag_left    * speed_left

- ``offset``: where the geometry puts the torso of someone standing still, relative to the scored
  point (0 if the chest really were ``TRUTH_OFFSET_M`` in front of the torso centre);
- ``lag``: how far behind the truth the images are, in seconds of the person's motion (capture
  latency, or an offset between the cameras' and the tracker's clocks). A lag forward larger
  than across means the chest moves ahead of the torso as the walk speeds up (a lean), which a
  constant offset cannot describe.

It also prints the forward error of the samples where the person stands still, and the floor
that a lag sets under any live figure scored at the samples' stamps: the error of the truth
itself, taken L earlier.

``--json-out F`` writes ``{"fits": {bucket: {...}}, "standing": {...}, "lag_floor": [...]}``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DEV = ROOT.parent / "shared" / "datasets" / "wheresthefellow" / "dev.json"
DEFAULT_SITE = ROOT / "deploy" / "sites" / "wtf-apartment.toml"
STANDING_MPS = 0.05  # a truth slower than this stands still
FLOOR_LAGS_MS = (50, 100, 150, 200)


def _fit(err: np.ndarray, speed: np.ndarray) -> tuple[float, float, float, float]:
    """err = offset - lag * speed by least squares: (offset m, lag s, MAE before, MAE after)."""
    A = np.column_stack([np.ones(len(err)), -speed])
    (offset, lag), *_ = np.linalg.lstsq(A, err, rcond=None)
    return float(offset), float(lag), float(np.abs(err).mean()), float(np.abs(err - A @ (offset, lag)).mean())


def budget(dataset: Path, site_path: Path) -> dict:
    from superbody.edge.angles import wrap_angle
    from superbody.edge.site import load_site
    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.models.data.wtf import TRUTH_OFFSET_M, load_wtf_raw, to_samples, truth_to_torso
    from superbody.models.evaluation.evaluate import predict
    from superbody.models.evaluation.temporal import view_stamps
    from superbody.models.evaluation.temporal_scores import truth_at, truth_track

    site = load_site(site_path)
    raw = load_wtf_raw(dataset)
    samples, stamps, track = to_samples(raw, site), view_stamps(raw), truth_track(raw)
    pred = predict(samples, AnalyticEstimator(site), progress=None)
    truth = truth_to_torso(np.array([s.truth for s in samples]), TRUTH_OFFSET_M)
    first = np.array([min(st.values()) for st in stamps], dtype=np.float64)  # the truth's time (models.wtf)
    h = 0.1e9
    v = (truth_to_torso(truth_at(track, first + h), TRUTH_OFFSET_M) - truth_to_torso(truth_at(track, first - h), TRUTH_OFFSET_M))[:, :2] / 0.2
    fwd = np.column_stack([np.cos(truth[:, 2]), np.sin(truth[:, 2])])  # (N, 2) the truth's heading
    left = np.column_stack([-fwd[:, 1], fwd[:, 0]])
    err = pred[:, :2] - truth[:, :2]
    e_f, e_l, v_f, v_l = (err * fwd).sum(1), (err * left).sum(1), (v * fwd).sum(1), (v * left).sum(1)
    cams = np.array([len(s.views) for s in samples])
    ok = np.isfinite(err).all(1)
    fits = {}
    for key, mask in [("all", ok)] + [(str(c), ok & (cams == c)) for c in sorted(set(cams.tolist()))] + [("2+", ok & (cams >= 2))]:
        if mask.sum() < 10:
            continue
        f, lf, fb, fa = _fit(e_f[mask], v_f[mask])
        o, ll, lb, la = _fit(e_l[mask], v_l[mask])
        fits[key] = {"samples": int(mask.sum()), "offset_forward_mm": round(f * 1000, 1), "lag_forward_ms": round(lf * 1000, 1),
                     "offset_left_mm": round(o * 1000, 1), "lag_left_ms": round(ll * 1000, 1),
                     "forward_mae_mm": [round(fb * 1000, 1), round(fa * 1000, 1)], "left_mae_mm": [round(lb * 1000, 1), round(la * 1000, 1)]}
    still = ok & (np.hypot(v[:, 0], v[:, 1]) < STANDING_MPS) & (cams >= 2)
    standing = {"samples": int(still.sum()), "forward_median_mm": round(float(np.median(e_f[still])) * 1000, 1) if still.any() else None,
                "left_median_mm": round(float(np.median(e_l[still])) * 1000, 1) if still.any() else None}
    floor = []
    for lag in FLOOR_LAGS_MS:
        late = truth_at(track, first - lag * 1e6)
        d = np.abs(late - truth_at(track, first))
        floor.append({"lag_ms": lag, "x_mm": round(float(d[:, 0].mean()) * 1000, 1), "y_mm": round(float(d[:, 1].mean()) * 1000, 1),
                      "yaw_deg": round(float(np.degrees(np.abs(wrap_angle(late[:, 2] - truth_at(track, first)[:, 2]))).mean()), 2)})
    return {"dataset": str(dataset), "truth_offset_m": TRUTH_OFFSET_M, "fits": fits, "standing": standing, "lag_floor": floor}


def format_budget(b: dict) -> str:
    lines = [f"the analytic estimator's position error on {Path(b['dataset']).name}, along the truth's heading (forward) and across it (left),",
             f"fitted as offset - lag * the truth's speed that way (scored point: the torso centre + {b['truth_offset_m']} m forward)",
             f"{'cameras':8s} {'n':>4s} {'fwd offset mm':>14s} {'fwd lag ms':>11s} {'left offset mm':>15s} {'left lag ms':>12s} "
             f"{'fwd MAE mm':>14s} {'left MAE mm':>14s}"]
    for key, f in b["fits"].items():
        lines.append(f"{key:8s} {f['samples']:4d} {f['offset_forward_mm']:14.0f} {f['lag_forward_ms']:11.0f} {f['offset_left_mm']:15.0f} "
                     f"{f['lag_left_ms']:12.0f} {f['forward_mae_mm'][0]:6.0f} -> {f['forward_mae_mm'][1]:4.0f} "
                     f"{f['left_mae_mm'][0]:6.0f} -> {f['left_mae_mm'][1]:4.0f}")
    s = b["standing"]
    if s["samples"]:
        lines.append(f"standing still (truth under {STANDING_MPS} m/s, 2+ cameras, n={s['samples']}): forward error median "
                     f"{s['forward_median_mm']:.0f} mm, left {s['left_median_mm']:.0f} mm")
    lines.append("the truth itself taken L earlier (the floor under a live figure whose images trail by L): "
                 + "; ".join(f"L={f['lag_ms']} ms: x {f['x_mm']:.0f} mm, y {f['y_mm']:.0f} mm, yaw {f['yaw_deg']:.1f} deg" for f in b["lag_floor"]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", type=Path, default=DEFAULT_DEV, help="a WheresTheFellow JSON file (default: the shared dev.json)")
    p.add_argument("--site", type=Path, default=DEFAULT_SITE, help="its site (default deploy/sites/wtf-apartment.toml)")
    p.add_argument("--json-out", type=Path, help="also write the figures as JSON")
    args = p.parse_args(argv)
    for flag, path in (("--dataset", args.dataset), ("--site", args.site)):
        if not path.is_file():
            print(f"truth_budget: {flag} {path}: no such file", file=sys.stderr)
            return 2
    try:
        b = budget(args.dataset, args.site)
    except ValueError as e:  # DatasetError, SiteError
        print(f"truth_budget: {e}", file=sys.stderr)
        return 2
    print(format_budget(b))
    if args.json_out:
        args.json_out.write_text(json.dumps(b, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
