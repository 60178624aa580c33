"""Procedural geometry: quadrupeds generated around the template, as GenLoco does (docs/robots.md).

GenLoco (Feng et al. 2022; its public generator ``quadruped_generator.py``) trains one morphology-agnostic
policy on procedurally generated A1-like robots. This module draws such robots around any template
:class:`~morfic_cli.morphology.robots.RobotSpec` (Go2 in morfic) and returns each as a new ``RobotSpec``, so the
one MJCF builder (:mod:`morfic_cli.morphology.builder`) compiles it and every model of a pool has the same
structure (bodies, joints, geoms, sensors), only other numbers: the CPU backend steps them together.

What one sample changes (ranges: :class:`~morfic_cli.config.GeometryRandCfg`; all four legs alike):

* a global scale s multiplies every length, and s^3 every link and rotor mass;
* the base box: each dimension x its own factor x s; its mass = nominal x a density factor x the volume ratio
  (GenLoco draws the density); its COM moves with the box and its inertia stretches with it
  (:func:`stretch_inertia`);
* hip joints: x and y positions follow the box's length and width, times a factor each (GenLoco U(0.9, 1.1));
  the lateral hip-to-thigh offset x s x a factor;
* leg lengths: calf (lower leg) length x a factor x s; thigh length x the calf's factor x a ratio (GenLoco ties
  the upper leg to the lower by U(0.75, 1.25)); capsule radii likewise (calf x factor x s, thigh x the calf's
  factor x a ratio, hip x s); the foot sphere follows the calf radius (GenLoco: foot = 1.5 x lower radius);
* link masses: hip, thigh, calf and foot each x a factor x s^3; each link's COM and its inertia's radius of
  gyration scale with its length (inertia x m'/m x length factor^2);
* actuators: Kp and Kd x total mass / nominal total mass (GenLoco's rule; ``gains_with_mass``), torque limits
  too with ``torque_with_mass`` (off: GenLoco keeps the motors);
* kept consistent: the default pose (the template's), the init height (the generated robot's standing height
  plus the template's clearance), joint limits (the template's), and the 11-D descriptor (the generated link and
  base masses with the template's limits), so the morphology observation z_m describes the generated robot.

Unlike GenLoco, one factor per link type is drawn for all four legs (GenLoco draws each of its 21 link masses
separately): the descriptor holds one mass per link type, and the robots morfic transfers to are symmetric.
A sample whose base box would sit lower than ``min_base_clearance`` above the ground at the default pose (it
would touch the ground and end every episode) is drawn again. Everything is a pure function of a
``numpy.random.Generator``; :func:`generate_pool` is reproducible from its seed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np

from morfic_cli.config import GeometryRandCfg
from morfic_cli.morphology.builder import nominal_height
from morfic_cli.morphology.descriptor import as_descriptor
from morfic_cli.morphology.robots import LINKS, LinkInertial, RobotSpec

POOL_SEED_SALT = 0x6E10C0
"""Mixed into the env seed for the pool's generator, so the pool never shares a stream with the env's draws."""

MAX_REDRAWS = 1000
"""Draws per robot before :func:`sample_geometry` gives up on ``min_base_clearance`` (a config that cannot be met)."""

FACTOR_NAMES: tuple[str, ...] = (
    "scale",
    "base_size_x",
    "base_size_y",
    "base_size_z",
    "base_density",
    "hip_pos_x",
    "hip_pos_y",
    "thigh_offset",
    "calf_length",
    "thigh_ratio",
    "calf_radius",
    "thigh_radius_ratio",
    "hip_mass",
    "thigh_mass",
    "calf_mass",
    "foot_mass",
)
"""Names of :meth:`GeometrySample.vector`'s entries (the mass entries are factors before scale^3)."""


@dataclass(frozen=True)
class GeometrySample:
    """The random factors of one generated robot (dimensionless; lengths are also multiplied by ``scale``).

    Attributes:
        scale: Global scale s.
        base_size: Factor of each base box dimension (x, y, z). Shape: (3,).
        base_density: Factor of the base's density.
        hip_pos: Extra factor of the hip joints' x and y positions. Shape: (2,).
        thigh_offset: Factor of the lateral hip-to-thigh offset.
        calf_length: Factor of the calf (lower leg) length.
        thigh_ratio: Thigh length factor over the calf's.
        calf_radius: Factor of the calf capsule radius (and the foot radius).
        thigh_radius_ratio: Thigh radius factor over the calf's.
        link_mass: Factor of the hip, thigh, calf and foot masses (before s^3). Shape: (4,), :data:`LINKS` order.
    """

    scale: float
    base_size: np.ndarray
    base_density: float
    hip_pos: np.ndarray
    thigh_offset: float
    calf_length: float
    thigh_ratio: float
    calf_radius: float
    thigh_radius_ratio: float
    link_mass: np.ndarray

    def vector(self) -> np.ndarray:
        """The factors in :data:`FACTOR_NAMES` order (e.g. an extended descriptor's input). Shape: (16,)."""
        return np.concatenate(
            [
                [self.scale],
                self.base_size,
                [self.base_density],
                self.hip_pos,
                [self.thigh_offset, self.calf_length, self.thigh_ratio, self.calf_radius, self.thigh_radius_ratio],
                self.link_mass,
            ]
        ).astype(np.float64)

    @classmethod
    def nominal(cls) -> GeometrySample:
        """Every factor 1: :func:`generate_robot` returns the template's geometry."""
        return cls(1.0, np.ones(3), 1.0, np.ones(2), 1.0, 1.0, 1.0, 1.0, 1.0, np.ones(4))

    def length_factors(self) -> dict[str, float]:
        """The factor of each link's length (hip: s x thigh offset, thigh, calf, foot: its radius)."""
        calf = self.calf_length * self.scale
        return {
            "hip": self.scale * self.thigh_offset,
            "thigh": calf * self.thigh_ratio,
            "calf": calf,
            "foot": self.calf_radius * self.scale,
        }


@overload
def _u(rng: np.random.Generator, bounds: tuple[float, float]) -> float: ...
@overload
def _u(rng: np.random.Generator, bounds: tuple[float, float], size: int) -> np.ndarray: ...
def _u(rng: np.random.Generator, bounds: tuple[float, float], size: int | None = None) -> np.ndarray | float:
    lo, hi = bounds
    value = rng.uniform(lo, hi, size)
    return float(value) if size is None else value


def _draw(rng: np.random.Generator, cfg: GeometryRandCfg) -> GeometrySample:
    return GeometrySample(
        scale=_u(rng, cfg.scale),
        base_size=_u(rng, cfg.base_size, 3),
        base_density=_u(rng, cfg.base_density),
        hip_pos=_u(rng, cfg.hip_pos, 2),
        thigh_offset=_u(rng, cfg.hip_pos),
        calf_length=_u(rng, cfg.link_length),
        thigh_ratio=_u(rng, cfg.thigh_length_ratio),
        calf_radius=_u(rng, cfg.link_radius),
        thigh_radius_ratio=_u(rng, cfg.thigh_radius_ratio),
        link_mass=_u(rng, cfg.link_mass, 4),
    )


def base_clearance(robot: RobotSpec, height: float) -> float:
    """Height of the base box's bottom above the ground (m) when the base stands ``height`` above it, level."""
    return height - float(robot.base_size[2]) / 2


def sample_geometry(
    rng: np.random.Generator,
    cfg: GeometryRandCfg,
    template: RobotSpec,
    name: str | None = None,
    *,
    template_height: float | None = None,
) -> tuple[GeometrySample, RobotSpec]:
    """Draw one robot, again until its base clears the ground by ``cfg.min_base_clearance`` at the default pose.

    ``template_height`` is ``builder.nominal_height(template)`` when the caller has it (saves a compile per robot).

    Returns:
        The factors and the generated robot (:func:`generate_robot`).

    Raises:
        ValueError: No draw in :data:`MAX_REDRAWS` clears the ground (the config's ranges cannot meet it).
    """
    template_height = nominal_height(template) if template_height is None else template_height
    for _ in range(MAX_REDRAWS):
        sample = _draw(rng, cfg)
        robot = generate_robot(template, sample, cfg, name, template_height=template_height)
        standing = robot.init_height - (template.init_height - template_height)
        if base_clearance(robot, standing) >= cfg.min_base_clearance:
            return sample, robot
    raise ValueError(
        f"no generated robot in {MAX_REDRAWS} draws has its base {cfg.min_base_clearance} m above "
        "the ground; widen env.rand.geometry's ranges or lower min_base_clearance."
    )


def stretch_inertia(inertia: np.ndarray, mass_ratio: float, axis_factor: np.ndarray) -> np.ndarray:
    """Principal inertia of a body whose mass is x ``mass_ratio`` and whose extent along x, y, z is x ``axis_factor``.

    Through the second moments S_x = sum m x^2 = (I_yy + I_zz - I_xx) / 2 (and cyclic): each S_k scales with the
    mass and the square of its axis' factor, and I_xx = S_y + S_z again, so the result is a physical inertia
    whenever the input is (a box's inertia stays a box's).

    Args:
        inertia: (I_xx, I_yy, I_zz) about the COM (kg m^2). Shape: (3,).
        mass_ratio: New mass over old.
        axis_factor: Stretch of each axis. Shape: (3,).

    Returns:
        The new (I_xx, I_yy, I_zz). Shape: (3,).
    """
    i = np.asarray(inertia, dtype=np.float64)
    second = np.array([i[1] + i[2] - i[0], i[0] + i[2] - i[1], i[0] + i[1] - i[2]]) / 2
    second = second * mass_ratio * np.asarray(axis_factor) ** 2
    return np.array([second[1] + second[2], second[0] + second[2], second[0] + second[1]])


def generate_robot(
    template: RobotSpec,
    sample: GeometrySample,
    cfg: GeometryRandCfg,
    name: str | None = None,
    *,
    template_height: float | None = None,
) -> RobotSpec:
    """The template with one sample's geometry, masses and gains (module docstring); a pure function.

    Args:
        template: The template robot (Go2).
        sample: The factors.
        cfg: The generator's config (``gains_with_mass``, ``torque_with_mass``).
        name: The generated robot's name (default ``<template>_generated``).
        template_height: ``builder.nominal_height(template)`` when the caller has it (saves a compile).

    Returns:
        A new spec; ``builder.build_model`` compiles it with the template's structure.
    """
    s = sample.scale
    size_f = sample.base_size * s
    base_size = template.base_size * size_f
    base_mass = template.base_mass * sample.base_density * float(np.prod(size_f))
    base_inertia = stretch_inertia(template.base_inertia, base_mass / template.base_mass, size_f)
    hip_f = np.array([size_f[0] * sample.hip_pos[0], size_f[1] * sample.hip_pos[1], size_f[2]])
    lengths = sample.length_factors()
    links = {}
    for i, link in enumerate(LINKS):
        nominal = template.links[link]
        mass = nominal.mass * sample.link_mass[i] * s**3
        ratio = mass / nominal.mass if nominal.mass > 0 else 0.0
        links[link] = LinkInertial(
            mass=mass, com=nominal.com * lengths[link], inertia=nominal.inertia * ratio * lengths[link] ** 2
        )
    calf_r = sample.calf_radius * s
    link_radius = template.link_radius * np.array([s, calf_r * sample.thigh_radius_ratio, calf_r])
    rotor_mass = template.rotor_mass * s**3
    total = base_mass + 4 * (sum(li.mass for li in links.values()) + float(rotor_mass.sum()))
    mass_ratio = total / template.total_mass
    gain = mass_ratio if cfg.gains_with_mass else 1.0
    torque = mass_ratio if cfg.torque_with_mass else 1.0
    descriptor = template.descriptor.copy()
    descriptor[[0, 1, 2, 3, 4]] = [
        links["thigh"].mass,
        links["calf"].mass,
        links["hip"].mass,
        links["foot"].mass,
        base_mass,
    ]
    robot = dataclasses.replace(
        template,
        name=name or f"{template.name}_generated",
        display_name=f"{template.display_name} (generated)",
        is_template=False,
        descriptor=as_descriptor(descriptor, "generated descriptor"),
        descriptor_source="generated (morfic_cli/morphology/procedural.py)",
        base_size=base_size,
        base_mass=base_mass,
        base_com=template.base_com * size_f,
        base_inertia=base_inertia,
        hip_pos=template.hip_pos * hip_f,
        thigh_offset=template.thigh_offset * lengths["hip"],
        calf_offset=template.calf_offset * lengths["thigh"],
        foot_offset=template.foot_offset * lengths["calf"],
        foot_radius=template.foot_radius * calf_r,
        link_radius=link_radius,
        links=links,
        rotor_mass=rotor_mass,
        rotor_radius=template.rotor_radius * s,
        torque_limit=template.torque_limit * torque,
        kp=template.kp * gain,
        kd=template.kd * gain,
        public_total_mass=total,
        conflicts=(),
        facts=(),
    )
    template_height = nominal_height(template) if template_height is None else template_height
    clearance = template.init_height - template_height
    return dataclasses.replace(robot, init_height=nominal_height(robot) + clearance)


@dataclass(frozen=True, eq=False)
class GeometryPool:
    """K generated robots, compiled once per env (``CpuBackend.set_geometry_pool``) and drawn at reset.

    Attributes:
        robots: The generated specs. Length K.
        samples: Their factors, in the same order. Length K.
        descriptors: Each robot's 11-D descriptor (kg, rad). Shape: (K, 11).
        init_height: Each robot's reset base height (m). Shape: (K,).
        nominal_foot_pos_b: Each robot's nominal foot xy under the hips (hip position + thigh offset), base frame
            (m), as the env's ``nominal_foot_pos_b``. Shape: (K, 4, 2).
    """

    robots: tuple[RobotSpec, ...]
    samples: tuple[GeometrySample, ...]
    descriptors: np.ndarray
    init_height: np.ndarray
    nominal_foot_pos_b: np.ndarray

    @classmethod
    def of(cls, robots: Sequence[RobotSpec], samples: Sequence[GeometrySample]) -> GeometryPool:
        """A pool of these robots and samples (same length)."""
        return cls(
            robots=tuple(robots),
            samples=tuple(samples),
            descriptors=np.stack([r.descriptor for r in robots]),
            init_height=np.array([r.init_height for r in robots]),
            nominal_foot_pos_b=np.stack([r.hip_pos[:, :2] + r.thigh_offset[:, :2] for r in robots]),
        )


def generate_pool(template: RobotSpec, cfg: GeometryRandCfg, seed: int) -> GeometryPool:
    """``cfg.pool_size`` robots generated around ``template``, reproducible from ``seed``.

    Args:
        template: The template robot.
        cfg: The generator's ranges and pool size.
        seed: Seed (the env's); mixed with :data:`POOL_SEED_SALT`.

    Returns:
        The pool; robot k is named ``<template>_gen<k>``.
    """
    rng = np.random.default_rng([int(seed), POOL_SEED_SALT])
    height = nominal_height(template)
    drawn = [
        sample_geometry(rng, cfg, template, f"{template.name}_gen{k}", template_height=height)
        for k in range(cfg.pool_size)
    ]
    return GeometryPool.of([robot for _, robot in drawn], [sample for sample, _ in drawn])
