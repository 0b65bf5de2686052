"""Temporal evaluation: replay a recording through the host's own aggregator and score what it publishes.

``superbody eval`` scores each sample on its own (per frame). The live system does more: the
tracker (host.tracking.tracker) keeps people over time, the estimator sees each person's set S (the
latest fresh view per camera, possibly from different instants) and the Kalman filter
(host.filtering.pose_filter) smooths the result (it takes each estimate at the mean capture time of its views
and predicts the pose on to the newest view's time). ``replay`` runs exactly that code, in-process, with the world
clock injected:

1. every view of every sample becomes an Observation encoded with ``edge.messages.wire``, as a camera
   node would publish it (and a camera with no view in a sample publishes an empty frame then, as a
   live node publishes every frame): keypoints (u, v, score), the box around them
   (``models.data.wtf.keypoint_bbox``), camera-frame 3D joints only when the estimator's graph uses
   them, and a colour signature. A WheresTheFellow recording has no colour: each view gets the
   same constant synthetic signature (``SIGNATURE``, a flat hue-saturation histogram), so colour
   never tells views apart and the tracker matches on geometry (one person in the recording);
2. the observations are fed in capture-time order, each at its own capture time; views with the
   same time stamp form one batch (one ingest each), and the host steps after each batch, as the
   live host does after draining its queue (``Aggregator.ingest``, ``Aggregator.step``; the
   cameras deliver at once: the host's clock reads the batch's capture time);
3. each sample is scored at its capture time (its first, earliest view's stamp, as
   ``models.data.wtf`` defines it, which is also its truth's time): on the first PoseArray as of
   that time or later (``Aggregator.as_of_ns``, the host's watermark: it fuses every camera up to
   it, in capture order), so the host has seen every view captured up to then. As live, the host
   holds an instant until every camera's frame of it is in (``Aggregator.step``), so that array
   describes the sample's instant whole: its other views too, captured up to about 0.2 s later in
   dev.json (until December 2026 they counted for the next sample, and the array held the other
   cameras' views of the sample before). ``at="last"`` scores once the sample's last view is in
   instead (the same views as the per-frame estimate, but a pose up to that much younger than
   the truth); with the held instants the two mostly agree.

Which person is the sample's (``SOURCES``):

- ``"track"``: the published person whose track holds the sample's view(s) captured by then (the
  tracker assigned them to it); its published pose is scored;
- ``"nearest"``: the sample's views went to no published person (a candidate not yet
  confirmed, or too few joints to track), but someone is published: the person nearest to the
  sample's per-frame estimate. The choice never looks at the ground truth;
- ``"per_frame"``: nobody is published yet (the first ``TrackerConfig.confirm_after_s``, about
  2 s, of a recording): the per-frame estimate, as a consumer would have nothing better.

The poses are torso centres, like the per-frame estimates, so ``models.evaluation.evaluate.summarise``
(which moves them to the dataset's chest tracker, ``torso_to_truth``) scores both alike, in the
same buckets: the number of cameras that saw the sample. The host's set S may hold more
cameras than that (a view stays fresh for ``HostConfig.freshness_s``); ``Replay.views`` says
how many it held.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Final, Literal

import numpy as np
from numpy.typing import NDArray

from superbody.edge import transport
from superbody.edge.colour import HIST_BINS
from superbody.edge.messages import wire
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.site import Site
from superbody.host.aggregator import Aggregator, HostConfig
from superbody.host.estimation.estimator import Estimator
from superbody.models.data.samples import Sample
from superbody.models.data.wtf import RawSample

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
    "simulated_recording",
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
    empty_frames: bool = True,
) -> list[tuple[int, list[tuple[str, bytes]]]]:
    """Every view as the (key, payload) a camera node would publish, batched by capture time.

    Args:
        samples: the recording, one person per sample.
        stamps: per sample, camera id -> capture time (UNIX ns) of that view (``view_stamps``).
        site: the site (its name and image sizes go into each Observation).
        with_3d: send the views' camera-frame 3D joints (``PersonView.points3d``).
        signature: the colour histogram every view carries; None keeps each view's own.
        empty_frames: a camera with no view in a sample publishes an empty frame at the sample's
            time (its first view's), as a live node publishes every frame: the host's watermark
            waits for every camera (``host.timeline``), so a camera that sent nothing would hold
            it back. False: only the views.

    Returns:
        ``(stamp_ns, [(key, payload), ...])`` in increasing time; within a batch, in the site's
        camera order. Each camera's ``seq`` counts its frames from 0.

    Raises:
        ValueError: the stamps do not match the samples' views, a camera is not in the site, a
            camera has two views with one stamp, or a view does not encode (the message names it).
    """
    if len(stamps) != len(samples):
        raise ValueError(f"observation_batches: {len(stamps)} stamp sets for {len(samples)} samples")
    events: dict[tuple[int, str], tuple[int, PersonView | None]] = {}
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
        if empty_frames:  # a live node publishes every frame, also when its detector found nobody
            first = min(int(t) for t in st.values())
            for cam in site.camera_ids:
                if cam not in st and (first, cam) not in events:
                    events[first, cam] = (i, None)
    order = sorted(events, key=lambda k: (k[0], site.camera_index(k[1])))
    seq = dict.fromkeys(site.camera_ids, 0)
    batches: list[tuple[int, list[tuple[str, bytes]]]] = []
    for stamp, cam in order:
        i, shown = events[(stamp, cam)]
        c = site.camera(cam)
        obs = Observation(site=site.name, camera=cam, seq=seq[cam], stamp_ns=stamp, width=c.width, height=c.height,
                          people=() if shown is None else (_wire_view(shown, with_3d, signature),))
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
            (``models.evaluation.evaluate.predict``): the fallback before anyone is published, and the
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
    # The host fuses in capture time, up to its watermark (host.timeline): a sample is scored on the
    # first PoseArray as of its time or later. A last step once every camera would have delivered
    # (max_delay_s after the last frame) lets the watermark pass the last samples.
    last = batches[-1][0] if batches else 0
    steps = [(stamp, batch) for stamp, batch in batches] + [(last + round(config.max_delay_s * 1e9) + 1, [])]
    for stamp, batch in steps:
        for key, payload in batch:
            agg.ingest(payload, key, stamp)
        arr = agg.step(stamp)
        as_of = agg.as_of_ns
        assert as_of is not None
        while k < n and when[due[k]] <= as_of:
            i = due[k]
            k += 1
            people[i] = len(arr.people)
            if not arr.people:
                continue
            seen = [(cam, int(t)) for cam, t in stamps[i].items() if int(t) <= as_of]
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


# --- the truth's clock ---------------------------------------------------------------------------


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
        ``(samples, stamps)``: as ``models.data.wtf.to_samples`` and ``view_stamps`` give for a file.
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


