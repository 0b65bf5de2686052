"""Scores of a live replay (``models/evaluation/temporal.py``): the truth's track over time, jitter
of the published poses, the summary per source, and the latency scan (how far the images trail
the truth)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Final, cast

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.models.data.wtf import RawSample, torso_to_truth
from superbody.models.evaluation.evaluate import sample_errors
from superbody.models.evaluation.temporal import _NS_PER_MS, SOURCES, Replay

__all__ = ["jitter", "truth_track", "truth_at", "LATENCY_SCAN_MS", "latency_scan", "format_latency_scan", "replay_summary", "format_replay"]


def jitter(pred: NDArray, truth: NDArray, truth_offset_m: float = 0.0, mask: NDArray | None = None) -> dict[str, float | None]:
    """How much the error changes from one sample to the next: the noise a filter should remove.

    RMS over consecutive pairs of samples (both finite, both in ``mask``) of the change of the
    error vector: ``|e_xy[i+1] - e_xy[i]|`` in millimetres and ``|wrap(e_yaw[i+1] - e_yaw[i])|``
    in degrees, with ``e = torso_to_truth(pred) - truth``. A prediction that follows the truth
    with a constant bias has no jitter.

    Args:
        pred: (N, 3) torso poses (x, y, yaw) in time order.
        truth: (N, 3) ground truth at the same times.
        truth_offset_m: how far in front of the torso the truth is (``models.data.wtf.TRUTH_OFFSET_M``).
        mask: (N,) bool, the samples to use (all by default).

    Returns:
        ``{"position_mm", "yaw_deg", "pairs"}``; the figures are None without a pair.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    if len(pred) != len(truth):
        raise ValueError(f"jitter: {len(pred)} predictions for {len(truth)} truths")
    ok = cast("NDArray[np.bool_]", np.isfinite(pred).all(axis=1) & np.isfinite(truth).all(axis=1))
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool).reshape(-1)
    err = torso_to_truth(np.where(ok[:, None], pred, 0.0), truth_offset_m) - truth  # (N, 3)
    pair = ok[1:] & ok[:-1]  # (N-1,)
    if not pair.any():
        return {"position_mm": None, "yaw_deg": None, "pairs": 0}
    d_xy = np.linalg.norm(np.diff(err[:, :2], axis=0), axis=1)[pair] * 1000.0
    d_yaw = np.degrees(np.abs(wrap_angle(np.diff(err[:, 2]))))[pair]
    return {
        "position_mm": float(np.sqrt(np.mean(d_xy**2))),
        "yaw_deg": float(np.sqrt(np.mean(np.square(d_yaw)))),
        "pairs": int(pair.sum()),
    }


# Lags scanned by ``latency_scan``, milliseconds: the truth taken this long before the views' capture time.
LATENCY_SCAN_MS: Final[tuple[int, ...]] = tuple(range(-100, 401, 25))


def truth_track(raw: Sequence[RawSample]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The recording's ground truth as a time series: every view's own truth at its own stamp.

    Each view of a WheresTheFellow sample carries the chest tracker's pose at that view's
    capture time, so the views of one sample carry different truths when they were captured
    apart (the sample's truth is its first view's, ``RawSample.truth``).

    Returns:
        ``(t_ns, truth)``: (M,) increasing UNIX ns, one per distinct stamp (the first view seen
        wins a repeated stamp), and (M, 3) (x, y, yaw) with yaw unwrapped along time.
    """
    by_stamp: dict[int, NDArray] = {}
    for s in raw:
        for v in s.views:
            by_stamp.setdefault(int(v.stamp_ms) * _NS_PER_MS, v.truth)
    if not by_stamp:
        raise ValueError("truth_track: the recording has no views")
    t_ns = np.array(sorted(by_stamp), dtype=np.int64)
    truth = np.array([by_stamp[int(t)] for t in t_ns], dtype=np.float64).reshape(-1, 3)
    truth[:, 2] = np.unwrap(truth[:, 2])
    return t_ns, truth


def truth_at(track: tuple[NDArray, NDArray], t_ns: NDArray) -> NDArray[np.float64]:
    """The truth (K, 3) at times ``t_ns`` (K,): linear between the track's stamps, held beyond its ends; yaw wrapped."""
    t_track, truth = track
    t = np.asarray(t_ns, dtype=np.float64).reshape(-1)
    ref = np.asarray(t_track, dtype=np.float64)
    out = np.stack([np.interp(t, ref, truth[:, k]) for k in range(3)], axis=1)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def latency_scan(
    pred: NDArray,
    stamps: Sequence[Mapping[str, int]],
    track: tuple[NDArray, NDArray],
    truth_offset_m: float,
    lags_ms: Sequence[int] = LATENCY_SCAN_MS,
) -> dict:
    """How well per-frame estimates match the truth taken ``lag`` before their views' mean capture time.

    An estimate describes the person when its images were taken. If the error is least at a lag
    L > 0, the images show the person about L earlier than their stamps say, on the truth's
    clock: capture latency, or an offset between the cameras' and the tracker's clocks. No live
    system can publish at time t what its cameras only show later, so such a lag bounds what a
    temporal score at the samples' stamps can reach (``replay``).

    Args:
        pred: (N, 3) per-frame torso poses (x, y, yaw) of the samples.
        stamps: per sample, camera id -> capture time of its view, UNIX ns (``view_stamps``).
        track: the truth as a time series (``truth_track``).
        truth_offset_m: how far in front of the torso the truth is (``models.data.wtf.TRUTH_OFFSET_M``).
        lags_ms: the lags to try, milliseconds.

    Returns:
        ``{"lags_ms": [...], "buckets": {key: {"samples", "position_mm": [...], "yaw_deg": [...],
        "best_position_ms", "best_yaw_ms"}}}``: MAE per lag (euclidean position, yaw), for
        ``"all"`` samples and by the number of cameras that saw them (``"1"``, ``"2"``, ...);
        rows with a non-finite estimate are left out.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    if len(pred) != len(stamps):
        raise ValueError(f"latency_scan: {len(pred)} predictions for {len(stamps)} samples")
    lags = [int(v) for v in lags_ms]
    if not lags:
        raise ValueError("latency_scan: no lags to try")
    ok = cast("NDArray[np.bool_]", np.isfinite(pred).all(axis=1))
    mean_t = np.array([np.mean([int(t) for t in st.values()]) for st in stamps], dtype=np.float64)
    cams = np.array([len(st) for st in stamps])
    point = torso_to_truth(np.where(ok[:, None], pred, 0.0), truth_offset_m)  # (N, 3)
    pos = np.empty((len(lags), len(pred)))
    yaw = np.empty((len(lags), len(pred)))
    for k, lag in enumerate(lags):
        err = sample_errors(point, truth_at(track, mean_t - lag * _NS_PER_MS))  # (N, 3) mm, mm, deg
        pos[k], yaw[k] = np.hypot(err[:, 0], err[:, 1]), err[:, 2]
    buckets = {}
    for key, mask in [("all", ok)] + [(str(c), ok & (cams == c)) for c in sorted(set(cams.tolist()))]:
        if not mask.any():
            continue
        p, y = pos[:, mask].mean(axis=1), yaw[:, mask].mean(axis=1)
        buckets[key] = {"samples": int(mask.sum()), "position_mm": p.round(1).tolist(), "yaw_deg": y.round(2).tolist(),
                        "best_position_ms": lags[int(np.argmin(p))], "best_yaw_ms": lags[int(np.argmin(y))]}
    return {"lags_ms": lags, "buckets": buckets}


def format_latency_scan(name: str, scan: Mapping) -> str:
    """A few lines on a ``latency_scan``: per bucket, the error at lag 0 and at the best lag."""
    lags = list(scan["lags_ms"])
    at0 = lags.index(0) if 0 in lags else None
    lines = [f"{name}: error against the truth taken L ms before the views' mean capture time (the lag that fits best)"]
    for key, b in scan["buckets"].items():
        label = "all" if key == "all" else f"{key} cam{'s' if key != '1' else ''}"
        bp, by = lags.index(b["best_position_ms"]), lags.index(b["best_yaw_ms"])
        zero = "" if at0 is None else f"L=0: {b['position_mm'][at0]:.0f} mm, {b['yaw_deg'][at0]:.1f} deg; "
        lines.append(f"  {label:7s} (n={b['samples']}): {zero}best position L={lags[bp]} ms {b['position_mm'][bp]:.0f} mm; "
                     f"best yaw L={lags[by]} ms {b['yaw_deg'][by]:.1f} deg")
    return "\n".join(lines)


def replay_summary(rep: Replay, per_frame: NDArray, truth: NDArray, truth_offset_m: float) -> dict:
    """The JSON-ready facts of a replay beside its scores.

    Returns:
        ``{"source": {source: samples}, "people_published": {count: samples},
        "views_scored": {count: samples}, "accepted", "rejected": {reason: n},
        "tracker": {...}, "jitter": {"per_frame": ..., "temporal": ...}}`` (``jitter``).
    """
    src, cnt = np.unique(rep.source, return_counts=True)
    ppl, pcnt = np.unique(rep.people, return_counts=True)
    vws, vcnt = np.unique(rep.views, return_counts=True)
    return {
        "source": {s: int(dict(zip(src, cnt)).get(s, 0)) for s in SOURCES},
        "people_published": {str(int(p)): int(c) for p, c in zip(ppl, pcnt)},
        "views_scored": {str(int(v)): int(c) for v, c in zip(vws, vcnt)},
        "accepted": int(rep.accepted),
        "rejected": {k: int(v) for k, v in sorted(rep.rejected.items())},
        "tracker": {k: int(v) for k, v in rep.tracker.items() if v},
        "jitter": {
            "per_frame": jitter(per_frame, truth, truth_offset_m),
            "temporal": jitter(rep.poses, truth, truth_offset_m),
        },
    }


def format_replay(name: str, summary: Mapping) -> str:
    """One line on a replay (``replay_summary``): how samples were scored, people published, jitter, rejections."""
    src, jit = summary["source"], summary["jitter"]

    def j(block: Mapping) -> str:
        if block["position_mm"] is None:
            return "-"
        return f"{block['position_mm']:.0f} mm {block['yaw_deg']:.1f} deg"

    people = ", ".join(f"{k}: {v}" for k, v in summary["people_published"].items())
    rejected = ", ".join(f"{k} {v}" for k, v in summary["rejected"].items()) or "none"
    return (
        f"{name} temporal: {src['track']} samples scored on the track holding their view, {src['nearest']} on the "
        f"nearest published person, {src['per_frame']} per-frame (nobody published yet); samples by people published "
        f"{{{people}}}; jitter per-frame {j(jit['per_frame'])} -> temporal {j(jit['temporal'])}; "
        f"observations accepted {summary['accepted']}, rejected {rejected}"
    )
