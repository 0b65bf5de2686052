"""Compare the simulator's detector statistics with a WheresTheFellow file, side by side.

    python scripts/sim_vs_dataset.py [--dataset ../shared/datasets/wheresthefellow/dev.json]
        [--site deploy/sites/wtf-apartment.toml] [--seconds 600] [--seed 0] [--json-out F]

Simulates one person (as in the recordings) walking the stretch of floor the recording walked
(``path_floor``: what a detector reports depends on where the person stands), sampled at the
dataset's rate, keeps the instants at which at least one camera reports the person (the dataset
holds only those), and prints joints per view, views per person, scores and per-joint detection
rates. Then the views by the camera's distance to the person (share, joints, <= 8 joints, cut
off at an image edge), the simulated person walking the whole floor this time.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from superbody.edge import body  # noqa: E402
from superbody.edge.site import load_site  # noqa: E402
from superbody.models.data.simstats import (  # noqa: E402
    facing_rates,
    lr_disagreement,
    path_floor,
    simulate,
    statistics,
    view_buckets,
)
from superbody.models.data.wtf import load_wtf  # noqa: E402


def _row(name: str, a: float, b: float, fmt: str = "{:.3f}") -> str:
    return f"  {name:<26}{fmt.format(a):>12}{fmt.format(b):>12}"


def main(dataset: str, site: str, seconds: float, seed: int, json_out: str | None) -> int:
    loaded = load_wtf(dataset)
    real = [{c: v.keypoints for c, v in s.views.items()} for s in loaded]
    ts = [s.stamp_ns for s in loaded]
    rate = (len(ts) - 1) / ((ts[-1] - ts[0]) * 1e-9)
    sim_truth: list = []
    # Like for like: the simulated person walks the stretch of floor the recording walked.
    sim = simulate(site, seconds, seed, rate, truths=sim_truth, floor=path_floor(np.array([s.truth[:2] for s in loaded])))
    a, b = statistics(real), statistics(sim)
    print(f"{'':28}{'dev.json':>12}{'simulator':>12}")
    print(_row("samples", a["samples"], b["samples"], "{:.0f}"))
    print(_row("views", a["views"], b["views"], "{:.0f}"))
    print(_row("joints/view mean", a["joints_per_view_mean"], b["joints_per_view_mean"], "{:.2f}"))
    print(_row("joints/view median", a["joints_per_view_median"], b["joints_per_view_median"], "{:.0f}"))
    for k in a["joints_per_view_buckets"]:
        print(_row(f"views with {k} joints", a["joints_per_view_buckets"][k], b["joints_per_view_buckets"][k]))
    for k in a["views_per_person"]:
        print(_row(f"persons seen by {k} camera(s)", a["views_per_person"][k], b["views_per_person"][k]))
    print(_row("joints/person median", a["joints_per_person_median"], b["joints_per_person_median"], "{:.0f}"))
    for q in a["score_quantiles"]:
        print(_row(f"score quantile {q}", a["score_quantiles"][q], b["score_quantiles"][q]))
    print(_row("score == 1", a["score_is_1"], b["score_is_1"]))
    print("  detection rate per joint:")
    for name in body.KEYPOINTS:
        print(_row(f"  {name}", a["joint_rate"][name], b["joint_rate"][name], "{:.2f}"))
    st = load_site(site)
    ra, ca = facing_rates(real, [s.truth for s in loaded], st)
    rb, cb = facing_rates(sim, sim_truth, st)
    a["facing_rates"], b["facing_rates"] = ra.tolist(), rb.tolist()
    print("  detection rate by where the person faces (0 = facing the camera), dev.json / simulator:")
    centres = np.degrees(-np.pi + (np.arange(ra.shape[1]) + 0.5) * 2 * np.pi / ra.shape[1])
    print("  " + " " * 16 + "".join(f"{c:>11.0f}" for c in centres))
    print("  " + "views".ljust(16) + "".join(f"{x:>5d}/{y:<5d}" for x, y in zip(ca, cb)))
    for j, name in enumerate(body.KEYPOINTS):
        print("  " + name.ljust(16) + "".join(f"{x:>5.2f}/{y:<5.2f}" for x, y in zip(ra[j], rb[j])))
    print("  facing-visibility table (dev.json rates over their view-weighted mean, edge.sim.FACING_VISIBILITY):")
    norm = ra / (ra @ (ca / ca.sum()))[:, None]
    for j, name in enumerate(body.KEYPOINTS):
        print("    (" + ", ".join(f"{x:.2f}" for x in norm[j]) + f"),  # {name}")
    (ba, ta), (bb, tb) = lr_disagreement(real, st), lr_disagreement(sim, st)
    a["lr_disagreement"], b["lr_disagreement"] = [ba, ta], [bb, tb]
    print("  view pairs that disagree about the person's left and right (label-free; edge.sim.NoiseModel.swap_prob):")
    print(f"    {ba}/{ta} = {ba / max(ta, 1):.3f} dev.json, {bb}/{tb} = {bb / max(tb, 1):.3f} simulator")
    # The buckets: the simulated person over the whole floor (far and cut-off views the recording has few of).
    whole_truth: list = []
    whole = simulate(site, seconds, seed, rate, truths=whole_truth)
    a["view_buckets"] = view_buckets(real, [s.truth for s in loaded], st)
    b["view_buckets"] = view_buckets(whole, whole_truth, st)
    print("  views by the camera's distance to the person, dev.json / simulator: share of views, joints per view,")
    print("  share with <= 8 joints, share cut off at an image edge (a joint within 8 px of the border):")
    for name in a["view_buckets"]:
        x, y = a["view_buckets"][name], b["view_buckets"][name]
        print(f"    {name:<9} " + "  ".join(f"{x[k]:>5.2f}/{y[k]:<5.2f}" for k in ("share", "joints_mean", "few_joints", "at_edge"))
              + f"   ({x['views']} / {y['views']} views)")
    if json_out:
        Path(json_out).write_text(json.dumps({"dev": a, "sim": b}, indent=1))
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dataset", default=str(ROOT.parent / "shared" / "datasets" / "wheresthefellow" / "dev.json"))
    p.add_argument("--site", default=str(ROOT / "deploy" / "sites" / "wtf-apartment.toml"))
    p.add_argument("--seconds", type=float, default=600.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.dataset, a.site, a.seconds, a.seed, a.json_out))
