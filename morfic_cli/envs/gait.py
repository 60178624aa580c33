"""The gait clock: a periodic phase per env, per-foot phases, and the desired contact schedule.

A trot by default (diagonal pairs FL+RR and FR+RL in phase, half a period apart). Conventions
follow walk-these-ways (Margolis & Agrawal 2023, ``_step_contact_targets``), which the paper's gait
terms r_gaitF / r_gaitV are adapted from:

- The env-level phase ``phase`` lives in [0, 1) and advances by ``frequency * dt`` per step.
- Foot i's phase is ``(phase + offset_i) mod 1``. A foot is in **stance for phase < duty** and in
  swing for the rest of the period (stance first, as ``EnvState.gait_phase`` documents).
- The desired contact d_i in [0, 1] is a smooth indicator of stance (1 = stance) built from normal
  CDFs of width ``kappa`` (walk-these-ways calls it "von Mises"; its code uses a normal CDF, and so
  do we) on the duty-normalised phase, so d_i is a smooth 0 -> 1 -> 0 pulse without jumps.

All functions are pure and batched; shapes use N = num_envs, legs FL, FR, RL, RR.
"""

from __future__ import annotations

import math

import torch

from morfic_cli.config import GaitCfg


def advance_phase(phase: torch.Tensor, freq: torch.Tensor, dt: float) -> torch.Tensor:
    """Advance the gait clock by one step: (phase + f dt) mod 1.

    Args:
        phase: Current env phase in [0, 1). Shape: (N,).
        freq: Gait frequency f (Hz). Shape: (N,).
        dt: Step length (s).

    Returns:
        The new phase in [0, 1). Shape: (N,).
    """
    return torch.remainder(phase + freq * dt, 1.0)


def foot_phases(phase: torch.Tensor, cfg: GaitCfg) -> torch.Tensor:
    """Per-foot phases (phase + offset_i) mod 1.

    Args:
        phase: Env phase in [0, 1). Shape: (N,).
        cfg: The gait (its ``offsets``).

    Returns:
        Foot phases in [0, 1), FL, FR, RL, RR; stance while below ``cfg.duty``. Shape: (N, 4).
    """
    offsets = torch.tensor(cfg.offsets, dtype=phase.dtype, device=phase.device)
    return torch.remainder(phase.unsqueeze(-1) + offsets, 1.0)


def normalized_phase(foot_phase: torch.Tensor, duty: float) -> torch.Tensor:
    """Map a foot phase so that stance fills [0, 0.5) and swing [0.5, 1) whatever the duty.

    Stance phi in [0, duty) -> phi * 0.5 / duty; swing phi in [duty, 1) -> 0.5 + (phi - duty) * 0.5 / (1 - duty)
    (walk-these-ways' duration remapping).

    Args:
        foot_phase: Foot phases in [0, 1). Shape: (N, 4).
        duty: Duty factor in (0, 1).

    Returns:
        Normalised phases in [0, 1). Shape: (N, 4).
    """
    phi = torch.remainder(foot_phase, 1.0)
    stance = phi * (0.5 / duty)
    swing = 0.5 + (phi - duty) * (0.5 / (1.0 - duty))
    return torch.where(phi < duty, stance, swing)


def _normal_cdf(x: torch.Tensor, kappa: float) -> torch.Tensor:
    """Phi(x / kappa), the CDF of N(0, kappa^2)."""
    return 0.5 * (1.0 + torch.erf(x / (kappa * math.sqrt(2.0))))


def desired_contact(foot_phases: torch.Tensor, cfg: GaitCfg) -> torch.Tensor:
    """Smooth desired contact state d_i (1 = stance, 0 = swing), walk-these-ways style.

    With phi the duty-normalised phase (:func:`normalized_phase`) and Phi the N(0, kappa^2) CDF:
    d = Phi(phi) (1 - Phi(phi - 0.5)) + Phi(phi - 1) (1 - Phi(phi - 1.5)).
    The first product is the current stance [0, 0.5); the second the next stance starting at 1, so
    d is continuous across the wrap (d = 0.5 at touchdown and lift-off).

    Args:
        foot_phases: Foot phases in [0, 1). Shape: (N, 4).
        cfg: The gait (``duty``, ``kappa``).

    Returns:
        d_i in [0, 1]. Shape: (N, 4).
    """
    phi = normalized_phase(foot_phases, cfg.duty)
    k = cfg.kappa
    return _normal_cdf(phi, k) * (1.0 - _normal_cdf(phi - 0.5, k)) + _normal_cdf(phi - 1.0, k) * (
        1.0 - _normal_cdf(phi - 1.5, k)
    )


def raibert_phase(foot_phase: torch.Tensor, duty: float) -> torch.Tensor:
    """Signed position of the foot along its stride, s in [-0.5, 0.5].

    s = +0.5 at touchdown, falls linearly to -0.5 at lift-off (the foot moves backwards under the
    body during stance), and rises back to +0.5 during swing. For duty 0.5 this is walk-these-ways'
    ``|1 - 2 phi| - 0.5``.

    Args:
        foot_phase: Foot phases in [0, 1), stance below ``duty``. Shape: (N, 4).
        duty: Duty factor in (0, 1).

    Returns:
        s. Shape: (N, 4).
    """
    return torch.abs(1.0 - 2.0 * normalized_phase(foot_phase, duty)) - 0.5


def raibert_foot_targets(
    foot_phase: torch.Tensor,
    command: torch.Tensor,
    frequency: torch.Tensor,
    nominal_xy: torch.Tensor,
    duty: float,
) -> torch.Tensor:
    """Raibert-heuristic desired foot xy in the base yaw frame (walk-these-ways ``raibert_heuristic``).

    x_des_i = p_nom_i + s_i * v_foot_i * T_st, with T_st = duty / f the stance time, s_i the
    :func:`raibert_phase`, and v_foot_i = (vx - omega_z * p_nom_y, vy + omega_z * p_nom_x) the
    commanded ground velocity under foot i (body velocity plus yaw rotation about the base).
    walk-these-ways is the special case vy = 0 with only the omega_z * p_nom_x part of the yaw term.
    The stride is therefore v_foot * T_st long, centred on the nominal foothold.

    Args:
        foot_phase: Foot phases in [0, 1). Shape: (N, 4).
        command: (vx, vy, yaw rate), base yaw frame. Shape: (N, 3).
        frequency: Gait frequency f (Hz), clamped below at 1e-3 Hz. Shape: (N,).
        nominal_xy: Nominal foot xy under each hip, base yaw frame (m). Shape: (N, 4, 2).
        duty: Duty factor in (0, 1).

    Returns:
        Desired foot xy, base yaw frame (m). Shape: (N, 4, 2).
    """
    s = raibert_phase(foot_phase, duty)  # (N, 4)
    t_stance = duty / frequency.clamp_min(1e-3)  # (N,)
    vx, vy, wz = command[:, 0:1], command[:, 1:2], command[:, 2:3]  # (N, 1) each
    v_foot_x = vx - wz * nominal_xy[..., 1]  # (N, 4)
    v_foot_y = vy + wz * nominal_xy[..., 0]
    v_foot = torch.stack([v_foot_x, v_foot_y], dim=-1)  # (N, 4, 2)
    return nominal_xy + (s * t_stance.unsqueeze(-1)).unsqueeze(-1) * v_foot
