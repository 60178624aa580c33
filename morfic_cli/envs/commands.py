"""Velocity commands c = (vx, vy, yaw rate) and the curriculum that widens the vx range."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from morfic_cli.config import CommandCfg


@dataclass
class CommandRanges:
    """Current command ranges (mutable: the curriculum widens ``vx``).

    Attributes:
        vx: Forward-velocity range (m/s): a pair of floats, or in the env a float64 tensor of shape (2,) on its
            device (the curriculum widens it there, with no host read).
        vy: Lateral-velocity range (m/s).
        yaw_rate: Yaw-rate range (rad/s).
    """

    vx: tuple[float, float] | torch.Tensor
    vy: tuple[float, float]
    yaw_rate: tuple[float, float]

    @classmethod
    def initial(cls, cfg: CommandCfg) -> CommandRanges:
        """The ranges at the start of training."""
        return cls(tuple(cfg.vx_init), tuple(cfg.vy), tuple(cfg.yaw_rate))  # type: ignore[arg-type]


def sample_commands(n: int, ranges: CommandRanges, cfg: CommandCfg, gen: torch.Generator) -> torch.Tensor:
    """Sample commands uniformly from the current ranges.

    A fraction ``cfg.zero_fraction`` of envs get a zero command, and planar commands smaller than
    ``cfg.small_command`` are zeroed, so standing still is part of the task. With ``cfg.fixed`` set, every
    command is that fixed one (evaluation).

    Args:
        n: Number of commands.
        ranges: Current ranges.
        cfg: Command config.
        gen: Random generator (CPU).

    Returns:
        Commands (vx, vy, yaw rate). Shape: (n, 3).
    """
    dev = gen.device
    if cfg.fixed is not None:
        return torch.tensor(cfg.fixed, dtype=torch.float32, device=dev).expand(n, 3).clone()
    u = torch.rand((n, 3), generator=gen, device=dev)
    vx = torch.as_tensor(ranges.vx, dtype=torch.float64, device=dev)
    rest = torch.tensor(
        [[ranges.vy[0], ranges.yaw_rate[0]], [ranges.vy[1], ranges.yaw_rate[1]]], dtype=torch.float64, device=dev
    )
    lo_hi = torch.cat([vx[:, None], rest], dim=1).float()  # float64 -> float32: the rounding of torch.tensor(floats)
    lo, hi = lo_hi[0], lo_hi[1]
    cmd = lo + (hi - lo) * u
    small = torch.linalg.norm(cmd[:, :2], dim=1) < cfg.small_command
    cmd[:, :2] = cmd[:, :2].masked_fill(small[:, None], 0.0)
    zero = torch.rand(n, generator=gen, device=dev) < cfg.zero_fraction
    return cmd.masked_fill(zero[:, None], 0.0)


def widen_vx(ranges: CommandRanges, mean_tracking: float | torch.Tensor, cfg: CommandCfg) -> bool | torch.Tensor:
    """Curriculum: widen the vx range when tracking is good enough.

    Args:
        ranges: Current ranges (updated in place).
        mean_tracking: Mean per-step r_lin over finished episodes divided by its maximum (4), in [0, 1]: a float,
            or a 0-d tensor when ``ranges.vx`` is a tensor (the env's; decided on its device, no host read).
        cfg: Command config.

    Returns:
        True when the range changed (a 0-d bool tensor for tensor ranges).
    """
    if isinstance(ranges.vx, torch.Tensor):
        vx = ranges.vx
        wider = torch.stack(
            [
                (vx[0] - cfg.curriculum_step).clamp(min=cfg.vx_limit[0]),
                (vx[1] + cfg.curriculum_step).clamp(max=cfg.vx_limit[1]),
            ]
        )
        new = torch.where(torch.as_tensor(mean_tracking, device=vx.device) >= cfg.curriculum_threshold, wider, vx)
        widened = (new != vx).any()
        vx.copy_(new)
        return widened
    if mean_tracking < cfg.curriculum_threshold:
        return False
    lo = max(cfg.vx_limit[0], ranges.vx[0] - cfg.curriculum_step)
    hi = min(cfg.vx_limit[1], ranges.vx[1] + cfg.curriculum_step)
    changed = (lo, hi) != ranges.vx
    ranges.vx = (lo, hi)
    return changed
