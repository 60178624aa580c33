"""URMA's joint and foot descriptions, read from a compiled robot model (docs/training.md, "External baselines").

A pure function of one :class:`mujoco.MjModel` (the env's own, with its descriptor applied), its
:class:`~morfic_cli.morphology.apply.TemplateInfo` and the env's default pose: the model is posed at the default
joint positions with the base at the origin, unrotated, so world coordinates are trunk coordinates
(``mj_kinematics``; nothing is simulated). Raw SI values; :func:`morfic_cli.envs.observations.joint_description_obs`
normalises them. The backend computes them once per env model (:meth:`morfic_cli.sim.cpu.CpuBackend.body_description`),
the env when a model changes (a reset in train mode, construction otherwise), never per step.

Per joint (12, model order; :data:`JOINT_FIELDS`): anchor position (3, m) and axis (3) in the trunk frame, direct
child joints (1 for hip and thigh, 0 for calf), default position q0 (rad), range (2, rad), torque limit (N m),
velocity limit (rad/s, the robot's spec: MuJoCo's position actuators have none), joint damping (N m s/rad),
armature (kg m^2), the PD gains Kp (N m/rad) and Kd (N m s/rad), the mass of the joint's child link (kg: hip, thigh
or calf, as the descriptor sets it) and the robot's total mass (kg).

Per foot (4, LEGS order; :data:`FOOT_FIELDS`): foot position in the trunk frame at the default pose (3, m), foot
sphere radius (m), foot mass (kg, the descriptor's) and total mass (kg).
"""

from __future__ import annotations

import mujoco
import numpy as np

from morfic_cli.morphology.apply import TemplateInfo
from morfic_cli.morphology.robots import JOINTS, LEGS

JOINT_FIELDS: tuple[str, ...] = (
    "anchor_x",
    "anchor_y",
    "anchor_z",
    "axis_x",
    "axis_y",
    "axis_z",
    "child_joints",
    "q0",
    "q_min",
    "q_max",
    "torque_limit",
    "velocity_limit",
    "damping",
    "armature",
    "kp",
    "kd",
    "link_mass",
    "total_mass",
)
"""The raw joint description's entries, in order (18)."""
FOOT_FIELDS: tuple[str, ...] = ("foot_x", "foot_y", "foot_z", "foot_radius", "foot_mass", "total_mass")
"""The raw foot description's entries, in order (6)."""
CHILD_JOINTS: tuple[int, ...] = (1, 1, 0)
"""Direct child joints of the hip, thigh and calf joints."""


def body_description(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    info: TemplateInfo,
    default_joint_pos: np.ndarray,
    velocity_limit: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The raw joint and foot descriptions of one model (module docstring).

    Args:
        model: The env's model (descriptor applied). Not modified.
        data: Scratch data of ``model``'s structure; its state is overwritten.
        info: Ids of the model's joints, links, actuators and foot sites.
        default_joint_pos: The env's default pose q0 (rad), model order. Shape: (12,).
        velocity_limit: Joint velocity limits (rad/s) per leg joint (hip, thigh, calf) or per joint. Shape: (3,)
            or (12,).

    Returns:
        Joint description (12, 18) and foot description (4, 6), float64, rows in :data:`JOINT_FIELDS` /
        :data:`FOOT_FIELDS` order.
    """
    mujoco.mj_resetData(model, data)
    data.qpos[:7] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)  # base at the origin, unrotated: world = trunk frame
    data.qpos[info.qpos_adr] = default_joint_pos
    mujoco.mj_kinematics(model, data)
    base = data.xpos[info.base_body]
    joint_ids = info.joint_ids.reshape(-1)
    links = info.link_bodies  # (4, 4): hip, thigh, calf, foot
    total_mass = float(model.body_subtreemass[info.base_body])
    act = info.actuator_ids
    kp = model.actuator_gainprm[act, 0]
    kd = -model.actuator_biasprm[act, 2]
    vel = np.broadcast_to(
        np.tile(velocity_limit, len(LEGS)) if len(velocity_limit) == len(JOINTS) else velocity_limit, (len(joint_ids),)
    )
    joints = np.column_stack(
        [
            data.xanchor[joint_ids] - base,
            data.xaxis[joint_ids],
            np.tile(CHILD_JOINTS, len(LEGS)),
            default_joint_pos,
            model.jnt_range[joint_ids],
            model.actuator_forcerange[act, 1],
            vel,
            model.dof_damping[info.dof_adr],
            model.dof_armature[info.dof_adr],
            kp,
            kd,
            model.body_mass[links[:, :3].reshape(-1)],
            np.full(len(joint_ids), total_mass),
        ]
    )
    foot_bodies = links[:, 3]
    radius = model.geom_size[model.body_geomadr[foot_bodies], 0]
    feet = np.column_stack(
        [
            data.site_xpos[info.foot_sites] - base,
            radius,
            model.body_mass[foot_bodies],
            np.full(len(LEGS), total_mass),
        ]
    )
    return joints.astype(np.float64), feet.astype(np.float64)
