"""Domain randomisation samplers (docs/concepts.md): pure functions of a generator and a config.

Every sample is drawn on the generator's device (the env's: the CPU, or the GPU the warp backend runs on).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from morfic_cli.config import DomainRandCfg
from morfic_cli.sim.args import NUM_JOINTS


@dataclass
class DynamicsSample:
    """Randomised contact and joint properties for k envs.

    Attributes:
        friction: Shape: (k,). restitution: Shape: (k,). com_offset: (m), shape (k, 3).
        joint_friction: (N m), shape (k, 12).
    """

    friction: torch.Tensor
    restitution: torch.Tensor
    com_offset: torch.Tensor
    joint_friction: torch.Tensor


def _uniform(shape: tuple[int, ...], lo: float, hi: float, gen: torch.Generator) -> torch.Tensor:
    return lo + (hi - lo) * torch.rand(shape, generator=gen, device=gen.device)


def nominal_dynamics(k: int, device: torch.device | str = "cpu") -> DynamicsSample:
    """No randomisation: friction 1, restitution 0, no COM offset, no joint friction (on ``device``)."""
    return DynamicsSample(
        torch.ones(k, device=device),
        torch.zeros(k, device=device),
        torch.zeros(k, 3, device=device),
        torch.zeros(k, NUM_JOINTS, device=device),
    )


def sample_dynamics(k: int, cfg: DomainRandCfg, gen: torch.Generator) -> DynamicsSample:
    """Sample friction U[0.5, 1.25], restitution, COM offset and joint friction for k envs."""
    if not cfg.enabled:
        return nominal_dynamics(k, gen.device)
    return DynamicsSample(
        friction=_uniform((k,), *cfg.friction, gen),
        restitution=_uniform((k,), *cfg.restitution, gen),
        com_offset=_uniform((k, 3), -cfg.com_offset, cfg.com_offset, gen),
        joint_friction=_uniform((k, NUM_JOINTS), *cfg.joint_friction, gen),
    )


def sample_latency(k: int, cfg: DomainRandCfg, gen: torch.Generator) -> torch.Tensor:
    """Action latency per env, uniform in 0..max_latency_steps policy steps. Shape: (k,), int64."""
    if not cfg.enabled or cfg.max_latency_steps <= 0:
        return torch.zeros(k, dtype=torch.long, device=gen.device)
    return torch.randint(0, cfg.max_latency_steps + 1, (k,), generator=gen, device=gen.device)


def sample_push(k: int, cfg: DomainRandCfg, gen: torch.Generator) -> torch.Tensor:
    """Planar push velocities, uniform in [-push_vel, push_vel] per axis (m/s). Shape: (k, 2)."""
    return _uniform((k, 2), -cfg.push_vel, cfg.push_vel, gen)


def sample_reset_joint_pos(
    default: torch.Tensor, joint_range: torch.Tensor, cfg: DomainRandCfg, gen: torch.Generator
) -> torch.Tensor:
    """Reset joint positions: q0 times U[init_joint_scale], clamped into each env's limits.

    Args:
        default: q0. Shape: (k, 12).
        joint_range: Limits. Shape: (k, 12, 2).
        cfg: Randomisation config (no scaling when both ``enabled`` and ``random_reset_pose`` are off).
        gen: Generator.

    Returns:
        Shape: (k, 12).
    """
    q = default.clone()
    if cfg.enabled or cfg.random_reset_pose:
        q = q * _uniform(tuple(default.shape), *cfg.init_joint_scale, gen).to(q)
    return torch.clamp(q, joint_range[..., 0], joint_range[..., 1])
