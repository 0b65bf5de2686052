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

import json
from dataclasses import dataclass
from functools import lru_cache
from typing import Final, Literal, Mapping, Sequence, get_args

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import KEYPOINTS, MIRROR, NUM_KEYPOINTS, PARENT, TYPICAL_HEIGHT_M
from superbody.edge.camera import normalised_to_rays, undistort
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site

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

Variant = Literal["site", "rays"]
VARIANTS: Final[tuple[str, ...]] = get_args(Variant)

SUPERBODY: Final[int] = 0  # node index of the superbody, where the models read the pose
SLOT_SIZE: Final[int] = 1 + NUM_KEYPOINTS  # body node + its 17 joints
NUM_NODE_TYPES: Final[int] = NUM_KEYPOINTS + 2  # 17 joints, body, superbody
BODY_TYPE: Final[int] = NUM_KEYPOINTS  # 17
SUPERBODY_TYPE: Final[int] = NUM_KEYPOINTS + 1  # 18

# Relation indices: the r axis of ``adj``. "A_TO_B" is a message from A (source) to B (target).
REL_SELF: Final[int] = 0               # every present node to itself
REL_CHILD_TO_PARENT: Final[int] = 1    # joint -> its kinematic parent (edge.body.PARENT)
REL_PARENT_TO_CHILD: Final[int] = 2    # parent -> joint
REL_MIRROR: Final[int] = 3             # joint <-> its left/right counterpart (edge.body.MIRROR)
REL_JOINT_TO_BODY: Final[int] = 4      # joint -> its view's body node
REL_BODY_TO_JOINT: Final[int] = 5      # body node -> its joints
REL_BODY_TO_SUPERBODY: Final[int] = 6  # body node -> superbody
REL_SUPERBODY_TO_BODY: Final[int] = 7  # superbody -> body nodes
RELATIONS: Final[tuple[str, ...]] = (
    "self", "child_to_parent", "parent_to_child", "mirror",
    "joint_to_body", "body_to_joint", "body_to_superbody", "superbody_to_body",
)
NUM_RELATIONS: Final[int] = len(RELATIONS)

# Bump when the node/edge/feature layout changes: models carry it in their metadata.
METADATA_VERSION: Final[str] = "1"
_META_PREFIX: Final[str] = "graph."


# Floor positions in the "geometry" features are in units of this many metres (as the outputs).
GEOMETRY_SCALE_M: Final[float] = 4.0
_JOINT_HEIGHTS: Final = np.asarray(TYPICAL_HEIGHT_M)


def floor_centre(site: Site) -> NDArray[np.float64]:
    """Centre of the bounding box of the site's floor polygon, (x, y) metres, shape (2,).

    The origin of the "rays" features and of the models' normalised position output.
    """
    x0, y0, x1, y1 = site.floor_bounds
    return np.array([(x0 + x1) / 2, (y0 + y1) / 2])


@dataclass(frozen=True)
class GraphSpec:
    """What graphs a model takes: variant, feature set and padded size.

    Attributes:
        variant: "site" (camera one-hot features, one slot per site camera, a model per site)
            or "rays" (world-ray features, one slot per view, one model for any layout).
        use_3d: add the joints' 3D positions (depth cameras) as features.
        camera_ids: "site" variant: the cameras, in slot / one-hot order. Empty for "rays".
        max_views: "rays" variant: the number of view slots. Ignored for "site".
        geometry: beyond the paper, add per node where its camera ray meets the joint's
            typical height (edge.body.TYPICAL_HEIGHT_M): a single-view floor position (x, y),
            floor-centred, in units of ``GEOMETRY_SCALE_M`` (body nodes: mean of their joints).
            Still RGB-only; it spares the network learning each camera's projection.
    """

    variant: Variant = "site"
    use_3d: bool = False
    camera_ids: tuple[str, ...] = ()
    max_views: int = 4
    geometry: bool = False

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"GraphSpec.variant must be one of {', '.join(VARIANTS)}, got {self.variant!r}")
        if not isinstance(self.camera_ids, tuple) or not all(isinstance(c, str) for c in self.camera_ids):
            raise ValueError(f"GraphSpec.camera_ids must be a tuple of strings, got {self.camera_ids!r}")
        if len(set(self.camera_ids)) != len(self.camera_ids):
            raise ValueError(f"GraphSpec.camera_ids must be unique, got {self.camera_ids!r}")
        if self.variant == "site" and not 1 <= len(self.camera_ids) <= 64:
            raise ValueError(f"GraphSpec.camera_ids: the 'site' variant needs 1 to 64 cameras, got {len(self.camera_ids)}")
        if self.variant == "rays" and self.camera_ids:
            raise ValueError("GraphSpec.camera_ids must be empty for the 'rays' variant (it serves any camera layout)")
        if isinstance(self.max_views, bool) or not isinstance(self.max_views, int) or not 1 <= self.max_views <= 64:
            raise ValueError(f"GraphSpec.max_views must be an integer in [1, 64], got {self.max_views!r}")

    @classmethod
    def for_site(cls, site: Site, variant: Variant = "site", use_3d: bool = False, max_views: int = 4, geometry: bool = False) -> GraphSpec:
        """The spec of a model for this site: its cameras in site order ("site"), or none ("rays")."""
        if variant not in VARIANTS:
            raise ValueError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        cams = site.camera_ids if variant == "site" else ()
        return cls(variant=variant, use_3d=use_3d, camera_ids=cams, max_views=max_views, geometry=geometry)

    @property
    def num_slots(self) -> int:
        """Slots of 18 nodes (body + joints): one per camera ("site") or per view ("rays")."""
        return len(self.camera_ids) if self.variant == "site" else self.max_views

    @property
    def num_nodes(self) -> int:
        return 1 + SLOT_SIZE * self.num_slots

    @property
    def num_relations(self) -> int:
        return NUM_RELATIONS

    @property
    def feature_names(self) -> tuple[str, ...]:
        """Name of each feature column, in order."""
        names = [f"type:{k}" for k in KEYPOINTS] + ["type:body", "type:superbody"]
        if self.variant == "site":
            names += [f"camera:{c}" for c in self.camera_ids]
        else:
            names += ["ray_x", "ray_y", "ray_z", "camera_x", "camera_y", "camera_z"]
        names += ["u", "v", "score"]
        if self.use_3d:
            names += ["x3d", "y3d", "z3d"]
        if self.geometry:
            names += ["floor_x", "floor_y"]
        return tuple(names)

    @property
    def num_features(self) -> int:
        return len(self.feature_names)

    def feature_slice(self, group: str) -> slice:
        """Columns of a feature group: "type", "camera" (site), "ray", "ray_origin" (rays),
        "uv", "score", "xyz" (use_3d)."""
        t = NUM_NODE_TYPES
        extra = len(self.camera_ids) if self.variant == "site" else 6
        groups = {"type": slice(0, t), "uv": slice(t + extra, t + extra + 2), "score": slice(t + extra + 2, t + extra + 3)}
        if self.variant == "site":
            groups["camera"] = slice(t, t + extra)
        else:
            groups["ray"], groups["ray_origin"] = slice(t, t + 3), slice(t + 3, t + 6)
        if self.use_3d:
            groups["xyz"] = slice(t + extra + 3, t + extra + 6)
        if self.geometry:
            end = t + extra + 3 + (3 if self.use_3d else 0)
            groups["floor"] = slice(end, end + 2)
        if group not in groups:
            raise ValueError(f"feature group {group!r} is not in this spec; groups: {', '.join(groups)}")
        return groups[group]

    def to_metadata(self) -> dict[str, str]:
        """String key/values for an ONNX model's metadata_props (derived sizes included, so a
        reader can check the model's input shapes)."""
        return {
            f"{_META_PREFIX}version": METADATA_VERSION,
            f"{_META_PREFIX}variant": self.variant,
            f"{_META_PREFIX}use_3d": "true" if self.use_3d else "false",
            f"{_META_PREFIX}camera_ids": json.dumps(list(self.camera_ids)),
            f"{_META_PREFIX}max_views": str(self.max_views),
            f"{_META_PREFIX}geometry": "true" if self.geometry else "false",
            f"{_META_PREFIX}num_nodes": str(self.num_nodes),
            f"{_META_PREFIX}num_features": str(self.num_features),
            f"{_META_PREFIX}num_relations": str(self.num_relations),
        }

    @classmethod
    def from_metadata(cls, meta: Mapping[str, str]) -> GraphSpec:
        """Inverse of ``to_metadata``; ``ValueError`` naming the key that is missing or wrong."""
        def get(key: str) -> str:
            full = _META_PREFIX + key
            if full not in meta:
                raise ValueError(f"model metadata has no {full!r} (not a superbody graph model?)")
            return meta[full]

        if get("version") != METADATA_VERSION:
            raise ValueError(f"model metadata {_META_PREFIX}version is {get('version')!r}; this code reads {METADATA_VERSION!r}")
        use_3d = get("use_3d")
        if use_3d not in ("true", "false"):
            raise ValueError(f"model metadata {_META_PREFIX}use_3d must be 'true' or 'false', got {use_3d!r}")
        try:
            cams = json.loads(get("camera_ids"))
            max_views = int(get("max_views"))
        except ValueError as e:
            raise ValueError(f"model metadata {_META_PREFIX}camera_ids / max_views unreadable: {e}") from None
        if not isinstance(cams, list):
            raise ValueError(f"model metadata {_META_PREFIX}camera_ids must be a JSON list, got {cams!r}")
        geometry = meta.get(f"{_META_PREFIX}geometry", "false")  # absent in models made before the option
        if geometry not in ("true", "false"):
            raise ValueError(f"model metadata {_META_PREFIX}geometry must be 'true' or 'false', got {geometry!r}")
        spec = cls(variant=get("variant"), use_3d=use_3d == "true", camera_ids=tuple(cams), max_views=max_views,  # type: ignore[arg-type]
                   geometry=geometry == "true")
        for key, value in (("num_nodes", spec.num_nodes), ("num_features", spec.num_features), ("num_relations", spec.num_relations)):
            if get(key) != str(value):
                raise ValueError(f"model metadata {_META_PREFIX}{key} is {get(key)}, but the spec implies {value}")
        return spec


@dataclass(frozen=True, eq=False)
class GraphBatch:
    """A batch of superbody graphs, one per person, as the models take them.

    Attributes:
        x: (B, N, F) float32 node features; zero rows for absent nodes.
        adj: (B, R, N, N) float32, ``adj[b, r, i, j] = 1``: edge of relation r from j to i.
        mask: (B, N) float32, 1 for present nodes.
    """

    x: NDArray[np.float32]
    adj: NDArray[np.float32]
    mask: NDArray[np.float32]

    def __len__(self) -> int:
        return len(self.x)

    def feeds(self) -> dict[str, NDArray[np.float32]]:
        """The onnxruntime input dict."""
        return {"x": self.x, "adj": self.adj, "mask": self.mask}

    @staticmethod
    def concat(batches: Sequence[GraphBatch]) -> GraphBatch:
        """Stack batches built with the same spec (e.g. from different sites, "rays" variant)."""
        return GraphBatch(
            x=np.concatenate([b.x for b in batches]),
            adj=np.concatenate([b.adj for b in batches]),
            mask=np.concatenate([b.mask for b in batches]),
        )


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
    vis = np.isfinite(uv_j).all(axis=2)  # (V, 17)
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
