"""The paper's 11-D morphology descriptor, its training support, sampling and distance.

Order (docs/robots.md; the paper's Table "Morphology randomization parameters"):

====  =================  =====
 i     name               unit
====  =================  =====
 0     thigh_mass         kg
 1     calf_mass          kg
 2     hip_mass           kg
 3     foot_mass          kg
 4     base_mass          kg
 5     hip_limit_min      rad
 6     hip_limit_max      rad
 7     thigh_limit_min    rad
 8     thigh_limit_max    rad
 9     calf_limit_min     rad
10     calf_limit_max     rad
====  =================  =====

The training support is the paper's "Train min / Train max" columns. The normalised distance is
eq. (morph_dist): ``d = ||m~_target - m~_train||_2 / sqrt(11)`` with ``m~`` min-max normalised per
dimension.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from morfic_cli.errors import DescriptorError

DESCRIPTOR_NAMES: tuple[str, ...] = (
    "thigh_mass",
    "calf_mass",
    "hip_mass",
    "foot_mass",
    "base_mass",
    "hip_limit_min",
    "hip_limit_max",
    "thigh_limit_min",
    "thigh_limit_max",
    "calf_limit_min",
    "calf_limit_max",
)
"""The 11 descriptor dimensions, in the paper's order."""

DESCRIPTOR_UNITS: tuple[str, ...] = ("kg",) * 5 + ("rad",) * 6
"""Unit of each dimension."""

DESCRIPTOR_LABELS: tuple[str, ...] = (
    "Thigh mass",
    "Calf mass",
    "Hip mass",
    "Foot mass",
    "Base mass",
    "Hip limit min",
    "Hip limit max",
    "Thigh limit min",
    "Thigh limit max",
    "Calf limit min",
    "Calf limit max",
)
"""Row labels as printed in the paper's table."""

DIM = len(DESCRIPTOR_NAMES)

TRAIN_MIN = np.array([0.634, 0.064, 0.510, 0.000, 3.300, -1.100, 0.800, -1.650, 3.490, -2.720, -0.950])
"""Paper, Table "Morphology randomization parameters", column "Train min". Shape: (11,)."""

TRAIN_MAX = np.array([1.152, 0.166, 0.696, 0.060, 6.921, -0.800, 1.100, -1.050, 4.050, -2.600, -0.780])
"""Paper, Table "Morphology randomization parameters", column "Train max". Shape: (11,)."""

#: Sanity bounds for any descriptor (not the training support): masses in [0, 500] kg, joint
#: limits within [-4 pi, 4 pi]. Values outside are rejected as physically implausible input.
SANE_MIN = np.array([0.0] * 5 + [-4 * math.pi] * 6)
SANE_MAX = np.array([500.0] * 5 + [4 * math.pi] * 6)

#: (min, max) index pairs of the three joint-limit intervals.
LIMIT_PAIRS: tuple[tuple[int, int], ...] = ((5, 6), (7, 8), (9, 10))


def as_descriptor(values: Sequence[float] | Mapping[str, float] | np.ndarray, what: str = "descriptor") -> np.ndarray:
    """Validate and convert a descriptor to a float64 array in the paper's order.

    Args:
        values: 11 numbers in :data:`DESCRIPTOR_NAMES` order, or a mapping name -> value.
        what: Name used in error messages (e.g. "go1 descriptor").

    Returns:
        Array. Shape: (11,).

    Raises:
        DescriptorError: wrong length, unknown or missing names, non-finite values, a value
            outside the sanity bounds, or a min limit above its max limit.
    """
    if isinstance(values, Mapping):
        unknown = sorted(set(values) - set(DESCRIPTOR_NAMES))
        missing = [n for n in DESCRIPTOR_NAMES if n not in values]
        if unknown or missing:
            raise DescriptorError(
                f"{what}: unknown keys {unknown} / missing keys {missing}; "
                f"the 11 keys are {', '.join(DESCRIPTOR_NAMES)}."
            )
        values = [values[n] for n in DESCRIPTOR_NAMES]
    try:
        m = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DescriptorError(f"{what}: expected 11 numbers, got {values!r}.") from exc
    if m.shape != (DIM,):
        raise DescriptorError(f"{what}: expected 11 numbers ({', '.join(DESCRIPTOR_NAMES)}), got shape {m.shape}.")
    if not np.all(np.isfinite(m)):
        raise DescriptorError(f"{what}: values must be finite, got {m.tolist()}.")
    for i in range(DIM):
        if not SANE_MIN[i] <= m[i] <= SANE_MAX[i]:
            raise DescriptorError(
                f"{what}: {DESCRIPTOR_NAMES[i]} = {m[i]:g} {DESCRIPTOR_UNITS[i]} is outside the sane range "
                f"[{SANE_MIN[i]:g}, {SANE_MAX[i]:g}]; check the units (kg, rad)."
            )
    for lo, hi in LIMIT_PAIRS:
        if m[lo] > m[hi]:
            raise DescriptorError(
                f"{what}: {DESCRIPTOR_NAMES[lo]} = {m[lo]:g} is above {DESCRIPTOR_NAMES[hi]} = {m[hi]:g}; "
                "a joint's min limit must not exceed its max limit."
            )
    return m


def support_flags(m: np.ndarray, lo: np.ndarray = TRAIN_MIN, hi: np.ndarray = TRAIN_MAX) -> np.ndarray:
    """Where a descriptor leaves the training support, as in the paper's up/down marks.

    Args:
        m: Descriptor(s). Shape: (..., 11).
        lo: Support minimum. Shape: (11,).
        hi: Support maximum. Shape: (11,).

    Returns:
        Int array, +1 above the support (paper's up arrow), -1 below (down arrow), 0 inside.
        Shape: (..., 11).
    """
    m = np.asarray(m, dtype=np.float64)
    return (m > hi).astype(np.int64) - (m < lo).astype(np.int64)


def sample_uniform(
    n: int, rng: np.random.Generator, lo: np.ndarray = TRAIN_MIN, hi: np.ndarray = TRAIN_MAX
) -> np.ndarray:
    """Sample descriptors uniformly from the box support, m ~ p_train(m).

    Args:
        n: Number of descriptors.
        rng: numpy random generator (seeded by the caller).
        lo: Support minimum. Shape: (11,).
        hi: Support maximum. Shape: (11,).

    Returns:
        Samples. Shape: (n, 11). Every joint-limit pair keeps min <= max because the support
        boxes of a min and its max do not overlap.
    """
    return lo + (hi - lo) * rng.random((n, DIM))


def normalize(m: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Min-max normalise per dimension, m~ = (m - lo) / (hi - lo).

    A dimension with zero span (hi == lo) normalises to 0.

    Args:
        m: Descriptor(s). Shape: (..., 11).
        lo: Per-dimension minimum. Shape: (11,).
        hi: Per-dimension maximum. Shape: (11,).

    Returns:
        Normalised descriptor(s). Shape: (..., 11).
    """
    span = np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)
    safe = np.where(span > 0, span, 1.0)
    return np.where(span > 0, (np.asarray(m, dtype=np.float64) - lo) / safe, 0.0)


@dataclass(frozen=True)
class NormalizationBounds:
    """Per-dimension min/max used to normalise descriptors for the distance.

    Attributes:
        lo: Minimum per dimension. Shape: (11,).
        hi: Maximum per dimension. Shape: (11,).
        mode: "span" (training support and every compared robot) or "support" (support only).
    """

    lo: np.ndarray
    hi: np.ndarray
    mode: str


def distance_bounds(descriptors: Sequence[np.ndarray], mode: str = "span") -> NormalizationBounds:
    """Normalisation bounds for eq. (morph_dist).

    Args:
        descriptors: Descriptors of every robot in the comparison (the reference included).
        mode: "span": min/max over the training support and all ``descriptors``, so every
            normalised value is in [0, 1] and d is in [0, 1]; "support": the training support
            only (values outside it normalise below 0 or above 1, and d can exceed 1).

    Returns:
        The bounds.
    """
    if mode == "support":
        return NormalizationBounds(TRAIN_MIN.copy(), TRAIN_MAX.copy(), mode)
    if mode != "span":
        raise DescriptorError(f"unknown normalisation '{mode}'; use 'span' or 'support'.")
    stack = np.vstack([TRAIN_MIN, TRAIN_MAX, *[np.asarray(d, dtype=np.float64) for d in descriptors]])
    return NormalizationBounds(stack.min(axis=0), stack.max(axis=0), mode)


def morph_distance(m_target: np.ndarray, m_train: np.ndarray, bounds: NormalizationBounds) -> float:
    """Normalised morphology distance, eq. (morph_dist) in the paper.

    d(m_target, m_train) = || m~_target - m~_train ||_2 / sqrt(11)

    Args:
        m_target: Target descriptor. Shape: (11,).
        m_train: Training (reference) descriptor. Shape: (11,).
        bounds: Per-dimension normalisation bounds (see :func:`distance_bounds`).

    Returns:
        d, a float (in [0, 1] for "span" bounds).
    """
    diff = normalize(m_target, bounds.lo, bounds.hi) - normalize(m_train, bounds.lo, bounds.hi)
    return float(np.linalg.norm(diff) / math.sqrt(DIM))
