"""The aggregator core: clock-injected, no threads, driven by simulated observations."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from superbody.edge.angles import wrap_angle
from superbody.edge.messages import wire
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.aggregator import Aggregator, HostConfig, confidence, confidences
from superbody.host.estimation.analytic import AnalyticEstimator
from superbody.host.messages import pose as pose_msg
from tests.conftest import WTF_SITE

T0 = 1_700_000_000 * 10**9
FPS = 15


@pytest.fixture(scope="module")
def site():
    return load_site(WTF_SITE)


def _frames(site, world, seconds: float):
    """Every camera's encoded observations in capture order, as (stamp, camera, payload)."""
    cams = [SimCamera(world, c) for c in site.camera_ids]
    out = []
    for k in range(int(seconds * FPS)):
        for i, cam in enumerate(cams):
            stamp = T0 + int((k + i / len(cams)) * 1e9 / FPS)
            out.append((stamp, cam.camera.id, wire.encode(cam.observe(stamp)[0])))
    return out


def test_three_people_confirmed_tracked_and_estimated(site):
    world = World(site, 3, seed=11)
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    confirmed_at = None
    errors = []
    for stamp, cam, payload in _frames(site, world, 12.0):
        assert agg.ingest(payload, f"superbody/{site.name}/cameras/{cam}/observations", stamp)
        arr = agg.step(stamp)
        if len(arr.people) == 3 and confirmed_at is None:
            confirmed_at = stamp
        if confirmed_at is not None and stamp - confirmed_at > 2e9:
            truth = world.states(stamp * 1e-9)
            for p in arr.people:
                d = [math.hypot(p.x - t.x, p.y - t.y) for t in truth]
                k = int(np.argmin(d))
                errors.append((d[k], abs(wrap_angle(p.yaw - truth[k].yaw))))
    assert confirmed_at is not None and (confirmed_at - T0) / 1e9 < 3.0
    assert len({p.id for p in arr.people}) == 3 and arr.seq > 0
    e = np.array(errors)
    assert np.median(e[:, 0]) < 0.25  # the analytic estimator, filtered
    assert not agg.rejected


def test_step_without_data_is_empty(site):
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    arr = agg.step(T0)
    assert arr.people == () and arr.site == site.name and arr.estimator == "analytic"


def _good(site) -> bytes:
    world = World(site, 1, seed=1)
    return wire.encode(SimCamera(world, "1").observe(T0)[0])


def _mutate(the_site, **changes) -> bytes:
    doc = json.loads(_good(the_site))
    doc.update(changes)
    return json.dumps(doc).encode()


# (payload maker, key camera, reason counted)
BAD = [
    (lambda s: b"\xff\xfe", "1", "not_utf8"),  # binary garbage
    (lambda s: b"{not json", "1", "not_json"),  # truncated text
    (lambda s: _mutate(s, version=99), "1", "version"),  # a future schema version
    (lambda s: _mutate(s, site="other-site"), "1", "site"),  # another site's camera on our key
    (lambda s: _mutate(s, camera="9"), "9", "unknown_camera"),  # a camera the site does not have
    (lambda s: _mutate(s, image=[1280, 720]), "1", "image_size"),  # not the calibrated image size
    (lambda s: _good(s), "2", "key_mismatch"),  # camera 1's payload on camera 2's key
    (lambda s: _mutate(s, stamp_ns=T0 + 60 * 10**9), "1", "future_stamp"),  # clock far ahead
    (lambda s: b"x" * (wire.MAX_PAYLOAD_BYTES + 1), "1", "oversize"),  # too big
]


@pytest.mark.parametrize("make,camera,reason", BAD)
def test_bad_payloads_are_counted_by_reason_and_dropped(site, make, camera, reason):
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    assert not agg.ingest(make(site), f"superbody/{site.name}/cameras/{camera}/observations", T0)
    assert agg.rejected == {reason: 1}
    assert agg.ingest(_good(site), f"superbody/{site.name}/cameras/1/observations", T0)  # still working
    assert agg.accepted == 1


def test_late_frames_are_counted(site):
    world = World(site, 1, seed=2)
    cam = SimCamera(world, "1")
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    key = f"superbody/{site.name}/cameras/1/observations"
    new, old = wire.encode(cam.observe(T0 + 10**9)[0]), wire.encode(cam.observe(T0)[0])
    assert agg.ingest(new, key, T0 + 10**9)
    assert not agg.ingest(old, key, T0 + 10**9)
    assert agg.rejected == {"late": 1}


def test_confidence_grows_with_what_was_seen():
    from superbody.edge.messages.observation import PersonView
    kp = np.full((17, 3), np.nan, np.float32)
    kp[:5] = [100, 100, 0.8]
    few = PersonView(kp, np.zeros(4, np.float32), np.zeros((16, 8), np.float32))
    full = PersonView(np.tile(np.array([[100, 100, 0.9]], np.float32), (17, 1)), np.zeros(4, np.float32), np.zeros((16, 8), np.float32))
    assert 0 < confidence({"1": few}) < confidence({"1": full}) < confidence({"1": full, "2": full}) == 1.0
    assert confidence({}) == 0.0
    sets = [{"1": few}, {"1": full, "2": few}, {"1": full, "2": full}, {"3": few, "1": few, "2": full}]
    assert np.allclose(confidences(sets), [confidence(v) for v in sets], rtol=0, atol=1e-6)


@pytest.mark.parametrize("field,value", [("freshness_s", 0), ("queue_size", 0), ("min_publish_hz", -1)])
def test_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        HostConfig(**{field: value})


def _replay_ids(site, world, start_ns: int, seconds: float, cameras: tuple[str, ...], estimator) -> dict[int, set[int]]:
    """Feed the cameras' frames in capture order, 5 ms after capture; the track ids each true person got."""
    agg = Aggregator(site, estimator, "onnx")
    cams = [SimCamera(world, c) for c in cameras]
    period = 1e9 / FPS
    k0 = math.ceil(start_ns / period)
    frames = sorted((int(k * period + period * site.camera_index(c.camera.id) / 3), c)
                    for k in range(k0, k0 + int(seconds * FPS)) for c in cams)
    ids: dict[int, set[int]] = {}
    for stamp, cam in frames:
        obs, who = cam.observe(stamp)
        assert agg.ingest(wire.encode(obs), f"superbody/{site.name}/cameras/{cam.camera.id}/observations", stamp + 5_000_000)
        arr = agg.step(stamp + 5_000_000)
        if not arr.people:
            continue
        # As the demo scores: each pose to the true person nearest at its capture time, jointly.
        truth = np.array([[t.x, t.y] for t in world.states(arr.people[0].stamp_ns * 1e-9)])
        cost = np.linalg.norm(np.array([[p.x, p.y] for p in arr.people])[:, None] - truth[None], axis=2)
        for r, k in zip(*linear_sum_assignment(cost)):
            if cost[r, k] < 1.0:
                ids.setdefault(int(k), set()).add(arr.people[r].id)
    return ids


@pytest.mark.parametrize(
    ("start_s", "seconds"),
    [
        # The apartment's floor without a range cut-off (December 2026) gave the world a new plan:
        (1_700_000_077, 14.0),  # person 1 unseen by cameras 1 and 2 for 5.9 s from 81.0 s (a new id without re-identification)
        (1_700_000_227, 14.0),  # person 0 unseen for 5.3 s from 231.6 s (likewise)
    ],
)
def test_a_person_out_of_every_live_camera_for_seconds_keeps_their_id(site, start_s, seconds):
    """The flaky demo test's failures, replayed deterministically: seed 7, camera 3 dead, the
    windows of the world's 600 s plan where a person stood where only camera 3 could see them
    for longer than remove_after_s; they used to come back under a new id (a fourth track and
    an identity switch)."""
    from superbody.host.estimation import build_estimator

    estimator, _ = build_estimator(site, "onnx")
    world = World(site, 3, seed=7)
    ids = _replay_ids(site, world, start_s * 10**9, seconds, ("1", "2"), estimator)
    assert sorted(ids) == [0, 1, 2] and all(len(v) == 1 for v in ids.values()), ids


def test_near_future_stamps_cannot_blind_a_camera(site):
    """Issue 11 #3: a peer's empty frames stamped ahead of the host's clock used to make the
    camera's real frames "late" until the clock caught up: 2 such frames a second kept it blind."""
    world = World(site, 1, seed=2)
    cam = SimCamera(world, "1")
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    key = f"superbody/{site.name}/cameras/1/observations"
    real_ok = forged_n = 0
    for k in range(10 * FPS):  # 10 s
        now = T0 + k * 10**9 // FPS
        real_ok += agg.ingest(wire.encode(cam.observe(now)[0]), key, now + 1_000_000)
        if k % 7 == 0:  # 2 forged frames a second, just inside and just past the limit
            forged_n += 1
            for ahead_s in (0.201, 0.9):  # posing as the camera's next frame
                agg.ingest(_mutate(site, stamp_ns=now + int(ahead_s * 1e9), people=[], seq=k + 1), key, now + 2_000_000)
    # Each forged frame inside the limit costs the real frame whose number it took; no more.
    assert real_ok == 10 * FPS - forged_n and agg.rejected == {"future_stamp": forged_n, "duplicate": forged_n}


@pytest.mark.parametrize(
    ("second", "reason"),
    [
        (dict(stamp_ns=T0, seq=1), "duplicate"),                    # the same stamp again
        (dict(stamp_ns=T0 + 10**8, seq=0), "duplicate"),            # the same frame re-stamped
        (dict(stamp_ns=T0 + 10**8), "seq_backwards"),               # seq goes back, no restart
        (dict(stamp_ns=T0 + 10**8, seq=5), "duplicate"),            # the same seq again
        (dict(stamp_ns=T0 - 10**8, seq=6), "late"),                 # older than the last one
        (dict(stamp_ns=T0 - 3 * 10**9, seq=6), "stale"),            # older than anyone is kept
    ],
)
def test_replayed_and_out_of_order_frames_are_rejected_by_reason(site, second, reason):
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    key = f"superbody/{site.name}/cameras/1/observations"
    assert agg.ingest(_mutate(site, stamp_ns=T0, seq=0 if second.get("seq") == 0 else 5), key, T0)
    assert not agg.ingest(_mutate(site, **{"seq": 2, **second}), key, T0 + 10**8)
    assert agg.rejected == {reason: 1} and agg.accepted == 1


def test_liveliness_of_names_outside_the_site_is_counted_and_ignored(site):
    """Issue 11 #1: a token ``cameras/ev.il/alive`` (or 65 tokens) made every PoseArray unencodable."""
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    assert agg.camera_liveliness(f"superbody/{site.name}/cameras/1/alive", True)
    bad = [f"superbody/{site.name}/cameras/ev.il/alive"] + [f"superbody/{site.name}/cameras/x{i}/alive" for i in range(65)]
    assert not any(agg.camera_liveliness(k, True) for k in bad)
    assert agg.rejected == {"unknown_camera_alive": 66}
    arr = agg.step(T0)
    assert arr.cameras_alive == ("1",)
    pose_msg.decode(pose_msg.encode(arr))  # publishable
    assert agg.camera_liveliness(f"superbody/{site.name}/cameras/1/alive", False) and agg.step(T0).cameras_alive == ()


def test_a_forged_high_sequence_number_costs_one_real_frame_not_the_camera(site):
    world = World(site, 1, seed=2)
    cam = SimCamera(world, "1")
    agg = Aggregator(site, AnalyticEstimator(site), "analytic")
    key = f"superbody/{site.name}/cameras/1/observations"
    used = 0
    for k in range(3 * FPS):
        now = T0 + k * 10**9 // FPS
        if k % FPS == 5:  # one forged frame a second, seq far ahead
            agg.ingest(_mutate(site, stamp_ns=now - 1_000_000, people=[], seq=10**9 + k), key, now)
        used += agg.ingest(wire.encode(cam.observe(now)[0]), key, now + 1_000_000)
    assert used == 3 * FPS - 3 and agg.rejected == {"seq_backwards": 3}


class _Jumpy:
    """Geometry whose yaw jumps by 3 rad on every other call: without the filter, rates of
    ~3 rad per 22 ms between cameras' frames, beyond what a PoseArray may carry."""

    def __init__(self, site):
        self._inner, self._calls = AnalyticEstimator(site), 0

    def estimate(self, view_sets):
        pose = np.asarray(self._inner.estimate(view_sets), dtype=np.float64).copy()
        self._calls += 1
        pose[:, 2] = wrap_angle(pose[:, 2] + 3.0 * (self._calls % 2))
        return pose


class _Astray:
    """Geometry whose every third estimate is 1.5 m off, claiming its usual sigma: a set S gone
    wrong (scene m: partial views through a doorway placed 1-3 m off by one camera's rays)."""

    def __init__(self, site):
        from superbody.host.estimation import geometry_sigmas

        sigmas = geometry_sigmas(site)  # the shipped model's calibration: geometry's sigmas per camera count
        assert sigmas is not None  # an estimator that gives none is not tested
        self._inner, self._calls = AnalyticEstimator(site, sigmas), 0

    def estimate_detailed(self, view_sets):
        est = self._inner.estimate_detailed(view_sets)
        pose = est.pose.copy()
        for row in pose:
            self._calls += 1
            row[0] += 1.5 * (self._calls % 3 == 0)
        return dataclasses.replace(est, pose=pose)


def test_an_estimate_where_the_persons_views_cannot_stand_is_not_published(site):
    world = World(site, 2, seed=4)
    agg = Aggregator(site, _Astray(site), "astray")
    errors = []
    for stamp, cam, payload in _frames(site, world, 8.0):
        assert agg.ingest(payload, f"superbody/{site.name}/cameras/{cam}/observations", stamp)
        arr = agg.step(stamp)
        if stamp - T0 > 4e9:
            truth = world.states(stamp * 1e-9)
            errors += [min(math.hypot(p.x - t.x, p.y - t.y) for t in truth) for p in arr.people]
    assert len(errors) > 300
    # Measured: median 72 mm, p90 157 mm, 109 estimates replaced; taking them: 142 and 395 mm.
    assert np.median(errors) < 0.15 and np.percentile(errors, 90) < 0.3, (np.median(errors), np.percentile(errors, 90))
    assert agg.rejected["estimate_off_track"] > 50


def test_an_out_of_range_rate_is_clamped_and_every_pose_array_publishes(site):
    from dataclasses import replace

    from superbody.host.filtering.pose_filter import FilterConfig
    from superbody.host.messages.pose_rules import MAX_SPEED

    world = World(site, 2, seed=4)
    agg = Aggregator(site, _Jumpy(site), "jumpy", HostConfig(filter=replace(FilterConfig(), enabled=False)))
    at_limit = 0
    for stamp, cam, payload in _frames(site, world, 5.0):
        assert agg.ingest(payload, f"superbody/{site.name}/cameras/{cam}/observations", stamp)
        arr = agg.step(stamp)
        assert pose_msg.decode(pose_msg.encode(arr)).seq == arr.seq  # never unpublishable
        at_limit += sum(abs(p.yaw_rate) == MAX_SPEED for p in arr.people)
    assert at_limit > 0 and len(arr.people) == 2  # the clamp was needed, and nobody was dropped


@pytest.mark.parametrize("kind", ["analytic", "auto"])
def test_views_that_show_no_yaw_keep_the_persons_last_yaw(site, kind):
    """People cut off at an image edge (scene g): a view of one side of a body (no shoulder or hip
    pair, no nose with an eye or ear) gives the analytic estimator a yaw of 0 by convention. That
    yaw says nothing and is reported so (``YAW_STD_NO_CUE``), by geometry alone and by the
    apartment's hybrid: the filter keeps the person's last yaw. Before, the filter took the 0 (at
    its default 4 deg; the hybrid, at the calibration's no-pair sigma, 1.6 rad) and within 1.5 s
    the person, who stood still facing 2 rad, had turned by 100-141 deg (scene g at seed 1: yaw
    p90 132 -> 58 deg)."""
    from superbody.edge import body
    from superbody.edge.messages.observation import Observation
    from superbody.edge.sim import NoiseModel, PersonState, render_views, skeleton
    from superbody.host.estimation import build_estimator

    clean = NoiseModel(pixel_noise_px=0.0, joint_rate=(1.0,) * 17, view_quality_std=0.0, view_miss_prob=0.0,
                       truncated_miss_prob=0.0, swap_prob=0.0, spurious_prob=0.0, facing_visibility=None, occluded_keep=1.0)
    x, y, yaw = -0.5, -1.0, 2.0
    state = PersonState(x, y, yaw, skeleton(x, y, yaw, 0.0, 0.0))
    world = World(site, 1, seed=0)
    left_side = [body.INDEX[n] for n in ("left_shoulder", "left_elbow", "left_wrist", "left_hip", "left_knee", "left_ankle")]
    est, name = build_estimator(site, kind)
    assert name.split(":")[0] == ("analytic" if kind == "analytic" else "hybrid")
    agg = Aggregator(site, est, name)
    yaws = []
    for k in range(int(4.5 * FPS)):
        for i, cam in enumerate(site.camera_ids):
            stamp = T0 + int((k + i / 3) * 1e9 / FPS)
            (_, view), = render_views([state], [world.people[0].appearance], site.camera(cam), np.random.default_rng(k), clean, site)
            if k >= 3 * FPS:  # from 3 s on, one side of the body only
                kp = np.full_like(view.keypoints, np.nan)
                kp[left_side] = view.keypoints[left_side]
                view = dataclasses.replace(view, keypoints=kp)
            obs = Observation(site.name, cam, k, stamp, site.camera(cam).width, site.camera(cam).height, (view,))
            assert agg.ingest(wire.encode(obs), f"superbody/{site.name}/cameras/{cam}/observations", stamp)
            arr = agg.step(stamp)
            if k >= 3 * FPS and arr.people:
                yaws.append(arr.people[0].yaw)
    assert AnalyticEstimator(site).estimate_with_cues([{"1": view}])[1][0] == 0  # the premise: no yaw cue in those views
    assert len(yaws) > 50 and max(abs(wrap_angle(a - yaw)) for a in yaws) < math.radians(8)
