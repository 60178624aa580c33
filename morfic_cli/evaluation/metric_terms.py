"""Eval metrics as registered terms: one :class:`MetricTerm` per column of ``eval.csv`` (docs/eval.md).

A term declares its name (the ``eval.csv`` column), its computation (a pure function of one rollout's recorded
arrays, :class:`RolloutData`), unit, format, whether higher is better, how ``compare-baselines`` aggregates it over
seeds (:class:`SeedColumn`) and whether the ``morfic eval`` table shows it. :data:`METRICS` is read by

- the eval row and ``eval.csv``'s columns (:func:`~morfic_cli.evaluation.protocol.metrics_row`,
  :func:`~morfic_cli.evaluation.protocol.eval_columns`; the store's ``eval`` manifests and ``eval --out``),
- the ``morfic eval`` table (``show``, ``header``, ``fmt``, ``legend``),
- ``compare-baselines``' ``transfer`` table (``seeds``), and through it the report.

The MCAP rollout logs hold the per-step arrays, not the metrics. The stock terms read the paper's metrics of
:func:`~morfic_cli.evaluation.metrics.transfer_metrics` (computed once per rollout), so their numbers are those
of that function. A new metric is one entry appended to :data:`METRICS` (or :func:`register_metric` from your own
module) and its row in docs/eval.md: docs/extending.md, "An eval metric".
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from morfic_cli.evaluation.metrics import TransferMetrics, alive_mask, paper_cell, transfer_metrics
from morfic_cli.evaluation.seeds import mean, num, seed_std, step_sigma

Rows = Sequence[Mapping[str, Any]]
"""One cell's eval rows over seeds (``eval.csv`` rows, values strings or numbers; a column may be missing)."""


@dataclass(frozen=True)
class RolloutData:
    """What a metric is computed from: one rollout of one robot and command.

    Attributes:
        arrays: The recorded arrays (:data:`~morfic_cli.evaluation.rollout.RECORDED` plus ``reward_terms``),
            each (T, N, ...): e.g. ``base_lin_vel`` (T, N, 3), ``base_ang_vel`` (T, N, 3, body frame, rad/s),
            ``foot_slip`` (T, N), ``done`` / ``time_out`` (T, N) bool.
        command_vx: Commanded forward velocity (m/s).
        dt: Policy step (s).
    """

    arrays: Mapping[str, np.ndarray]
    command_vx: float
    dt: float

    @functools.cached_property
    def terminated(self) -> np.ndarray:
        """Falls (done and not a time-out). Shape: (T, N) bool."""
        return self.arrays["done"] & ~self.arrays["time_out"]

    @functools.cached_property
    def alive(self) -> np.ndarray:
        """alive[t, i]: env i has not terminated at or before step t (:func:`~.metrics.alive_mask`). (T, N) bool."""
        return alive_mask(self.terminated)

    @functools.cached_property
    def transfer(self) -> TransferMetrics:
        """The paper's metrics of this rollout (:func:`~morfic_cli.evaluation.metrics.transfer_metrics`)."""
        a = self.arrays
        return transfer_metrics(
            a["base_lin_vel"][..., 0],
            self.terminated,
            self.command_vx,
            self.dt,
            tilt=a["tilt"],
            height_ratio=a["height_ratio"],
            foot_slip=a["foot_slip"],
        )


@dataclass(frozen=True)
class SeedColumn:
    """One column of ``compare-baselines``' ``transfer`` table: a metric over one cell's seeds.

    Attributes:
        name: The column.
        reduce: The group's eval rows (one per seed) -> the value (None where there is none).
        header: Header in the ``compare-baselines`` table; None: JSON/CSV only.
        fmt: Format spec of that table's cell (``format(value, fmt)``).
    """

    name: str
    reduce: Callable[[Rows], Any]
    header: str | None = None
    fmt: str = ".2f"


def seed_mean(column: str) -> Callable[[Rows], float | None]:
    """Reducer: the mean over seeds of ``column`` (finite values; None if none)."""
    return lambda rows: mean(r.get(column) for r in rows)


def seed_spread(column: str) -> Callable[[Rows], float | None]:
    """Reducer: the sample std (ddof 1) over seeds of ``column`` (None with fewer than two seeds)."""
    return lambda rows: seed_std(r.get(column) for r in rows)


@dataclass(frozen=True)
class MetricTerm:
    """One eval metric: a column of ``eval.csv`` and everything that shows or aggregates it.

    Attributes:
        name: Column of ``eval.csv`` (and key of the ``morfic eval --format json`` rows).
        compute: Pure function of one rollout -> a float, int, bool or str.
        unit: Unit ("m/s", "rad/s", "1" for a ratio or fraction, "count", "text").
        doc: One line: what it is.
        fmt: Format spec of its cell in the ``morfic eval`` table; None: shown as text.
        higher_is_better: True / False, or None where neither is (a spread, a count, a verdict).
        seeds: Its columns in ``compare-baselines``' ``transfer`` table, over seeds; () for none.
        show: Its place in the ``morfic eval`` table, lower first (ties in column order); 0: not shown by default
            (JSON and CSV always hold every metric).
        header: Its header in that table (default ``name``).
        legend: Its entry in that table's caption (e.g. "track: v_x / cmd"); "" for none.
        align: Justification in that table ("right" or "left").
        drop: Where the terminal is too narrow, shown columns with ``drop > 0`` go first, highest first.
    """

    name: str
    compute: Callable[[RolloutData], Any]
    unit: str
    doc: str
    fmt: str | None = ".3f"
    higher_is_better: bool | None = None
    seeds: tuple[SeedColumn, ...] = ()
    show: int = 0
    header: str | None = None
    legend: str = ""
    align: str = "right"
    drop: int = 0


def _paper(field: str) -> Callable[[RolloutData], Any]:
    """The field ``field`` of the rollout's :class:`~morfic_cli.evaluation.metrics.TransferMetrics`."""
    return lambda r: getattr(r.transfer, field)


def _cell_over_seeds(rows: Rows) -> str:
    """The paper's cell over seeds: mean v_x ± σ pooled over steps / mean S ("1.84 ± 0.26 / 1.000")."""
    vx, s = mean(r.get("vx_mean") for r in rows), mean(r.get("survival") for r in rows)
    return f"{num(vx, 2)} ± {num(step_sigma(rows), 2)} / {num(s, 3)}"


METRICS: list[MetricTerm] = [
    MetricTerm(
        "vx_mean",
        _paper("vx_mean"),
        "m/s",
        "v_x: per env the mean forward velocity over its alive steps, then the mean over envs",
        higher_is_better=True,
        seeds=(SeedColumn("vx", seed_mean("vx_mean")),),
    ),
    MetricTerm(
        "vx_std",
        _paper("vx_std"),
        "m/s",
        "σ, the paper's ± term: std over every alive (env, step) sample",
        seeds=(SeedColumn("vx_std", step_sigma), SeedColumn("vx_seed_std", seed_spread("vx_mean"), header="σ seeds")),
    ),
    MetricTerm("vx_env_std", _paper("vx_env_std"), "m/s", "std over envs of the per-env means (not the paper's σ)"),
    MetricTerm("vx_step_mean", _paper("vx_step_mean"), "m/s", "mean over the alive (env, step) samples"),
    MetricTerm("n_alive", _paper("n_alive"), "count", "alive (env, step) samples behind σ"),
    MetricTerm(
        "vx_peak_1s_mean",
        _paper("vx_peak_1s_mean"),
        "m/s",
        "best 1 s moving average of v_x, mean over envs",
        fmt=".2f",
        higher_is_better=True,
        seeds=(SeedColumn("vx_peak_1s", seed_mean("vx_peak_1s_mean"), header="peak 1 s"),),
        show=2,
        header="peak",
        legend="peak: best 1 s moving average (morfic's extra)",
        drop=3,
    ),
    MetricTerm("vx_peak_1s_std", _paper("vx_peak_1s_std"), "m/s", "std over envs of that peak"),
    MetricTerm(
        "survival",
        _paper("survival"),
        "1",
        "S: fraction of envs alive at the last step",
        higher_is_better=True,
        seeds=(SeedColumn("survival", seed_mean("survival")), SeedColumn("survival_seed_std", seed_spread("survival"))),
    ),
    MetricTerm(
        "tracking_ratio",
        _paper("tracking_ratio"),
        "1",
        "v_x / vx_cmd",
        fmt=".2f",
        seeds=(SeedColumn("tracking_ratio", seed_mean("tracking_ratio")),),
        show=3,
        header="track",
        legend="track: v_x / cmd",
        drop=2,
    ),
    MetricTerm(
        "valid", _paper("valid"), "bool", "at least half the envs survive with a valid gait", higher_is_better=True
    ),
    MetricTerm(
        "valid_fraction",
        _paper("valid_fraction"),
        "1",
        "fraction of envs that survive with a valid gait",
        higher_is_better=True,
        seeds=(SeedColumn("valid_fraction", seed_mean("valid_fraction")),),
    ),
    MetricTerm(
        "verdict",
        _paper("verdict"),
        "text",
        '"ok" or the most common failure',
        fmt=None,
        show=4,
        header="validity",
        legend="validity: moving, upright, no dragging",
        align="left",
    ),
    MetricTerm(
        "cell",
        lambda r: paper_cell(r.transfer),
        "text",
        "the paper's cell v_x ± σ / S",
        fmt=None,
        seeds=(SeedColumn("cell", _cell_over_seeds),),
        show=1,
        header="v_x ± σ / S",
        legend="v_x: mean forward velocity over alive steps (at 2.5 m/s also the paper's v_x^max); σ: std over "
        "all alive (env, step) samples; S: survival",
    ),
]
"""The eval metrics, in ``eval.csv``'s column order (append a new one at the end)."""


def register_metric(term: MetricTerm) -> None:
    """Append ``term`` to :data:`METRICS` (from a user's module; a test monkeypatches :data:`METRICS` first).

    Raises:
        ValueError: its name, or one of its seed columns' names, is taken.
    """
    taken = {t.name for t in METRICS} | {c.name for c in seed_columns()}
    clash = {term.name, *(c.name for c in term.seeds)} & taken
    if clash:
        raise ValueError(f"eval metric '{term.name}': {sorted(clash)} already registered")
    METRICS.append(term)


def metric_terms() -> tuple[MetricTerm, ...]:
    """The registered metrics, in column order."""
    return tuple(METRICS)


def metric_values(data: RolloutData) -> dict[str, Any]:
    """Every registered metric of one rollout, name -> value, in column order."""
    return {t.name: t.compute(data) for t in METRICS}


def seed_columns() -> tuple[SeedColumn, ...]:
    """The ``transfer`` table's columns over seeds, in the metrics' order."""
    return tuple(c for t in METRICS for c in t.seeds)


def shown_terms() -> tuple[MetricTerm, ...]:
    """The metrics the ``morfic eval`` table shows by default, in the table's order (``MetricTerm.show``)."""
    return tuple(sorted((t for t in METRICS if t.show > 0), key=lambda t: t.show))
