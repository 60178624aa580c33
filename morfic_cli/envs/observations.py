"""Observation groups (docs/concepts.md; paper Table "Observation streams").

- ``policy``: o_t (48) = [v (3), omega (3), g_proj (3), c (3), q - q0 (12), qdot (12), a_{t-1} (12)],
  scaled, with sensor noise during training.
- ``history``: [h_t, o_t] with h_t = {o_{t-k}}, k = 1..15 (paper Table "Observation streams"): the 15 previous
  observations then the current one, oldest first, noisy. Shape (N, 16, 48) = (N, :func:`history_frames`, 48).
  With ``ObsCfg.history_includes_current`` (runs before that field) it is o_{t-14..t}, (N, 15, 48).
- ``critic``: the same history with clean values (the critic sees clean observations).
- ``privileged``: p_t (18) = [ground friction, restitution, base mass, COM offset (3), joint friction (12)].
- ``morphology``: the 11-D descriptor normalised to [-1, 1] over the training support.
  With ``ObsCfg.extended_morphology`` it is the extended descriptor (N, 28; :mod:`morfic_cli.morphology.extended`),
  log-scaled and bounded in (-3, 3) (:func:`extended_morphology_obs`).

With ``ObsCfg.body_tokens`` (variant ``urma``; URMA's tokens, docs/training.md, "External baselines"), also:

- ``joint_description`` (N, 12, 18): each joint's description read from the env's model
  (:mod:`morfic_cli.morphology.description`), normalised by :func:`joint_description_obs`; constant per model;
- ``foot_description`` (N, 4, 6): each foot's, the same way (:func:`foot_description_obs`);
- ``foot_state`` (N, 4, 2): [contact c_i (0 or 1), time since the foot's last touchdown (s)], clean.
"""

from __future__ import annotations

from functools import lru_cache

import torch

from morfic_cli.config import ObsCfg
from morfic_cli.envs.state import EnvState
from morfic_cli.morphology import extended as E

POLICY_DIM = 48
PRIVILEGED_DIM = 18

#: Layout of o_t: (name, start, stop).
POLICY_LAYOUT: tuple[tuple[str, int, int], ...] = (
    ("base_lin_vel", 0, 3),
    ("base_ang_vel", 3, 6),
    ("projected_gravity", 6, 9),
    ("command", 9, 12),
    ("joint_pos", 12, 24),
    ("joint_vel", 24, 36),
    ("last_action", 36, 48),
)


JOINT_DESCRIPTION_NORM: tuple[tuple[float, float], ...] = (
    (0.0, 0.5),
    (0.0, 0.5),
    (0.0, 0.5),  # anchor (m)
    (0.0, 1.0),
    (0.0, 1.0),
    (0.0, 1.0),  # axis
    (1.0, 1.0),  # direct child joints: 1 -> 0, 0 -> -1 (URMA's "children - 1")
    (0.0, 4.6),
    (0.0, 4.6),
    (0.0, 4.6),  # q0, q_min, q_max (rad; URMA's / 4.6)
    (75.0, 75.0),  # torque limit (N m): 0..150
    (25.0, 25.0),  # velocity limit (rad/s): 0..50
    (0.0, 1.0),  # damping (N m s/rad)
    (0.0, 0.02),  # armature (kg m^2)
    (150.0, 150.0),  # Kp (N m/rad): 0..300
    (5.0, 5.0),  # Kd (N m s/rad): 0..10
    (0.6, 0.6),  # child link mass (kg): 0..1.2
    (30.0, 30.0),  # total mass (kg): 0..60
)
"""(centre, half-width) of each raw joint-description entry (:data:`~morfic_cli.morphology.description.JOINT_FIELDS`):
the observation is (raw - centre) / half-width, about [-1, 1] over the seven robots (URMA's ranges are set for its
sixteen robots, humanoids included; these for ours)."""
FOOT_DESCRIPTION_NORM: tuple[tuple[float, float], ...] = (
    (0.0, 0.5),
    (0.0, 0.5),
    (0.0, 0.5),  # foot position (m)
    (0.025, 0.025),  # foot radius (m): 0..0.05
    (0.1, 0.1),  # foot mass (kg): 0..0.2
    (30.0, 30.0),  # total mass (kg)
)
"""(centre, half-width) of each raw foot-description entry (:data:`~morfic_cli.morphology.description.FOOT_FIELDS`)."""
JOINT_DESCRIPTION_DIM = len(JOINT_DESCRIPTION_NORM)
FOOT_DESCRIPTION_DIM = len(FOOT_DESCRIPTION_NORM)
FOOT_STATE_DIM = 2
BODY_TOKEN_GROUPS: tuple[str, ...] = ("joint_description", "foot_description", "foot_state")
"""The groups ``ObsCfg.body_tokens`` adds."""


def _normalise(raw: torch.Tensor, norm: tuple[tuple[float, float], ...]) -> torch.Tensor:
    centre = torch.tensor([c for c, _ in norm], dtype=raw.dtype, device=raw.device)
    half = torch.tensor([h for _, h in norm], dtype=raw.dtype, device=raw.device)
    return (raw - centre) / half


def joint_description_obs(raw: torch.Tensor) -> torch.Tensor:
    """The normalised joint description (:data:`JOINT_DESCRIPTION_NORM`). Shape: (N, 12, 18) -> (N, 12, 18)."""
    return _normalise(raw, JOINT_DESCRIPTION_NORM)


def foot_description_obs(raw: torch.Tensor) -> torch.Tensor:
    """The normalised foot description (:data:`FOOT_DESCRIPTION_NORM`). Shape: (N, 4, 6) -> (N, 4, 6)."""
    return _normalise(raw, FOOT_DESCRIPTION_NORM)


def touchdown_time(time: torch.Tensor, contact: torch.Tensor, contact_prev: torch.Tensor, dt: float) -> torch.Tensor:
    """Time since each foot's last touchdown: 0 at a touchdown (contact now, none before), else ``time + dt``.

    Shapes: (N, 4) float, (N, 4) bool, (N, 4) bool -> (N, 4).
    """
    return torch.where(contact & ~contact_prev, torch.zeros_like(time), time + dt)


def history_frames(cfg: ObsCfg) -> int:
    """Observations in the ``history`` / ``critic`` groups: |h_t| + 1 for o_t (16).

    |h_t| (15) when ``history_includes_current`` counts o_t as one of h_t's entries.
    """
    return cfg.history_len + (0 if cfg.history_includes_current else 1)


def obs_scales(cfg: ObsCfg) -> torch.Tensor:
    """Per-element scale of o_t. Shape: (48,)."""
    s = torch.ones(POLICY_DIM)
    s[0:3] = cfg.lin_vel_scale
    s[3:6] = cfg.ang_vel_scale
    s[9:12] = torch.tensor(cfg.command_scale)
    s[12:24] = cfg.joint_pos_scale
    s[24:36] = cfg.joint_vel_scale
    return s


def noise_scales(cfg: ObsCfg) -> torch.Tensor:
    """Uniform-noise half-width of each (scaled) element of o_t; zero for command and last action. Shape: (48,)."""
    n = torch.zeros(POLICY_DIM)
    n[0:3] = cfg.noise_lin_vel * cfg.lin_vel_scale
    n[3:6] = cfg.noise_ang_vel * cfg.ang_vel_scale
    n[6:9] = cfg.noise_gravity
    n[12:24] = cfg.noise_joint_pos * cfg.joint_pos_scale
    n[24:36] = cfg.noise_joint_vel * cfg.joint_vel_scale
    return n


def policy_obs(state: EnvState, cfg: ObsCfg) -> torch.Tensor:
    """Clean, scaled o_t.

    Args:
        state: The env state; ``action`` is the action just applied, a_{t-1} for the next decision.
        cfg: Observation config.

    Returns:
        o_t. Shape: (N, 48).
    """
    raw = torch.cat(
        [
            state.base_lin_vel_b,
            state.base_ang_vel_b,
            state.projected_gravity_b,
            state.command,
            state.joint_pos - state.default_joint_pos,
            state.joint_vel,
            state.action,
        ],
        dim=1,
    )
    return torch.clamp(raw * _on(obs_scales, cfg, raw), -cfg.clip, cfg.clip)


def add_noise(obs: torch.Tensor, cfg: ObsCfg, gen: torch.Generator) -> torch.Tensor:
    """o_t with uniform sensor noise U[-n, n] per element. Shape: (N, 48)."""
    if not cfg.noise:
        return obs
    u = torch.rand(obs.shape, generator=gen, device=gen.device).to(obs) * 2.0 - 1.0
    return obs + u * _on(noise_scales, cfg, obs)


def _on(make, cfg: ObsCfg, like: torch.Tensor) -> torch.Tensor:
    """``make(cfg)`` (a per-element scale of o_t) with ``like``'s dtype and device, made once per config and device.

    Shape: (48,).
    """
    return _cached(make, cfg, like.dtype, like.device)


@lru_cache(maxsize=64)
def _cached(make, cfg: ObsCfg, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    return make(cfg).to(dtype=dtype, device=device)


def privileged_obs(
    friction: torch.Tensor,
    restitution: torch.Tensor,
    base_mass: torch.Tensor,
    com_offset: torch.Tensor,
    joint_friction: torch.Tensor,
) -> torch.Tensor:
    """p_t = [mu_fric, e, m_base, Delta c, mu_joint] (paper Table "Observation streams").

    Scaled to order one: base mass in units of 10 kg, COM offset in units of 0.1 m.

    Args:
        friction: Ground friction. Shape: (N,).
        restitution: Contact restitution. Shape: (N,).
        base_mass: Base mass (kg). Shape: (N,).
        com_offset: Base COM offset (m). Shape: (N, 3).
        joint_friction: Joint dry friction (N m). Shape: (N, 12).

    Returns:
        p_t. Shape: (N, 18).
    """
    return torch.cat(
        [friction[:, None], restitution[:, None], base_mass[:, None] / 10.0, com_offset * 10.0, joint_friction],
        dim=1,
    )


def morphology_obs(descriptor: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """The normalised descriptor, 2 (m - lo) / (hi - lo) - 1: [-1, 1] inside the training support.

    Args:
        descriptor: Raw descriptors m. Shape: (N, 11).
        lo: Train min. Shape: (11,).
        hi: Train max. Shape: (11,).

    Returns:
        Shape: (N, 11).
    """
    return 2.0 * (descriptor - lo) / (hi - lo) - 1.0


def extended_morphology_obs(raw: torch.Tensor) -> torch.Tensor:
    """The bounded encoding of extended descriptors (docs/robots.md, "Extended descriptor").

    t = log(x + eps) on the log-scaled entries (x on the joint limits), z = 2 (t - lo) / (hi - lo) - 1 over the fixed
    support, then 3 tanh(z / 3): z within 3.6 % inside the support, never beyond +-3 outside it. The numpy
    :func:`morfic_cli.morphology.extended.encode` is the same function.

    Args:
        raw: Extended descriptors (:data:`~morfic_cli.morphology.extended.EXTENDED_NAMES`, raw units). Shape: (N, 28).

    Returns:
        Shape: (N, 28), float32.
    """
    lo, hi = (torch.as_tensor(v, dtype=torch.float64, device=raw.device) for v in E.extended_support())
    mask = torch.as_tensor(E.LOG_SCALED, device=raw.device)
    eps = torch.as_tensor(E.log_eps(), dtype=torch.float64, device=raw.device)
    x = raw.double()
    t = torch.where(mask, torch.log(torch.where(mask, x, torch.ones_like(x)) + eps), x)
    z = 2.0 * (t - lo) / (hi - lo) - 1.0
    return (E.BOUND * torch.tanh(z / E.BOUND)).float()


def push_history(history: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
    """Append o_t as the newest entry, dropping the oldest. Shapes: (N, H, 48), (N, 48) -> (N, H, 48)."""
    return torch.cat([history[:, 1:], obs[:, None]], dim=1)
