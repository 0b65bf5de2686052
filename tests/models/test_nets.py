"""The pose networks: shapes, masking, the layers' formulas, the factory and normalisation."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from superbody.edge.messages.observation import PersonView  # noqa: E402
from superbody.edge.site import Site, parse_site  # noqa: E402
from superbody.host.estimation.graph import NUM_RELATIONS, GraphSpec, build_batch, floor_centre  # noqa: E402
from superbody.models.nets import (  # noqa: E402
    ARCHS,
    OUT_DIM,
    GATLayer,
    RGCNLayer,
    build_model,
    decode_pose,
    num_parameters,
    pose_targets,
)


def make_site(n: int = 3) -> Site:
    corners = [(0.2, 0.2), (5.8, 0.2), (5.8, 4.8)]
    cams = [
        dict(id=str(k + 1), width=640, height=480, fps=15.0, fx=617.0, fy=617.0, cx=320.0, cy=240.0,
             position=[*corners[k], 2.4], look_at=[3.0, 2.5, 0.9])
        for k in range(n)
    ]
    return parse_site({"site": {"name": "room"}, "floor": {"polygon": [[0, 0], [6, 0], [6, 5], [0, 5]]}, "cameras": cams})


SITE = make_site()
SPECS = {
    "site": GraphSpec.for_site(SITE),
    "site3d": GraphSpec.for_site(SITE, use_3d=True),
    "rays": GraphSpec.for_site(SITE, "rays"),
}


def random_batch(spec: GraphSpec, n: int, seed: int = 0):
    """Graphs of n people with random joints missing, as torch tensors."""
    rng = np.random.default_rng(seed)
    sets = []
    for _ in range(n):
        views = {}
        for cid in SITE.camera_ids:
            if rng.uniform() < 0.4 and views:
                continue
            kp = np.full((17, 3), np.nan, np.float32)
            vis = rng.uniform(size=17) < 0.7
            kp[vis] = np.column_stack([rng.uniform(0, 640, vis.sum()), rng.uniform(0, 480, vis.sum()), rng.uniform(0.5, 1, vis.sum())])
            p3 = np.where(vis[:, None], rng.uniform(0.5, 5, (17, 3)), np.nan).astype(np.float32)
            views[cid] = PersonView(kp, np.array([100, 50, 300, 450], np.float32), np.zeros((16, 8), np.float32), p3)
        sets.append(views)
    g = build_batch(sets, SITE, spec)
    return tuple(torch.from_numpy(a) for a in (g.x, g.adj, g.mask))


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("spec_name", list(SPECS))
def test_output_shape_and_batch_independence(arch, spec_name):
    spec = SPECS[spec_name]
    torch.manual_seed(0)
    model = build_model(arch, spec).eval()
    x, adj, mask = random_batch(spec, 5)
    with torch.no_grad():
        out = model(x, adj, mask)  # (5, OUT_DIM)
        singles = torch.cat([model(x[i : i + 1], adj[i : i + 1], mask[i : i + 1]) for i in range(5)])
    assert out.shape == (5, OUT_DIM) and torch.isfinite(out).all()
    torch.testing.assert_close(out, singles, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("arch", ARCHS)
def test_absent_nodes_are_ignored(arch):
    # Whatever sits in the rows of absent nodes must not change the pose.
    spec = SPECS["site"]
    torch.manual_seed(0)
    model = build_model(arch, spec).eval()
    x, adj, mask = random_batch(spec, 4, seed=1)
    garbage = x + torch.randn_like(x) * 10 * (1 - mask).unsqueeze(-1)
    with torch.no_grad():
        torch.testing.assert_close(model(garbage, adj, mask), model(x, adj, mask), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("arch", ARCHS)
def test_lone_superbody_is_finite(arch):
    # No view at all (every node but the superbody masked): no NaN from the masked softmax.
    spec = SPECS["rays"]
    model = build_model(arch, spec).eval()
    x = torch.zeros(2, spec.num_nodes, spec.num_features)
    x[:, 0, 18] = 1
    mask = torch.zeros(2, spec.num_nodes)
    mask[:, 0] = 1
    adj = torch.zeros(2, NUM_RELATIONS, spec.num_nodes, spec.num_nodes)
    adj[:, 0, 0, 0] = 1
    with torch.no_grad():
        assert torch.isfinite(model(x, adj, mask)).all()


@pytest.mark.parametrize("arch", ARCHS)
def test_gradients_reach_every_parameter(arch):
    spec = SPECS["site"]
    model = build_model(arch, spec)
    x, adj, mask = random_batch(spec, 8, seed=2)
    model(x, adj, mask).pow(2).mean().backward()
    for name, p in model.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
        assert p.grad.abs().sum() > 0, name


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("spec_name", ["site", "rays"])
def test_default_models_are_small(arch, spec_name):
    # < 1 MB of fp32 weights (the shipped limit is 5 MB).
    assert num_parameters(build_model(arch, SPECS[spec_name])) * 4 < 1_000_000


def test_gat_layer_matches_the_formula():
    torch.manual_seed(0)
    N, D, H = 5, 6, 2
    layer = GATLayer(D, H)
    h = torch.randn(1, N, D)
    A = (torch.rand(1, N, N) > 0.5).float()
    A[0].fill_diagonal_(1)
    out = layer(h, (A.unsqueeze(1) - 1) * 1e9)  # the neighbourhood as an additive bias
    Dh = D // H
    z = (h[0] @ layer.lin.weight.T).reshape(N, H, Dh)
    expected = torch.zeros(N, D)
    for k in range(H):
        for i in range(N):
            nbrs = [j for j in range(N) if A[0, i, j] > 0]
            e = torch.stack([torch.nn.functional.leaky_relu(layer.att_dst[k] @ z[i, k] + layer.att_src[k] @ z[j, k], 0.2) for j in nbrs])
            alpha = torch.softmax(e, 0)
            expected[i, k * Dh : (k + 1) * Dh] = sum(a * z[j, k] for a, j in zip(alpha, nbrs))
    torch.testing.assert_close(out[0], expected + layer.bias, atol=1e-5, rtol=1e-5)


def test_rgcn_layer_matches_the_formula():
    torch.manual_seed(0)
    N, D, Dout, R, nb = 5, 4, 3, 3, 2
    layer = RGCNLayer(D, Dout, R, nb)
    h = torch.randn(1, N, D)
    adj = (torch.rand(1, R, N, N) > 0.5).float()
    A = adj / adj.sum(-1, keepdim=True).clamp(min=1)
    out = layer(h, A)
    expected = h[0] @ layer.root.weight.T + layer.root.bias
    for r in range(R):
        W_r = sum(layer.coeffs[r, b] * layer.bases[b] for b in range(nb))  # W_r = sum_b a_rb V_b
        for i in range(N):
            nbrs = [j for j in range(N) if adj[0, r, i, j] > 0]
            for j in nbrs:  # (1 / c_ir) W_r h_j
                expected[i] = expected[i] + (h[0, j] @ W_r) / len(nbrs)
    torch.testing.assert_close(out[0], expected, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize(
    "arch, hparams, match",
    [
        ("gnn", {}, "gat, rgcn, mlp"),  # unknown name lists the valid ones
        ("gat", {"hidden": 30, "heads": 4}, "multiple of heads"),
        ("rgcn", {"depth": 3}, "depth"),  # unknown hyper-parameter
        ("mlp", {"scale": -1.0}, "scale"),
    ],
)
def test_build_model_errors(arch, hparams, match):
    with pytest.raises(ValueError, match=match):
        build_model(arch, SPECS["site"], **hparams)


@pytest.mark.parametrize(
    "truth",
    [
        [1.0, 2.0, 0.0],
        [5.5, 0.3, np.pi],  # yaw pi stays pi
        [3.0, 2.5, -np.pi / 2],
        [0.0, 0.0, 3.0],
    ],
)
@pytest.mark.parametrize("variant", ["site", "rays"])
def test_targets_round_trip(truth, variant):
    model = build_model("mlp", SPECS[variant], origin=(3.0, 2.5), scale=4.0)
    t = model.targets(np.array([truth]), SITE)
    assert t.shape == (1, 4) and t.dtype == np.float32
    np.testing.assert_allclose(model.decode(t, SITE)[0], truth, atol=1e-6)
    np.testing.assert_allclose(t[0, 2:], [np.sin(truth[2]), np.cos(truth[2])], atol=1e-6)


def test_rays_targets_use_the_serving_sites_floor_centre():
    model = build_model("gat", SPECS["rays"], origin=(100.0, 100.0))  # ignored by "rays" models
    t = model.targets(np.array([[3.0, 2.5, 0.0]]), SITE)
    np.testing.assert_allclose(t[0, :2], (np.array([3.0, 2.5]) - floor_centre(SITE)) / model.scale, atol=1e-7)


def test_pose_targets_and_decode_are_inverse():
    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.uniform(-5, 5, 50), rng.uniform(-5, 5, 50), rng.uniform(-np.pi, np.pi, 50)])
    back = decode_pose(pose_targets(truth, np.array([1.0, -2.0]), 4.0), np.array([1.0, -2.0]), 4.0)
    np.testing.assert_allclose(back, truth, atol=1e-5)
    assert (back[:, 2] > -np.pi).all() and (back[:, 2] <= np.pi).all()
