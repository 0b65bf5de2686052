"""The GAT for inference: the same function, computed only where the output needs it.

``models.nets.GAT`` attends over every pair of the N = 1 + 18 S nodes in every layer, then reads
one node, the superbody. Two facts about the superbody graph (``host.estimation.graph``) make most of that
work unnecessary, without changing a single output:

1. **Locality.** Every edge of a graph built by ``host.estimation.graph.build_batch`` is an edge of the
   spec's template (``adjacency_template``): a joint's neighbours lie in its own slot (its body
   node, parent, children, mirror joint), a body node's are its slot and the superbody, the
   superbody's are the body nodes. So each slot's 18 nodes attend over 19 keys (their slot and
   the superbody) instead of N, and the superbody over 1 + S keys.
2. **Reach.** After L layers the superbody depends only on nodes within L hops. The last layer
   is needed at the superbody alone, the one before at the superbody and the body nodes; only
   the layers before those are needed at every node.

Keys left out are exactly those the dense model masks with -1e9, whose softmax weight is 0.0 in
float32, so the outputs agree to rounding (tests/models/test_fast_gat.py). Per graph, for the
shipped 3-layer, 4-slot model, the attention work drops from 3 x 73 x 73 to 72 x 19 + 5 + 4 x 19
+ 5 + 5 score pairs per head, about 10 x fewer.

The module takes the trained ``GAT`` (its parameters are shared, not copied) and the same
inputs (x, adj, mask), but does not read ``adj``: an edge is a template edge whose two ends are
present, ``adj == host.estimation.graph.masked_adjacency(spec, mask)``, which holds for every graph
``build_batch`` makes and every graph the models are trained on, not for arbitrary adjacency.
It exists for export (``models.training.export``; metadata ``model.reads_adj`` "false").

Shapes: B graphs, S slots of Q = 18 nodes (body first), H heads of Dh features, D = H Dh.
"""

from __future__ import annotations

from typing import cast

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from superbody.host.estimation.graph import SLOT_SIZE, SUPERBODY, adjacency_template
from superbody.models.nets import _NEG, GAT, GATLayer

__all__ = ["FastGAT"]


class FastGAT(nn.Module):
    """``GAT.forward`` restricted to the template's neighbourhoods and the superbody's reach.

    Args:
        net: a trained GAT (any number of layers, "site" or "rays" spec).
    """

    block: torch.Tensor  # buffers, registered in __init__
    slot_keys: torch.Tensor
    top_nodes: torch.Tensor

    def __init__(self, net: GAT):
        super().__init__()
        if not isinstance(net, GAT):
            raise TypeError(f"FastGAT needs a models.nets.GAT, got {type(net).__name__}")
        self.net = net
        S, Q = net.spec.num_slots, SLOT_SIZE
        self.S = S
        body = 1 + Q * np.arange(S)  # (S,) body node of each slot
        slot_nodes = body[:, None] + np.arange(Q)[None, :]  # (S, Q) the nodes of each slot, body first
        keys = np.concatenate([slot_nodes, np.full((S, 1), SUPERBODY)], axis=1)  # (S, Q + 1) a slot's keys: itself, then the superbody
        top = np.concatenate([[SUPERBODY], body])  # (1 + S,) the superbody's keys
        # Which (query, key) pairs of a slot block are template edges, any relation: the same for
        # every slot (joint structure, body, superbody). The superbody's keys are all edges.
        union = adjacency_template(net.spec).max(axis=0)  # (N, N)
        block = union[slot_nodes[0][:, None], keys[0][None, :]]  # (Q, Q+1)
        self.register_buffer("block", torch.as_tensor(block, dtype=torch.float32), persistent=False)
        self.register_buffer("slot_keys", torch.as_tensor(keys.reshape(-1)), persistent=False)  # (S (Q+1),)
        self.register_buffer("top_nodes", torch.as_tensor(top), persistent=False)  # (1 + S,)

    @staticmethod
    def _attend(layer: GATLayer, zq: torch.Tensor, zk: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        """GATLayer's attention for queries zq (..., Nq, H, Dh) over keys zk (..., Nk, H, Dh),
        bias (..., 1, Nq, Nk) -> (..., Nq, D) (layer bias added)."""
        e_dst = (zq * layer.att_dst).sum(-1).transpose(-1, -2)  # (..., H, Nq)
        e_src = (zk * layer.att_src).sum(-1).transpose(-1, -2)  # (..., H, Nk)
        e = F.leaky_relu(e_dst.unsqueeze(-1) + e_src.unsqueeze(-2), layer.negative_slope)  # (..., H, Nq, Nk)
        alpha = torch.softmax(e + bias, dim=-1)  # (..., H, Nq, Nk)
        out = alpha @ zk.transpose(-2, -3)  # (..., H, Nq, Dh)
        out = out.transpose(-2, -3)  # (..., Nq, H, Dh)
        return out.reshape(*out.shape[:-2], -1) + layer.bias  # (..., Nq, D)

    def forward(self, x: torch.Tensor, adj: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        net, S, Q, top = self.net, self.S, SLOT_SIZE, self.top_nodes
        # An edge is a template edge whose two ends are present (host.estimation.graph.masked_adjacency),
        # so the attention biases come from the mask: adj is not read.
        m_slot = mask[:, 1:].reshape(-1, S, Q)  # (B, S, Q)
        m_keys = torch.cat([m_slot, mask[:, :1, None].expand(-1, S, 1)], dim=2)  # (B, S, Q+1)
        block_bias = (1.0 - self.block * m_slot.unsqueeze(-1) * m_keys.unsqueeze(-2)) * _NEG  # (B, S, Q, Q+1)
        block_bias = block_bias.unsqueeze(2)  # (B, S, 1, Q, Q+1)
        m = mask.unsqueeze(-1)  # (B, N, 1)
        m_top = m[:, top]  # (B, 1+S, 1) superbody, then the body nodes
        top_bias = ((1.0 - mask[:, :1] * m_top[:, :, 0]) * _NEG).reshape(-1, 1, 1, S + 1)  # (B, 1, 1, 1+S)
        *inner, last = cast("list[GATLayer]", list(net.layers))  # GAT.layers holds GATLayers
        before = inner.pop() if inner else None
        if before is None:  # one layer: the superbody's keys are all that is needed
            h_top = F.elu(net.embed(x[:, top])) * m_top  # (B, 1+S, D)
        else:
            h = F.elu(net.embed(x)) * m  # (B, N, D)
            for layer in inner:  # every node
                z = self._heads(layer, h)  # (B, N, H, Dh)
                zk = z[:, self.slot_keys].reshape(-1, S, Q + 1, *z.shape[2:])  # (B, S, Q+1, H, Dh) each slot's keys
                z_top = z[:, top]  # (B, 1+S, H, Dh)
                out = torch.cat([self._attend(layer, z_top[:, :1], z_top, top_bias),  # (B, 1, D) the superbody
                                 self._attend(layer, zk[:, :, :Q], zk, block_bias).reshape(-1, S * Q, h.shape[-1])], dim=1)  # (B, N, D)
                h = (h + F.elu(out)) * m  # (B, N, D)
            # The layer before the last: the superbody and the body nodes only.
            z = self._heads(before, h)  # (B, N, H, Dh)
            zk = z[:, self.slot_keys].reshape(-1, S, Q + 1, *z.shape[2:])  # (B, S, Q+1, H, Dh)
            z_top = z[:, top]  # (B, 1+S, H, Dh)
            out = torch.cat([self._attend(before, z_top[:, :1], z_top, top_bias),  # (B, 1, D)
                             self._attend(before, zk[:, :, :1], zk, block_bias[:, :, :, :1]).reshape(-1, S, h.shape[-1])], dim=1)  # (B, 1+S, D)
            h_top = (h[:, top] + F.elu(out)) * m_top  # (B, 1+S, D)
        # The last layer: the superbody alone, over itself and the body nodes.
        z = self._heads(last, h_top)  # (B, 1+S, H, Dh)
        h0 = (h_top[:, :1] + F.elu(self._attend(last, z[:, :1], z, top_bias))) * m_top[:, :1]  # (B, 1, D)
        return net._outputs(h0[:, 0])  # (B, OUT_DIM)

    @staticmethod
    def _heads(layer: GATLayer, h: torch.Tensor) -> torch.Tensor:
        """(B, n, D) -> z = W h split into heads (B, n, H, Dh)."""
        return layer.lin(h).reshape(-1, h.shape[1], layer.heads, layer.head_dim)
