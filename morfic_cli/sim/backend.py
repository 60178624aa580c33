"""The protocol every simulation backend implements (the factory that picks one is :mod:`morfic_cli.sim.factory`).

The environment (``envs/``) talks only to this protocol, so the warp backend (mujoco_warp, on a GPU
or on warp's CPU device) replaces the CPU one without touching env code. Everything crossing the
boundary is a batched torch tensor on ``backend.device``; the first dimension is always
``num_envs`` (N). Leg order is FL, FR, RL, RR;
joint order is hip, thigh, calf per leg (12 joints, the builder's model order).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Sequence

    import torch

    from morfic_cli.morphology.robots import RobotSpec


#: Bodies whose ground contact ``SimFrame.body_contact_force`` reports, in this order.
CONTACT_BODIES: tuple[str, ...] = (
    "base",
    "FL_thigh",
    "FR_thigh",
    "RL_thigh",
    "RR_thigh",
    "FL_calf",
    "FR_calf",
    "RL_calf",
    "RR_calf",
)


@dataclass
class SimFrame:
    """Batched physical state after a step. Shapes use N = num_envs.

    Attributes:
        base_pos_w: Base position, world frame (m). Shape: (N, 3).
        base_quat_w: Base orientation quaternion (w, x, y, z), world frame. Shape: (N, 4).
        base_lin_vel_w: Base linear velocity, world frame (m/s). Shape: (N, 3).
        base_lin_vel_b: Base linear velocity, base frame (m/s). Shape: (N, 3).
        base_ang_vel_b: Base angular velocity, base frame (rad/s). Shape: (N, 3).
        joint_pos: Joint positions q (rad). Shape: (N, 12).
        joint_vel: Joint velocities qdot (rad/s). Shape: (N, 12).
        joint_torque: Actuator torques tau (N m). Shape: (N, 12).
        foot_pos_w: Foot-centre positions, world frame (m). Shape: (N, 4, 3).
        foot_vel_w: Foot-centre linear velocities, world frame (m/s). Shape: (N, 4, 3).
        foot_force_w: Ground contact force on each foot, world frame (N). Shape: (N, 4, 3).
        body_contact_force: Norm of the ground contact force on each of :data:`CONTACT_BODIES` (N).
            Shape: (N, 9).
        bad: True where the env's state became non-finite (or MuJoCo flagged it unstable) during
            this step; the env must reset it. Other envs are unaffected. Shape: (N,).
    """

    base_pos_w: torch.Tensor
    base_quat_w: torch.Tensor
    base_lin_vel_w: torch.Tensor
    base_lin_vel_b: torch.Tensor
    base_ang_vel_b: torch.Tensor
    joint_pos: torch.Tensor
    joint_vel: torch.Tensor
    joint_torque: torch.Tensor
    foot_pos_w: torch.Tensor
    foot_vel_w: torch.Tensor
    foot_force_w: torch.Tensor
    body_contact_force: torch.Tensor
    bad: torch.Tensor


@dataclass
class SimParams:
    """Per-env physical parameters currently applied (they follow morphology and randomisation).

    Attributes:
        joint_range: Joint limits (rad), [..., 0] = min, [..., 1] = max. Shape: (N, 12, 2).
        default_joint_pos: Default standing pose q0 (rad). Shape: (N, 12).
        torque_limit: Actuator force limits (N m). Shape: (N, 12).
        base_mass: Base body mass (kg). Shape: (N,).
        total_mass: Whole-robot mass (kg). Shape: (N,).
        nominal_height: Base height above the feet at the default pose (m). Shape: (N,).
        friction: Ground sliding friction coefficient. Shape: (N,).
        restitution: Contact restitution coefficient in [0, 1). Shape: (N,).
        com_offset: Base centre-of-mass offset from its nominal position (m). Shape: (N, 3).
        joint_friction: Joint dry friction (frictionloss, N m). Shape: (N, 12).
        descriptor: The 11-D descriptor in effect (raw units). Shape: (N, 11).
    """

    joint_range: torch.Tensor
    default_joint_pos: torch.Tensor
    torque_limit: torch.Tensor
    base_mass: torch.Tensor
    total_mass: torch.Tensor
    nominal_height: torch.Tensor
    friction: torch.Tensor
    restitution: torch.Tensor
    com_offset: torch.Tensor
    joint_friction: torch.Tensor
    descriptor: torch.Tensor


class SimBackend(Protocol):
    """Batched quadruped physics for N envs, each of which may have its own morphology."""

    num_envs: int
    device: torch.device
    physics_dt: float
    """Physics time step (s)."""
    morphology_mutable: bool
    """True when :meth:`set_morphology` is allowed (the Go2 template); False for ``full`` mode."""

    def step(self, joint_targets: torch.Tensor, nsteps: int) -> SimFrame:
        """Hold position targets for ``nsteps`` physics steps in every env and return the new frame.

        Args:
            joint_targets: Position-actuator targets (rad), clipped to each env's joint range.
                Shape: (N, 12).
            nsteps: Physics steps (the decimation).
        """
        ...

    def frame(self) -> SimFrame:
        """The current frame without stepping."""
        ...

    def params(self) -> SimParams:
        """The per-env physical parameters now in effect."""
        ...

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The physics state of every env (what a training checkpoint needs to continue bit-exactly).

        Morphology and dynamics are not in it: they are in :meth:`params` and are re-applied with
        :meth:`set_morphology` / :meth:`set_dynamics` before :meth:`load_state_dict`.
        """
        ...

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore what :meth:`state_dict` returned (same number of envs and robot)."""
        ...

    def reset_envs(
        self,
        env_ids: torch.Tensor,
        base_pos: torch.Tensor,
        base_quat: torch.Tensor,
        base_vel: torch.Tensor,
        joint_pos: torch.Tensor,
        joint_vel: torch.Tensor,
    ) -> None:
        """Set the state of some envs (all else zeroed: warm-start, actuator activations).

        Args:
            env_ids: Envs to reset. Shape: (k,), int64.
            base_pos: Base position (m). Shape: (k, 3).
            base_quat: Base orientation (w, x, y, z). Shape: (k, 4).
            base_vel: Linear (world) then angular (base frame) velocity. Shape: (k, 6).
            joint_pos: Joint positions (rad). Shape: (k, 12).
            joint_vel: Joint velocities (rad/s). Shape: (k, 12).
        """
        ...

    def set_morphology(self, env_ids: torch.Tensor, descriptors: torch.Tensor) -> None:
        """Apply 11-D descriptors (raw units) to some envs' models (docs/robots.md).

        Link masses are set with inertia scaled by the same factor, joint ranges and actuator
        control ranges follow the new limits, and derived constants are recomputed. Raises
        ``MorficError`` when ``morphology_mutable`` is False.

        Args:
            env_ids: Envs to change. Shape: (k,).
            descriptors: Raw descriptors. Shape: (k, 11).
        """
        ...

    def set_geometry_pool(self, robots: Sequence[RobotSpec]) -> None:
        """Compile K generated robots with the template's structure (:mod:`morfic_cli.morphology.procedural`).

        Only the CPU backend implements it; the warp backend raises ``MorficError`` (its worlds share geometry).
        """
        ...

    def set_actuation(
        self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor, torque_limit: torch.Tensor
    ) -> None:
        """Set some envs' PD gains and torque limits, absolute values (the CPU backend only).

        For ``env.rand.actuation`` and the eval mode ``actuation-matched``. Shapes: (k,), (k,), (k,), (k, 3) hip /
        thigh / calf.
        """
        ...

    def set_geometry(self, env_ids: torch.Tensor, robot_ids: torch.Tensor) -> None:
        """Give some envs a pool robot's model (its geometry, masses, gains, descriptor), at rest at its home.

        Args:
            env_ids: Envs to change. Shape: (k,).
            robot_ids: Each env's robot in the pool. Shape: (k,).
        """
        ...

    def body_description(self, env_ids: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """URMA's raw joint (k, 12, 18) and foot (k, 4, 6) descriptions of some envs' models.

        :mod:`morfic_cli.morphology.description`. Only the CPU backend implements it; warp raises ``MorficError``.
        """
        ...

    def set_dynamics(
        self,
        env_ids: torch.Tensor,
        friction: torch.Tensor,
        restitution: torch.Tensor,
        com_offset: torch.Tensor,
        joint_friction: torch.Tensor,
    ) -> None:
        """Domain randomisation of contact and joint properties for some envs.

        Args:
            env_ids: Envs to change. Shape: (k,).
            friction: Ground sliding friction. Shape: (k,).
            restitution: Restitution in [0, 1). Shape: (k,).
            com_offset: Base COM offset (m). Shape: (k, 3).
            joint_friction: Joint dry friction (N m). Shape: (k, 12).
        """
        ...

    def push(self, env_ids: torch.Tensor, delta_vel_xy: torch.Tensor) -> None:
        """Add a planar velocity kick to some envs' bases. Shapes: (k,), (k, 2) in m/s."""
        ...

    def close(self) -> None:
        """Release threads and memory."""
        ...
