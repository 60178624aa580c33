"""BodyTransformer (Sferrazza et al. 2024) as the ``bot`` variant: a graph-masked transformer over body nodes.

Re-implemented from the paper and its public code for morfic's pipeline (docs/training.md, "External baselines";
where ours differs: docs/fidelity.md). The body graph of every quadruped here has 13 nodes: the root (the trunk)
and the 12 joints in morfic's order, legs FL, FR, RL, RR, each hip, thigh, calf. Edges are the kinematic tree:
root-hip, hip-thigh, thigh-calf of each leg (:func:`kinematic_edges`).

Tokens (from the newest frame o_t of the history, o_t's layout :data:`~morfic_cli.envs.observations.POLICY_LAYOUT`):

- root: [v (3), omega (3), g_proj (3), c (3)] = o_t[0:12];
- joint k: [q_k - q0_k, qdot_k, a_{t-1,k}] = o_t[12 + k], o_t[24 + k], o_t[36 + k].

The critic's tokens also carry p_t, as every stock critic sees it: the root token the trunk-level entries
[friction, restitution, base mass, COM offset (3)] (p_t[0:6]), joint k its own joint friction p_t[6 + k].

Network (paper "BoT-Hard"): one linear embedding per node, plus a learned node embedding; an 8-layer
``nn.TransformerEncoder`` (d = 64, 2 heads, feed-forward 128, ReLU, no dropout, post-norm) whose attention is masked
in every layer to each node's closed neighbourhood on the tree (:func:`attention_mask`); per-joint linear heads give
the 12 action means (actor); per-node linear value heads averaged over the 13 nodes give V (critic). Parameters:
:func:`parameter_count` (actor 273,304 with the action std; critic 274,509).
"""

from __future__ import annotations

import copy
import math

import torch
import torch.nn as nn
from tensordict import TensorDict

from morfic_cli.envs.observations import POLICY_DIM
from morfic_cli.morphology.robots import JOINTS, LEGS
from morfic_cli.rl.external import TokenModel, float32_linear, init_transformer_weights
from morfic_cli.rl.models import ExportedPolicy

NUM_NODES = 1 + len(LEGS) * len(JOINTS)
"""The root and the 12 joints."""
NODE_NAMES: tuple[str, ...] = ("root", *(f"{leg}_{joint}" for leg in LEGS for joint in JOINTS))
ROOT_DIM = 12
"""o_t[0:12]: base linear and angular velocity, projected gravity, command."""
JOINT_DIM = 3
"""(q - q0, qdot, previous action) of one joint."""
PRIVILEGED_ROOT_DIM = 6
"""p_t[0:6]: ground friction, restitution, base mass, COM offset; p_t[6:18] is the joint friction."""


def kinematic_edges() -> list[tuple[int, int]]:
    """The quadruped's kinematic tree as node-index pairs (parent, child): root-hip, hip-thigh, thigh-calf per leg."""
    edges = []
    for leg in range(len(LEGS)):
        hip = 1 + len(JOINTS) * leg
        edges += [(0, hip), (hip, hip + 1), (hip + 1, hip + 2)]
    return edges


def attention_mask() -> torch.Tensor:
    """Which node may not attend to which, torch's convention: True = masked. Shape: (13, 13).

    Node i attends to j exactly when j is i or a neighbour of i on the tree (shortest path < 2, BoT-Hard).
    """
    allowed = torch.eye(NUM_NODES, dtype=torch.bool)
    for a, b in kinematic_edges():
        allowed[a, b] = allowed[b, a] = True
    return ~allowed


class NodeLinear(nn.Module):
    """One linear map per node, applied to that node's input: ``y[:, k] = x[:, k] W_k + b_k``.

    Same parameters and initialisation as ``nodes`` separate ``nn.Linear(in_dim, out_dim)``, in one batched product.
    Shapes: (N, nodes, in_dim) -> (N, nodes, out_dim).
    """

    def __init__(self, nodes: int, in_dim: int, out_dim: int) -> None:
        super().__init__()
        bound = 1.0 / math.sqrt(in_dim)
        self.weight = nn.Parameter(torch.empty(nodes, in_dim, out_dim).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(nodes, out_dim).uniform_(-bound, bound))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Shapes: (N, nodes, in_dim) -> (N, nodes, out_dim)."""
        return torch.einsum("nki,kio->nko", x, self.weight.to(x.dtype)) + self.bias.to(x.dtype)


class BodyEncoder(nn.Module):
    """Tokenizer (a linear embedding per node + a learned node embedding) and the graph-masked encoder.

    Shapes: root (N, root_dim), joints (N, 12, joint_dim) -> node features (N, 13, d_model).
    """

    def __init__(
        self, root_dim: int, joint_dim: int, d_model: int, nhead: int, num_layers: int, dim_feedforward: int
    ) -> None:
        super().__init__()
        self.root_embedding = nn.Linear(root_dim, d_model)
        self.joint_embedding = NodeLinear(NUM_NODES - 1, joint_dim, d_model)
        self.node_embedding = nn.Embedding(NUM_NODES, d_model)
        layer = nn.TransformerEncoderLayer(
            d_model, nhead, dim_feedforward, dropout=0.0, activation="relu", batch_first=True, norm_first=False
        )
        self.encoder = nn.TransformerEncoder(layer, num_layers, enable_nested_tensor=False)
        init_transformer_weights(self.encoder)
        init_transformer_weights(self.node_embedding)
        self.register_buffer("mask", attention_mask(), persistent=False)

    def tokens(self, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """The 13 input tokens. Shapes: (N, root_dim), (N, 12, joint_dim) -> (N, 13, d_model)."""
        tokens = torch.cat([self.root_embedding(root)[:, None], self.joint_embedding(joints)], dim=1)
        return tokens + self.node_embedding.weight.to(tokens.dtype)

    def forward(self, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """Node features after the encoder. Shapes: (N, root_dim), (N, 12, joint_dim) -> (N, 13, d_model).

        The encoder's layers compute what ``self.encoder(tokens, mask=self.mask)`` computes (post-norm, ReLU, no
        dropout; tested equal), written out with the attention's softmax over a non-last axis: torch's CPU softmax
        over a last axis of 13 entries, and its flash-attention kernel on 13 tokens, made the update several times
        slower (docs/training.md, "External baselines"). The plain operations also export to ONNX (torch's fused
        inference kernel does not).
        """
        x = self.tokens(root, joints)
        mask = self.get_buffer("mask")  # (13, 13) bool, True where attention is not allowed
        bias = torch.zeros(mask.shape, dtype=x.dtype, device=x.device).masked_fill(mask, float("-inf"))
        for layer in self.encoder.layers:
            x = encoder_layer(layer, x, bias)
        return x


def encoder_layer(layer: nn.TransformerEncoderLayer, x: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """One post-norm ``nn.TransformerEncoderLayer`` (ReLU, no dropout) on ``x`` with an additive attention mask.

    Args:
        layer: The layer (its parameters are used as they are).
        x: Tokens. Shape: (N, L, d).
        bias: Added to the attention logits of query i and key j at [i, j] (0 or -inf). Shape: (L, L).

    Returns:
        Shape: (N, L, d).
    """
    attn = layer.self_attn
    n, length, d = x.shape
    heads = attn.num_heads
    qkv = nn.functional.linear(x, attn.in_proj_weight, attn.in_proj_bias).view(n, length, 3, heads, d // heads)
    q, k, v = qkv.unbind(2)  # (N, L, h, d_h) each
    # logits[n, h, j, i] for key j and query i: the softmax runs over axis 2 (keys), not the last axis
    logits = torch.einsum("njhc,nihc->nhji", k, q) * (d // heads) ** -0.5 + bias.T.to(q.dtype)
    weights = torch.softmax(logits, dim=2)
    out = torch.einsum("nhji,njhc->nihc", weights.to(v.dtype), v).reshape(n, length, d)
    x = layer.norm1(x + attn.out_proj(out))
    return layer.norm2(x + layer.linear2(torch.relu(layer.linear1(x))))


def _frame(obs: TensorDict, group: str) -> torch.Tensor:
    """The newest frame o_t of a history group (or the group itself if it is one frame). Shape: (N, 48)."""
    x = obs[group]
    return x[:, -1] if x.dim() == 3 else x


def split_frame(frame: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """o_t as the root's input and the joints' inputs. Shapes: (N, 48) -> (N, 12), (N, 12, 3)."""
    n = NUM_NODES - 1
    joints = torch.stack(
        [
            frame[:, ROOT_DIM : ROOT_DIM + n],
            frame[:, ROOT_DIM + n : ROOT_DIM + 2 * n],
            frame[:, ROOT_DIM + 2 * n : ROOT_DIM + 3 * n],
        ],
        dim=-1,
    )
    return frame[:, :ROOT_DIM], joints


class BotActor(TokenModel):
    """The BoT policy: per-joint linear heads on the joint nodes' features give the 12 action means."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        d_model: int = 64,
        nhead: int = 2,
        num_layers: int = 8,
        dim_feedforward: int = 128,
        distribution_cfg: dict | None = None,
    ) -> None:
        """Build the actor.

        Args:
            obs: Example observations (shapes only).
            obs_groups: ``obs_groups[obs_set]`` = [the history group], e.g. ``["history"]`` (N, H, 48).
            obs_set: ``"actor"``.
            output_dim: 12.
            d_model: Token width (BoT-Hard: 64).
            nhead: Attention heads (2).
            num_layers: Encoder layers (8).
            dim_feedforward: Feed-forward width (128).
            distribution_cfg: rsl-rl output distribution (Gaussian, state-independent std).
        """
        super().__init__(obs, obs_groups, obs_set, output_dim, distribution_cfg)
        if len(self.obs_groups) != 1 or obs[self.obs_groups[0]].shape[-1] != POLICY_DIM:
            raise ValueError(f"BotActor reads one history group of {POLICY_DIM}-D frames, got {self.obs_groups}.")
        if output_dim != NUM_NODES - 1:
            raise ValueError(f"BotActor has one head per joint ({NUM_NODES - 1}), not {output_dim} outputs.")
        self.body = BodyEncoder(ROOT_DIM, JOINT_DIM, d_model, nhead, num_layers, dim_feedforward)
        self.heads = NodeLinear(NUM_NODES - 1, d_model, 1)

    def compute(self, obs: TensorDict) -> torch.Tensor:
        """Action means. Shape: (N, 12)."""
        return self.mean_from_frame(_frame(obs, self.obs_groups[0]))

    def mean_from_frame(self, frame: torch.Tensor) -> torch.Tensor:
        """Action means from o_t. Shapes: (N, 48) -> (N, 12)."""
        h = self.body(*split_frame(frame))
        return float32_linear(self.heads, h[:, 1:]).squeeze(-1)

    def as_jit(self) -> nn.Module:
        """A TorchScript-able deterministic policy on the flattened history (N, H * 48)."""
        return _ExportedBot(self)

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """An ONNX-exportable deterministic policy on the flattened history (N, H * 48)."""
        return _ExportedBot(self)


class BotCritic(TokenModel):
    """The BoT value function: per-node linear value heads, averaged over the 13 nodes. Output (N, 1)."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        d_model: int = 64,
        nhead: int = 2,
        num_layers: int = 8,
        dim_feedforward: int = 128,
        privileged_group: str | None = "privileged",
    ) -> None:
        """Build the critic.

        Args:
            obs: Example observations (shapes only).
            obs_groups: ``obs_groups[obs_set]`` = [the clean history group, ``privileged_group``].
            obs_set: ``"critic"``.
            output_dim: 1.
            d_model: Token width (BoT-Hard: 64).
            nhead: Attention heads (2).
            num_layers: Encoder layers (8).
            dim_feedforward: Feed-forward width (128).
            privileged_group: Group holding p_t (N, 18), spread over the root and joint tokens; None: o_t only.
        """
        super().__init__(obs, obs_groups, obs_set, output_dim)
        self.privileged_group = privileged_group
        self.state_group = next(g for g in self.obs_groups if g != privileged_group)
        extra_root, extra_joint = (PRIVILEGED_ROOT_DIM, 1) if privileged_group is not None else (0, 0)
        self.body = BodyEncoder(
            ROOT_DIM + extra_root, JOINT_DIM + extra_joint, d_model, nhead, num_layers, dim_feedforward
        )
        self.heads = NodeLinear(NUM_NODES, d_model, output_dim)

    def compute(self, obs: TensorDict) -> torch.Tensor:
        """V = the mean over nodes of the per-node values. Shape: (N, 1)."""
        root, joints = split_frame(_frame(obs, self.state_group))
        if self.privileged_group is not None:
            p = obs[self.privileged_group]
            root = torch.cat([root, p[:, :PRIVILEGED_ROOT_DIM]], dim=-1)
            joints = torch.cat([joints, p[:, PRIVILEGED_ROOT_DIM:, None]], dim=-1)
        return float32_linear(self.heads, self.body(root, joints)).mean(dim=1)


def parameter_count(
    d_model: int = 64, dim_feedforward: int = 128, num_layers: int = 8, critic: bool = False, privileged: bool = True
) -> int:
    """The number of parameters of :class:`BotActor` (with its 12 action stds) or :class:`BotCritic`, by formula.

    One encoder layer: attention 4 d^2 + 4 d (Q, K, V and output projections), feed-forward 2 d f + f + d, two
    LayerNorms 4 d. The tokenizer: the root's Linear, 12 joint Linears, the node embedding 13 d.
    """
    d, f = d_model, dim_feedforward
    layer = 4 * d * d + 4 * d + 2 * d * f + f + d + 4 * d
    root_in = ROOT_DIM + (PRIVILEGED_ROOT_DIM if critic and privileged else 0)
    joint_in = JOINT_DIM + (1 if critic and privileged else 0)
    tokenizer = (root_in + 1) * d + (NUM_NODES - 1) * (joint_in + 1) * d + NUM_NODES * d
    heads = NUM_NODES * (d + 1) if critic else (NUM_NODES - 1) * (d + 1) + (NUM_NODES - 1)  # + action stds
    return num_layers * layer + tokenizer + heads


class _ExportedBot(ExportedPolicy):
    """Deterministic BoT policy on the flattened history for TorchScript and ONNX: (N, H * 48) -> (N, 12)."""

    def __init__(self, actor: BotActor) -> None:
        super().__init__()
        self.body = copy.deepcopy(actor.body)
        self.heads = copy.deepcopy(actor.heads)
        self.input_size = actor.obs_dim

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Action means from the newest frame (the last 48 entries). Shape: (N, H * 48) -> (N, 12)."""
        root, joints = split_frame(x[:, -POLICY_DIM:])
        return self.heads(self.body(root, joints)[:, 1:]).squeeze(-1)
