"""The superbody graph builder, checked against the paper's description of the graph."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from superbody.edge.body import INDEX, KEYPOINTS, MIRROR, NUM_KEYPOINTS, PARENT
from superbody.edge.camera import pixel_to_ray
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site, parse_site
from superbody.host.estimation.graph import (
    BODY_TYPE,
    NUM_RELATIONS,
    REL_BODY_TO_JOINT,
    REL_BODY_TO_SUPERBODY,
    REL_CHILD_TO_PARENT,
    REL_JOINT_TO_BODY,
    REL_MIRROR,
    REL_PARENT_TO_CHILD,
    REL_SELF,
    REL_SUPERBODY_TO_BODY,
    SUPERBODY_TYPE,
    GraphBatch,
    GraphSpec,
    build_batch,
    floor_centre,
)

J = NUM_KEYPOINTS


def make_site(n: int = 3) -> Site:
    """A 6 m x 5 m room with ``n`` 640x480 cameras 2.4 m up in its corners (the paper's setup)."""
    corners = [(0.2, 0.2), (5.8, 0.2), (5.8, 4.8), (0.2, 4.8), (3.0, 0.2)]
    cams = [
        dict(id=str(k + 1), width=640, height=480, fps=15.0, fx=617.0, fy=617.0, cx=320.0, cy=240.0,
             position=[*corners[k], 2.4], look_at=[3.0, 2.5, 0.9])
        for k in range(n)
    ]
    return parse_site({"site": {"name": "room"}, "floor": {"polygon": [[0, 0], [6, 0], [6, 5], [0, 5]]}, "cameras": cams})


SITE = make_site(3)


def view(joints: list[str] | None = None, bbox=(100.0, 50.0, 300.0, 450.0), with_3d: bool = False, seed: int = 0) -> PersonView:
    """A view with the named joints detected (all if None) at arbitrary in-image pixels."""
    rng = np.random.default_rng(seed)
    kp = np.full((J, 3), np.nan, dtype=np.float32)
    idx = list(range(J)) if joints is None else [INDEX[n] for n in joints]
    kp[idx, 0] = rng.uniform(100, 300, len(idx))
    kp[idx, 1] = rng.uniform(50, 450, len(idx))
    kp[idx, 2] = rng.uniform(0.5, 1.0, len(idx))
    p3 = None
    if with_3d:
        p3 = np.full((J, 3), np.nan, dtype=np.float32)
        p3[idx] = rng.uniform(-1, 4, (len(idx), 3))
    return PersonView(keypoints=kp, bbox=np.asarray(bbox, dtype=np.float32), histogram=np.zeros((16, 8), np.float32), points3d=p3)


def body_node(k: int) -> int:
    return 1 + 18 * k


def joint_node(k: int, j: int) -> int:
    return 1 + 18 * k + 1 + j


def expected_adjacency(present: dict[int, np.ndarray], num_slots: int) -> np.ndarray:
    """The paper's graph written out edge by edge, independently of the builder.

    Args:
        present: slot -> (17,) bool of detected joints, for the slots that have a view.
    """
    N = 1 + 18 * num_slots
    A = np.zeros((NUM_RELATIONS, N, N), dtype=np.float32)

    def edge(r: int, src: int, dst: int) -> None:
        A[r, dst, src] = 1

    edge(REL_SELF, 0, 0)
    for k, vis in present.items():
        b = body_node(k)
        edge(REL_SELF, b, b)
        edge(REL_BODY_TO_SUPERBODY, b, 0)
        edge(REL_SUPERBODY_TO_BODY, 0, b)
        for j in np.flatnonzero(vis):
            n = joint_node(k, j)
            edge(REL_SELF, n, n)
            edge(REL_JOINT_TO_BODY, n, b)
            edge(REL_BODY_TO_JOINT, b, n)
            if PARENT[j] >= 0 and vis[PARENT[j]]:
                edge(REL_CHILD_TO_PARENT, n, joint_node(k, PARENT[j]))
                edge(REL_PARENT_TO_CHILD, joint_node(k, PARENT[j]), n)
            if MIRROR[j] != j and vis[MIRROR[j]]:
                edge(REL_MIRROR, n, joint_node(k, MIRROR[j]))
    return A


# --- sizes ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "cameras, variant, use_3d, max_views, nodes, features",
    [
        (3, "site", False, 4, 55, 25),  # the paper: 19 types + 3 cameras + u, v + score
        (3, "site", True, 4, 55, 28),  # + camera-frame x, y, z
        (1, "site", False, 4, 19, 23),  # a one-camera site
        (3, "rays", False, 4, 73, 28),  # 19 types + ray 3 + camera centre 3 + u, v + score
        (3, "rays", True, 4, 73, 31),
        (3, "rays", False, 2, 37, 28),  # slots follow max_views, not the site
    ],
)
def test_spec_sizes(cameras, variant, use_3d, max_views, nodes, features):
    spec = GraphSpec.for_site(make_site(cameras), variant, use_3d, max_views)
    assert (spec.num_nodes, spec.num_features, spec.num_relations) == (nodes, features, NUM_RELATIONS)
    assert len(spec.feature_names) == features
    g = build_batch([{"1": view()}], make_site(cameras), spec)
    assert g.x.shape == (1, nodes, features) and g.x.dtype == np.float32
    assert g.adj.shape == (1, NUM_RELATIONS, nodes, nodes) and g.adj.dtype == np.float32
    assert g.mask.shape == (1, nodes) and g.mask.dtype == np.float32


# --- nodes and edges -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "cameras",
    [
        ["1"],  # one view
        ["3"],  # one view, in the last slot
        ["1", "3"],  # two views
        ["1", "2", "3"],  # three views
    ],
)
def test_views_take_their_camera_slots(cameras):
    spec = GraphSpec.for_site(SITE)
    g = build_batch([{c: view() for c in cameras}], SITE, spec)
    slots = [SITE.camera_index(c) for c in cameras]
    expected_mask = np.zeros(spec.num_nodes, np.float32)
    expected_mask[0] = 1
    for k in slots:
        expected_mask[body_node(k) : body_node(k) + 18] = 1
    np.testing.assert_array_equal(g.mask[0], expected_mask)
    np.testing.assert_array_equal(g.adj[0], expected_adjacency({k: np.ones(J, bool) for k in slots}, 3))


@pytest.mark.parametrize(
    "views, counts",
    [
        # Per full view: 18 self-loops, 16 bones each way, 8 mirror pairs = 16, 17 joint-body
        # each way, 1 body-superbody each way; plus the superbody's self-loop.
        (1, {REL_SELF: 19, REL_CHILD_TO_PARENT: 16, REL_PARENT_TO_CHILD: 16, REL_MIRROR: 16,
             REL_JOINT_TO_BODY: 17, REL_BODY_TO_JOINT: 17, REL_BODY_TO_SUPERBODY: 1, REL_SUPERBODY_TO_BODY: 1}),
        (2, {REL_SELF: 37, REL_CHILD_TO_PARENT: 32, REL_PARENT_TO_CHILD: 32, REL_MIRROR: 32,
             REL_JOINT_TO_BODY: 34, REL_BODY_TO_JOINT: 34, REL_BODY_TO_SUPERBODY: 2, REL_SUPERBODY_TO_BODY: 2}),
        (3, {REL_SELF: 55, REL_CHILD_TO_PARENT: 48, REL_PARENT_TO_CHILD: 48, REL_MIRROR: 48,
             REL_JOINT_TO_BODY: 51, REL_BODY_TO_JOINT: 51, REL_BODY_TO_SUPERBODY: 3, REL_SUPERBODY_TO_BODY: 3}),
    ],
)
def test_edge_counts_per_relation(views, counts):
    g = build_batch([{c: view() for c in SITE.camera_ids[:views]}], SITE, GraphSpec.for_site(SITE))
    assert {r: int(g.adj[0, r].sum()) for r in range(NUM_RELATIONS)} == counts


def test_directed_relations_are_transposes_and_mirror_is_symmetric():
    g = build_batch([{c: view(seed=i) for i, c in enumerate(SITE.camera_ids)}], SITE, GraphSpec.for_site(SITE))
    a = g.adj[0]
    for fwd, back in [(REL_CHILD_TO_PARENT, REL_PARENT_TO_CHILD), (REL_JOINT_TO_BODY, REL_BODY_TO_JOINT), (REL_BODY_TO_SUPERBODY, REL_SUPERBODY_TO_BODY)]:
        np.testing.assert_array_equal(a[fwd], a[back].T)
    np.testing.assert_array_equal(a[REL_MIRROR], a[REL_MIRROR].T)
    np.testing.assert_array_equal(a[REL_SELF], np.diag(g.mask[0]))


@pytest.mark.parametrize(
    "joints, edge, relation, exists",
    [
        # (detected joints, (source, target) joint names, relation, edge expected?)
        (["left_shoulder", "left_elbow"], ("left_elbow", "left_shoulder"), REL_CHILD_TO_PARENT, True),
        (["left_shoulder", "left_elbow"], ("left_shoulder", "left_elbow"), REL_PARENT_TO_CHILD, True),
        (["left_wrist", "left_shoulder"], ("left_wrist", "left_shoulder"), REL_CHILD_TO_PARENT, False),  # no skipping a missing elbow
        (["left_shoulder", "right_shoulder"], ("left_shoulder", "right_shoulder"), REL_MIRROR, True),  # both present
        (["left_shoulder", "right_shoulder"], ("right_shoulder", "left_shoulder"), REL_MIRROR, True),
        (["left_elbow", "right_shoulder"], ("left_elbow", "right_elbow"), REL_MIRROR, False),  # one side missing
        (["nose"], ("nose", "nose"), REL_MIRROR, False),  # the nose mirrors itself: self-loop only
        (["nose"], ("nose", "nose"), REL_SELF, True),
    ],
)
def test_joint_edges(joints, edge, relation, exists):
    g = build_batch([{"2": view(joints)}], SITE, GraphSpec.for_site(SITE))
    src, dst = joint_node(1, INDEX[edge[0]]), joint_node(1, INDEX[edge[1]])
    assert g.adj[0, relation, dst, src] == float(exists)


def test_missing_joints_have_no_node_and_no_edges():
    joints = ["nose", "left_shoulder", "right_shoulder", "left_elbow"]
    g = build_batch([{"1": view(joints)}], SITE, GraphSpec.for_site(SITE))
    present = np.zeros(J, bool)
    present[[INDEX[n] for n in joints]] = True
    for j in range(J):
        n = joint_node(0, j)
        assert g.mask[0, n] == float(present[j])
        if not present[j]:
            assert not g.adj[0, :, n, :].any() and not g.adj[0, :, :, n].any()
            assert not g.x[0, n].any()
    np.testing.assert_array_equal(g.adj[0], expected_adjacency({0: present}, 3))


@settings(max_examples=40, deadline=None)
@given(
    visibility=st.lists(st.lists(st.booleans(), min_size=J, max_size=J), min_size=3, max_size=3),
    seen=st.lists(st.booleans(), min_size=3, max_size=3).filter(any),
)
def test_adjacency_matches_the_papers_graph(visibility, seen):
    views, present = {}, {}
    for k, (vis, s) in enumerate(zip(visibility, seen)):
        if s:
            views[SITE.camera_ids[k]] = view([KEYPOINTS[j] for j in range(J) if vis[j]], seed=k)
            present[k] = np.array(vis)
    g = build_batch([views], SITE, GraphSpec.for_site(SITE))
    np.testing.assert_array_equal(g.adj[0], expected_adjacency(present, 3))
    # Every edge joins present nodes.
    assert not (g.adj[0].max(axis=0) * (1 - g.mask[0])[:, None]).any()


# --- features ------------------------------------------------------------------------------


def test_site_features_one_hots_coordinates_and_scores():
    spec = GraphSpec.for_site(SITE)
    kp = np.full((J, 3), np.nan, np.float32)
    kp[INDEX["nose"]] = (320, 240, 0.9)  # image centre
    kp[INDEX["left_hip"]] = (640, 0, 0.5)  # top-right corner
    kp[INDEX["right_hip"]] = (0, 480, 0.7)  # bottom-left corner
    v = PersonView(keypoints=kp, bbox=np.array([0, 0, 320, 480], np.float32), histogram=np.zeros((16, 8), np.float32))
    g = build_batch([{"2": v}], SITE, spec)
    x = g.x[0]
    t, cam, uv, score = (spec.feature_slice(s) for s in ("type", "camera", "uv", "score"))
    assert (t, cam, uv, score) == (slice(0, 19), slice(19, 22), slice(22, 24), slice(24, 25))
    # Superbody: its type only.
    expected = np.zeros(25, np.float32)
    expected[SUPERBODY_TYPE] = 1
    np.testing.assert_array_equal(x[0], expected)
    # Body node of camera "2" (slot 1): type 17, camera one-hot 1, bbox centre (160, 240), mean score.
    b = body_node(1)
    np.testing.assert_array_equal(x[b, t], np.eye(19)[BODY_TYPE])
    np.testing.assert_array_equal(x[b, cam], [0, 1, 0])
    np.testing.assert_allclose(x[b, uv], [-0.5, 0.0])
    np.testing.assert_allclose(x[b, score], [0.7])
    # Joints: type one-hot j, camera one-hot, (u - w/2)/(w/2), (h/2 - v)/(h/2), score.
    for name, uv_n, s in [("nose", (0, 0), 0.9), ("left_hip", (1, 1), 0.5), ("right_hip", (-1, -1), 0.7)]:
        n = joint_node(1, INDEX[name])
        np.testing.assert_array_equal(x[n, t], np.eye(19)[INDEX[name]])
        np.testing.assert_array_equal(x[n, cam], [0, 1, 0])
        np.testing.assert_allclose(x[n, uv], uv_n)
        np.testing.assert_allclose(x[n, score], [s])


@pytest.mark.parametrize(
    "bbox, centre",
    [
        ((100, 50, 300, 450), (200, 250)),  # a proper box: its centre
        ((300, 50, 100, 450), None),  # x1 < x0: the centre of the visible joints
        ((np.nan,) * 4, None),  # no box
    ],
)
def test_body_node_position(bbox, centre):
    v = view(["left_shoulder", "right_shoulder", "left_hip"], bbox=bbox)
    if centre is None:
        centre = np.nanmean(v.keypoints[:, :2], axis=0)
    spec = GraphSpec.for_site(SITE)
    g = build_batch([{"1": v}], SITE, spec)
    u, vv = centre
    np.testing.assert_allclose(g.x[0, body_node(0), spec.feature_slice("uv")], [(u - 320) / 320, (240 - vv) / 240], rtol=1e-5)


def test_3d_features_camera_frame_zeros_where_missing():
    spec = GraphSpec.for_site(SITE, use_3d=True)
    v = view(["nose", "left_shoulder", "right_shoulder"], with_3d=True)
    p3 = v.points3d.copy()
    p3[INDEX["right_shoulder"]] = np.nan  # detected in 2D, no depth
    v = dataclasses.replace(v, points3d=p3)
    g = build_batch([{"1": v}, {"1": view(["nose"])}], SITE, spec)  # the second has no points3d at all
    xyz = spec.feature_slice("xyz")
    assert xyz == slice(25, 28)
    np.testing.assert_allclose(g.x[0, joint_node(0, INDEX["nose"]), xyz], p3[INDEX["nose"]])
    np.testing.assert_array_equal(g.x[0, joint_node(0, INDEX["right_shoulder"]), xyz], [0, 0, 0])
    np.testing.assert_allclose(g.x[0, body_node(0), xyz], np.nanmean(p3, axis=0), rtol=1e-6)
    np.testing.assert_array_equal(g.x[0, 0, xyz], [0, 0, 0])
    np.testing.assert_array_equal(g.x[1, :, xyz], 0)


def test_absent_nodes_are_zero_rows():
    g = build_batch([{"1": view(["nose"])}], SITE, GraphSpec.for_site(SITE))
    assert not g.x[0][g.mask[0] == 0].any()
    assert set(np.unique(g.adj)) <= {0.0, 1.0}


# --- rays variant --------------------------------------------------------------------------


def test_rays_slots_follow_site_order_and_rays_match_the_camera_model():
    spec = GraphSpec.for_site(SITE, "rays")
    assert spec.camera_ids == () and spec.num_nodes == 1 + 18 * 4
    views = {"3": view(seed=3), "1": view(["nose", "left_hip"], seed=1)}
    g = build_batch([views], SITE, spec)
    ray, origin, t = spec.feature_slice("ray"), spec.feature_slice("ray_origin"), spec.feature_slice("type")
    centre = np.array([*floor_centre(SITE), 0.0])
    for slot, cid in [(0, "1"), (1, "3")]:  # camera "1" before "3": site order, not dict order
        cam = SITE.camera(cid)
        v = views[cid]
        vis = np.flatnonzero(v.visible)
        nodes = [joint_node(slot, j) for j in vis]
        _, d = pixel_to_ray(v.keypoints[vis, :2], cam)
        np.testing.assert_allclose(g.x[0, nodes, ray], d, atol=1e-6)
        np.testing.assert_allclose(g.x[0, nodes + [body_node(slot)], origin], np.tile(cam.t - centre, (len(nodes) + 1, 1)), atol=1e-6)
        _, d_body = pixel_to_ray(((v.bbox[:2] + v.bbox[2:]) / 2)[None], cam)
        np.testing.assert_allclose(g.x[0, body_node(slot), ray], d_body[0], atol=1e-6)
    assert g.mask[0, body_node(2)] == 0 and g.mask[0, body_node(3)] == 0
    assert not g.x[0, 0, ray.start :].any() and g.x[0, 0, t].argmax() == SUPERBODY_TYPE


def test_rays_drop_the_views_with_fewest_joints_beyond_max_views():
    spec = GraphSpec.for_site(SITE, "rays", max_views=2)
    views = {"1": view(["nose"]), "2": view(), "3": view(["nose", "left_eye"])}
    g = build_batch([views], SITE, spec)
    # Kept: "2" (17 joints) and "3" (2 joints), in site order.
    assert g.mask[0, 1 : 1 + 18].sum() == 18 and g.mask[0, 19:].sum() == 3


def test_rays_3d_is_world_frame_floor_centred():
    spec = GraphSpec.for_site(SITE, "rays", use_3d=True)
    cam = SITE.camera("2")
    v = view(["nose", "left_hip"], with_3d=True)
    g = build_batch([{"2": v}], SITE, spec)
    vis = np.flatnonzero(v.visible)
    world = v.points3d[vis].astype(np.float64) @ cam.R.T + cam.t
    expected = world - [*floor_centre(SITE), 0.0]
    np.testing.assert_allclose(g.x[0, [joint_node(0, j) for j in vis], spec.feature_slice("xyz")], expected, atol=1e-5)


# --- batches, errors, metadata -------------------------------------------------------------


def test_batch_rows_are_the_single_graphs():
    spec = GraphSpec.for_site(SITE)
    sets = [{"1": view(seed=1)}, {"2": view(["nose"], seed=2), "3": view(seed=3)}, {"1": view(seed=4), "3": view(seed=5)}]
    g = build_batch(sets, SITE, spec)
    for b, s in enumerate(sets):
        one = build_batch([s], SITE, spec)
        np.testing.assert_array_equal(g.x[b], one.x[0])
        np.testing.assert_array_equal(g.adj[b], one.adj[0])
        np.testing.assert_array_equal(g.mask[b], one.mask[0])
    both = GraphBatch.concat([build_batch(sets[:1], SITE, spec), build_batch(sets[1:], SITE, spec)])
    np.testing.assert_array_equal(both.x, g.x)
    assert set(g.feeds()) == {"x", "adj", "mask"} and len(g) == 3


@pytest.mark.parametrize("variant", ["site", "rays"])
def test_empty_batch(variant):
    spec = GraphSpec.for_site(SITE, variant)
    g = build_batch([], SITE, spec)
    assert g.x.shape == (0, spec.num_nodes, spec.num_features)
    assert g.adj.shape == (0, NUM_RELATIONS, spec.num_nodes, spec.num_nodes)
    assert g.mask.shape == (0, spec.num_nodes)


@pytest.mark.parametrize(
    "variant, views, match",
    [
        ("site", {"9": None}, "'9'"),  # a camera the spec does not know
        ("rays", {"1": None, "cam-x": None}, "'cam-x'"),  # a camera the site does not know
        ("site", {}, "empty"),  # nobody seen
    ],
)
def test_bad_view_sets_raise(variant, views, match):
    views = {c: view() for c in views}
    with pytest.raises(ValueError, match=match):
        build_batch([{"1": view()}, views], SITE, GraphSpec.for_site(SITE, variant))


def test_spec_for_a_different_site_names_the_camera():
    spec = GraphSpec(variant="site", camera_ids=("1", "2", "lobby"))
    with pytest.raises(ValueError, match="'lobby'"):
        build_batch([{"lobby": view()}], SITE, spec)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(variant="graph", camera_ids=("1",)), "site, rays"),  # unknown variant lists the valid ones
        (dict(variant="site", camera_ids=()), "1 to 64 cameras"),
        (dict(variant="site", camera_ids=("1", "1")), "unique"),
        (dict(variant="rays", camera_ids=("1",)), "empty"),
        (dict(variant="rays", max_views=0), r"\[1, 64\]"),
    ],
)
def test_invalid_specs(kwargs, match):
    with pytest.raises(ValueError, match=match):
        GraphSpec(**kwargs)


@pytest.mark.parametrize(
    "spec",
    [
        GraphSpec.for_site(SITE),
        GraphSpec.for_site(SITE, use_3d=True),
        GraphSpec.for_site(SITE, "rays", max_views=6),
        GraphSpec.for_site(make_site(1), "site"),
    ],
)
def test_metadata_round_trip(spec):
    meta = spec.to_metadata()
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in meta.items())
    assert GraphSpec.from_metadata(meta) == spec


@pytest.mark.parametrize(
    "change, match",
    [
        ({"graph.variant": None}, "graph.variant"),  # missing key
        ({"graph.version": "0"}, "version"),
        ({"graph.num_features": "24"}, "num_features"),  # derived size disagrees
        ({"graph.use_3d": "yes"}, "use_3d"),
    ],
)
def test_bad_metadata(change, match):
    meta = GraphSpec.for_site(SITE).to_metadata()
    for k, v in change.items():
        if v is None:
            del meta[k]
        else:
            meta[k] = v
    with pytest.raises(ValueError, match=match):
        GraphSpec.from_metadata(meta)


def test_unknown_feature_group():
    with pytest.raises(ValueError, match="ray"):
        GraphSpec.for_site(SITE).feature_slice("ray")


def test_adjacency_is_the_template_masked_by_present_nodes():
    from superbody.edge.site import load_site
    from superbody.host.estimation.graph import adjacency_template
    from superbody.models.data.simdata import SimDataConfig, generate
    from tests.conftest import WTF_SITE

    site = load_site(WTF_SITE)
    samples = generate(site, SimDataConfig(samples=60, seed=5), workers=1, progress=False)
    for variant in ("site", "rays"):
        spec = GraphSpec.for_site(site, variant=variant)
        batch = build_batch([s.views for s in samples], site, spec)
        m = batch.mask
        rebuilt = adjacency_template(spec)[None] * m[:, None, :, None] * m[:, None, None, :]
        np.testing.assert_array_equal(rebuilt, batch.adj)
