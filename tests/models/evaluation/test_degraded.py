"""The degraded-view cross-validation's degradations and buckets (models/evaluation/degraded.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from superbody.edge.site import load_site
from superbody.models.data.wtf import load_wtf, truth_to_torso
from superbody.models.evaluation.degraded import FAR_M, KINDS, bucket_masks, degrade, degraded_set
from tests.conftest import WTF_SITE


@pytest.fixture(scope="module")
def dev(dev_json):
    return load_wtf(dev_json, load_site(WTF_SITE))


def _three_views(dev):
    return next(s for s in dev if len(s.views) == 3 and all((~np.isnan(v.keypoints[:, 0])).sum() >= 11 for v in s.views.values()))


def _seen(v) -> np.ndarray:
    return ~np.isnan(v.keypoints[:, 0])


def test_a_top_edge_takes_the_head_and_keeps_the_legs(dev):
    s = _three_views(dev)
    for seed in range(10):
        d = degrade(s, "top_edge", np.random.default_rng(seed))
        changed = [c for c in s.views if d.views[c] is not s.views[c]]
        assert len(changed) == 1 and set(d.views) == set(s.views)  # one view cut, none lost
        before, after = s.views[changed[0]], d.views[changed[0]]
        assert not _seen(after)[:5].any()  # the face is above the edge
        assert (_seen(after)[13:] == _seen(before)[13:]).all()  # knees and ankles are below it
        rows = after.keypoints[_seen(after), 1]
        assert after.bbox[1] == pytest.approx(rows.min()) and after.bbox[3] == pytest.approx(rows.max())


def test_a_side_edge_keeps_one_side_of_the_body(dev):
    s = _three_views(dev)
    d = degrade(s, "side_edge", np.random.default_rng(3))
    (cam,) = [c for c in s.views if d.views.get(c) is not s.views[c]]
    kept = d.views.get(cam)
    assert kept is None or _seen(kept).sum() < _seen(s.views[cam]).sum()


def test_far_single_leaves_one_view_with_fewer_face_and_arm_joints(dev):
    s = _three_views(dev)
    lost = []
    for seed in range(30):
        d = degrade(s, "far_single", np.random.default_rng(seed))
        (cam,) = d.views
        lost.append(_seen(s.views[cam])[[0, 1, 2, 3, 4, 7, 8, 9, 10]].sum() - _seen(d.views[cam])[[0, 1, 2, 3, 4, 7, 8, 9, 10]].sum())
        assert (_seen(d.views[cam])[[5, 6, 11, 12]] == _seen(s.views[cam])[[5, 6, 11, 12]]).all()  # the torso stays
    assert 1.5 < np.mean(lost) < 5  # 0.7 of each face joint and 0.5 of each arm joint seen (1.5-4.8 by view here)


def test_drop_camera_needs_two_views(dev):
    one = next(s for s in dev if len(s.views) == 1)
    assert degrade(one, "drop_camera", np.random.default_rng(0)) is None
    s = _three_views(dev)
    assert len(degrade(s, "drop_camera", np.random.default_rng(0)).views) == 2
    with pytest.raises(ValueError, match="unknown degradation 'blur'"):
        degrade(s, "blur", np.random.default_rng(0))


def test_the_degraded_set_is_seeded_and_its_buckets_hold_what_they_say(dev):
    a, src, kinds = degraded_set(dev[:40], seed=1)
    b, _, _ = degraded_set(dev[:40], seed=1)
    assert set(kinds) == set(KINDS) and len(a) == len(src) == len(kinds)
    assert all(np.array_equal(x.views[c].keypoints, y.views[c].keypoints, equal_nan=True) for x, y in zip(a, b, strict=True) for c in x.views)
    site = load_site(WTF_SITE)
    torso = truth_to_torso(np.array([dev[i].truth for i in src]))
    m = bucket_masks(a, torso, site)
    assert m["all"].all() and (m["one view"] >= m["one far view"]).all()
    assert m["one view"][kinds == "far_single"].all()
    for i in np.flatnonzero(m["one far view"]):
        (cid,) = a[i].views
        assert math.dist(site.camera(cid).t[:2], torso[i, :2]) > FAR_M
    for i in np.flatnonzero(m["<= 8 joints"]):
        assert max(int(_seen(v).sum()) for v in a[i].views.values()) <= 8
