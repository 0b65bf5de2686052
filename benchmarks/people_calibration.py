"""Calibration kept true from the people walking by (issue 40, items 2 and 3): one camera of a
site knocked by a given rotation and shift in the site file, the health monitor and
``superbody calibrate people``'s refinement run on a recording, and their figures.

    python -m benchmarks.people_calibration [--dev PATH] [--sites wtf-apartment,lab-example,room5]
                                            [--seconds 20] [--people 3] [--seeds 6] [--json-out F]
    python -m benchmarks.people_calibration --cost

Recordings: the real WheresTheFellow dev split (3 cameras, one person, 27 s), and simulated
ones of the shipped sites and of the five-camera room of ``benchmarks/scenes.py`` (scene k),
several people, the detector noise model of ``edge/sim/noise.py``; the cameras render from
where they really are and the host is given the knocked site file.

For each case: how far the knock moves the image of the people's joints in the knocked camera
(``shift``, median degrees: a rotation and a shift can cancel there), when the monitor first
flags the knocked camera (``CalibrationHealth`` over the recording, reported each second of
capture time), what it says of every camera at the end, and the refinement that frees the
flagged camera (or the knocked one, as ``--fix`` would, when nothing was flagged): how far the
knocked camera ends from its true pose, how far the others move, the residuals before and after,
and the time it took.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Final

import cv2
import numpy as np

from benchmarks import scenes
from superbody.edge.camera import Camera
from superbody.edge.resources import site_path
from superbody.edge.site import Site, load_site
from superbody.host.calibration.bundle import build_problem, pose_change, refine_cameras
from superbody.host.calibration.collect import Frame, person_instants
from superbody.host.calibration.health import CalibrationHealth, image_shift_deg
from superbody.host.calibration.refine import camera_residuals, subsample

__all__ = ["knock", "dev_frames", "sim_frames", "sim_site", "run_case", "measure_cost", "main"]

DEGREES: Final = 2.0
METRES: Final = 0.10
SITES: Final = ("wtf-apartment", "lab-example", "room5")


def knock(site: Site, camera: str, degrees: float = DEGREES, metres: float = METRES, seed: int = 0, view: bool = False) -> Site:
    """The site with one camera turned by exactly ``degrees`` and its optical centre moved by
    exactly ``metres``, seeded.

    ``view=False``: about a random axis and in a random direction (the two may cancel in the
    image: a roll about the optical axis barely moves its centre). ``view=True``: a knock that
    moves the view: about a random axis across the optical axis, the centre moved across it so
    that the image moves the same way as the turn makes it (both add, as when a bumped mount
    swings).
    """
    rng = np.random.default_rng([seed, 0x40])
    a, d = rng.normal(size=3), rng.normal(size=3)
    cams = []
    for c in site.cameras:
        if c.id == camera:
            if view:
                a[2] = 0.0  # across the optical axis (camera frame)
                d = c.R @ np.cross(a, [0.0, 0.0, 1.0])  # turning by w about a moves points by -w (a x p); a shift d by -d
            R = c.R @ cv2.Rodrigues(a / np.linalg.norm(a) * math.radians(degrees))[0]
            c = dataclasses.replace(c, rotation=tuple(tuple(float(v) for v in r) for r in R),
                                    position=tuple(float(v) for v in c.t + d / np.linalg.norm(d) * metres))
        cams.append(c)
    return dataclasses.replace(site, cameras=tuple(cams))


def dev_frames(path: str | Path, site: Site) -> list[Frame]:
    """The WheresTheFellow file's views as the camera frames a host would have received."""
    from superbody.models.data.wtf import load_wtf_raw, to_samples
    from superbody.models.evaluation.temporal import observation_batches, view_stamps

    raw = load_wtf_raw(path)
    batches = observation_batches(to_samples(raw), view_stamps(raw), site)
    return [Frame(stamp, key.split("/")[3], payload) for stamp, batch in batches for key, payload in batch]


def sim_site(name: str) -> Site:
    """A shipped site by name, or ``room5``: the five-camera room of ``benchmarks/scenes.py`` (scene k)."""
    return scenes.scene_four_person_room().site if name == "room5" else load_site(site_path(name))


def sim_frames(site: Site, people: int, seconds: float, seed: int) -> list[Frame]:
    """``seconds`` of ``people`` simulated people in the site, every camera at 15 fps, staggered."""
    rec = scenes.simulate(scenes.Scene("x", site.name, site, people), seconds, seed)
    return [Frame(stamp, cam, payload) for stamp, cam, payload, _, _ in rec.frames]


def _mean_change(a: Sequence[Camera], b: Sequence[Camera], skip: str) -> tuple[float, float]:
    ch = [pose_change(x, y) for x, y in zip(a, b) if x.id != skip]
    return max((c.rotation_deg for c in ch), default=0.0), max((c.position_m for c in ch), default=0.0)


def run_case(frames: Sequence[Frame], truth: Site, host: Site, knocked: str | None, report_every_s: float = 1.0,
             check_every_s: float = 5.0, refine: bool = True) -> dict:
    """The monitor and the refinement on one recording whose host has ``host``'s calibration.

    Returns:
        A dict: ``shift_deg``, ``detected_s`` (capture seconds until the knocked camera was first
        flagged, None if never), ``wrong`` (other cameras ever flagged), ``health`` (the last
        report per camera), and with ``refine`` the refinement's figures.
    """
    t0 = time.monotonic()
    instants, counts = person_instants(frames, host)
    collect_s = time.monotonic() - t0
    mon = CalibrationHealth(host, check_every_s=check_every_s)
    start = instants[0].stamp_ns if instants else 0
    detected, wrong, next_report, report_s = None, set(), start, []
    rep = {}
    for ins in instants:
        mon.observe_instant(ins)
        if ins.stamp_ns >= next_report:
            t = time.monotonic()
            rep = mon.report(ins.stamp_ns)
            report_s.append(time.monotonic() - t)
            next_report = ins.stamp_ns + round(report_every_s * 1e9)
            for c, h in rep.items():
                if h.moved and c == knocked and detected is None:
                    detected = (ins.stamp_ns - frames[0].stamp_ns) / 1e9
                if h.moved and c != knocked:
                    wrong.add(c)
    if instants:
        rep = mon.report(instants[-1].stamp_ns)
    prob_pts = build_problem(instants, truth.cameras).points
    out: dict = {
        "instants": len(instants), "people": counts["people"], "collect_s": collect_s, "detected_s": detected, "wrong": sorted(wrong),
        "report_s_max": max(report_s, default=0.0),
        "shift_deg": image_shift_deg(truth.camera(knocked), host.camera(knocked), prob_pts) if knocked else 0.0,
        "health": {c: {"residual_deg": h.residual_deg, "residual_px": h.residual_px, "samples": h.samples, "state": h.state,
                       "explained": h.explained} for c, h in rep.items()},
    }
    if refine and knocked is not None:
        flagged = [c for c, h in rep.items() if h.moved]
        free = flagged or [knocked]
        t = time.monotonic()
        res = refine_cameras(host.cameras, subsample(instants), free)
        i = host.camera_index(knocked)
        err = pose_change(truth.cameras[i], res.cameras[i])
        before = camera_residuals(instants, host.cameras)
        after = camera_residuals(instants, res.cameras)
        others = _mean_change(host.cameras, res.cameras, knocked)
        out["refine"] = {
            "free": list(res.free), "seconds": time.monotonic() - t, "points": res.points,
            "error_deg": err.rotation_deg, "error_m": err.position_m,
            "error_shift_deg": image_shift_deg(truth.cameras[i], res.cameras[i], prob_pts),
            "others_moved_deg": others[0], "others_moved_m": others[1],
            "residual_deg_before": {c: v[1] for c, v in before.items()}, "residual_deg_after": {c: v[1] for c, v in after.items()},
        }
    return out


def _line(label: str, r: dict) -> str:
    h = r["health"]
    states = " ".join(f"{c}:{v['state'][:4]}({v['residual_deg']:.2f})" for c, v in h.items())
    det = "-" if r["detected_s"] is None else f"{r['detected_s']:.0f}s"
    s = f"{label:<26} shift {r['shift_deg']:4.2f}  found {det:>4}  wrong {','.join(r['wrong']) or '-':<5} {states}"
    if "refine" in r:
        f = r["refine"]
        s += (f" | freed {','.join(f['free']):<5} error {f['error_deg']:.2f} deg {100 * f['error_m']:.1f} cm (image {f['error_shift_deg']:.2f}) "
              f"others {f['others_moved_deg']:.2f} deg {100 * f['others_moved_m']:.1f} cm, {f['seconds']:.1f} s")
    return s


def measure_cost(seconds: float = 10.0, people: int = 3) -> dict[str, float]:
    """The monitor's cost on the sites' simulated people: ``observe`` per call for room5's
    five-camera sets (one view new, as at a host step; all five new), ``report`` without its
    test over the window, and the test for three, four and five cameras."""
    from superbody.edge.messages.observation import PersonView, empty_histogram

    out: dict[str, float] = {}
    for name in ("wtf-apartment", "lab-example", "room5"):
        site = sim_site(name)
        instants, _ = person_instants(sim_frames(site, people, seconds, seed=1), site)
        mon = CalibrationHealth(site, check_every_s=0.0)
        for ins in instants:
            mon.observe_instant(ins)
        sample = mon._sample()
        t = time.perf_counter()
        from superbody.host.calibration.health import attribute

        attribute(site.cameras, sample)
        out[f"test_s_{len(site.cameras)}_cameras"] = time.perf_counter() - t
        if name != "room5":
            continue
        mon.check_ns = 10**18  # no test: the medians alone
        t = time.perf_counter()
        for _ in range(20):
            mon.report(instants[-1].stamp_ns)
        out["report_ms_without_test"] = (time.perf_counter() - t) / 20 * 1e3
        sets = [ins for ins in instants if len(ins.cameras) == 5][:50]
        views = [{c: PersonView(keypoints=ins.keypoints[i].astype(np.float32), bbox=np.zeros(4, np.float32), histogram=empty_histogram())
                  for i, c in enumerate(ins.cameras)} for ins in sets]
        for label, one in (("observe_ms_one_new", True), ("observe_ms_all_new", False)):
            m = CalibrationHealth(site)
            t, n = time.perf_counter(), 0
            for r in range(20):
                for k, v in enumerate(views):
                    now = sets[0].stamp_ns + (r * 100 + k) * 10_000_000
                    stamps = {c: (now if (j == r % 5 or not one) else sets[0].stamp_ns) for j, c in enumerate(v)}
                    m.observe(v, now, stamps=stamps, velocity=(0.5, 0.2), person=k)
                    n += 1
            out[label] = (time.perf_counter() - t) / max(n, 1) * 1e3
    return out


def main(dev: str | None, sites: Sequence[str], seconds: float, people: int, seeds: int, json_out: str | None) -> int:
    results: dict[str, dict] = {}
    print(f"each case: one camera knocked {DEGREES:g} deg and {100 * METRES:g} cm in the host's site file, the view moved (view: turn and "
          "shift add in the image) or about a random axis and direction (random: they may cancel); shift = median image shift of its "
          "people's joints; found = capture seconds until the monitor flags it; wrong = other cameras ever flagged; states at the end "
          "(median residual, deg); error = the refined camera against its true pose; others = the most another camera moved", flush=True)

    def case(label: str, frames: Sequence[Frame], site: Site, cam: str | None, seed: int, view: bool) -> None:
        t = time.monotonic()
        host = site if cam is None else knock(site, cam, seed=seed, view=view)
        results[label] = r = run_case(frames, site, host, cam)
        r["seconds"] = time.monotonic() - t
        print(_line(label, r), flush=True)

    if dev:
        site = load_site(site_path("wtf-apartment"))
        frames = dev_frames(dev, site)
        case("dev.json clean", frames, site, None, 0, False)
        for view in (True, False):
            for cam in site.camera_ids:
                for seed in range(seeds):
                    case(f"dev.json {'view' if view else 'random'} {cam} {seed}", frames, site, cam, seed, view)
    for name in sites:
        site = sim_site(name)
        frames = sim_frames(site, people, seconds, seed=1)
        case(f"{name} clean", frames, site, None, 0, False)
        for view in (True, False):
            for cam in site.camera_ids:
                case(f"{name} {'view' if view else 'random'} {cam}", frames, site, cam, 1, view)
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dev", help="the WheresTheFellow dev.json (e.g. ../shared/datasets/wheresthefellow/dev.json)")
    p.add_argument("--sites", default=",".join(SITES), help=f"simulated sites (default {','.join(SITES)}; empty: none)")
    p.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per site (default 20)")
    p.add_argument("--people", type=int, default=3, help="simulated people (default 3)")
    p.add_argument("--seeds", type=int, default=6, help="random knocks per dev.json camera (default 6)")
    p.add_argument("--json-out")
    p.add_argument("--cost", action="store_true", help="only the monitor's cost per call (observe, report, its test)")
    a = p.parse_args()
    if a.cost:
        for k, v in measure_cost().items():
            print(f"{k}: {v:.3f}")
        sys.exit(0)
    sys.exit(main(a.dev, [s for s in a.sites.split(",") if s], a.seconds, a.people, a.seeds, a.json_out))
