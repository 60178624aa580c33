"""Reward terms of the paper's Table "Reward terms" and their weighted sum, eq. (rews).

Every term is a pure function ``(state, cfg) -> Tensor`` of shape (N,) returning the **unweighted**
value exactly as the table defines it (``r_lin`` keeps its factor 4, ``r_gaitF`` its minus sign).
:data:`TERMS` holds one :class:`RewardTerm` object per term (function, group, weight and parameter fields)::

    r_t = sum_{i in T} w_i r_i  -  sum_{j in P} w_j p_j  +  sum_{k in S} w_k s_k

``task`` (T) and ``stability`` (S) terms are added, ``penalty`` (P) terms are subtracted; every
weight is a non-negative number in :class:`~morfic_cli.config.RewardCfg`, in the field the term names.
:func:`compute_rewards` returns eq. (rews) exactly; the env multiplies the total (and the logged
contributions) by the policy step dt, as legged_gym and mjlab do, so the weights read as rates
per second and compare with theirs.

Frames: velocities in the base frame as the backend reports them (legged_gym convention); foot
geometry in the base *yaw* frame (world frame rotated by the base heading only). Legs FL, FR, RL, RR.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from morfic_cli.config import RewardCfg
from morfic_cli.envs.gait import raibert_foot_targets
from morfic_cli.envs.math import quat_rotate, yaw_from_quat
from morfic_cli.envs.state import EnvState

GRAVITY = 9.81
"""Standard gravity (m/s^2), for the body-weight force threshold of p_f."""

LEFT_RIGHT_PAIRS = ((0, 1), (2, 3))
"""(left, right) foot indices of the front (FL, FR) and rear (RL, RR) pairs, for the stance width."""


# --------------------------------------------------------------------------------------------------
# helpers


def _yaw_frame_xy(state: EnvState, vec_w: torch.Tensor) -> torch.Tensor:
    """Rotate world-frame xy vectors by minus the base heading (into the base yaw frame).

    Args:
        state: For ``base_quat_w``.
        vec_w: World vectors; only xy is used. Shape: (N, ..., >=2).

    Returns:
        The xy components in the base yaw frame. Shape: (N, ..., 2).
    """
    yaw = yaw_from_quat(state.base_quat_w)  # (N,)
    shape = (-1,) + (1,) * (vec_w.dim() - 2)
    c, s = torch.cos(yaw).view(shape), torch.sin(yaw).view(shape)
    x, y = vec_w[..., 0], vec_w[..., 1]
    return torch.stack([c * x + s * y, -s * x + c * y], dim=-1)


def foot_pos_yaw(state: EnvState) -> torch.Tensor:
    """Foot xy relative to the base, in the base yaw frame (m). Shape: (N, 4, 2)."""
    return _yaw_frame_xy(state, state.foot_pos_w - state.base_pos_w.unsqueeze(1))


def stance_width(foot_xy: torch.Tensor) -> torch.Tensor:
    """Stance width w: the narrower of the front (FL - FR) and rear (RL - RR) lateral spacings.

    Args:
        foot_xy: Foot xy in a yaw frame (x forward, y left). Shape: (N, 4, 2).

    Returns:
        w (m); negative when the legs cross. Shape: (N,).
    """
    widths = [foot_xy[:, left, 1] - foot_xy[:, right, 1] for left, right in LEFT_RIGHT_PAIRS]
    return torch.minimum(widths[0], widths[1])


# --------------------------------------------------------------------------------------------------
# task / tracking


def r_lin(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Linear-velocity tracking: 4 exp(-||v_cmd_xy - v_xy||^2 / sigma_lin). Range (0, 4]. Shape: (N,).

    v_xy is the base-frame planar velocity (legged_gym's ``tracking_lin_vel``).
    """
    err2 = (state.command[:, :2] - state.base_lin_vel_b[:, :2]).square().sum(dim=1)
    return 4.0 * torch.exp(-err2 / cfg.sigma_lin)


def r_yaw(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Yaw-rate tracking: exp(-(omega_cmd_z - omega_z)^2 / sigma_yaw). Range (0, 1]. Shape: (N,)."""
    err2 = (state.command[:, 2] - state.base_ang_vel_b[:, 2]).square()
    return torch.exp(-err2 / cfg.sigma_yaw)


def r_gaitF(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Swing-force shaping: -1/4 sum_i (1 - d_i)(1 - exp(-f_i^2 / sigma_F)). Range [-1, 0]. Shape: (N,).

    f_i = ||foot_force_w_i||, d_i the desired contact (walk-these-ways
    ``tracking_contacts_shaped_force``).
    """
    f2 = state.foot_force_w.square().sum(dim=-1)  # (N, 4)
    return -0.25 * ((1.0 - state.desired_contact) * (1.0 - torch.exp(-f2 / cfg.sigma_F))).sum(dim=1)


def r_gaitV(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Stance-velocity shaping: -1/4 sum_i d_i (1 - exp(-||xdot_i||^2 / sigma_V)). Range [-1, 0]. Shape: (N,).

    ||xdot_i|| is the full 3-D foot speed (walk-these-ways ``tracking_contacts_shaped_vel``).
    """
    v2 = state.foot_vel_w.square().sum(dim=-1)  # (N, 4)
    return -0.25 * (state.desired_contact * (1.0 - torch.exp(-v2 / cfg.sigma_V))).sum(dim=1)


def r_jump(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Base-height tracking: -(z - (h_cmd + h0))^2. Range (-inf, 0]. Shape: (N,).

    z is the base height above the ground (``base_pos_w`` z; the terrain is flat at z = 0), the
    same reference as h0 = ``nominal_height`` (base above the foot soles at the default pose) and
    as the ``base_too_low`` termination (walk-these-ways ``_reward_jump``, reference height 0).
    """
    target = cfg.h_cmd + state.nominal_height
    return -(state.base_pos_w[:, 2] - target).square()


# --------------------------------------------------------------------------------------------------
# penalties


def p_vz(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Vertical base velocity: v_z^2 (base frame). Shape: (N,)."""
    return state.base_lin_vel_b[:, 2].square()


def p_omega_xy(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Roll and pitch rate: ||omega_xy||^2 (base frame). Shape: (N,)."""
    return state.base_ang_vel_b[:, :2].square().sum(dim=1)


def p_ori(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Base tilt: ||g_xy||^2, g the projected gravity (0 upright, sin^2(tilt) tilted). Shape: (N,)."""
    return state.projected_gravity_b[:, :2].square().sum(dim=1)


def p_tau(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Joint torques: ||tau||^2. Shape: (N,)."""
    return state.joint_torque.square().sum(dim=1)


def p_qddot(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Joint accelerations: ||(qdot_{t-1} - qdot_t) / dt||^2, dt the policy step. Shape: (N,)."""
    return ((state.joint_vel_prev - state.joint_vel) / state.dt).square().sum(dim=1)


def p_da(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Action rate: ||a_{t-1} - a_t||^2. Shape: (N,)."""
    return (state.action_prev - state.action).square().sum(dim=1)


def p_coll(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Body collisions, eq. (collision_count): sum_b 1(||f_b|| > 0.1 N) over CONTACT_BODIES. Shape: (N,).

    The bodies are :data:`morfic_cli.sim.backend.CONTACT_BODIES` (base, 4 thighs, 4 calves); the
    threshold is ``cfg.collision_force``.
    """
    return (state.body_contact_force > cfg.collision_force).sum(dim=1).to(state.body_contact_force.dtype)


def p_jl(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Joint-limit excess, eq. (joint_limit_penalty): sum_i max(0, q_i - q_max_i) + max(0, q_min_i - q_i).

    Uses the per-env limits after morphology (``joint_pos_min`` / ``joint_pos_max``), in rad. Shape: (N,).
    """
    q = state.joint_pos
    above = (q - state.joint_pos_max).clamp_min(0.0)
    below = (state.joint_pos_min - q).clamp_min(0.0)
    return (above + below).sum(dim=1)


def p_slip(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Foot slip: sum_i 1(c_i) ||xdot_i,xy||^2 (world-frame planar foot speed). Shape: (N,)."""
    v2 = state.foot_vel_w[..., :2].square().sum(dim=-1)  # (N, 4)
    return (state.foot_contact.to(v2.dtype) * v2).sum(dim=1)


def p_impact(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Touchdown speed: sum_i 1(c_i) clip(zdot_i,t-1, -100, 0)^2. Shape: (N,).

    Uses the foot z-velocity of the *previous* step, so a foot that has just touched down is
    charged for the speed it hit the ground with; upward motion costs nothing.
    """
    vz_prev = state.foot_vel_w_prev[..., 2].clamp(-cfg.impact_clip, 0.0)  # (N, 4)
    return (state.foot_contact.to(vz_prev.dtype) * vz_prev.square()).sum(dim=1)


def p_f(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Excess foot force: sum_i max(0, ||f_i|| - f_max), f_max = f_max_factor * m g (N). Shape: (N,)."""
    f = torch.linalg.vector_norm(state.foot_force_w, dim=-1)  # (N, 4)
    f_max = (cfg.f_max_factor * GRAVITY * state.total_mass).unsqueeze(1)  # (N, 1)
    return (f - f_max).clamp_min(0.0).sum(dim=1)


def p_q(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Deviation from the default pose: ||q - q0||^2. Shape: (N,)."""
    return (state.joint_pos - state.default_joint_pos).square().sum(dim=1)


def p_qdot(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Joint speeds: ||qdot||^2. Shape: (N,)."""
    return state.joint_vel.square().sum(dim=1)


def r_raibert(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Raibert-heuristic foothold error: sum_i ||x_des_i - x_i||^2 in the base yaw frame. Shape: (N,).

    Non-negative, as the paper's table writes it, so it is a **penalty** in :data:`TERMS`
    (walk-these-ways weights it -10). x_i is the foot xy relative to the base in the yaw frame;
    x_des_i from :func:`morfic_cli.envs.gait.raibert_foot_targets` (nominal foothold plus the
    stride offset from the foot's phase and the command), plus ``raibert_kv (v - v_cmd)`` with v
    the base planar velocity in the yaw frame.
    """
    x_des = raibert_foot_targets(
        state.gait_phase, state.command, state.gait_frequency, state.nominal_foot_pos_b, cfg.gait_duty
    )  # (N, 4, 2)
    if cfg.raibert_kv != 0.0:
        v_yaw = _yaw_frame_xy(state, quat_rotate(state.base_quat_w, state.base_lin_vel_b))  # (N, 2)
        x_des = x_des + cfg.raibert_kv * (v_yaw - state.command[:, :2]).unsqueeze(1)
    return (x_des - foot_pos_yaw(state)).square().sum(dim=(1, 2))


# --------------------------------------------------------------------------------------------------
# stability shaping


def r_upright(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Upright stability, eq. (upright_stability): exp(-||g_xy||^2 / sin^2(theta0)). Range (0, 1]. Shape: (N,)."""
    g2 = state.projected_gravity_b[:, :2].square().sum(dim=1)
    return torch.exp(-g2 / math.sin(cfg.theta0) ** 2)


def r_cop(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """CoP stability, eq. (cop_stability): 1(n_c >= 2) exp(-||CoP - center|| / tau). Range [0, 1]. Shape: (N,).

    Over the feet in contact (``foot_contact``, n_c of them), in the horizontal plane:

    - CoP = sum_i w_i p_i / sum_i w_i with w_i = max(f_z,i, 0) + 1e-6, the normal (vertical)
      ground force on foot i — the centre of pressure on flat ground. The 1e-6 makes a contact set
      that carries no normal force fall back to the plain mean.
    - center = the unweighted mean of the contact feet's xy, the centroid of the support
      polygon's vertices (the midpoint for two feet, the triangle centroid for three).

    The distance does not depend on the frame's heading, so world xy is used.
    """
    c = state.foot_contact.to(state.foot_pos_w.dtype)  # (N, 4)
    p = state.foot_pos_w[..., :2]  # (N, 4, 2)
    n_c = c.sum(dim=1)  # (N,)
    w = c * (state.foot_force_w[..., 2].clamp_min(0.0) + 1e-6)  # (N, 4)
    cop = (w.unsqueeze(-1) * p).sum(dim=1) / w.sum(dim=1, keepdim=True).clamp_min(1e-12)
    center = (c.unsqueeze(-1) * p).sum(dim=1) / n_c.unsqueeze(-1).clamp_min(1.0)
    dist = torch.linalg.vector_norm(cop - center, dim=-1)
    return (n_c >= 2).to(dist.dtype) * torch.exp(-dist / cfg.tau_cop)


def width_gate(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Eq. (width_gate): 1(||g_xy||^2 > eta or ||v_xy|| > v_th), v_xy the base-frame planar velocity.

    Returns:
        The gate as 0. / 1. Shape: (N,).
    """
    g2 = state.projected_gravity_b[:, :2].square().sum(dim=1)
    speed = torch.linalg.vector_norm(state.base_lin_vel_b[:, :2], dim=1)
    return ((g2 > cfg.eta) | (speed > cfg.v_th)).to(g2.dtype)


def r_width(state: EnvState, cfg: RewardCfg) -> torch.Tensor:
    """Stance-width stability, eq. (stance_width): gate exp(-max(0, w_min - w) / sigma_w) + (1 - gate).

    w is :func:`stance_width` of the feet in the base yaw frame (the narrower of the front and rear
    pairs); w_min = ``w_min_ratio`` times the same width of ``nominal_foot_pos_b``; the gate is
    :func:`width_gate`. Range (0, 1], exactly 1 when the gate is off. Shape: (N,).
    """
    gate = width_gate(state, cfg)
    w = stance_width(foot_pos_yaw(state))
    w_min = cfg.w_min_ratio * stance_width(state.nominal_foot_pos_b)
    s = torch.exp(-(w_min - w).clamp_min(0.0) / cfg.sigma_w)
    return gate * s + (1.0 - gate)


# --------------------------------------------------------------------------------------------------
# the terms, eq. (rews)

TermFn = Callable[[EnvState, RewardCfg], torch.Tensor]

GROUP_SIGN = {"task": 1.0, "penalty": -1.0, "stability": 1.0}
"""Sign of each group in eq. (rews): task T and stability S added, penalties P subtracted."""


@dataclass(frozen=True)
class RewardTerm:
    """One reward term: its function, its group, and the config fields of its weight and parameters.

    Modelled on mjlab's ``RewardTerm(func, weight, params)``; the numbers stay in the typed
    :class:`~morfic_cli.config.RewardCfg`, so ``--set env.rewards.<field>=...`` and the run manifest see them.

    Attributes:
        name: The paper's name (``r_lin``); logged as ``reward/<name>`` and ``reward_raw/<name>``.
        func: ``(state, cfg) -> (N,)``, the unweighted value exactly as the paper's table defines it.
        group: ``task``, ``penalty`` or ``stability`` (the sign, :data:`GROUP_SIGN`).
        weight: Name of the RewardCfg field with the non-negative weight w.
        params: Names of the RewardCfg fields ``func`` reads.
    """

    name: str
    func: TermFn
    group: str
    weight: str
    params: tuple[str, ...] = ()

    def weight_of(self, cfg: RewardCfg) -> float:
        """The term's weight w in ``cfg``."""
        return float(getattr(cfg, self.weight))

    def sign(self) -> float:
        """+1 for task and stability terms, -1 for penalties."""
        return GROUP_SIGN[self.group]


TERMS: tuple[RewardTerm, ...] = (
    RewardTerm("r_lin", r_lin, "task", "w_lin", ("sigma_lin",)),
    RewardTerm("r_yaw", r_yaw, "task", "w_yaw", ("sigma_yaw",)),
    RewardTerm("p_vz", p_vz, "penalty", "w_vz"),
    RewardTerm("p_omega_xy", p_omega_xy, "penalty", "w_omega_xy"),
    RewardTerm("p_ori", p_ori, "penalty", "w_ori"),
    RewardTerm("p_tau", p_tau, "penalty", "w_tau"),
    RewardTerm("p_qddot", p_qddot, "penalty", "w_qddot"),
    RewardTerm("p_da", p_da, "penalty", "w_da"),
    RewardTerm("p_coll", p_coll, "penalty", "w_coll", ("collision_force",)),
    RewardTerm("p_jl", p_jl, "penalty", "w_jl"),
    RewardTerm("r_upright", r_upright, "stability", "w_upright", ("theta0",)),
    RewardTerm("r_cop", r_cop, "stability", "w_cop", ("tau_cop",)),
    RewardTerm("r_width", r_width, "stability", "w_width", ("eta", "v_th", "w_min_ratio", "sigma_w")),
    RewardTerm("r_gaitF", r_gaitF, "task", "w_gaitF", ("sigma_F",)),
    RewardTerm("r_gaitV", r_gaitV, "task", "w_gaitV", ("sigma_V",)),
    RewardTerm("p_slip", p_slip, "penalty", "w_slip"),
    RewardTerm("p_impact", p_impact, "penalty", "w_impact", ("impact_clip",)),
    RewardTerm("p_f", p_f, "penalty", "w_f", ("f_max_factor",)),
    RewardTerm("p_q", p_q, "penalty", "w_q"),
    RewardTerm("p_qdot", p_qdot, "penalty", "w_qdot"),
    RewardTerm("r_jump", r_jump, "task", "w_jump", ("h_cmd",)),
    RewardTerm("r_raibert", r_raibert, "penalty", "w_raibert", ("gait_duty", "raibert_kv")),
)
"""Every term of the paper's Table "Reward terms", in its order."""

TERMS_BY_NAME: dict[str, RewardTerm] = {t.name: t for t in TERMS}

TRACKING_TERM = "r_lin"
"""The term the command curriculum reads, unweighted (legged_gym's tracking rule; range [0, 4])."""


def compute_rewards(
    state: EnvState, cfg: RewardCfg
) -> tuple[torch.Tensor, dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """The total reward, eq. (rews), each term's weighted, signed contribution, and each term's raw value.

    contribution_k = sign(group_k) * w_k * raw_k with raw_k = term_k(state), and the total is the sum of the
    contributions. No dt factor: the env multiplies by the policy step dt. Every term's raw value is computed
    (so it is logged, and the curriculum reads r_lin, whatever the weights); a term of weight 0 contributes
    zeros, so the logged keys are always the same.

    Args:
        state: The batched env state.
        cfg: Weights and parameters.

    Returns:
        ``(total, contributions, raw)``: total shape (N,); contributions and raw map every name of
        :data:`TERMS` to a tensor of shape (N,).
    """
    n = state.base_pos_w.shape[0]
    ref = state.base_pos_w
    total = torch.zeros(n, dtype=ref.dtype, device=ref.device)
    contributions: dict[str, torch.Tensor] = {}
    raw: dict[str, torch.Tensor] = {}
    for term in TERMS:
        raw[term.name] = term.func(state, cfg)
        w = term.weight_of(cfg)
        if w == 0.0:
            contributions[term.name] = torch.zeros_like(total)
            continue
        value = term.sign() * w * raw[term.name]
        contributions[term.name] = value
        total = total + value
    return total, contributions, raw
