"""The morphology-distance table of eq. (morph_dist) over robots of the library."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

from morfic_cli.morphology.descriptor import (
    DESCRIPTOR_NAMES,
    distance_bounds,
    morph_distance,
    support_flags,
)
from morfic_cli.morphology.robots import RobotSpec, list_robots, load_robot

ARROWS = {1: "↑", -1: "↓"}


@dataclass(frozen=True)
class DistanceRow:
    """One robot's distance to the reference.

    Attributes:
        robot: Robot name.
        d: Normalised distance, eq. (morph_dist).
        outside: Descriptor dimensions outside the training support, name -> +1 (above) / -1 (below).
    """

    robot: str
    d: float
    outside: dict[str, int]

    def as_row(self, reference: str, normalize: str) -> dict:
        """A flat dict for printing and CSV (``outside`` as ``"name↑; name↓"``)."""
        return {
            "robot": self.robot,
            "d": round(self.d, 6),
            "reference": reference,
            "normalize": normalize,
            "n_outside": len(self.outside),
            "outside": "; ".join(f"{k}{ARROWS[v]}" for k, v in self.outside.items()),
        }


def parse_robot_list(robots: str) -> list[str]:
    """Parse ``--robots`` ("all" or "go1,a1"), validating every name (UnknownNameError otherwise)."""
    if robots.strip().lower() == "all":
        return list_robots()
    names = [n.strip() for n in robots.split(",") if n.strip()]
    return [load_robot(n).name for n in names]


def distance_table(names: Sequence[str], reference: str = "go2", normalize: str = "span") -> list[DistanceRow]:
    """Distance of each robot to the reference robot, eq. (morph_dist).

    The ``span`` bounds cover the training support, the reference and every robot in ``names``.

    Args:
        names: Robots to report (validated against the library).
        reference: Robot whose descriptor is m_train (default the Go2 template).
        normalize: "span" or "support" (see :func:`~morfic_cli.morphology.descriptor.distance_bounds`).

    Returns:
        One row per robot of ``names``, in that order.
    """
    ref = load_robot(reference)
    specs: list[RobotSpec] = [load_robot(n) for n in names]
    bounds = distance_bounds([ref.descriptor, *[s.descriptor for s in specs]], normalize)
    rows = []
    for spec in specs:
        flags = support_flags(spec.descriptor)
        outside = {DESCRIPTOR_NAMES[i]: int(f) for i, f in enumerate(flags) if f != 0}
        rows.append(DistanceRow(spec.name, morph_distance(spec.descriptor, ref.descriptor, bounds), outside))
    return rows


def robot_file_digests(names: Sequence[str]) -> dict[str, str]:
    """sha256 of each robot's TOML file, recorded in table manifests as provenance."""
    return {n: hashlib.sha256(load_robot(n).source_path.read_bytes()).hexdigest() for n in names}
