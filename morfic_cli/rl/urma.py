"""URMA (Bohlinger et al. 2024) as the ``urma`` variant: description-weighted attention pooling, a universal decoder.

Re-implemented from the paper and its public code for morfic's pipeline (docs/training.md, "External baselines";
where ours differs: docs/fidelity.md). The env gives URMA's tokens (``env.obs.body_tokens``, which the variant turns
on; :mod:`morfic_cli.envs.observations`):

- joint j: its description d_j (18, read from the env's own model, :mod:`morfic_cli.morphology.description`) and its
  state s_j = [q_j - q0_j, qdot_j, a_{t-1,j}] (3, from the newest frame o_t of the history, as o_t scales it);
- foot i: its description (6) and state [contact, time since touchdown] (2);
- general: [v, omega, g_proj, c] = o_t[0:12]; the critic's also p_t (18, clean o_t).

Encoder (:class:`AttentionPool`, one for joints with 64 slots, one for feet with 32): per token a softmax over the
slots, ``w = softmax(tanh(W2 ELU(LN(W1 d))) / T)`` with a learned temperature T > 0.015, and a value
``u = ELU(W_u s)`` (4); the latent is ``sum_tokens w (x) u`` (64 x 4 = 256 for joints, 32 x 4 = 128 for feet). So
the morphology enters additively: it decides where each joint's state lands in the latent.

Actor: core MLP ``[joint latent, foot latent, general] -> 512 -> LN -> ELU -> 256 -> ELU -> 128``; the universal
decoder, one set of weights for every joint, reads ``[core (128), sg(u_j) (4), e(d_j) (128)]`` with
``e(d) = W ELU(LN(W d))`` (128) and gives ``mean_j = W_o ELU(LN(W_h [...]))`` (260 -> 128 -> 1). The action std is
morfic's (rsl-rl's state-independent std per joint). Critic: its own encoders, then
``[latents, general, p_t] -> 512 -> LN -> ELU -> 256 -> ELU -> 128 -> ELU -> 1``. Parameters:
:func:`parameter_count` (actor 428,395 with the action std; critic 384,735).
"""

from __future__ import annotations

import math

import torch
import torch.nn as nn
from tensordict import TensorDict

from morfic_cli.envs.observations import FOOT_DESCRIPTION_DIM, FOOT_STATE_DIM, JOINT_DESCRIPTION_DIM, POLICY_DIM
from morfic_cli.errors import MorficError
from morfic_cli.rl.bot import JOINT_DIM, ROOT_DIM, split_frame
from morfic_cli.rl.external import TokenModel, float32_linear

GROUPS: tuple[str, ...] = ("joint_description", "foot_description", "foot_state")
"""The env groups URMA reads besides the history (``env.obs.body_tokens``)."""
MIN_TEMPERATURE = 0.015
"""URMA's lower bound of the softmax temperature."""


def _orthogonal(layer: nn.Linear, gain: float) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


class AttentionPool(nn.Module):
    """URMA's encoder of one token kind: description-weighted pooling of the tokens' state values into slots.

    Shapes: description (N, T, D_d), state (N, T, D_s) -> latent (N, slots * value_dim), values (N, T, value_dim).
    """

    def __init__(
        self, description_dim: int, state_dim: int, slots: int, value_dim: int = 4, temperature: float = 1.0
    ) -> None:
        super().__init__()
        self.mask = nn.Sequential(
            nn.Linear(description_dim, slots), nn.LayerNorm(slots), nn.ELU(), nn.Linear(slots, slots)
        )
        self.value = nn.Linear(state_dim, value_dim)
        self.log_temperature = nn.Parameter(torch.tensor([math.log(temperature - MIN_TEMPERATURE)]))

    def weights(self, description: torch.Tensor) -> torch.Tensor:
        """Each token's softmax over the slots; sums to 1 over the last axis. Shape: (N, T, D_d) -> (N, T, slots)."""
        logits = torch.tanh(self.mask(description))
        temperature = self.log_temperature.exp() + MIN_TEMPERATURE
        return torch.softmax(logits / temperature, dim=-1)

    def forward(self, description: torch.Tensor, state: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The pooled latent and the tokens' values (the decoder reads them). See the class docstring for shapes."""
        values = nn.functional.elu(self.value(state))
        latent = torch.einsum("nts,ntv->nsv", self.weights(description), values)
        return latent.flatten(1), values


class _Encoders(nn.Module):
    """The joint and foot pools of one network. Returns [joint latent, foot latent] (N, 384) and joint values."""

    def __init__(self) -> None:
        super().__init__()
        self.joints = AttentionPool(JOINT_DESCRIPTION_DIM, JOINT_DIM, 64)
        self.feet = AttentionPool(FOOT_DESCRIPTION_DIM, FOOT_STATE_DIM, 32)

    def forward(self, obs: TensorDict, joint_state: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        joint_latent, joint_values = self.joints(obs["joint_description"], joint_state)
        foot_latent, _ = self.feet(obs["foot_description"], obs["foot_state"])
        return torch.cat([joint_latent, foot_latent], dim=-1), joint_values


LATENT_DIM = 64 * 4 + 32 * 4
"""The encoders' output: 256 (joints) + 128 (feet)."""


def _check_groups(model: TokenModel, obs: TensorDict, state_group: str) -> None:
    missing = [g for g in GROUPS if g not in obs.keys()]
    if missing:
        raise ValueError(f"{type(model).__name__} needs the env groups {', '.join(missing)} (env.obs.body_tokens).")
    if obs[state_group].shape[-1] != POLICY_DIM:
        raise ValueError(f"{type(model).__name__} reads a history group of {POLICY_DIM}-D frames, not '{state_group}'.")


def _frame(obs: TensorDict, group: str) -> torch.Tensor:
    x = obs[group]
    return x[:, -1] if x.dim() == 3 else x


class UrmaActor(TokenModel):
    """URMA's policy: attention-pooling encoders, the core MLP and the universal per-joint decoder. Output (N, 12)."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        state_group: str = "history",
        distribution_cfg: dict | None = None,
    ) -> None:
        """Build the actor.

        Args:
            obs: Example observations (shapes only).
            obs_groups: ``obs_groups[obs_set]`` = [``state_group``, joint_description, foot_description, foot_state].
            obs_set: ``"actor"``.
            output_dim: 12 (one action per joint token).
            state_group: The history group whose newest frame gives the joint states and the general state.
            distribution_cfg: rsl-rl output distribution (Gaussian, state-independent std).
        """
        super().__init__(obs, obs_groups, obs_set, output_dim, distribution_cfg)
        _check_groups(self, obs, state_group)
        self.state_group = state_group
        self.encoders = _Encoders()
        gain = math.sqrt(2.0)
        self.core = nn.Sequential(
            _orthogonal(nn.Linear(LATENT_DIM + ROOT_DIM, 512), gain),
            nn.LayerNorm(512),
            nn.ELU(),
            _orthogonal(nn.Linear(512, 256), gain),
            nn.ELU(),
            _orthogonal(nn.Linear(256, 128), gain),
        )
        self.description_latent = nn.Sequential(
            nn.Linear(JOINT_DESCRIPTION_DIM, 128), nn.LayerNorm(128), nn.ELU(), nn.Linear(128, 128)
        )
        self.decoder = nn.Sequential(_orthogonal(nn.Linear(128 + 4 + 128, 128), gain), nn.LayerNorm(128), nn.ELU())
        self.mean = _orthogonal(nn.Linear(128, 1), 0.01)

    def compute(self, obs: TensorDict) -> torch.Tensor:
        """Action means, one per joint token. Shape: (N, 12)."""
        general, joint_state = split_frame(_frame(obs, self.state_group))
        latent, joint_values = self.encoders(obs, joint_state)
        core = self.core(torch.cat([latent, general], dim=-1))  # (N, 128)
        description = self.description_latent(obs["joint_description"])  # (N, 12, 128)
        per_joint = torch.cat(
            [core[:, None].expand(-1, description.shape[1], -1), joint_values.detach(), description], dim=-1
        )
        return float32_linear(self.mean, self.decoder(per_joint)).squeeze(-1)

    def as_jit(self) -> nn.Module:
        """Not supported (:meth:`as_onnx`)."""
        return self.as_onnx()

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """Not supported: export's inputs are the history (and the descriptor); URMA also reads the descriptions."""
        raise MorficError(
            "variant urma cannot be exported: its policy also reads the per-joint and per-foot "
            "descriptions and foot states (env.obs.body_tokens), which the exported model's inputs "
            "(history, morphology) do not carry; export its weights with `morfic export RUN --to "
            "rsl-rl`, or evaluate it with `morfic eval`."
        )


class UrmaCritic(TokenModel):
    """URMA's value function: its own encoders, then an MLP on the latents, o_t's general part and p_t. (N, 1)."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        state_group: str = "critic",
        privileged_group: str | None = "privileged",
    ) -> None:
        """Build the critic.

        Args:
            obs: Example observations (shapes only).
            obs_groups: ``obs_groups[obs_set]`` = [``state_group``, ``privileged_group``, the three token groups].
            obs_set: ``"critic"``.
            output_dim: 1.
            state_group: The clean history group.
            privileged_group: Group holding p_t (N, 18), appended to the general state; None: left out.
        """
        super().__init__(obs, obs_groups, obs_set, output_dim)
        _check_groups(self, obs, state_group)
        self.state_group = state_group
        self.privileged_group = privileged_group
        extra = obs[privileged_group].shape[-1] if privileged_group is not None else 0
        self.encoders = _Encoders()
        gain = math.sqrt(2.0)
        self.mlp = nn.Sequential(
            _orthogonal(nn.Linear(LATENT_DIM + ROOT_DIM + extra, 512), gain),
            nn.LayerNorm(512),
            nn.ELU(),
            _orthogonal(nn.Linear(512, 256), gain),
            nn.ELU(),
            _orthogonal(nn.Linear(256, 128), gain),
            nn.ELU(),
        )
        self.value = _orthogonal(nn.Linear(128, output_dim), 1.0)

    def compute(self, obs: TensorDict) -> torch.Tensor:
        """V. Shape: (N, 1)."""
        general, joint_state = split_frame(_frame(obs, self.state_group))
        latent, _ = self.encoders(obs, joint_state)
        parts = [latent, general] + ([obs[self.privileged_group]] if self.privileged_group is not None else [])
        return float32_linear(self.value, self.mlp(torch.cat(parts, dim=-1)))


def parameter_count(critic: bool = False, privileged_dim: int = 18) -> int:
    """The number of parameters of :class:`UrmaActor` (with its 12 action stds) or :class:`UrmaCritic`, by formula.

    A Linear(a, b) has (a + 1) b, a LayerNorm(b) 2 b; each pool has one temperature.
    """

    def lin(a: int, b: int) -> int:
        return (a + 1) * b

    def pool(d: int, s: int, slots: int) -> int:
        return lin(d, slots) + 2 * slots + lin(slots, slots) + lin(s, 4) + 1

    encoders = pool(JOINT_DESCRIPTION_DIM, JOINT_DIM, 64) + pool(FOOT_DESCRIPTION_DIM, FOOT_STATE_DIM, 32)
    if critic:
        return (
            encoders
            + lin(LATENT_DIM + ROOT_DIM + privileged_dim, 512)
            + 2 * 512
            + lin(512, 256)
            + lin(256, 128)
            + lin(128, 1)
        )
    core = lin(LATENT_DIM + ROOT_DIM, 512) + 2 * 512 + lin(512, 256) + lin(256, 128)
    description = lin(JOINT_DESCRIPTION_DIM, 128) + 2 * 128 + lin(128, 128)
    decoder = lin(128 + 4 + 128, 128) + 2 * 128 + lin(128, 1)
    return encoders + core + description + decoder + 12
