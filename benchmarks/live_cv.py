"""The live system on a cross-validation again, from its kept fold models, once per host setting.

    python benchmarks/live_cv.py --cv build/models/crossval-space-m1.npz --folds build/models/folds-space-m1
        [--set filter.accel_std_mps2=2,3,4] [--set freshness_s=0.35,0.5] [--dataset dev.json] [--json-out F]

``superbody crossval --temporal --models-out DIR`` keeps each fold's fp32 model with the hybrid
calibration fitted on the other folds. This replays the recording through the host's aggregator
with each of them (``models.temporal.replay``, as crossval does: fold k's samples are scored on
what fold k's model makes the host publish, the per-frame fallback before anyone is published is
the cross-validation's own) once per combination of the ``--set`` values, every other parameter at
the host's defaults, and prints the per-frame hybrid and each setting's live figures side by side.
The first row, the host's defaults, is the cross-validation's own ``hybrid temporal`` when the host
has not changed since it ran: a change to the tracker, the filter or set S is scored on data no
fold model saw in a minute, without retraining. Figures chosen this way have seen the
cross-validation: say so beside them.

``--set KEY=V1,V2,...``: KEY is a ``HostConfig`` field (``freshness_s``) or one of its
``filter.`` / ``tracker.`` fields (``filter.accel_std_mps2``); the configs' own checks refuse a
value out of range. ``--json-out F`` writes ``{"settings": [{KEY: value, ...}, ...], "reports":
{name: report}}`` (reports as ``models.evaluate.summarise`` gives them).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
from pathlib import Path

import numpy as np

from superbody.host.aggregator import HostConfig

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DEV = ROOT.parent / "shared" / "datasets" / "wheresthefellow" / "dev.json"


def _settable() -> dict[str, tuple[str | None, str, object]]:
    """KEY -> (parent field or None, field, default): HostConfig's scalar fields and its filter's and tracker's."""
    keys = {}
    for f in dataclasses.fields(HostConfig):
        value = getattr(HostConfig(), f.name)
        if dataclasses.is_dataclass(value):
            keys.update({f"{f.name}.{g.name}": (f.name, g.name, getattr(value, g.name)) for g in dataclasses.fields(value)})
        else:
            keys[f.name] = (None, f.name, value)
    return keys


_KEYS = _settable()


def _parse_set(text: str) -> tuple[str, list]:
    key, sep, values = text.partition("=")
    if not sep or key not in _KEYS:
        raise argparse.ArgumentTypeError(f"--set must be KEY=V1,V2,... with KEY one of {', '.join(sorted(_KEYS))}, got {text!r}")
    kind = type(_KEYS[key][2])
    out = []
    for v in values.split(","):
        if kind is bool and v.lower() not in ("true", "false"):
            raise argparse.ArgumentTypeError(f"--set {key}: must be true or false, got {v!r}")
        try:
            value = v.lower() == "true" if kind is bool else kind(v)
            _apply(HostConfig(), {key: value})  # the configs' own range checks name the field and the range
        except ValueError as e:
            raise argparse.ArgumentTypeError(f"--set {key}: {e}") from None
        out.append(value)
    return key, out


def _apply(config: HostConfig, setting: dict) -> HostConfig:
    """``config`` with each ``KEY: value`` of ``setting`` replaced (nested keys on filter / tracker)."""
    for key, value in setting.items():
        parent, name, _ = _KEYS[key]
        if parent is None:
            config = dataclasses.replace(config, **{name: value})
        else:
            config = dataclasses.replace(config, **{parent: dataclasses.replace(getattr(config, parent), **{name: value})})
    return config


def _label(setting: dict) -> str:
    return "live " + (", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in setting.items()) or "defaults")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cv", type=Path, required=True, help="superbody crossval --temporal --predictions-out file (.npz)")
    p.add_argument("--folds", type=Path, required=True, help="its --models-out folder (fold<k>.fp32.onnx)")
    p.add_argument("--dataset", type=Path, default=DEFAULT_DEV, help="the recording it cross-validated (default: dev.json beside the checkout)")
    p.add_argument("--site", type=Path, default=ROOT / "deploy" / "sites" / "wtf-apartment.toml", help="site file")
    p.add_argument("--set", dest="sets", type=_parse_set, action="append", default=[], metavar="KEY=V1,V2",
                   help="a host parameter and the values to try; repeat for a grid")
    p.add_argument("--json-out", type=Path)
    args = p.parse_args(argv)

    from superbody.edge.site import SiteError, load_site
    from superbody.host.estimation import build_estimator
    from superbody.host.estimation.hybrid import HybridEstimator
    from superbody.models.data.wtf import DatasetError, load_wtf_raw, to_samples
    from superbody.models.evaluation.evaluate import format_table, score
    from superbody.models.evaluation.temporal import replay, view_stamps

    try:
        cv = np.load(args.cv)
        fold, per_frame, offset = cv["fold"], cv["hybrid"], float(cv["truth_offset_m"])
    except (OSError, ValueError, KeyError) as e:
        p.error(f"--cv {args.cv}: not a crossval --temporal predictions file ({e})")
    try:
        site = load_site(args.site)
        raw = load_wtf_raw(args.dataset)
        samples = to_samples(raw, site)
    except (SiteError, DatasetError, ValueError) as e:
        p.error(str(e))
    if len(fold) != len(samples):
        p.error(f"--cv {args.cv}: {len(fold)} samples, --dataset {args.dataset} has {len(samples)}")
    estimators = {}
    for k in sorted(set(fold.tolist())):
        path = args.folds / f"fold{k}.fp32.onnx"
        if not path.is_file():
            p.error(f"--folds {args.folds}: no {path.name} (crossval --temporal --models-out keeps one per fold)")
        est = build_estimator(site, "auto", path)[0]
        if not isinstance(est, HybridEstimator):
            p.error(f"{path}: no hybrid calibration (not a crossval --models-out fold model)")
        estimators[k] = est

    stamps = view_stamps(raw)
    names = [key for key, _ in args.sets]
    settings = [{}] + [dict(zip(names, combo)) for combo in itertools.product(*[values for _, values in args.sets])]
    poses = {_label(s): np.full((len(samples), 3), np.nan) for s in settings}
    for i, (k, est) in enumerate(estimators.items()):
        held = fold == k
        for s in settings:
            rep = replay(samples, stamps, per_frame, site, est, f"hybrid:fold{k}", config=_apply(HostConfig(), s))
            poses[_label(s)][held] = rep.poses[held]
        print(f"fold {k} replayed ({i + 1}/{len(estimators)})", file=sys.stderr, flush=True)
    reports = score(samples, {"hybrid per frame": per_frame, **poses}, offset)
    print(f"the live system on {args.cv.name}'s folds ({len(estimators)} fold models from {args.folds}), {len(samples)} samples")
    print(format_table(reports, offset))
    if args.json_out:
        args.json_out.write_text(json.dumps({"settings": settings, "reports": reports}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
