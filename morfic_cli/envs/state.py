"""``EnvState``: everything a reward, termination or observation term reads, batched over envs.

Terms are pure functions ``(state, cfg) -> Tensor[num_envs]``; the env builds one ``EnvState`` per
policy step from the backend's :class:`~morfic_cli.sim.backend.SimFrame` plus its own buffers
(commands, actions, gait clock). Shapes use N = num_envs. Leg order FL, FR, RL, RR; joints hip,
thigh, calf per leg.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class EnvState:
    """Batched state seen by the terms.

    Attributes:
        base_pos_w: Base position, world frame (m). Shape: (N, 3).
        base_quat_w: Base orientation (w, x, y, z). Shape: (N, 4).
        base_lin_vel_b: Base linear velocity v in the base frame (m/s). Shape: (N, 3).
        base_ang_vel_b: Base angular velocity omega in the base frame (rad/s). Shape: (N, 3).
        projected_gravity_b: Unit gravity direction in the base frame, g_proj ((0, 0, -1) upright).
            Shape: (N, 3).
        joint_pos: q (rad). Shape: (N, 12).
        joint_vel: qdot (rad/s). Shape: (N, 12).
        joint_vel_prev: qdot at the previous policy step (rad/s). Shape: (N, 12).
        joint_torque: Actuator torques tau (N m). Shape: (N, 12).
        default_joint_pos: q0, the default standing pose (rad). Shape: (N, 12).
        joint_pos_min: Per-env lower joint limits q_min (rad), after morphology. Shape: (N, 12).
        joint_pos_max: Per-env upper joint limits q_max (rad), after morphology. Shape: (N, 12).
        foot_pos_w: Foot-centre positions, world frame (m). Shape: (N, 4, 3).
        foot_vel_w: Foot-centre velocities x_dot_i, world frame (m/s). Shape: (N, 4, 3).
        foot_vel_w_prev: Foot velocities at the previous policy step (m/s). Shape: (N, 4, 3).
        foot_force_w: Ground contact force f_i on each foot, world frame (N). Shape: (N, 4, 3).
        foot_contact: c_i, the foot touches the ground (|f_i| above a threshold). Shape: (N, 4), bool.
        body_contact_force: Norm of the ground force on base, thighs and calves (N), in
            :data:`morfic_cli.sim.backend.CONTACT_BODIES` order. Shape: (N, 9).
        command: c = (vx, vy, yaw rate) commanded, base yaw frame (m/s, m/s, rad/s). Shape: (N, 3).
        action: a_t, the policy's action this step. Shape: (N, 12).
        action_prev: a_{t-1}. Shape: (N, 12).
        gait_phase: Per-foot gait phase in [0, 1) (stance for phase < duty). Shape: (N, 4).
        desired_contact: d_i in [0, 1], the gait's desired contact state (1 = stance). Shape: (N, 4).
        gait_frequency: Gait frequency (Hz). Shape: (N,).
        nominal_foot_pos_b: Nominal foot xy under each hip in the base yaw frame (m). Shape: (N, 4, 2).
        nominal_height: h0, base height at the default pose (m). Shape: (N,).
        total_mass: Robot mass (kg), for force thresholds that scale with weight. Shape: (N,).
        dt: Policy time step Delta t (s), physics dt times decimation.
    """

    base_pos_w: torch.Tensor
    base_quat_w: torch.Tensor
    base_lin_vel_b: torch.Tensor
    base_ang_vel_b: torch.Tensor
    projected_gravity_b: torch.Tensor
    joint_pos: torch.Tensor
    joint_vel: torch.Tensor
    joint_vel_prev: torch.Tensor
    joint_torque: torch.Tensor
    default_joint_pos: torch.Tensor
    joint_pos_min: torch.Tensor
    joint_pos_max: torch.Tensor
    foot_pos_w: torch.Tensor
    foot_vel_w: torch.Tensor
    foot_vel_w_prev: torch.Tensor
    foot_force_w: torch.Tensor
    foot_contact: torch.Tensor
    body_contact_force: torch.Tensor
    command: torch.Tensor
    action: torch.Tensor
    action_prev: torch.Tensor
    gait_phase: torch.Tensor
    desired_contact: torch.Tensor
    gait_frequency: torch.Tensor
    nominal_foot_pos_b: torch.Tensor
    nominal_height: torch.Tensor
    total_mass: torch.Tensor
    dt: float


OBSERVED = "observed"
"""In o_t (every network's history), or the policy's own action a_t (o_{t+1}'s last action)."""
MORPHOLOGY = "morphology"
"""A function of the morphology descriptor m (the ``morphology`` group) or a constant."""
PHYSICAL = "physical"
"""A function of the simulator's state and of p_t (the ``privileged`` group): Markov state that the history
estimates (base height, foot positions, contact forces, torques)."""
CLOCK = "clock"
"""The gait clock: a phase drawn at each reset that no observation group carries, so no network can know it."""

#: Where each :class:`EnvState` field comes from, for the rule that every reward term with a non-zero weight is a
#: function of what the networks observe (issue 16 item 4; tested in tests/envs/test_rewards.py): it may read
#: ``observed``, ``morphology`` and ``physical`` fields, never a ``clock`` one. For ``observed`` fields the value is
#: the :data:`~morfic_cli.envs.observations.POLICY_LAYOUT` term that carries it.
FIELD_SOURCES: dict[str, tuple[str, str | None]] = {
    "base_pos_w": (PHYSICAL, None),
    "base_quat_w": (PHYSICAL, None),
    "base_lin_vel_b": (OBSERVED, "base_lin_vel"),
    "base_ang_vel_b": (OBSERVED, "base_ang_vel"),
    "projected_gravity_b": (OBSERVED, "projected_gravity"),
    "joint_pos": (OBSERVED, "joint_pos"),
    "joint_vel": (OBSERVED, "joint_vel"),
    "joint_vel_prev": (OBSERVED, "joint_vel"),
    "joint_torque": (PHYSICAL, None),
    "default_joint_pos": (MORPHOLOGY, None),
    "joint_pos_min": (MORPHOLOGY, None),
    "joint_pos_max": (MORPHOLOGY, None),
    "foot_pos_w": (PHYSICAL, None),
    "foot_vel_w": (PHYSICAL, None),
    "foot_vel_w_prev": (PHYSICAL, None),
    "foot_force_w": (PHYSICAL, None),
    "foot_contact": (PHYSICAL, None),
    "body_contact_force": (PHYSICAL, None),
    "command": (OBSERVED, "command"),
    "action": (OBSERVED, "last_action"),
    "action_prev": (OBSERVED, "last_action"),
    "gait_phase": (CLOCK, None),
    "desired_contact": (CLOCK, None),
    "gait_frequency": (CLOCK, None),
    "nominal_foot_pos_b": (MORPHOLOGY, None),
    "nominal_height": (MORPHOLOGY, None),
    "total_mass": (MORPHOLOGY, None),
    "dt": (MORPHOLOGY, None),
}
