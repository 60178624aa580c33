"""CSV table artifacts: one place for each table's columns and how it enters the store."""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

DISTANCE_COLUMNS: tuple[str, ...] = ("robot", "d", "reference", "normalize", "n_outside", "outside")
"""Columns of the distance table (``morfic distance``)."""


@dataclass(frozen=True)
class WrittenArtifact:
    """An artifact a command wrote: manifest id, the ref it advanced, and that ref's new version."""

    id: str
    ref: str
    version: int


def rows_to_csv(rows: Sequence[dict], columns: Sequence[str]) -> bytes:
    """Serialise rows to CSV bytes with pandas, columns in the given order."""
    import pandas as pd

    buf = io.StringIO()
    pd.DataFrame(list(rows), columns=list(columns)).to_csv(buf, index=False, lineterminator="\n")
    return buf.getvalue().encode()


def write_distance_table(
    store_root: Path, rows: Sequence[dict], names: Sequence[str], reference: str, normalize: str
) -> WrittenArtifact:
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
    config = {"table": "distance", "robots": list(names), "reference": reference, "normalize": normalize}
    with store.writing():
        mid = store.put_manifest(
            "table",
            config=config,
            files={"distance.csv": rows_to_csv(rows, DISTANCE_COLUMNS)},
            meta={"robot_toml_sha256": robot_file_digests(sorted({*names, reference}))},
        )
        version = store.set_ref("tables/distance", mid)
    return WrittenArtifact(mid, "tables/distance", version)


BENCH_ENV_COLUMNS: tuple[str, ...] = (
    "num_envs", "steps", "backend", "device", "threads", "env_steps_per_s", "physics_floor_steps_per_s",
    "floor_env_steps_per_s", "ratio", "cpu_model", "cores", "repeats", "ratio_spread", "env_steps_per_s_spread",
    "noisy", "load_before", "load_after",
)
"""Columns of the env benchmark table (``morfic bench env``)."""


def write_bench_table(store_root: Path, rows: Sequence[dict]) -> WrittenArtifact:
    """Store a ``morfic bench env`` table as a ``table`` manifest and advance ref ``tables/bench-env``."""
    from morfic_cli.store import Store

    store = Store(store_root)
    with store.writing():
        mid = store.put_manifest(
            "table",
            config={"table": "bench-env", "num_envs": [r["num_envs"] for r in rows]},
            files={"bench_env.csv": rows_to_csv(rows, BENCH_ENV_COLUMNS)},
        )
        version = store.set_ref("tables/bench-env", mid)
    return WrittenArtifact(mid, "tables/bench-env", version)


BENCH_TRAIN_COLUMNS: tuple[str, ...] = (
    "preset", "variant", "backend", "device", "num_envs", "iterations", "transitions", "s_per_iteration",
    "collect_s_per_iteration", "learn_s_per_iteration", "train_steps_per_s", "floor_env_steps_per_s",
    "fraction_of_floor", "torch_threads", "cpu_model", "cores", "s_per_iteration_spread", "fraction_spread", "noisy",
    "load_before", "load_after", "omp_wait_policy",
)
"""Columns of the training benchmark table (``morfic bench train``)."""


def write_bench_train_table(store_root: Path, rows: Sequence[dict]) -> WrittenArtifact:
    """Store a ``morfic bench train`` table as a ``table`` manifest and advance ref ``tables/bench-train``."""
    from morfic_cli.store import Store

    store = Store(store_root)
    with store.writing():
        mid = store.put_manifest(
            "table",
            config={"table": "bench-train", "preset": [r["preset"] for r in rows]},
            files={"bench_train.csv": rows_to_csv(rows, BENCH_TRAIN_COLUMNS)},
        )
        version = store.set_ref("tables/bench-train", mid)
    return WrittenArtifact(mid, "tables/bench-train", version)
