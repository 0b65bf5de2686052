"""The pose networks: GAT, RGCN and the paper's MLP baseline, on dense superbody graphs.

Every model takes the tensors of ``host.estimation.graph.build_batch`` and returns the normalised pose of
each person, read at the superbody node (node 0)::

    x    (B, N, F) node features       adj  (B, R, N, N) 0/1, adj[b, r, i, j]: edge j -> i
    mask (B, N)    1 = node present    out  (B, 7) = ((x - ox)/s, (y - oy)/s, sin yaw, cos yaw,
                                                      log sigma_x/s, log sigma_y/s, log sigma_yaw)

The last three outputs are the network's own uncertainty (a heteroscedastic Gaussian head for
the position and a von Mises head for the yaw, trained by ``pose_nll``); the host's filter uses
them as the measurement noise, so a poor single-view yaw moves a track less.

Output normalisation: positions are metres relative to an origin (ox, oy), divided by the
scale s (``DEFAULT_SCALE`` = 4 m, as the original code's x/4000 mm). The origin is the
training site's floor centre for the "site" variant (``hparams["origin"]``, fixed in the
model) and the serving site's floor centre for the "rays" variant (whose features are
floor-centred too, so the model never sees absolute coordinates). ``PoseNet.targets`` builds
the training targets and ``PoseNet.decode`` inverts them; the ONNX export bakes the scale and,
for "site" models, the origin into the graph (see ``models.training.export``).

Everything is dense tensors and static shapes (N, F, R come from the GraphSpec), with no
data-dependent Python control flow, so the models export to ONNX with a dynamic batch axis.
"""

from __future__ import annotations

import math
from typing import Final, Literal, get_args

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
from numpy.typing import NDArray

from superbody.edge.site import Site
from superbody.host.estimation.estimator import decode_output
from superbody.host.estimation.graph import SLOT_SIZE, SUPERBODY, GraphSpec, floor_centre

__all__ = [
    "OUT_DIM",
    "decode_std",
    "pose_nll",
    "Arch",
    "ARCHS",
    "DEFAULT_SCALE",
    "PoseNet",
    "GATLayer",
    "GAT",
    "RGCNLayer",
    "RGCN",
    "MLP",
    "build_model",
    "pose_targets",
    "decode_pose",
    "num_parameters",
]

Arch = Literal["gat", "rgcn", "mlp"]
ARCHS: Final[tuple[str, ...]] = get_args(Arch)
DEFAULT_SCALE: Final[float] = 4.0
# Masked attention logits: large and negative but finite (not -inf), so a row with no neighbour
# at all (an absent node) softmaxes to a uniform distribution instead of NaN.
_NEG: Final[float] = -1e9

# Outputs: the normalised pose (x, y, sin yaw, cos yaw) and its log 1-sigma (x, y, yaw).
OUT_DIM: Final[int] = 7


def pose_targets(truth: NDArray, origin: NDArray, scale: float) -> NDArray[np.float32]:
    """World poses (B, 3) (x, y, yaw) -> normalised targets (B, 4)."""
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    xy = (truth[:, :2] - np.asarray(origin, dtype=np.float64)) / scale  # (B, 2)
    return np.column_stack([xy, np.sin(truth[:, 2]), np.cos(truth[:, 2])]).astype(np.float32)


def decode_pose(out: NDArray, origin: NDArray, scale: float) -> NDArray[np.float64]:
    """Normalised outputs (B, 4 or OUT_DIM) -> world poses (B, 3), yaw wrapped to (-pi, pi]."""
    out = np.asarray(out, dtype=np.float64)
    out = out.reshape(len(out), -1)[:, :4]  # (B, 4) the pose; the rest is its uncertainty
    return decode_output(np.column_stack([out[:, :2] * scale, out[:, 2:]]), origin)


def decode_std(out: NDArray, scale: float) -> NDArray[np.float64]:
    """Normalised outputs (B, OUT_DIM) -> predicted 1-sigma (B, 3): x, y in metres, yaw in radians."""
    s = np.exp(np.clip(np.asarray(out, dtype=np.float64)[:, 4:7], -12.0, 4.0))  # (B, 3)
    return s * [scale, scale, 1.0]


def pose_nll(out: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """(B,) negative log-likelihood of the targets under the predicted uncertainty.

    Position: a Gaussian per axis with log-sigma ``out[:, 4:6]``; yaw: a von Mises with
    concentration kappa = 1 / sigma^2, log-sigma ``out[:, 6]``. The means are detached: the
    uncertainty head learns how wrong the pose is, without pulling the pose toward easy cases.

        NLL_xy  = 0.5 (d / sigma)^2 + log sigma
        NLL_yaw = kappa (1 - cos d) + log I0e(kappa)    (= -kappa cos d + log I0(kappa))
    """
    mean = out[:, :4].detach()
    log_s = out[:, 4:7].clamp(-8.0, 4.0)  # (B, 3)
    d_xy = mean[:, :2] - y[:, :2]  # (B, 2)
    nll_xy = (0.5 * (d_xy / log_s[:, :2].exp()) ** 2 + log_s[:, :2]).sum(1)
    d_yaw = torch.atan2(mean[:, 2], mean[:, 3]) - torch.atan2(y[:, 2], y[:, 3])  # (B,)
    kappa = torch.exp(-2.0 * log_s[:, 2])
    nll_yaw = kappa * (1.0 - torch.cos(d_yaw)) + torch.log(torch.special.i0e(kappa))
    return nll_xy + nll_yaw


class PoseNet(nn.Module):
    """What every pose network shares: its graph spec, output normalisation and config."""

    arch: str = ""
    head: nn.Module  # (B, D) pose embedding -> (B, 4) pose; set by each architecture
    std_head: nn.Module  # (B, D) -> (B, 3) log-sigma; set by _with_std

    def __init__(self, spec: GraphSpec, scale: float = DEFAULT_SCALE, origin: tuple[float, float] = (0.0, 0.0)):
        super().__init__()
        if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive number of metres, got {scale!r}")
        self.spec = spec
        self.scale = float(scale)
        self.origin = (float(origin[0]), float(origin[1]))
        self.hparams: dict[str, object] = {}

    def _with_std(self, dim: int, hidden: int) -> None:
        """Add the uncertainty head on the ``dim``-wide pose embedding."""
        self.std_head = nn.Sequential(nn.Linear(dim, hidden), nn.ELU(), nn.Linear(hidden, 3))

    def _outputs(self, z: torch.Tensor) -> torch.Tensor:
        """(B, OUT_DIM) pose and log-sigma from the pose embedding z (B, D). The uncertainty head
        reads a detached copy: learning how wrong the pose is must not change the pose."""
        return torch.cat([self.head(z), self.std_head(z.detach())], dim=1)

    def config(self) -> dict[str, object]:
        """Architecture, hyper-parameters and output normalisation (JSON-able)."""
        return {"arch": self.arch, **self.hparams, "scale": self.scale, "origin": list(self.origin)}

    def origin_for(self, site: Site) -> NDArray[np.float64]:
        """Origin of the position outputs for graphs of this site."""
        return floor_centre(site) if self.spec.variant == "rays" else np.asarray(self.origin)

    def targets(self, truth: NDArray, site: Site) -> NDArray[np.float32]:
        """Training targets (B, 4) for world poses (B, 3) of people seen in ``site``."""
        return pose_targets(truth, self.origin_for(site), self.scale)

    def decode(self, out: NDArray, site: Site) -> NDArray[np.float64]:
        """World poses (B, 3) from this model's outputs (B, 4) on graphs of ``site``."""
        return decode_pose(out, self.origin_for(site), self.scale)


# --------------------------------------------------------------------------------------------
# GAT
# --------------------------------------------------------------------------------------------


class GATLayer(nn.Module):
    """Multi-head graph attention (Velickovic et al., "Graph Attention Networks", 2018), dense.

        z_i = W h_i                                       per head k: z_i^k, D/H features
        e_ij^k = LeakyReLU(a_dst^k . z_i^k + a_src^k . z_j^k)   for j in N(i) (incl. i)
        alpha_ij^k = softmax_j(e_ij^k)
        h_i' = concat_k sum_j alpha_ij^k z_j^k + b

    The neighbourhood comes in as an additive bias, 0 on edges and -1e9 elsewhere (computed
    once per forward pass; cheaper than a select in every layer, and finite, so a node with no
    edge at all gets a uniform softmax instead of NaN).

    Shapes: h (B, N, D), bias (B, 1, N, N) with bias[b, 0, i, j] = 0 for an edge j -> i
    -> (B, N, D).
    """

    def __init__(self, dim: int, heads: int, negative_slope: float = 0.2):
        super().__init__()
        if dim % heads:
            raise ValueError(f"GAT hidden size {dim} must be a multiple of heads {heads}")
        self.heads, self.head_dim, self.negative_slope = heads, dim // heads, negative_slope
        self.lin = nn.Linear(dim, dim, bias=False)
        self.att_src = nn.Parameter(torch.empty(heads, self.head_dim))
        self.att_dst = nn.Parameter(torch.empty(heads, self.head_dim))
        self.bias = nn.Parameter(torch.zeros(dim))
        nn.init.xavier_uniform_(self.lin.weight)
        nn.init.xavier_uniform_(self.att_src)
        nn.init.xavier_uniform_(self.att_dst)

    def forward(self, h: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        N, H, Dh = h.shape[1], self.heads, self.head_dim
        z = self.lin(h).reshape(-1, N, H, Dh)  # (B, N, H, Dh)
        e_dst = (z * self.att_dst).sum(-1).transpose(1, 2)  # (B, H, N)
        e_src = (z * self.att_src).sum(-1).transpose(1, 2)  # (B, H, N)
        e = F.leaky_relu(e_dst.unsqueeze(-1) + e_src.unsqueeze(-2), self.negative_slope)  # (B, H, N, N)
        alpha = torch.softmax(e + bias, dim=-1)  # (B, H, N, N) over neighbours j
        out = alpha @ z.transpose(1, 2)  # (B, H, N, Dh)
        return out.transpose(1, 2).reshape(-1, N, H * Dh) + self.bias  # (B, N, D)


class GAT(PoseNet):
    """Embedding, ``layers`` residual GAT layers (ELU) on the union of the relations, and an
    MLP head on the superbody node."""

    arch = "gat"

    def __init__(self, spec: GraphSpec, hidden: int = 64, heads: int = 4, layers: int = 3, **norm):
        super().__init__(spec, **norm)
        self.hparams = {"hidden": hidden, "heads": heads, "layers": layers}
        self.embed = nn.Linear(spec.num_features, hidden)
        self.layers = nn.ModuleList(GATLayer(hidden, heads) for _ in range(layers))
        self.head = nn.Sequential(nn.Linear(hidden, hidden), nn.ELU(), nn.Linear(hidden, 4))
        self._with_std(hidden, hidden)

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        m = mask.unsqueeze(-1)  # (B, N, 1)
        bias = (1.0 - adj.amax(dim=1, keepdim=True)) * _NEG  # (B, 1, N, N) 0 on edges of any relation, -1e9 elsewhere
        h = F.elu(self.embed(x)) * m  # (B, N, D)
        for layer in self.layers:
            h = (h + F.elu(layer(h, bias))) * m  # (B, N, D) absent nodes stay zero
        return self._outputs(h[:, SUPERBODY])  # (B, OUT_DIM)


# --------------------------------------------------------------------------------------------
# RGCN
# --------------------------------------------------------------------------------------------


class RGCNLayer(nn.Module):
    """Relational graph convolution with basis decomposition (Schlichtkrull et al., "Modeling
    Relational Data with Graph Convolutional Networks", 2018), dense.

        h_i' = W_0 h_i + b + sum_r sum_{j in N_r(i)} (1 / c_ir) W_r h_j,   W_r = sum_b a_rb V_b

    with c_ir = |N_r(i)|. Summing over relations first, sum_r a_rb A_r, keeps every product a
    plain MatMul: h' = W_0 h + b + sum_b (sum_r a_rb A_r) (h V_b).

    Shapes: h (B, N, D_in), A (B, R, N, N) already divided by c_ir -> (B, N, D_out).
    """

    def __init__(self, in_dim: int, out_dim: int, num_relations: int, num_bases: int):
        super().__init__()
        self.num_relations, self.num_bases = num_relations, num_bases
        self.bases = nn.Parameter(torch.empty(num_bases, in_dim, out_dim))  # V_b
        self.coeffs = nn.Parameter(torch.empty(num_relations, num_bases))  # a_rb
        self.root = nn.Linear(in_dim, out_dim)  # W_0, b: the self-connection
        nn.init.xavier_uniform_(self.bases)
        nn.init.xavier_uniform_(self.coeffs)

    def forward(self, h: torch.Tensor, A: torch.Tensor) -> torch.Tensor:
        N, R, nb = h.shape[1], self.num_relations, self.num_bases
        # sum_r a_rb A_r
        A_b = (self.coeffs.t() @ A.reshape(-1, R, N * N)).reshape(-1, nb, N, N)  # (B, nb, N, N)
        hV = h.unsqueeze(1) @ self.bases  # (B, nb, N, D_out)
        return self.root(h) + (A_b @ hV).sum(1)  # (B, N, D_out)


class RGCN(PoseNet):
    """Embedding, ``layers`` residual RGCN layers (ReLU) over the graph's relations, and an MLP
    head on the superbody node.

    The graph's self-loop relation gives each node a second, basis-shared path to itself next
    to the layer's own self-connection W_0; harmless, and it keeps the model blind to which
    relations the builder emits.
    """

    arch = "rgcn"

    def __init__(self, spec: GraphSpec, hidden: int = 64, bases: int = 4, layers: int = 3, **norm):
        super().__init__(spec, **norm)
        self.hparams = {"hidden": hidden, "bases": bases, "layers": layers}
        self.embed = nn.Linear(spec.num_features, hidden)
        self.layers = nn.ModuleList(RGCNLayer(hidden, hidden, spec.num_relations, bases) for _ in range(layers))
        self.head = nn.Sequential(nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 4))
        self._with_std(hidden, hidden)

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        m = mask.unsqueeze(-1)  # (B, N, 1)
        # Per-relation degree normalisation 1 / c_ir (rows with no edge stay zero).
        A = adj / adj.sum(-1, keepdim=True).clamp(min=1.0)  # (B, R, N, N)
        h = F.relu(self.embed(x)) * m  # (B, N, D)
        for layer in self.layers:
            h = (h + F.relu(layer(h, A))) * m  # (B, N, D)
        return self._outputs(h[:, SUPERBODY])  # (B, OUT_DIM)


# --------------------------------------------------------------------------------------------
# MLP baseline
# --------------------------------------------------------------------------------------------


class MLP(PoseNet):
    """The paper's MLP baseline, on the same tensors.

    Each slot (a camera for "site", a view for "rays") is its 18 nodes' features, flattened,
    plus their 18 mask bits (the missing-data mask); shared layers turn each slot into an
    embedding, zeroed when the slot is empty; the embeddings are concatenated in slot order
    and a head maps them to the pose. The graph's edges are not used (the export still declares
    ``adj`` as an input, so every model has the same interface).
    """

    arch = "mlp"

    def __init__(self, spec: GraphSpec, hidden: int = 128, slot_dim: int = 64, **norm):
        super().__init__(spec, **norm)
        self.hparams = {"hidden": hidden, "slot_dim": slot_dim}
        self.slot_dim = slot_dim
        S, F_ = spec.num_slots, spec.num_features
        self.slot = nn.Sequential(
            nn.Linear(SLOT_SIZE * (F_ + 1), hidden), nn.ReLU(), nn.Linear(hidden, slot_dim), nn.ReLU()
        )
        self.head = nn.Sequential(nn.Linear(S * slot_dim, hidden), nn.ReLU(), nn.Linear(hidden, 4))
        self._with_std(S * slot_dim, hidden)

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        S, F_ = self.spec.num_slots, self.spec.num_features
        x = x * mask.unsqueeze(-1)  # (B, N, F) absent nodes are zeros, whatever the input says
        xs = x[:, 1:].reshape(-1, S, SLOT_SIZE * F_)  # (B, S, 18 F) the superbody carries nothing
        ms = mask[:, 1:].reshape(-1, S, SLOT_SIZE)  # (B, S, 18)
        e = self.slot(torch.cat([xs, ms], dim=-1))  # (B, S, E)
        e = e * ms[:, :, :1]  # (B, S, E) empty slots (no body node) contribute nothing
        return self._outputs(e.reshape(-1, S * self.slot_dim))  # (B, OUT_DIM)


# --------------------------------------------------------------------------------------------
# Factory
# --------------------------------------------------------------------------------------------

_MODELS: Final[dict[str, type[PoseNet]]] = {"gat": GAT, "rgcn": RGCN, "mlp": MLP}


def build_model(arch: Arch, spec: GraphSpec, **hparams: object) -> PoseNet:
    """A fresh model by name.

    Args:
        arch: "gat", "rgcn" or "mlp".
        spec: the graphs it takes.
        **hparams: the architecture's hyper-parameters (GAT: hidden, heads, layers; RGCN:
            hidden, bases, layers; MLP: hidden, slot_dim) and the output normalisation
            (scale: metres, default 4; origin: (x, y) of the training site's floor centre for
            "site" models, e.g. ``host.estimation.graph.floor_centre(site)``).

    Raises:
        ValueError: unknown arch (the message lists the valid ones) or hyper-parameter.
    """
    if arch not in _MODELS:
        raise ValueError(f"unknown model architecture {arch!r}; valid: {', '.join(ARCHS)}")
    try:
        return _MODELS[arch](spec, **hparams)  # type: ignore[arg-type]
    except TypeError as e:
        raise ValueError(f"bad hyper-parameters for {arch!r}: {e}") from None


def num_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
