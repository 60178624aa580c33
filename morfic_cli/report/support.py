"""The morphology-support table (paper Table "Morphology randomization parameters") as a store artifact.

Its numbers are facts of the robot library (each robot's 11-D descriptor) and of the training support; the report
reads them from a ``table`` manifest (ref ``tables/morphology-support``) so that they, like every other number of
the report, carry an artifact id. :func:`ensure_support_table` writes it once per robot-library content (the TOML
digests are in its config) and finds it again afterwards.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from morfic_cli.store import Store

SUPPORT_REF = "tables/morphology-support"
SUPPORT_COLUMNS: tuple[str, ...] = ("parameter", "label", "unit", "robot", "value", "train_min", "train_max", "support")


def support_rows(robots: Sequence[str]) -> list[dict[str, Any]]:
    """One row per (descriptor dimension, robot): value, training support, +1 above / -1 below / 0 inside."""
    from morfic_cli.morphology.descriptor import DESCRIPTOR_LABELS
    from morfic_cli.morphology.robots import descriptor_rows, load_robot

    rows = []
    for robot in robots:
        for label, d in zip(DESCRIPTOR_LABELS, descriptor_rows(load_robot(robot)), strict=True):
            rows.append(
                {
                    "parameter": d["name"],
                    "label": label,
                    "unit": d["unit"],
                    "robot": robot,
                    "value": d["value"],
                    "train_min": d["train_min"],
                    "train_max": d["train_max"],
                    "support": d["support"],
                }
            )
    return rows


def ensure_support_table(store: Store, robots: Sequence[str] | None = None) -> tuple[str, bool]:
    """The id of the support table of ``robots`` (default: the paper's seven), writing it if not stored yet.

    Returns:
        ``(manifest id, reused)``.
    """
    from morfic_cli.morphology.distance import robot_file_digests
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.report.paper import ROBOTS

    names = list(robots or ROBOTS)
    config = {"table": "morphology-support", "robots": names, "robot_toml_sha256": robot_file_digests(names)}
    pub = store.publish(
        "table",
        SUPPORT_REF,
        config=config,
        reuse=True,
        files={"support.csv": rows_to_csv(support_rows(names), SUPPORT_COLUMNS)},
    )
    return pub.id, pub.reused
