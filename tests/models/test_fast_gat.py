"""The inference GAT (models.fast_gat): the dense GAT's outputs, computed where they are needed."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from superbody.host.estimation.graph import GraphSpec, build_batch  # noqa: E402
from superbody.models.fast_gat import FastGAT  # noqa: E402
from superbody.models.nets import build_model  # noqa: E402
from tests.models.training.test_export import SITE, people  # noqa: E402


@pytest.mark.parametrize(
    ("variant", "layers", "max_views"),
    [
        ("rays", 3, 4),   # the shipped site-independent layout
        ("site", 3, 4),   # the shipped per-site layout (3 cameras)
        ("rays", 1, 2),   # one layer: only the superbody's keys
        ("rays", 2, 3),   # no layer over every node
        ("site", 4, 4),   # two layers over every node
    ],
)
def test_fast_gat_equals_the_dense_gat(variant, layers, max_views):
    torch.manual_seed(layers)
    spec = GraphSpec.for_site(SITE, variant, max_views=max_views, geometry=True)
    net = build_model("gat", spec, hidden=16, heads=2, layers=layers).eval()
    # Trained-like weights: the attention must not be uniform for the test to mean anything.
    with torch.no_grad():
        for layer in net.layers:
            layer.att_src.mul_(4.0)
            layer.att_dst.mul_(4.0)
    batch = build_batch(people(48, seed=7), SITE, spec)
    assert (batch.mask[:, 1:].reshape(48, -1, 18)[:, :, 0] == 0).any()  # some slots are padding
    feeds = [torch.from_numpy(a) for a in (batch.x, batch.adj, batch.mask)]
    with torch.no_grad():
        dense, fast = net(*feeds).numpy(), FastGAT(net)(*feeds).numpy()
    assert np.abs(dense).max() > 0.1
    np.testing.assert_allclose(fast, dense, atol=2e-5, rtol=1e-4)


def test_fast_gat_takes_only_a_gat():
    spec = GraphSpec.for_site(SITE, "site")
    with pytest.raises(TypeError, match="GAT"):
        FastGAT(build_model("mlp", spec))


def test_reexport_gives_the_same_poses_and_keeps_the_metadata(tmp_path):
    # A dense export (as the models shipped before the fast one), exported again as the fast
    # GAT: the host's estimator, which then feeds no edges, gives the same poses and sigmas.
    import onnx

    from superbody.host.estimation.estimator import OnnxEstimator
    from superbody.models.training.export import export_onnx, read_metadata, reexport

    torch.manual_seed(0)
    spec = GraphSpec.for_site(SITE, "rays", max_views=3, geometry=True)
    net = build_model("gat", spec, hidden=16, heads=2, layers=3).eval()
    with torch.no_grad():  # trained-like: no two parameters equal (the exporter merges equal initializers)
        for p in net.parameters():
            p.add_(0.1 * torch.randn_like(p))
    dense = export_onnx(net, spec, {"lr": 1e-3}, tmp_path / "m.fp32.onnx", fast=False)
    proto = onnx.load(str(dense))
    proto.metadata_props.add(key="hybrid.calibration", value='{"made": "later"}')  # written after export by calibrate
    onnx.save(proto, str(dense))
    fast = reexport(dense, tmp_path / "m.fast.onnx")
    before, after = read_metadata(dense), read_metadata(fast)
    assert after["export.formulation"] == "fast_gat" and after["model.reads_adj"] == "false"
    assert before["export.formulation"] == "dense" and before["model.reads_adj"] == "true"
    assert {k: v for k, v in after.items() if not k.startswith(("export.", "model.reads"))} == \
           {k: v for k, v in before.items() if not k.startswith(("export.", "model.reads"))}
    views = people(40, seed=3)
    a, b = OnnxEstimator(dense, SITE), OnnxEstimator(fast, SITE)
    assert a.reads_adj and not b.reads_adj
    (pa, sa), (pb, sb) = a.estimate_with_std(views), b.estimate_with_std(views)
    np.testing.assert_allclose(pb, pa, atol=1e-4)
    np.testing.assert_allclose(sb, sa, rtol=1e-4)
    assert np.isfinite(pb).all() and b.estimate_with_std(views[:1])[0].shape == (1, 3)  # the reused zero adj, sliced
