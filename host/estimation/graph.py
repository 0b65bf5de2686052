"""The superbody graph: the views of one person from several cameras joined in one graph.

As in Rodriguez-Criado et al., "Multi-camera Torso Pose Estimation using Graph Neural
Networks": node 0 is the *superbody*; every camera that sees the person adds a *body* node,
and every joint that camera detected adds a *joint* node. The same code builds the graphs the
host feeds the ONNX model every tick and the graphs the models are trained on.

Layout (dense, padded, fixed size so the models export cleanly to ONNX)::

    node 0                      superbody
    node 1 + 18 k               body node of slot k
    node 1 + 18 k + 1 + j       joint j (COCO-17 order) of slot k
    N = 1 + 18 S                S slots: the site's cameras ("site"), or max_views ("rays")

In the "site" variant slot k is the site's k-th camera; in the "rays" variant slot k is the
k-th view of the person, views in the site's camera order. Absent nodes (a camera that did not
see the person, a joint it did not detect) are zero rows with ``mask = 0`` and no edges.

Edges carry one of ``NUM_RELATIONS`` relation types (for RGCN; GAT uses their union).
``adj[b, r, i, j] = 1`` means an edge of relation r from node j (source) to node i (target),
so a layer aggregates messages as ``adj @ h``. Directions are split into two relations
wherever the two ends play different roles (child/parent, joint/body, body/superbody); the
mirror relation is symmetric. Every present node has a self-loop (``REL_SELF``).

Node features (F columns; see ``GraphSpec.feature_names`` and ``GraphSpec.feature_slice``)::

    "site" variant, C cameras              "rays" variant
    0..16   node type: joint j             0..16   node type: joint j
    17      node type: body                17      node type: body
    18      node type: superbody           18      node type: superbody
    19..    camera one-hot (C, site order) 19..21  unit ray direction, world frame
                                           22..24  camera centre, world frame minus the
                                                   floor centre (metres)
    +0, +1  u, v normalised: (u - w/2)/(w/2), (h/2 - v)/(h/2)
    +2      detection score (body: mean over its joints; superbody 0)
    +3..+5  (use_3d only) joint position in metres: camera frame ("site"), or world frame
            minus the floor centre ("rays"); body: mean over its joints; zeros if missing

So F = 19 + C + 3 (+3) for "site" (25 / 28 with three cameras) and 19 + 6 + 3 (+3) = 28 / 31
for "rays". Body nodes take the bbox centre (the centre of the visible joints if the bbox is
not a proper box) for u, v and for the ray.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import cast

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import MIRROR, NUM_KEYPOINTS, PARENT
from superbody.edge.camera import normalised_to_rays, undistort
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.host.estimation.graph_spec import (
    _JOINT_HEIGHTS,
    BODY_TYPE,
    GEOMETRY_SCALE_M,
    METADATA_VERSION,
    NUM_NODE_TYPES,
    NUM_RELATIONS,
    REL_BODY_TO_JOINT,
    REL_BODY_TO_SUPERBODY,
    REL_CHILD_TO_PARENT,
    REL_JOINT_TO_BODY,
    REL_MIRROR,
    REL_PARENT_TO_CHILD,
    REL_SELF,
    REL_SUPERBODY_TO_BODY,
    RELATIONS,
    SLOT_SIZE,
    SUPERBODY,
    SUPERBODY_TYPE,
    VARIANTS,
    GraphBatch,
    GraphSpec,
    Variant,
    floor_centre,
)

__all__ = [
    "Variant",
    "VARIANTS",
    "GraphSpec",
    "GraphBatch",
    "build_batch",
    "adjacency_template",
    "masked_adjacency",
    "floor_centre",
    "SLOT_SIZE",
    "NUM_NODE_TYPES",
    "BODY_TYPE",
    "SUPERBODY_TYPE",
    "SUPERBODY",
    "REL_SELF",
    "REL_CHILD_TO_PARENT",
    "REL_PARENT_TO_CHILD",
    "REL_MIRROR",
    "REL_JOINT_TO_BODY",
    "REL_BODY_TO_JOINT",
    "REL_BODY_TO_SUPERBODY",
    "REL_SUPERBODY_TO_BODY",
    "RELATIONS",
    "NUM_RELATIONS",
    "METADATA_VERSION",
]


@dataclass(frozen=True)
class _Static:
    """Per-spec constant arrays, computed once."""

    template: NDArray[np.float32]  # (R, N, N) every edge of a graph whose nodes are all present
    edge_flat: NDArray[np.intp]    # (E,) flat indices into (R, N, N) of the template's edges
    edge_dst: NDArray[np.intp]     # (E,) target node of each edge
    edge_src: NDArray[np.intp]     # (E,) source node of each edge
    node_x: NDArray[np.float32]    # (N, F) node-type one-hot, plus camera one-hot ("site")
    slot_of: dict[str, int]        # "site": camera id -> slot
    cols: dict[str, slice]         # feature group -> columns


@lru_cache(maxsize=32)
def _static(spec: GraphSpec) -> _Static:
    N, S = spec.num_nodes, spec.num_slots
    A = np.zeros((NUM_RELATIONS, N, N), dtype=np.float32)
    A[REL_SELF] = np.eye(N, dtype=np.float32)
    x = np.zeros((N, spec.num_features), dtype=np.float32)
    x[SUPERBODY, SUPERBODY_TYPE] = 1
    cam_cols = spec.feature_slice("camera") if spec.variant == "site" else None
    for k in range(S):
        body = 1 + SLOT_SIZE * k
        joint = body + 1  # joint j of this slot is node joint + j
        x[body, BODY_TYPE] = 1
        x[body + 1 : body + SLOT_SIZE, :NUM_KEYPOINTS] = np.eye(NUM_KEYPOINTS)
        if cam_cols is not None:
            x[body : body + SLOT_SIZE, cam_cols.start + k] = 1
        A[REL_BODY_TO_SUPERBODY, SUPERBODY, body] = 1
        A[REL_SUPERBODY_TO_BODY, body, SUPERBODY] = 1
        for j in range(NUM_KEYPOINTS):
            A[REL_JOINT_TO_BODY, body, joint + j] = 1
            A[REL_BODY_TO_JOINT, joint + j, body] = 1
            if PARENT[j] >= 0:
                A[REL_CHILD_TO_PARENT, joint + PARENT[j], joint + j] = 1
                A[REL_PARENT_TO_CHILD, joint + j, joint + PARENT[j]] = 1
            if MIRROR[j] != j:
                A[REL_MIRROR, joint + MIRROR[j], joint + j] = 1
    r, dst, src = np.nonzero(A)
    for arr in (A, x, r, dst, src):
        arr.setflags(write=False)
    groups = (("type", "uv", "score") + (("camera",) if spec.variant == "site" else ("ray", "ray_origin"))
              + (("xyz",) if spec.use_3d else ()) + (("floor",) if spec.geometry else ()))
    return _Static(
        template=A, edge_flat=np.ravel_multi_index((r, dst, src), A.shape), edge_dst=dst, edge_src=src,
        node_x=x, slot_of={c: k for k, c in enumerate(spec.camera_ids)},
        cols={g: spec.feature_slice(g) for g in groups},
    )


def adjacency_template(spec: GraphSpec) -> NDArray[np.float32]:
    """(R, N, N) every edge of a graph whose nodes are all present (read-only).

    Edges depend only on which nodes are present, so for any batch built with ``spec``,
    ``adj == template * mask[:, None, :, None] * mask[:, None, None, :]``: training keeps x and
    mask only and rebuilds adj per mini-batch.
    """
    return _static(spec).template


def masked_adjacency(spec: GraphSpec, mask: NDArray) -> NDArray[np.float32]:
    """(B, R, N, N) adjacency of graphs whose present nodes are ``mask`` (B, N): the template
    with every edge that touches an absent node removed (what ``build_batch`` gives)."""
    m = np.asarray(mask, dtype=np.float32)
    return adjacency_template(spec)[None] * m[:, None, :, None] * m[:, None, None, :]


def _slots_for(views: Mapping[str, PersonView], b: int, spec: GraphSpec, st: _Static, site_index: dict[str, int]) -> list[tuple[int, str]]:
    """(slot, camera id) for each view of one person; "rays": every view, in site order (``_keep_best`` trims)."""
    known = st.slot_of if spec.variant == "site" else site_index
    for cid in views:
        if cid not in known:
            where = "graph spec" if spec.variant == "site" else "site"
            raise ValueError(
                f"view set {b}: camera {cid!r} is not in the {where}; cameras: {', '.join(known) or '(none)'}"
            )
    if spec.variant == "site":
        return [(st.slot_of[cid], cid) for cid in views]
    return list(enumerate(sorted(views, key=site_index.__getitem__)))


def _keep_best(view_sets: Sequence[Mapping[str, PersonView]], slots: list[list[tuple[int, str]]], max_views: int) -> None:
    """"rays": trim each person's views (in site order) to the ``max_views`` with the most
    detected joints (ties: site order), kept in site order; visible joints counted in one pass."""
    over = [b for b, sl in enumerate(slots) if len(sl) > max_views]
    if not over:
        return
    kp_u = np.stack([view_sets[b][cid].keypoints[:, 0] for b in over for _, cid in slots[b]])  # (n, 17)
    counts = np.isfinite(kp_u).sum(axis=1).tolist()  # (n,)
    k = 0
    for b in over:
        order = [cid for _, cid in slots[b]]
        n_vis = dict(zip(order, counts[k : k + len(order)]))
        k += len(order)
        keep = set(sorted(order, key=lambda c: -n_vis[c])[:max_views])  # stable: ties keep site order
        slots[b] = list(enumerate(c for c in order if c in keep))


@lru_cache(maxsize=16)
def _site_rays(site: Site) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """Per camera of the site: (fx, fy, cx, cy) (C, 4), R (C, 3, 3), t (C, 3), and whether it
    has lens distortion (C,) (those go through ``edge.camera.undistort``); and the floor centre
    on the floor, (x, y, 0) (3,), the origin of the "rays" features."""
    cams = site.cameras
    return (np.array([[c.fx, c.fy, c.cx, c.cy] for c in cams], dtype=np.float64), np.stack([c.R for c in cams]),
            np.stack([c.t for c in cams]), np.array([bool(np.any(c.D)) for c in cams]), np.array([*floor_centre(site), 0.0]))


def build_batch(view_sets: Sequence[Mapping[str, PersonView]], site: Site, spec: GraphSpec, adjacency: bool = True) -> GraphBatch:
    """Build the superbody graphs of a batch of people.

    Args:
        view_sets: per person, camera id -> that camera's view of the person (1 or more).
        site: the cameras' calibration (image sizes, and rays for the "rays" variant).
        spec: the graph layout the model takes.
        adjacency: False leaves the edges out: ``adj`` is then a read-only all-zero view, for
            models that take their edges from ``mask`` (``masked_adjacency``; metadata
            ``model.reads_adj`` "false"), which spares building (B, R, N, N) floats.

    Returns:
        The batch: x (B, N, F), adj (B, R, N, N), mask (B, N), all float32.

    Raises:
        ValueError: a view set is empty, or names a camera that is not in the spec ("site")
            or the site ("rays"). The "rays" variant keeps at most ``max_views`` views per
            person: those with the most detected joints.
    """
    st = _static(spec)
    B, S, J = len(view_sets), spec.num_slots, NUM_KEYPOINTS
    N, F = st.node_x.shape  # the spec's num_nodes and num_features, without rebuilding its feature names
    site_index = {c: i for i, c in enumerate(site.camera_ids)}

    # Gather the views into padded arrays: one Python pass, then everything is vectorised.
    bi: list[int] = []
    si: list[int] = []
    ci: list[int] = []
    kps: list[NDArray] = []
    boxes: list[NDArray] = []
    pts: list[NDArray] = []
    no_depth = np.full((J, 3), np.nan, dtype=np.float32)
    slots: list[list[tuple[int, str]]] = []
    for b, views in enumerate(view_sets):
        if not views:
            raise ValueError(f"view set {b} is empty: a person needs at least one view")
        slots.append(_slots_for(views, b, spec, st, site_index))
    if spec.variant == "rays":
        _keep_best(view_sets, slots, spec.max_views)
    for b, views in enumerate(view_sets):
        for slot, cid in slots[b]:
            if cid not in site_index:
                raise ValueError(f"camera {cid!r} of the graph spec is not in site {site.name!r}; cameras: {', '.join(site.camera_ids)}")
            v = views[cid]
            bi.append(b)
            si.append(slot)
            ci.append(site_index[cid])
            kps.append(v.keypoints)
            boxes.append(v.bbox)
            if spec.use_3d:
                pts.append(no_depth if v.points3d is None else v.points3d)
    b_idx, s_idx, c_idx = np.array(bi, dtype=np.intp), np.array(si, dtype=np.intp), np.array(ci, dtype=np.intp)
    V = len(bi)  # views in the batch
    kp = np.stack(kps).astype(np.float32, copy=False) if V else np.zeros((0, J, 3), np.float32)  # (V, 17, 3)
    box = np.stack(boxes).astype(np.float32, copy=False) if V else np.zeros((0, 4), np.float32)  # (V, 4)

    # Per view: joints present, pixel coordinates of its 18 nodes (body first), scores.
    uv_j = kp[:, :, :2]  # (V, 17, 2)
    vis = cast("NDArray[np.bool_]", np.isfinite(uv_j).all(axis=2))  # (V, 17)
    n_vis = vis.sum(axis=1)  # (V,)
    uv_j = np.where(vis[:, :, None], uv_j, 0.0)  # (V, 17, 2)
    score_j = kp[:, :, 2]
    score_j = np.where(vis & np.isfinite(score_j), score_j, 0.0)  # (V, 17)
    joint_centre = uv_j.sum(axis=1) / np.maximum(n_vis, 1)[:, None]  # (V, 2)
    box_ok = np.isfinite(box).all(axis=1) & (box[:, 2] > box[:, 0]) & (box[:, 3] > box[:, 1])  # (V,)
    box_centre = (box[:, :2] + box[:, 2:]) / 2  # (V, 2)
    uv_body = np.where(box_ok[:, None], box_centre, joint_centre)  # (V, 2)
    uv = np.concatenate([uv_body[:, None], uv_j], axis=1)  # (V, 18, 2) pixels
    present = np.concatenate([np.ones((V, 1), bool), vis], axis=1)  # (V, 18)
    score = np.concatenate([(score_j.sum(axis=1) / np.maximum(n_vis, 1))[:, None], score_j], axis=1)  # (V, 18)

    # Normalised image coordinates: (u - w/2)/(w/2), (h/2 - v)/(h/2).
    half = np.array([[c.width / 2, c.height / 2] for c in site.cameras], dtype=np.float32)[c_idx]  # (V, 2)
    uvn = (uv - half[:, None]) / half[:, None] * np.array([1, -1], np.float32)  # (V, 18, 2)

    feats = np.zeros((V, SLOT_SIZE, F), dtype=np.float32)  # (V, 18, F) dynamic columns only
    feats[:, :, st.cols["uv"]] = uvn
    feats[:, :, st.cols["score"]] = score[:, :, None]
    if spec.use_3d:
        p3 = np.stack(pts).astype(np.float64) if V else np.zeros((0, J, 3))  # (V, 17, 3) camera frame
    if spec.variant == "rays" or spec.geometry:
        # Every present node's ray, all views at once (edge.camera.pixel_to_ray per camera, in one
        # pass): normalised coordinates; cameras with lens distortion undistort their pixels.
        f_c, R_c, t_c, distorted, origin = _site_rays(site)  # origin (3,): the floor centre
        k = f_c[c_idx]  # (V, 4)
        xn = (uv - k[:, None, 2:]) / k[:, None, :2]  # (V, 18, 2) normalised image coordinates
        for c in np.unique(c_idx[distorted[c_idx]]) if distorted.any() else ():
            sel = c_idx == c  # (V,)
            sub = present[sel]  # (v, 18)
            x_c = xn[sel]
            x_c[sub] = undistort(uv[sel][sub], site.cameras[c])
            xn[sel] = x_c
        rays = np.where(present[:, :, None], normalised_to_rays(xn, R_c[c_idx]), 0.0)  # (V, 18, 3) world frame
        centres = t_c[c_idx] - origin  # (V, 3)
        if spec.use_3d and spec.variant == "rays":
            p3 = np.einsum("vij,vnj->vni", R_c[c_idx], p3) + centres[:, None]  # world frame, floor-centred
    if spec.variant == "rays":
        feats[:, :, st.cols["ray"]] = rays
        feats[:, :, st.cols["ray_origin"]] = centres[:, None]
    if spec.geometry:
        # Where each joint's ray meets its typical height: camera centre + s * ray, z = h_j.
        dz = rays[:, 1:, 2]  # (V, 17)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (_JOINT_HEIGHTS[None] - (centres[:, 2:3] + origin[2])) / dz  # (V, 17)
            ok = vis & np.isfinite(s) & (s > 0) & (s < 30)  # (V, 17) in front of the camera, within 30 m
            floor = np.where(ok[:, :, None], centres[:, None, :2] + s[:, :, None] * rays[:, 1:, :2], 0.0) / GEOMETRY_SCALE_M  # (V, 17, 2)
        geo = np.zeros((V, SLOT_SIZE, 2))  # (V, 18, 2) body node: mean of its joints
        geo[:, 0] = floor.sum(axis=1) / np.maximum(ok.sum(axis=1), 1)[:, None]
        geo[:, 1:] = floor
        feats[:, :, st.cols["floor"]] = geo
    if spec.use_3d:
        has3 = np.isfinite(p3).all(axis=2) & vis  # (V, 17)
        p3 = np.where(has3[:, :, None], p3, 0.0)  # (V, 17, 3)
        xyz = np.zeros((V, SLOT_SIZE, 3))  # (V, 18, 3) body node: mean of its joints
        xyz[:, 0] = p3.sum(axis=1) / np.maximum(has3.sum(axis=1), 1)[:, None]
        xyz[:, 1:] = p3
        feats[:, :, st.cols["xyz"]] = xyz
    feats *= present[:, :, None]

    # Scatter the views into their slots, add the static one-hots, mask, and edges.
    x = np.zeros((B, S, SLOT_SIZE, F), dtype=np.float32)  # (B, S, 18, F)
    x[b_idx, s_idx] = feats
    mask = np.zeros((B, S, SLOT_SIZE), dtype=np.float32)  # (B, S, 18)
    mask[b_idx, s_idx] = present
    mask = np.concatenate([np.ones((B, 1), np.float32), mask.reshape(B, S * SLOT_SIZE)], axis=1)  # (B, N)
    x = np.concatenate([np.zeros((B, 1, F), np.float32), x.reshape(B, S * SLOT_SIZE, F)], axis=1)  # (B, N, F)
    x += st.node_x * mask[:, :, None]
    if not adjacency:
        return GraphBatch(x=x, adj=np.broadcast_to(np.zeros((), np.float32), (B, NUM_RELATIONS, N, N)), mask=mask)
    # An edge of the template exists iff both its ends are present: m_dst * m_src.
    present_edges = mask.take(st.edge_dst, axis=1)  # (B, E)
    present_edges *= mask.take(st.edge_src, axis=1)
    adj = np.zeros((B, NUM_RELATIONS * N * N), dtype=np.float32)  # (B, R*N*N)
    adj[:, st.edge_flat] = present_edges
    adj = adj.reshape(B, NUM_RELATIONS, N, N)  # (B, R, N, N)
    return GraphBatch(x=x, adj=adj, mask=mask)
