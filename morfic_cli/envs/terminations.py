"""Termination terms: pure functions ``(state, cfg) -> BoolTensor[num_envs]``."""

from __future__ import annotations

import math

import torch

from morfic_cli.config import TerminationCfg
from morfic_cli.envs.state import EnvState

#: Columns of ``EnvState.body_contact_force`` that end an episode: the base and the four thighs.
TERMINAL_BODIES = slice(0, 5)


def illegal_contact(state: EnvState, cfg: TerminationCfg) -> torch.Tensor:
    """Base or thigh touches the ground with more than ``cfg.contact_force`` newtons. Shape: (N,)."""
    return (state.body_contact_force[:, TERMINAL_BODIES] > cfg.contact_force).any(dim=1)


def excessive_tilt(state: EnvState, cfg: TerminationCfg) -> torch.Tensor:
    """The base z axis is more than ``cfg.max_tilt_rad`` from world up.

    With g_proj the unit gravity in the base frame, cos(tilt) = -g_proj_z. Shape: (N,).
    """
    return -state.projected_gravity_b[:, 2] < math.cos(cfg.max_tilt_rad)


def base_too_low(state: EnvState, cfg: TerminationCfg) -> torch.Tensor:
    """Base height (above flat ground at z = 0) below a fraction of the nominal height h0. Shape: (N,)."""
    return state.base_pos_w[:, 2] < cfg.min_height_fraction * state.nominal_height


TERMINATIONS = {
    "illegal_contact": illegal_contact,
    "excessive_tilt": excessive_tilt,
    "base_too_low": base_too_low,
}
"""Every termination term, by name (each is logged as the fraction of envs it ended)."""

NONFINITE = "nonfinite"
"""The name of the env's own end of an episode beside :data:`TERMINATIONS`: the physics state became non-finite
(``SimFrame.bad``)."""


def compute_terminations(state: EnvState, cfg: TerminationCfg) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Evaluate every termination term.

    Returns:
        ``terminated`` (any term true, shape (N,), bool) and each term's mask.
    """
    masks = {name: fn(state, cfg) for name, fn in TERMINATIONS.items()}
    terminated = torch.zeros_like(next(iter(masks.values())))
    for mask in masks.values():
        terminated |= mask
    return terminated, masks
