"""The aggregator core: clock-injected, no threads, driven by simulated observations."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from superbody.edge import wire
from superbody.edge.angles import wrap_angle
from superbody.edge.simulator import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.aggregator import Aggregator, HostConfig, confidence
from superbody.host.analytic import AnalyticEstimator
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
    from superbody.edge.observation import PersonView
    kp = np.full((17, 3), np.nan, np.float32)
    kp[:5] = [100, 100, 0.8]
    few = PersonView(kp, np.zeros(4, np.float32), np.zeros((16, 8), np.float32))
    full = PersonView(np.tile(np.array([[100, 100, 0.9]], np.float32), (17, 1)), np.zeros(4, np.float32), np.zeros((16, 8), np.float32))
    assert 0 < confidence({"1": few}) < confidence({"1": full}) < confidence({"1": full, "2": full}) == 1.0
    assert confidence({}) == 0.0


@pytest.mark.parametrize("field,value", [("freshness_s", 0), ("queue_size", 0), ("min_publish_hz", -1)])
def test_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        HostConfig(**{field: value})
