"""Simulated datasets: deterministic, truth offset, storage, random sites."""

import math

import numpy as np
import pytest

from superbody.edge.camera import project
from superbody.edge.site import load_site
from superbody.models.data.simdata import SimDataConfig, generate, load_samples, random_site, save_samples
from tests.conftest import WTF_SITE


@pytest.fixture(scope="module")
def site():
    return load_site(WTF_SITE)


def test_same_config_same_samples_whatever_the_workers(site):
    cfg = SimDataConfig(samples=900, seed=4)
    a = generate(site, cfg, workers=1, progress=False)
    b = generate(site, cfg, workers=2, progress=False)
    assert len(a) == len(b) == 900
    assert all(np.array_equal(x.truth, y.truth) and x.views.keys() == y.views.keys() for x, y in zip(a, b))
    assert all(1 <= len(s.views) <= 3 for s in a)


def test_truth_offset_moves_the_truth_forward(site):
    base = generate(site, SimDataConfig(samples=50, seed=1), workers=1, progress=False)
    moved = generate(site, SimDataConfig(samples=50, seed=1, truth_offset_m=0.21), workers=1, progress=False)
    for a, b in zip(base, moved):
        yaw = a.truth[2]
        np.testing.assert_allclose(b.truth[:2] - a.truth[:2], 0.21 * np.array([math.cos(yaw), math.sin(yaw)]), atol=1e-12)


# (field, value) that the config rejects
BAD = [("samples", 0), ("max_people", 0), ("max_people", 11), ("truth_offset_m", 0.9)]


@pytest.mark.parametrize("field,value", BAD)
def test_config_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        SimDataConfig(**{field: value})


def test_save_load_round_trip(site, tmp_path):
    samples = generate(site, SimDataConfig(samples=40, seed=2, depth=True), workers=1, progress=False)
    path = tmp_path / "d.npz"
    save_samples(path, samples, site.camera_ids)
    back = load_samples(path)
    for a, b in zip(samples, back):
        assert a.views.keys() == b.views.keys()
        np.testing.assert_array_equal(a.truth, b.truth)
        for c in a.views:
            np.testing.assert_array_equal(a.views[c].keypoints, b.views[c].keypoints)
            np.testing.assert_array_equal(a.views[c].points3d, b.views[c].points3d)


@pytest.mark.parametrize("seed", range(5))
def test_random_sites_look_into_the_room(seed):
    site = random_site(np.random.default_rng(seed))
    x0, y0, x1, y1 = site.floor_bounds
    centre = np.array([[(x0 + x1) / 2, (y0 + y1) / 2, 1.0]])
    assert 2 <= len(site.cameras) <= 5
    for cam in site.cameras:
        uv, z = project(centre, cam)
        assert z[0] > 0 and 0 <= uv[0, 0] < cam.width and 0 <= uv[0, 1] < cam.height
    samples = generate(site, SimDataConfig(samples=30, seed=seed), workers=1, progress=False)
    assert len(samples) == 30
