"""A user's own critic variant: a gated critic, trained and evaluated by morfic without changing morfic.

Each hidden layer of the critic trunk is multiplied, feature by feature, by a gate computed from the morphology
latent z_m::

    h_l <- (W_l x + b_l) * 2 sigmoid(g_l(z_m))

with ``g_l`` a small MLP (z_m (64) -> 128 -> H_l) whose last layer starts at zero, so the gate is exactly 1 and the
critic computes its unconditioned trunk at initialisation (as the paper's FiLM critic does). The actor is
morfic's stock actor with z_m.

Install it as its own package (examples/pyproject.toml), then use it from the command line by import path::

    pip install -e examples/
    morfic train --variant custom_variant:GatedCritic --preset smoke
    morfic eval runs/custom_variant.GatedCritic-smoke-s0 --robots go2
    morfic compare-baselines

docs/extending.md walks through it.
"""

from __future__ import annotations

import torch
import torch.nn as nn
from rsl_rl.modules import MLP

from morfic_cli.rl.models import MorficCritic


class Gate(nn.Module):
    """Multiplicative gate of one hidden layer: ``h * 2 sigmoid(g(z_m))``; 1 at initialisation.

    Args:
        latent_dim: Size of z_m (64).
        hidden_dim: Width H of the gated layer.
        generator_hidden_dim: Hidden width of g (128).
        activation: Activation of g ("elu").
    """

    def __init__(self, latent_dim: int, hidden_dim: int, generator_hidden_dim: int, activation: str) -> None:
        super().__init__()
        self.generator = MLP(latent_dim, hidden_dim, [generator_hidden_dim], activation)
        last = [m for m in self.generator.modules() if isinstance(m, nn.Linear)][-1]
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)

    def forward(self, linear: nn.Linear, x: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """Gated pre-activation. Shapes: x (N, D_in), z_m (N, 64) -> (N, H)."""
        h = linear(x)
        if z_m is None:
            return h
        return h * 2.0 * torch.sigmoid(self.generator(z_m))


class GatedCritic(MorficCritic):
    """MorficCritic whose hidden layers are gated by z_m (one :class:`Gate` per layer)."""

    label = "Gated"
    """The name of this variant in morfic's tables and figures."""
    critic_defaults = {"conditioning": "gated"}
    """Critic config entries: the conditioning name is ours (MorficCritic calls make_modulator for it)."""

    def make_modulator(self, linear: nn.Linear) -> nn.Module:
        """One gate per hidden trunk layer, sized by the layer's output width."""
        c = self.modulator_cfg
        return Gate(c["latent_dim"], linear.out_features, c["generator_hidden_dim"], c["activation"])
