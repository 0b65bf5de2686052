"""Temporal evaluation: replay a recording through the host's own aggregator and score what it publishes.

``superbody eval`` scores each sample on its own (per frame). The live system does more: the
tracker (host.tracking.tracker) keeps people over time, the estimator sees each person's set S (the
latest fresh view per camera, possibly from different instants) and the Kalman filter
(host.filtering.pose_filter) smooths the result (it takes each estimate at the mean capture time of its views
and predicts the pose on to the newest view's time). ``replay`` runs exactly that code, in-process, with the world
clock injected:

1. every view of every sample becomes an Observation encoded with ``edge.messages.wire``, as a camera
   node would publish it: keypoints (u, v, score), the box around them
   (``models.wtf.keypoint_bbox``), camera-frame 3D joints only when the estimator's graph uses
   them, and a colour signature. A WheresTheFellow recording has no colour: each view gets the
   same constant synthetic signature (``SIGNATURE``, a flat hue-saturation histogram), so colour
   never tells views apart and the tracker matches on geometry (one person in the recording);
2. the observations are fed in capture-time order, each at its own capture time; views with the
   same time stamp form one batch (one ingest each), and the host steps after each batch, as the
   live host does after draining its queue (``Aggregator.ingest``, ``Aggregator.step``; zero
   latency: the host's clock reads the batch's capture time);
3. each sample is scored at its capture time (its first, earliest view's stamp, as
   ``models.wtf`` defines it, which is also its truth's time): the PoseArray of the step after
   the batch holding that view, so the host has seen every view captured up to then and none
   captured later. The sample's other views, captured a few milliseconds (at most about 0.2 s
   in dev.json) later, count for the next sample; the per-frame estimate does use them.
   ``at="last"`` scores once the sample's last view is in instead (the same views as the
   per-frame estimate, but a pose up to that much younger than the truth).

Which person is the sample's (``SOURCES``):

- ``"track"``: the published person whose track holds the sample's view(s) captured by then (the
  tracker assigned them to it); its published pose is scored;
- ``"nearest"``: the sample's views went to no published person (a candidate not yet
  confirmed, or too few joints to track), but someone is published: the person nearest to the
  sample's per-frame estimate. The choice never looks at the ground truth;
- ``"per_frame"``: nobody is published yet (the first ``TrackerConfig.confirm_after_s``, about
  2 s, of a recording): the per-frame estimate, as a consumer would have nothing better.

The poses are torso centres, like the per-frame estimates, so ``models.evaluate.summarise``
(which moves them to the dataset's chest tracker, ``torso_to_truth``) scores both alike, in the
same buckets: the number of cameras that saw the sample. The host's set S may hold more
cameras than that (a view stays fresh for ``HostConfig.freshness_s``); ``Replay.views`` says
how many it held.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Final, Literal, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.angles import wrap_angle
from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.estimation.estimator import Estimator
from superbody.models.evaluate import sample_errors
from superbody.models.samples import Sample
from superbody.models.wtf import RawSample, torso_to_truth

if TYPE_CHECKING:
    from superbody.edge.sim import NoiseModel

__all__ = [
    "SIGNATURE",
    "SOURCES",
    "Source",
    "SCORE_AT",
    "ScoreAt",
    "Replay",
    "view_stamps",
    "observation_batches",
    "uses_3d",
    "replay",
    "jitter",
    "replay_summary",
    "format_replay",
    "simulated_recording",
    "LATENCY_SCAN_MS",
    "truth_track",
    "truth_at",
    "latency_scan",
    "format_latency_scan",
]

Source = Literal["track", "nearest", "per_frame"]
SOURCES: Final[tuple[str, ...]] = ("track", "nearest", "per_frame")
ScoreAt = Literal["first", "last"]
SCORE_AT: Final[tuple[str, ...]] = ("first", "last")

# The recording has no colour: every view carries this flat hue-saturation histogram (sums to 1).
SIGNATURE: Final[NDArray[np.float32]] = np.full(HIST_BINS, 1.0 / (HIST_BINS[0] * HIST_BINS[1]), dtype=np.float32)
SIGNATURE.setflags(write=False)

_NS_PER_MS: Final[int] = 1_000_000


@dataclass(frozen=True, eq=False)
class Replay:
    """What the host published for each sample of a replayed recording.

    Attributes:
        poses: (N, 3) float64 torso poses (x, y, yaw) scored for each sample, REP-103; the
            per-frame estimate where ``source`` is ``"per_frame"``.
        source: (N,) which person was scored, one of ``SOURCES`` per sample.
        track_ids: (N,) int64 the scored person's track id, -1 for ``"per_frame"``.
        views: (N,) int64 cameras in the scored person's set S (0 for ``"per_frame"``).
        people: (N,) int64 people the host published at each sample's time (1 is right for a
            one-person recording; more means duplicate tracks).
        accepted: observations the aggregator accepted.
        rejected: observations it rejected, by reason (``Aggregator.rejected``).
        tracker: the tracker's counters at the end (``Tracker.stats``).
    """

    poses: NDArray[np.float64]
    source: NDArray[np.str_]
    track_ids: NDArray[np.int64]
    views: NDArray[np.int64]
    people: NDArray[np.int64]
    accepted: int
    rejected: dict[str, int] = field(default_factory=dict)
    tracker: dict[str, int] = field(default_factory=dict)


def view_stamps(raw: Sequence[RawSample]) -> list[dict[str, int]]:
    """Each sample's per-view capture times: camera id -> UNIX ns (the file's milliseconds)."""
    return [{v.camera: int(v.stamp_ms) * _NS_PER_MS for v in s.views} for s in raw]


def uses_3d(estimator: Estimator) -> bool:
    """Whether the estimator's graphs read camera-frame 3D joints (an ONNX model exported with them)."""
    spec = getattr(estimator, "spec", None)
    return bool(getattr(spec, "use_3d", False))


def _wire_view(view: PersonView, with_3d: bool, signature: NDArray | None) -> PersonView:
    return replace(
        view,
        histogram=view.histogram if signature is None else signature,
        points3d=view.points3d if with_3d else None,
    )


def observation_batches(
    samples: Sequence[Sample],
    stamps: Sequence[Mapping[str, int]],
    site: Site,
    with_3d: bool = False,
    signature: NDArray | None = SIGNATURE,
) -> list[tuple[int, list[tuple[str, bytes]]]]:
    """Every view as the (key, payload) a camera node would publish, batched by capture time.

    Args:
        samples: the recording, one person per sample.
        stamps: per sample, camera id -> capture time (UNIX ns) of that view (``view_stamps``).
        site: the site (its name and image sizes go into each Observation).
        with_3d: send the views' camera-frame 3D joints (``PersonView.points3d``).
        signature: the colour histogram every view carries; None keeps each view's own.

    Returns:
        ``(stamp_ns, [(key, payload), ...])`` in increasing time; within a batch, in the site's
        camera order. Each camera's ``seq`` counts its frames from 0.

    Raises:
        ValueError: the stamps do not match the samples' views, a camera is not in the site, a
            camera has two views with one stamp, or a view does not encode (the message names it).
    """
    if len(stamps) != len(samples):
        raise ValueError(f"observation_batches: {len(stamps)} stamp sets for {len(samples)} samples")
    events: dict[tuple[int, str], tuple[int, PersonView]] = {}
    for i, (s, st) in enumerate(zip(samples, stamps)):
        if set(st) != set(s.views):
            raise ValueError(f"sample {i}: stamps for cameras {sorted(st)}, views from cameras {sorted(s.views)}")
        for cam, view in s.views.items():
            if cam not in site.camera_ids:
                raise ValueError(f"sample {i}: camera {cam!r} is not in site {site.name!r} (cameras: {', '.join(site.camera_ids)})")
            key = (int(st[cam]), cam)
            if key in events:
                raise ValueError(f"sample {i}: camera {cam} has another view with the same stamp (sample {events[key][0]})")
            events[key] = (i, view)
    order = sorted(events, key=lambda k: (k[0], site.camera_index(k[1])))
    seq = dict.fromkeys(site.camera_ids, 0)
    batches: list[tuple[int, list[tuple[str, bytes]]]] = []
    for stamp, cam in order:
        i, view = events[(stamp, cam)]
        c = site.camera(cam)
        obs = Observation(site=site.name, camera=cam, seq=seq[cam], stamp_ns=stamp, width=c.width, height=c.height,
                          people=(_wire_view(view, with_3d, signature),))
        seq[cam] += 1
        try:
            payload = wire.encode(obs)
        except ValueError as e:
            raise ValueError(f"sample {i}, camera {cam}: {e}") from None
        if not batches or batches[-1][0] != stamp:
            batches.append((stamp, []))
        batches[-1][1].append((transport.observation_key(site.name, cam), payload))
    return batches


def replay(
    samples: Sequence[Sample],
    stamps: Sequence[Mapping[str, int]],
    per_frame: NDArray,
    site: Site,
    estimator: Estimator,
    estimator_name: str,
    config: HostConfig = HostConfig(),
    signature: NDArray | None = SIGNATURE,
    at: ScoreAt = "first",
) -> Replay:
    """Replay a recording through a fresh ``Aggregator`` and take what it publishes at each sample's time.

    Args:
        samples: the recording.
        stamps: per sample, camera id -> capture time of that view, UNIX ns (``view_stamps``).
        per_frame: (N, 3) the estimator's per-frame torso poses of the samples
            (``models.evaluate.predict``): the fallback before anyone is published, and the
            reference for ``"nearest"``.
        site: the site.
        estimator: the host's estimator (ONNX model or analytic).
        estimator_name: the name the host reports (e.g. ``onnx:wtf-apartment.int8.onnx``).
        config: the host's parameters (``superbody host run``'s defaults by default).
        signature: the colour histogram given to every view (None: keep the views' own).
        at: when each sample is scored: at its ``"first"`` view's capture time (the sample's
            time and its truth's, ``Sample.stamp_ns``), or once its ``"last"`` view is in.

    Returns:
        The ``Replay``: one pose per sample, in sample order.

    Raises:
        ValueError: as ``observation_batches``; ``per_frame`` has the wrong shape; ``at`` is
            not in ``SCORE_AT``.
    """
    n = len(samples)
    per_frame = np.asarray(per_frame, dtype=np.float64)
    if per_frame.shape != (n, 3):
        raise ValueError(f"replay: per_frame must have shape ({n}, 3), has {per_frame.shape}")
    if at not in SCORE_AT:
        raise ValueError(f"replay: at must be one of {', '.join(SCORE_AT)}, got {at!r}")
    batches = observation_batches(samples, stamps, site, uses_3d(estimator), signature)
    agg = Aggregator(site, estimator, estimator_name, config)

    poses = per_frame.copy()
    source = np.full(n, "per_frame", dtype="<U9")
    track_ids = np.full(n, -1, dtype=np.int64)
    views = np.zeros(n, dtype=np.int64)
    people = np.zeros(n, dtype=np.int64)
    pick = min if at == "first" else max
    when = [pick(int(t) for t in st.values()) for st in stamps]  # (N,) scoring times
    due = sorted(range(n), key=lambda i: when[i])
    k = 0
    for b, (stamp, batch) in enumerate(batches):
        for key, payload in batch:
            agg.ingest(payload, key, stamp)
        arr = agg.step(stamp)
        nxt = batches[b + 1][0] if b + 1 < len(batches) else math.inf
        # Every sample due before the next batch is scored on this PoseArray.
        while k < n and when[due[k]] < nxt:
            i = due[k]
            k += 1
            people[i] = len(arr.people)
            if not arr.people:
                continue
            seen = [(cam, int(t)) for cam, t in stamps[i].items() if int(t) <= stamp]
            holds = [sum(_holds(agg, p.id, cam, t) for cam, t in seen) for p in arr.people]
            if max(holds) > 0:
                j, source[i] = int(np.argmax(holds)), "track"
            else:
                d = [math.hypot(p.x - per_frame[i, 0], p.y - per_frame[i, 1]) for p in arr.people]
                j, source[i] = int(np.nanargmin(d)) if np.isfinite(d).any() else 0, "nearest"
            p = arr.people[j]
            poses[i] = (p.x, p.y, p.yaw)
            track_ids[i], views[i] = p.id, p.views
    return Replay(poses, source, track_ids, views, people, agg.accepted, dict(agg.rejected), dict(agg.tracker.stats))


def _holds(agg: Aggregator, track_id: int, camera: str, stamp_ns: int) -> bool:
    """Whether the track's latest view from ``camera`` is the one captured at ``stamp_ns``."""
    tr = agg.tracker.track(track_id)
    sv = None if tr is None else tr.views.get(camera)
    return sv is not None and sv.stamp_ns == stamp_ns


def jitter(pred: NDArray, truth: NDArray, truth_offset_m: float = 0.0, mask: NDArray | None = None) -> dict[str, float | None]:
    """How much the error changes from one sample to the next: the noise a filter should remove.

    RMS over consecutive pairs of samples (both finite, both in ``mask``) of the change of the
    error vector: ``|e_xy[i+1] - e_xy[i]|`` in millimetres and ``|wrap(e_yaw[i+1] - e_yaw[i])|``
    in degrees, with ``e = torso_to_truth(pred) - truth``. A prediction that follows the truth
    with a constant bias has no jitter.

    Args:
        pred: (N, 3) torso poses (x, y, yaw) in time order.
        truth: (N, 3) ground truth at the same times.
        truth_offset_m: how far in front of the torso the truth is (``models.wtf.TRUTH_OFFSET_M``).
        mask: (N,) bool, the samples to use (all by default).

    Returns:
        ``{"position_mm", "yaw_deg", "pairs"}``; the figures are None without a pair.
    """
    pred = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    if len(pred) != len(truth):
        raise ValueError(f"jitter: {len(pred)} predictions for {len(truth)} truths")
    ok = np.isfinite(pred).all(axis=1) & np.isfinite(truth).all(axis=1)
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


# --- the truth's clock ---------------------------------------------------------------------------

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
        truth_offset_m: how far in front of the torso the truth is (``models.wtf.TRUTH_OFFSET_M``).
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
    ok = np.isfinite(pred).all(axis=1)
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


def simulated_recording(
    site: Site,
    duration_s: float = 20.0,
    rate_hz: float = 8.0,
    seed: int = 0,
    noise: NoiseModel | None = None,
    camera_offsets_ms: Sequence[float] | None = None,
    start_s: float = 1_000.0,
) -> tuple[list[Sample], list[dict[str, int]]]:
    """One simulated person walking in the site, recorded like WheresTheFellow (truth known exactly).

    Every ``1 / rate_hz`` seconds each camera captures a frame, camera ``k`` at its own offset
    (``camera_offsets_ms[k]``, default ``7 k`` ms, as the dataset's cameras are not synchronised);
    the views that show the person make one sample. The truth is the person's torso pose
    (x, y, yaw) at the sample's time, its first view's (score with ``truth_offset_m = 0``).
    Spurious detections are off: a sample holds one person.

    Args:
        site: the site (cameras, floor, obstacles).
        duration_s: length of the recording.
        rate_hz: samples per second (dev.json: about 8).
        seed: the person, their walk and the detector noise follow from it.
        noise: the detector noise model (``edge.sim.NoiseModel()`` by default).
        camera_offsets_ms: capture offset of each camera of the site, in site order.
        start_s: world time of the first frame, seconds.

    Returns:
        ``(samples, stamps)``: as ``models.wtf.to_samples`` and ``view_stamps`` give for a file.
    """
    from superbody.edge.sim import NoiseModel, World, render_views  # OpenCV: only for simulated recordings

    if not (0 < duration_s <= 3600 and 0 < rate_hz <= 100):
        raise ValueError(f"simulated_recording: duration_s must be in (0, 3600] and rate_hz in (0, 100], got {duration_s}, {rate_hz}")
    offsets = [7.0 * k for k in range(len(site.cameras))] if camera_offsets_ms is None else list(camera_offsets_ms)
    if len(offsets) != len(site.cameras) or not all(0 <= o < 1000.0 / rate_hz for o in offsets):
        raise ValueError(f"simulated_recording: camera_offsets_ms needs {len(site.cameras)} values in [0, {1000.0 / rate_hz:g}), got {offsets}")
    noise = replace(noise or NoiseModel(), spurious_prob=0.0)
    world = World(site, num_people=1, seed=seed)
    person = world.people[0]
    samples: list[Sample] = []
    stamps: list[dict[str, int]] = []
    for k in range(int(duration_s * rate_hz)):
        t0_ns = round((start_s + k / rate_hz) * 1e9)
        views: dict[str, PersonView] = {}
        st: dict[str, int] = {}
        for c, (cam, off) in enumerate(zip(site.cameras, offsets)):
            t_ns = t0_ns + round(off * _NS_PER_MS)
            rng = np.random.default_rng([seed, c, k])
            out = render_views(world.states(t_ns * 1e-9), [person.appearance], cam, rng, noise, site, histograms=False)
            for who, view in out:
                if who == 0:
                    views[cam.id], st[cam.id] = view, t_ns
        if not views:
            continue
        first = min(st.values())
        state = person.state(first * 1e-9)
        samples.append(Sample(views=views, truth=np.array([state.x, state.y, state.yaw]), stamp_ns=first))
        stamps.append(st)
    return samples, stamps


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
