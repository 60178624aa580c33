"""Heavier bodies, gains and torque limits with mass, and the morphology curriculum (docs/training.md, issue 58).

Pure functions of a generator and :class:`~morfic_cli.config.ActuationRandCfg`; the env calls them at reset
(:meth:`~morfic_cli.envs.locomotion.LocomotionEnv._reset_envs`) and once per max episode length (the curriculum,
beside the command curriculum of :mod:`morfic_cli.envs.commands`). The evaluation mode ``actuation-matched``
(docs/eval.md) uses :func:`matched_actuation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from morfic_cli.config import ActuationRandCfg

MATCHED_TORQUE_EXPONENT = 1.0
"""Evaluation mode ``actuation-matched``: Kp, Kd and torque limits all x M / M_Go2, Go2's stiffness and torque per
kilogram (docs/falls.md's counterfactual that keeps AlienGo and ANYmal-C up); the same for every run."""

MASS_DIMS: list[int] = [0, 1, 2, 3, 4]
"""The descriptor's mass entries (thigh, calf, hip, foot, base)."""


@dataclass
class Actuation:
    """Each env's PD gains and torque limits.

    Attributes:
        kp: Kp (N m/rad). Shape: (k,).
        kd: Kd (N m s/rad). Shape: (k,).
        torque_limit: Per joint type, hip / thigh / calf (N m). Shape: (k, 3).
    """

    kp: torch.Tensor
    kd: torch.Tensor
    torque_limit: torch.Tensor


def _log_uniform(k: int, bounds: tuple[float, float] | torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Draw k factors exp(U[log lo, log hi]) in float64 on the generator's device. Shape: (k,)."""
    lo, hi = (float(bounds[0]), float(bounds[1])) if not isinstance(bounds, torch.Tensor) else bounds
    u = torch.rand(k, generator=gen, dtype=torch.float64, device=gen.device)
    log_lo = torch.log(torch.as_tensor(lo, dtype=torch.float64, device=gen.device))
    log_hi = torch.log(torch.as_tensor(hi, dtype=torch.float64, device=gen.device))
    return torch.exp(log_lo + (log_hi - log_lo) * u)


def scale_masses(
    descriptors: torch.Tensor, upper: torch.Tensor, cfg: ActuationRandCfg, gen: torch.Generator
) -> torch.Tensor:
    """The descriptors with their five masses x s_m, s_m log-uniform in [cfg.mass_scale[0], upper] per env.

    Args:
        descriptors: Raw descriptors. Shape: (k, 11), float64.
        upper: The current upper bound of s_m (the curriculum's). Shape: (), float64.
        cfg: The config.
        gen: Generator.

    Returns:
        New descriptors. Shape: (k, 11).
    """
    lo = torch.as_tensor(cfg.mass_scale[0], dtype=torch.float64, device=upper.device)
    s = _log_uniform(len(descriptors), torch.stack([lo, upper.double()]), gen)
    out = descriptors.clone()
    out[:, MASS_DIMS] = out[:, MASS_DIMS] * s[:, None]
    return out


def sample_actuation(
    total_mass: torch.Tensor, template: Actuation, template_mass: float, cfg: ActuationRandCfg, gen: torch.Generator
) -> Actuation:
    """Gains and torque limits of k envs of these total masses, by the mass rule with log-uniform jitter.

    Kp = Kp_t x (M / M_t)^g x f_kp, Kd = Kd_t x (M / M_t)^g x f_kd (g = 1 with ``gains_with_mass``, else 0),
    torque = torque_t x (M / M_t)^``torque_mass_exponent`` x f_tau.

    Args:
        total_mass: M per env (kg). Shape: (k,).
        template: The template's gains (one row: shapes (1,), (1,), (1, 3)).
        template_mass: M_t (kg).
        cfg: The config.
        gen: Generator (three draws per env: f_kp, f_kd, f_tau).
    """
    k = len(total_mass)
    ratio = total_mass.double() / template_mass
    gain = ratio if cfg.gains_with_mass else torch.ones_like(ratio)
    f_kp, f_kd = _log_uniform(k, cfg.kp_factor, gen), _log_uniform(k, cfg.kd_factor, gen)
    f_tau = _log_uniform(k, cfg.torque_factor, gen)
    torque = template.torque_limit.double() * (ratio**cfg.torque_mass_exponent * f_tau)[:, None]
    return Actuation(template.kp.double() * gain * f_kp, template.kd.double() * gain * f_kd, torque)


def matched_actuation(total_mass: torch.Tensor, template: Actuation, template_mass: float) -> Actuation:
    """Evaluation mode ``actuation-matched``: Kp, Kd and torque limits x M / M_t (:data:`MATCHED_TORQUE_EXPONENT`).

    Shapes: (k,) -> an :class:`Actuation` of k rows.
    """
    ratio = total_mass.double() / template_mass
    return Actuation(
        template.kp.double() * ratio,
        template.kd.double() * ratio,
        template.torque_limit.double() * (ratio**MATCHED_TORQUE_EXPONENT)[:, None],
    )


def initial_upper(cfg: ActuationRandCfg) -> float:
    """The upper bound of s_m at the start.

    ``curriculum_init`` (never past ``mass_scale[1]``) with the curriculum, else ``mass_scale[1]`` (the fixed wide
    support).
    """
    return min(cfg.curriculum_init, cfg.mass_scale[1]) if cfg.curriculum else cfg.mass_scale[1]


def widen_mass_scale(upper: torch.Tensor, mean_tracking: torch.Tensor | float, cfg: ActuationRandCfg) -> torch.Tensor:
    """Curriculum: x ``curriculum_step`` the upper bound when tracking reaches the threshold (on the device).

    The command curriculum's pattern (:func:`morfic_cli.envs.commands.widen_vx`): ``upper`` is updated in place and
    never passes ``mass_scale[1]``.

    Args:
        upper: The current upper bound of s_m. Shape: (), float64.
        mean_tracking: The finished episodes' r_lin over the max episode length / its maximum, in [0, 1].
        cfg: The config.

    Returns:
        Whether it changed, a 0-d bool tensor.
    """
    wider = (upper * cfg.curriculum_step).clamp(max=cfg.mass_scale[1])
    new = torch.where(torch.as_tensor(mean_tracking, device=upper.device) >= cfg.curriculum_threshold, wider, upper)
    changed = new != upper
    upper.copy_(new)
    return changed


def log_mass_width(upper: torch.Tensor | float, cfg: ActuationRandCfg) -> float:
    """The support's width in log mass, log(upper / mass_scale[0]) (what grows by log ``curriculum_step``)."""
    return math.log(float(upper) / cfg.mass_scale[0])
