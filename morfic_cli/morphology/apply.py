"""Apply an 11-D morphology descriptor to a compiled model (docs/robots.md).

Pure functions on one :class:`mujoco.MjModel` plus a scratch :class:`mujoco.MjData`. A
:class:`TemplateInfo`, made once from the template model, remembers the nominal masses, inertias
and limits, so every application starts from the nominal model and repeated applications never
compound.

What a descriptor m (DESCRIPTOR_NAMES order) changes, on all four legs alike:

* link masses: the ``{leg}_hip``, ``{leg}_thigh``, ``{leg}_calf`` and ``{leg}_foot`` body masses
  become m[2], m[0], m[1], m[3] and the ``base`` mass m[4]. Each body's principal inertia is scaled
  by the same factor (new mass / nominal mass), which keeps its radius of gyration; a body whose
  nominal mass is zero keeps zero inertia (a point mass), whatever mass it is given.
* joint ranges: hip [m[5], m[6]], thigh [m[7], m[8]], calf [m[9], m[10]] (``jnt_range``), and the
  position actuators' ``ctrlrange`` follows the same limits.
* derived constants: ``mujoco.mj_setConst`` recomputes what the compiler derived from the masses
  (subtree masses, inverse weights, actuator acc0, ...): skipping it silently breaks the physics.

Everything else (rotor bodies, geometry, gains, torque limits, contact and DR fields) is left as is.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from morfic_cli.morphology.descriptor import LIMIT_PAIRS, as_descriptor
from morfic_cli.morphology.robots import JOINTS, LEGS, LINKS

DESCRIPTOR_MASS_INDEX: dict[str, int] = {"thigh": 0, "calf": 1, "hip": 2, "foot": 3, "base": 4}
"""Index of each link's (and the base's) mass in the 11-D descriptor."""


@dataclass(frozen=True, eq=False)
class TemplateInfo:
    """Ids and nominal values of a template model, made once by :meth:`from_model`.

    Attributes:
        base_body: Body id of ``base``.
        link_bodies: Body ids of each leg's links. Shape: (4, 4), LEGS x LINKS (hip, thigh, calf, foot).
        joint_ids: Joint ids. Shape: (4, 3), LEGS x JOINTS.
        qpos_adr: qpos addresses of the joints. Shape: (12,), model (leg-major) order.
        dof_adr: qvel / dof addresses of the joints. Shape: (12,).
        actuator_ids: Actuator ids driving each joint. Shape: (12,).
        foot_sites: Site ids of ``{leg}_foot_site``. Shape: (4,).
        body_mass: Nominal body masses of the whole model (kg). Shape: (nbody,).
        body_inertia: Nominal principal inertias (kg m^2). Shape: (nbody, 3).
        jnt_range: Nominal joint ranges (rad). Shape: (njnt, 2).
        ctrlrange: Nominal actuator control ranges (rad). Shape: (nu, 2).
    """

    base_body: int
    link_bodies: np.ndarray
    joint_ids: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuator_ids: np.ndarray
    foot_sites: np.ndarray
    body_mass: np.ndarray
    body_inertia: np.ndarray
    jnt_range: np.ndarray
    ctrlrange: np.ndarray

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> TemplateInfo:
        """Read ids and nominal values from a model built by :mod:`morfic_cli.morphology.builder`.

        Args:
            model: The nominal (unmodified) template model.

        Returns:
            The info; its arrays are read-only copies.
        """
        joints = np.array([[model.joint(f"{leg}_{j}_joint").id for j in JOINTS] for leg in LEGS])
        flat = joints.reshape(-1)
        fields = {
            "link_bodies": np.array([[model.body(f"{leg}_{link}").id for link in LINKS] for leg in LEGS]),
            "joint_ids": joints,
            "qpos_adr": model.jnt_qposadr[flat].copy(),
            "dof_adr": model.jnt_dofadr[flat].copy(),
            "actuator_ids": np.array([model.actuator(f"{leg}_{j}_joint").id for leg in LEGS for j in JOINTS]),
            "foot_sites": np.array([model.site(f"{leg}_foot_site").id for leg in LEGS]),
            "body_mass": model.body_mass.copy(),
            "body_inertia": model.body_inertia.copy(),
            "jnt_range": model.jnt_range.copy(),
            "ctrlrange": model.actuator_ctrlrange.copy(),
        }
        for value in fields.values():
            value.setflags(write=False)
        return cls(base_body=model.body("base").id, **fields)


def descriptor_ranges(descriptor: np.ndarray) -> np.ndarray:
    """Joint ranges of one leg from a descriptor.

    Args:
        descriptor: Validated descriptor. Shape: (11,).

    Returns:
        (min, max) per joint (hip, thigh, calf), rad. Shape: (3, 2).
    """
    return np.array([[descriptor[lo], descriptor[hi]] for lo, hi in LIMIT_PAIRS])


def joint_ranges(descriptor: np.ndarray) -> np.ndarray:
    """The descriptor's joint ranges for all 12 joints (every leg alike), model order. Shape: (12, 2)."""
    return np.tile(descriptor_ranges(descriptor), (len(LEGS), 1))


@dataclass(frozen=True)
class DescriptorFields:
    """The model fields a batch of k descriptors sets, whole arrays per model (what :func:`apply_descriptor` writes).

    Backends that keep one array per field for all envs (mujoco_warp's per-world fields) write these
    rows directly; derived constants still have to be recomputed afterwards (``mj_setConst`` /
    ``mujoco_warp.set_const``).

    Attributes:
        body_mass: Body masses (kg). Shape: (k, nbody).
        body_inertia: Principal inertias, nominal scaled by new/nominal mass (kg m^2). Shape: (k, nbody, 3).
        jnt_range: Joint ranges (rad). Shape: (k, njnt, 2).
        ctrlrange: Actuator control ranges (rad). Shape: (k, nu, 2).
    """

    body_mass: np.ndarray
    body_inertia: np.ndarray
    jnt_range: np.ndarray
    ctrlrange: np.ndarray


def descriptor_fields(descriptors: np.ndarray, base: TemplateInfo) -> DescriptorFields:
    """The model fields of k validated descriptors, starting from the nominal template (module docstring).

    Args:
        descriptors: Validated raw descriptors (kg, rad). Shape: (k, 11).
        base: The template's ids and nominal values.

    Returns:
        The fields, float64.
    """
    m = np.asarray(descriptors, dtype=np.float64).reshape(-1, 11)
    k = m.shape[0]
    mass = np.tile(base.body_mass, (k, 1))
    for li, link in enumerate(LINKS):
        mass[:, base.link_bodies[:, li]] = m[:, DESCRIPTOR_MASS_INDEX[link], None]
    mass[:, base.base_body] = m[:, DESCRIPTOR_MASS_INDEX["base"]]
    # inertia scales with mass (radius of gyration kept); a zero nominal mass keeps zero inertia
    changed = np.append(base.link_bodies.reshape(-1), base.base_body)
    nominal = np.broadcast_to(base.body_mass[changed], (k, changed.size))
    scale = np.ones_like(mass)
    scale[:, changed] = np.divide(mass[:, changed], nominal, out=np.zeros((k, changed.size)), where=nominal > 0)
    ranges = np.tile(m[:, [list(pair) for pair in LIMIT_PAIRS]], (1, len(LEGS), 1))  # (k, 12, 2)
    jnt_range = np.tile(base.jnt_range, (k, 1, 1))
    jnt_range[:, base.joint_ids.reshape(-1)] = ranges
    ctrlrange = np.tile(base.ctrlrange, (k, 1, 1))
    ctrlrange[:, base.actuator_ids] = ranges
    return DescriptorFields(mass, base.body_inertia[None] * scale[..., None], jnt_range, ctrlrange)


def apply_descriptor(
    model: mujoco.MjModel, data: mujoco.MjData, descriptor: np.ndarray, base: TemplateInfo
) -> np.ndarray:
    """Apply an 11-D descriptor to ``model`` in place, starting from the nominal template.

    Args:
        model: A model compiled from the template spec (modified in place).
        data: Scratch data of a model with the same sizes; ``mj_setConst`` overwrites it.
        descriptor: Raw descriptor (kg, rad) in DESCRIPTOR_NAMES order. Shape: (11,).
        base: The template's ids and nominal values.

    Returns:
        The validated descriptor. Shape: (11,).

    Raises:
        DescriptorError: wrong shape, non-finite, implausible values or a min limit above its max.
    """
    m = as_descriptor(descriptor)
    fields = descriptor_fields(m[None], base)
    model.body_mass[:] = fields.body_mass[0]
    model.body_inertia[:] = fields.body_inertia[0]
    model.jnt_range[:] = fields.jnt_range[0]
    model.actuator_ctrlrange[:] = fields.ctrlrange[0]
    mujoco.mj_setConst(model, data)
    return m


def clamp_to_limits(q: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Clamp joint angles into their ranges.

    Args:
        q: Joint angles (rad). Shape: (..., 12).
        ranges: (min, max) per joint (rad). Shape: (..., 12, 2), broadcastable against ``q``.

    Returns:
        The clamped angles. Shape: like ``q``.
    """
    return np.clip(q, ranges[..., 0], ranges[..., 1])


def model_joint_ranges(model: mujoco.MjModel, base: TemplateInfo) -> np.ndarray:
    """The model's current joint ranges in model joint order (rad). Shape: (12, 2)."""
    return model.jnt_range[base.joint_ids.reshape(-1)].copy()


def standing_height(
    model: mujoco.MjModel, data: mujoco.MjData, base: TemplateInfo, joint_pos: np.ndarray, foot_radius: float
) -> float:
    """Base height above the lowest foot bottom with the base upright at the origin.

    Same definition as :func:`morfic_cli.morphology.builder.nominal_height`, on a given model.

    Args:
        model: The (possibly modified) model.
        data: Scratch data for ``model`` (overwritten).
        base: The template's ids.
        joint_pos: Joint angles (rad). Shape: (12,).
        foot_radius: Foot sphere radius (m).

    Returns:
        Height in m.
    """
    data.qpos[:] = model.qpos0
    data.qpos[:3] = 0.0
    data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    data.qpos[base.qpos_adr] = joint_pos
    mujoco.mj_kinematics(model, data)
    return -(float(np.min(data.site_xpos[base.foot_sites, 2])) - foot_radius)


@dataclass(frozen=True)
class MorphologySummary:
    """Derived per-model quantities after a descriptor is applied.

    Attributes:
        default_joint_pos: The default pose clamped into the model's joint ranges (rad). Shape: (12,).
        nominal_height: Base height above the feet at that pose (m).
        total_mass: Sum of every body mass (kg).
        base_mass: Mass of the ``base`` body (kg).
    """

    default_joint_pos: np.ndarray
    nominal_height: float
    total_mass: float
    base_mass: float


def summarize(
    model: mujoco.MjModel, data: mujoco.MjData, base: TemplateInfo, default_joint_pos: np.ndarray, foot_radius: float
) -> MorphologySummary:
    """Default pose, nominal height and masses of a model (after :func:`apply_descriptor`).

    Args:
        model: The model.
        data: Scratch data for ``model`` (overwritten).
        base: The template's ids.
        default_joint_pos: The robot's default standing pose (rad). Shape: (12,).
        foot_radius: Foot sphere radius (m).

    Returns:
        The summary.
    """
    q0 = clamp_to_limits(np.asarray(default_joint_pos, dtype=np.float64), model_joint_ranges(model, base))
    return MorphologySummary(
        default_joint_pos=q0,
        nominal_height=standing_height(model, data, base, q0, foot_radius),
        total_mass=float(model.body_mass.sum()),
        base_mass=float(model.body_mass[base.base_body]),
    )
