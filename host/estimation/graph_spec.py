"""The superbody graph's layout: node and relation numbering, feature columns (``GraphSpec``, kept
in a model's ONNX metadata) and the batch the models take (``GraphBatch``). The layout itself is
described at the top of ``host/estimation/graph.py``, which builds the graphs."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from superbody.edge.body import KEYPOINTS, NUM_KEYPOINTS, TYPICAL_HEIGHT_M
from superbody.edge.site import Site

__all__ = ["BODY_TYPE", "METADATA_VERSION", "NUM_NODE_TYPES", "NUM_RELATIONS", "RELATIONS", "REL_BODY_TO_JOINT", "REL_BODY_TO_SUPERBODY", "REL_CHILD_TO_PARENT", "REL_JOINT_TO_BODY", "REL_MIRROR", "REL_PARENT_TO_CHILD", "REL_SELF", "REL_SUPERBODY_TO_BODY", "SLOT_SIZE", "SUPERBODY", "SUPERBODY_TYPE", "VARIANTS", "Variant", "floor_centre", "GraphSpec", "GraphBatch"]


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
