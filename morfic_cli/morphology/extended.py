"""The extended morphology descriptor: the paper's 11-D vector, the actuators and the geometry (docs/robots.md).

The paper's descriptor (:mod:`morfic_cli.morphology.descriptor`) holds link masses and joint limits only, so a heavy
robot on the Go2 template looks like a heavy Go2 on Go2's gains (docs/falls.md). The extended vector adds what a
deployer knows about a robot: its total mass, its PD gains and torque limits, and the geometry the procedural
generator (:mod:`morfic_cli.morphology.procedural`) varies. Order (:data:`EXTENDED_NAMES`):

====  ==========================================  ==========
 i     name                                        unit
====  ==========================================  ==========
 0-10  the paper's 11-D descriptor, its order      kg, rad
 11    total_mass (base + 4 legs, rotors too)       kg
 12    kp                                           N m/rad
 13    kd                                           N m s/rad
 14-16 torque_limit_hip / _thigh / _calf            N m
 17-19 base_length / base_width / base_height       m
 20-21 hip_x / hip_y (hip joint from the base)      m
 22    thigh_offset (lateral hip-to-thigh)           m
 23    thigh_length                                 m
 24    calf_length                                  m
 25-26 thigh_radius / calf_radius (capsules)        m
 27    foot_radius                                  m
====  ==========================================  ==========

Entries 17-27 hold every length the generator scales (its ``scale``, base size, hip position, thigh offset, calf
length, thigh ratio, radii); its density and link-mass factors act through the masses 0-4 and 11. A generated
robot's entries are the template's times its factors (tested against ``GeometrySample``).

The bounded encoding (:func:`morfic_cli.envs.observations.extended_morphology_obs`, the group ``morphology`` when
``ObsCfg.extended_morphology`` is on): every positive quantity (masses, gains, torques, lengths) is log-scaled,
t = log(x + eps) with eps 5 % of Go2's value (:data:`LOG_EPS`; a zero foot mass or Kd stays finite); joint limits
stay in radians. t is normalised over a fixed support, z = 2 (t - lo) / (hi - lo) - 1 (:func:`extended_support`:
the paper's train min / max for entries 0-10, Go2's value / 2 to x 2 for the rest), then bounded,
BOUND * tanh(z / BOUND) with BOUND = 3: inside the support ([-1, 1]) that is z within 3.6 %, and no input, however
far out, goes beyond +-3 (B1's Kp of 250 N m/rad, 12.5x Go2's, encodes to 2.55; its descriptor's masses, +13 to +18
in the paper's normalisation, to 2.8-3.0).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from morfic_cli.morphology.descriptor import DESCRIPTOR_NAMES, TRAIN_MAX, TRAIN_MIN
from morfic_cli.morphology.robots import RobotSpec

ACTUATION_NAMES: tuple[str, ...] = (
    "total_mass",
    "kp",
    "kd",
    "torque_limit_hip",
    "torque_limit_thigh",
    "torque_limit_calf",
)
"""Entries 11-16 of the extended vector."""

GEOMETRY_NAMES: tuple[str, ...] = (
    "base_length",
    "base_width",
    "base_height",
    "hip_x",
    "hip_y",
    "thigh_offset",
    "thigh_length",
    "calf_length",
    "thigh_radius",
    "calf_radius",
    "foot_radius",
)
"""Entries 17-27 of the extended vector (m)."""

EXTENDED_NAMES: tuple[str, ...] = (*DESCRIPTOR_NAMES, *ACTUATION_NAMES, *GEOMETRY_NAMES)
"""The extended vector's entries, in order."""

EXTENDED_UNITS: tuple[str, ...] = (
    ("kg",) * 5 + ("rad",) * 6 + ("kg", "N m/rad", "N m s/rad") + ("N m",) * 3 + ("m",) * len(GEOMETRY_NAMES)
)
"""Unit of each entry."""

EXTENDED_DIM = len(EXTENDED_NAMES)
"""28."""

ACTUATION_START = len(DESCRIPTOR_NAMES)
"""Index of ``total_mass``: entries 11-16 are the actuation block."""

GEOMETRY_START = ACTUATION_START + len(ACTUATION_NAMES)
"""Index of ``base_length``: entries 17-27 are the geometry block."""

LOG_SCALED = np.array([True] * 5 + [False] * 6 + [True] * (EXTENDED_DIM - 11))
"""Which entries are log-scaled (everything but the six joint limits). Shape: (28,)."""

EPS_FRACTION = 0.05
"""eps of each log-scaled entry as a fraction of Go2's value."""

SUPPORT_FACTOR = 2.0
"""The support of entries 11-27: Go2's value / this to x this."""

BOUND = 3.0
"""The encoding's bound: BOUND * tanh(z / BOUND) lies in (-3, 3), 1.5 support widths from the support's centre."""


def geometry_vector(robot: RobotSpec) -> np.ndarray:
    """Entries 17-27 of a robot (front-left leg; every leg mirrors it). Shape: (11,), m."""
    return np.array(
        [
            *robot.base_size,
            abs(robot.hip_pos[0, 0]),
            abs(robot.hip_pos[0, 1]),
            abs(robot.thigh_offset[0, 1]),
            float(np.linalg.norm(robot.calf_offset[0])),
            float(np.linalg.norm(robot.foot_offset[0])),
            robot.link_radius[1],
            robot.link_radius[2],
            robot.foot_radius,
        ],
        dtype=np.float64,
    )


def actuation_vector(total_mass: float, kp: float, kd: float, torque_limit: np.ndarray) -> np.ndarray:
    """Entries 11-16: total mass (kg), Kp, Kd and the hip, thigh, calf torque limits. Shape: (6,)."""
    return np.array([total_mass, kp, kd, *np.asarray(torque_limit, dtype=np.float64)[:3]], dtype=np.float64)


def extended_descriptor(robot: RobotSpec, descriptor: np.ndarray | None = None) -> np.ndarray:
    """A robot's extended vector from its spec (its own model: full mode). Shape: (28,).

    Args:
        robot: The robot (robots/*.toml, or a generated one).
        descriptor: The 11-D descriptor to put first (default the robot's own).
    """
    desc = robot.descriptor if descriptor is None else descriptor
    return np.concatenate(
        [
            np.asarray(desc, dtype=np.float64),
            actuation_vector(robot.total_mass, robot.kp, robot.kd, robot.torque_limit),
            geometry_vector(robot),
        ]
    )


@lru_cache(maxsize=1)
def _go2() -> np.ndarray:
    from morfic_cli.morphology.robots import load_robot

    return extended_descriptor(load_robot("go2"))


def log_eps() -> np.ndarray:
    """The eps of t = log(x + eps) per entry: 5 % of Go2's value (0 for the joint limits, which are not logged).

    Shape: (28,).
    """
    return np.where(LOG_SCALED, EPS_FRACTION * _go2(), 0.0)


def transform(x: np.ndarray) -> np.ndarray:
    """t: log(x + eps) on the log-scaled entries, x on the joint limits. Shape: (..., 28) -> (..., 28)."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(LOG_SCALED, np.log(np.where(LOG_SCALED, x, 1.0) + log_eps()), x)


@lru_cache(maxsize=1)
def extended_support() -> tuple[np.ndarray, np.ndarray]:
    """The fixed support (lo, hi) of t (:func:`transform`'s space), each of shape (28,).

    Entries 0-10: the paper's train min / max; entries 11-27: Go2's value / :data:`SUPPORT_FACTOR` to
    x :data:`SUPPORT_FACTOR`. Fixed, so the encoding of a robot never changes during training.
    """
    go2 = _go2()
    lo = np.concatenate([TRAIN_MIN, go2[11:] / SUPPORT_FACTOR])
    hi = np.concatenate([TRAIN_MAX, go2[11:] * SUPPORT_FACTOR])
    return transform(lo), transform(hi)


def encode(x: np.ndarray) -> np.ndarray:
    """The bounded encoding, in numpy (the env's torch version is ``observations.extended_morphology_obs``).

    BOUND * tanh(z / BOUND) with z = 2 (t - lo) / (hi - lo) - 1. Shape: (..., 28) -> (..., 28), in (-3, 3).
    """
    lo, hi = extended_support()
    z = 2.0 * (transform(x) - lo) / (hi - lo) - 1.0
    return BOUND * np.tanh(z / BOUND)


def mass_ratio_gains(
    kp: float, kd: float, torque_limit: np.ndarray, ratio: float, torque_exponent: float
) -> tuple[float, float, np.ndarray]:
    """A deployer's rule: Kp, Kd x ratio, torque limits x ratio^torque_exponent (ratio = M / M_template).

    Returns:
        (Kp, Kd, torque limits); the limits keep ``torque_limit``'s shape.
    """
    return kp * ratio, kd * ratio, np.asarray(torque_limit, dtype=np.float64) * math.pow(ratio, torque_exponent)
