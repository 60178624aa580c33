"""CSV table artifacts: one place for each table's columns and how it enters the store."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from morfic_cli.store import Published

DISTANCE_COLUMNS: tuple[str, ...] = ("robot", "d", "reference", "normalize", "n_outside", "outside")
"""Columns of the distance table (``morfic distance``)."""


def rows_to_csv(rows: Sequence[dict], columns: Sequence[str]) -> bytes:
    """Serialise rows to CSV bytes with pandas, columns in the given order."""
    import pandas as pd

    buf = io.StringIO()
    pd.DataFrame(list(rows), columns=list(columns)).to_csv(buf, index=False, lineterminator="\n")
    return buf.getvalue().encode()


def write_distance_table(
    store_root: Path, rows: Sequence[dict], names: Sequence[str], reference: str, normalize: str
) -> Published:
    """Store the distance table as a ``table`` manifest and advance ref ``tables/distance``.

    Args:
        store_root: Store root directory.
        rows: Flat rows with :data:`DISTANCE_COLUMNS`.
        names: Robots in the comparison.
        reference: Reference robot (m_train).
        normalize: "span" or "support".

    Returns:
        The manifest id, ref and ref version.
    """
    from morfic_cli.morphology.distance import robot_file_digests
    from morfic_cli.store import Store

    store = Store(store_root)
    digests = robot_file_digests(sorted({*names, reference}))
    # the robot files are part of the config: the same files and options give the same table, which is then reused
    # (running `morfic distance` again adds no ref version); an edited TOML gives a new one
    config = {
        "table": "distance",
        "robots": list(names),
        "reference": reference,
        "normalize": normalize,
        "robot_toml_sha256": digests,
    }
    return store.publish(
        "table",
        "tables/distance",
        config=config,
        reuse=True,
        files={"distance.csv": rows_to_csv(rows, DISTANCE_COLUMNS)},
        meta={"robot_toml_sha256": digests},
    )


BENCH_ENV_COLUMNS: tuple[str, ...] = (
    "num_envs",
    "steps",
    "backend",
    "device",
    "threads",
    "env_steps_per_s",
    "physics_floor_steps_per_s",
    "floor_env_steps_per_s",
    "ratio",
    "cpu_model",
    "cores",
    "repeats",
    "ratio_spread",
    "env_steps_per_s_spread",
    "noisy",
    "load_before",
    "load_after",
)
"""Columns of the env benchmark table (``morfic bench env``)."""


BENCH_TRAIN_COLUMNS: tuple[str, ...] = (
    "preset",
    "variant",
    "backend",
    "device",
    "num_envs",
    "iterations",
    "transitions",
    "s_per_iteration",
    "collect_s_per_iteration",
    "learn_s_per_iteration",
    "train_steps_per_s",
    "floor_env_steps_per_s",
    "fraction_of_floor",
    "torch_threads",
    "cpu_model",
    "cores",
    "s_per_iteration_spread",
    "fraction_spread",
    "noisy",
    "load_before",
    "load_after",
    "omp_wait_policy",
    "mixed_precision",
    "bf16_kernels",
    "bf16_matmul",
)
"""Columns of the training benchmark table (``morfic bench train``)."""


BENCH_KEYS: dict[str, tuple[str, tuple[str, ...]]] = {
    "env": ("num_envs", BENCH_ENV_COLUMNS),
    "train": ("preset", BENCH_TRAIN_COLUMNS),
}
"""Per benchmark: the column its config lists, and the table's columns."""


def write_bench_table(store_root: Path, what: str, rows: Sequence[dict]) -> Published:
    """Store a ``morfic bench env|train`` table as a ``table`` manifest and advance ref ``tables/bench-<what>``."""
    from morfic_cli.store import Store

    key, columns = BENCH_KEYS[what]
    return Store(store_root).publish(
        "table",
        f"tables/bench-{what}",
        config={"table": f"bench-{what}", key: [r[key] for r in rows]},
        files={f"bench_{what}.csv": rows_to_csv(rows, columns)},
    )
