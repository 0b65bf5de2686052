"""The ONNX estimator: model/site checks, one batched call per tick, decoding to REP-103."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

# Building the tiny test models needs the training extra; the estimator itself does not.
torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from superbody.edge.messages.observation import PersonView  # noqa: E402
from superbody.edge.site import Site, parse_site  # noqa: E402
from superbody.host.estimation.estimator import Estimator, ModelMismatchError, OnnxEstimator, decode_output  # noqa: E402
from superbody.host.estimation.graph import GraphSpec, build_batch  # noqa: E402


def make_site(ids=("1", "2", "3"), name: str = "room", shift: float = 0.0) -> Site:
    corners = [(0.2, 0.2), (5.8, 0.2), (5.8, 4.8), (0.2, 4.8), (3.0, 0.2), (3.0, 4.8)]
    cams = [
        dict(id=cid, width=640, height=480, fps=15.0, fx=617.0, fy=617.0, cx=320.0, cy=240.0,
             position=[corners[k][0] + shift, corners[k][1], 2.4], look_at=[3.0 + shift, 2.5, 0.9])
        for k, cid in enumerate(ids)
    ]
    floor = [[shift, 0], [6 + shift, 0], [6 + shift, 5], [shift, 5]]
    return parse_site({"site": {"name": name}, "floor": {"polygon": floor}, "cameras": cams})


SITE = make_site()


def people(n: int, seed: int = 0, cameras=("1", "2", "3")) -> list[dict[str, PersonView]]:
    rng = np.random.default_rng(seed)
    sets = []
    for _ in range(n):
        views = {}
        for cid in cameras:
            if views and rng.uniform() < 0.3:
                continue
            kp = np.full((17, 3), np.nan, np.float32)
            vis = rng.uniform(size=17) < 0.7
            kp[vis] = np.column_stack([rng.uniform(0, 640, vis.sum()), rng.uniform(0, 480, vis.sum()), rng.uniform(0.5, 1, vis.sum())])
            views[cid] = PersonView(kp, np.array([100, 50, 300, 450], np.float32), np.zeros((16, 8), np.float32))
        sets.append(views)
    return sets


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """Tiny exported models: GAT "site" and RGCN "rays"; with their PyTorch originals."""
    from superbody.host.estimation.graph import floor_centre
    from superbody.models.nets import build_model
    from superbody.models.training.export import export_onnx

    out = {}
    d = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    for name, arch, spec, hp in [
        ("site", "gat", GraphSpec.for_site(SITE), dict(hidden=16, heads=2, layers=1)),
        ("rays", "rgcn", GraphSpec.for_site(SITE, "rays"), dict(hidden=16, bases=2, layers=1)),
    ]:
        model = build_model(arch, spec, origin=tuple(floor_centre(SITE)), **hp).eval()
        out[name] = (export_onnx(model, spec, {"test": True}, d / f"{name}.onnx"), model)
    return out


def torch_estimate(model, site: Site, sets) -> np.ndarray:
    g = build_batch(sets, site, model.spec)
    with torch.no_grad():
        out = model(*(torch.from_numpy(a) for a in (g.x, g.adj, g.mask))).numpy()
    return model.decode(out, site)


class CountingSession:
    """Wraps an onnxruntime session, counting run() calls."""

    def __init__(self, inner):
        self.inner, self.calls = inner, 0

    def run(self, *args, **kwargs):
        self.calls += 1
        return self.inner.run(*args, **kwargs)


@pytest.mark.parametrize("name", ["site", "rays"])
def test_batch_of_ten_in_one_call(models, name):
    path, model = models[name]
    est = OnnxEstimator(path, SITE)
    assert isinstance(est, Estimator)
    est.session = CountingSession(est.session)
    sets = people(10, seed=1)
    poses = est.estimate(sets)
    assert est.session.calls == 1
    assert poses.shape == (10, 3) and poses.dtype == np.float64
    assert ((poses[:, 2] > -np.pi) & (poses[:, 2] <= np.pi)).all()
    # The same as PyTorch, decoded to the world frame.
    np.testing.assert_allclose(poses, torch_estimate(model, SITE, sets), atol=1e-4)
    # Each person's pose does not depend on who else is in the batch.
    np.testing.assert_allclose(poses[3:4], est.estimate(sets[3:4]), atol=1e-5)


def test_rays_model_follows_the_serving_sites_floor(models):
    # A "rays" model serves another layout: the same room moved 10 m along x gives the same
    # poses moved 10 m.
    path, _ = models["rays"]
    moved = make_site(name="moved", shift=10.0)
    sets = people(4, seed=2)
    here, there = OnnxEstimator(path, SITE).estimate(sets), OnnxEstimator(path, moved).estimate(sets)
    np.testing.assert_allclose(there - here, np.tile([10.0, 0.0, 0.0], (4, 1)), atol=1e-3)


@pytest.mark.parametrize("name", ["site", "rays"])
def test_empty_batch_does_not_call_the_model(models, name):
    est = OnnxEstimator(models[name][0], SITE)
    est.session = CountingSession(est.session)
    poses = est.estimate([])
    assert poses.shape == (0, 3) and est.session.calls == 0


def test_unknown_camera_in_a_view_set(models):
    est = OnnxEstimator(models["site"][0], SITE)
    with pytest.raises(ValueError, match="'7'"):
        est.estimate(people(1, cameras=("1", "7")))


@pytest.mark.parametrize(
    "model, site, kwargs, match",
    [
        # (model, serving site, extra arguments, what the error must name)
        ("site", make_site(("1", "2", "4")), {}, r"missing from the site: \['3'\].*unknown to the model: \['4'\]"),
        ("site", make_site(("1", "3", "2")), {}, "different order"),
        ("site", make_site(("1", "2")), {}, r"missing from the site: \['3'\]"),
        ("site", SITE, {"variant": "rays"}, "expected a 'rays' variant model, this one is 'site'"),
        ("rays", SITE, {"variant": "site"}, "expected a 'site' variant model"),
    ],
)
def test_model_mismatch(models, model, site, kwargs, match):
    with pytest.raises(ModelMismatchError, match=match):
        OnnxEstimator(models[model][0], site, **kwargs)


def test_rays_model_serves_sites_with_more_cameras_than_view_slots(models):
    big = make_site(("a", "b", "c", "d", "e", "f"), name="big")
    poses = OnnxEstimator(models["rays"][0], big).estimate(people(2, cameras=("a", "b", "c", "d", "e", "f")))
    assert poses.shape == (2, 3) and np.isfinite(poses).all()


def test_rays_model_serves_any_camera_ids(models):
    other = make_site(("north", "south"), name="other")
    poses = OnnxEstimator(models["rays"][0], other).estimate(people(3, cameras=("south", "north")))
    assert poses.shape == (3, 3) and np.isfinite(poses).all()


def test_model_without_metadata(tmp_path):
    import onnx

    x = onnx.helper.make_tensor_value_info("x", onnx.TensorProto.FLOAT, ["batch", 4])
    y = onnx.helper.make_tensor_value_info("pose", onnx.TensorProto.FLOAT, ["batch", 4])
    graph = onnx.helper.make_graph([onnx.helper.make_node("Identity", ["x"], ["pose"])], "plain", [x], [y])
    path = tmp_path / "plain.onnx"
    onnx.save(onnx.helper.make_model(graph, opset_imports=[onnx.helper.make_opsetid("", 17)]), str(path))
    with pytest.raises(ModelMismatchError, match="graph.version"):
        OnnxEstimator(path, SITE)


def test_metadata_that_disagrees_with_the_inputs(models, tmp_path):
    import onnx

    proto = onnx.load(str(models["site"][0]))
    meta = {p.key: p.value for p in proto.metadata_props}
    meta.update(dataclasses.replace(GraphSpec.for_site(SITE), use_3d=True).to_metadata())  # claims 28 features
    del proto.metadata_props[:]
    for k, v in meta.items():
        proto.metadata_props.add(key=k, value=v)
    path = tmp_path / "lying.onnx"
    onnx.save(proto, str(path))
    with pytest.raises(ModelMismatchError, match="input 'x'"):
        OnnxEstimator(path, SITE)


@pytest.mark.parametrize(
    "pose, origin, expected",
    [
        ([1.0, 2.0, 0.0, 1.0], [0.0, 0.0], [1.0, 2.0, 0.0]),  # facing +x
        ([1.0, 2.0, 1.0, 0.0], [3.0, 2.5], [4.0, 4.5, np.pi / 2]),  # facing +y, floor-centred frame
        ([0.0, 0.0, 0.0, -1.0], [0.0, 0.0], [0.0, 0.0, np.pi]),  # facing -x: +pi
        ([0.0, 0.0, -0.0, -1.0], [0.0, 0.0], [0.0, 0.0, np.pi]),  # atan2 gives -pi: wrapped to +pi
        ([0.0, 0.0, -2.0, -2.0], [0.0, 0.0], [0.0, 0.0, -3 * np.pi / 4]),  # unnormalised sin, cos
    ],
)
def test_decode_output(pose, origin, expected):
    np.testing.assert_allclose(decode_output(np.array([pose], np.float32), np.array(origin))[0], expected, atol=1e-6)


class RecordingSession(CountingSession):
    """Also records the batch size of every call."""

    def __init__(self, inner):
        super().__init__(inner)
        self.batches: list[int] = []

    def run(self, names, feeds, *args, **kwargs):
        self.batches.append(len(next(iter(feeds.values()))))
        return super().run(names, feeds, *args, **kwargs)


@pytest.mark.parametrize("name", ["site", "rays"])
def test_a_crowd_runs_in_calls_of_at_most_max_batch(models, name):
    # 40 people (a peer may flood 64) with max_batch 16: calls of 16, 16 and 8; the same poses as one call.
    path, _ = models[name]
    est = OnnxEstimator(path, SITE, max_batch=16)
    est.session = RecordingSession(est.session)
    sets = people(40, seed=3)
    pose, std = est.estimate_with_std(sets)
    assert est.session.batches == [16, 16, 8]
    whole_pose, whole_std = OnnxEstimator(path, SITE, max_batch=64).estimate_with_std(sets)
    np.testing.assert_allclose(pose, whole_pose, atol=1e-5)
    np.testing.assert_allclose(std, whole_std, atol=1e-5, equal_nan=True)


@pytest.mark.parametrize("bad", [0, -1, 1025, 2.0, None])
def test_max_batch_out_of_range(models, bad):
    with pytest.raises(ValueError, match=r"max_batch must be an integer in \[1, 1024\]"):
        OnnxEstimator(models["rays"][0], SITE, max_batch=bad)


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS:"))


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/status"), reason="reads VmRSS from /proc (Linux)")
def test_a_64_person_flood_does_not_grow_the_hosts_memory():
    # The soak's hostile phase (64 copies of a person per frame) raised the host's RSS by ~100 MB
    # for good: onnxruntime's arena kept the size of a 64-person batch (+45 MB measured here
    # before the fix). With calls of at most max_batch people, sized at construction, it stays.
    from superbody.edge.resources import model_path

    path = model_path("site-independent.int8.onnx")
    if path is None:
        pytest.skip("the shipped site-independent model is not in this checkout")
    site = make_site(("1", "2", "3", "4", "5", "6"))
    est = OnnxEstimator(path, site)
    crowd = people(est.max_batch, seed=4, cameras=site.camera_ids)
    for _ in range(3):  # what normal operation reaches: full calls of every size up to max_batch
        for n in range(1, est.max_batch + 1):
            est.estimate(crowd[:n])
    before = _rss_mb()
    flood = crowd * 4  # 64 people
    for _ in range(10):
        est.estimate(flood)
    grown = _rss_mb() - before
    assert grown < 8.0, f"resident memory grew by {grown:.1f} MB over ten 64-person calls"
