"""Statistics over seeds: what ``compare-baselines`` makes of one cell's runs (docs/report.md).

Pure functions of plain values (CSV strings, numbers, None); non-finite and unparsable values are left out.
The reducers of the eval metrics (:mod:`morfic_cli.evaluation.metric_terms`, ``MetricTerm.seeds``) are built on them.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from typing import Any


def finite(values: Iterable[Any]) -> list[float]:
    """The values that parse as finite floats, in order."""
    out = []
    for v in values:
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        if math.isfinite(f):
            out.append(f)
    return out


def mean(values: Iterable[Any]) -> float | None:
    """Mean of the finite values, None when there are none."""
    v = finite(values)
    return sum(v) / len(v) if v else None


def seed_std(values: Iterable[Any]) -> float | None:
    """Sample standard deviation over seeds (ddof 1); None with fewer than two finite values."""
    v = finite(values)
    return statistics.stdev(v) if len(v) >= 2 else None


def pooled_std(means: Sequence[Any], stds: Sequence[Any], counts: Sequence[Any] | None = None) -> float | None:
    """Population σ of the union of several sample sets from their means μ_i, σ_i and sizes n_i.

    σ² = Σ n_i (σ_i² + (μ_i - μ)²) / Σ n_i with μ = Σ n_i μ_i / Σ n_i; equal sizes when ``counts`` is None.
    With one set it is that set's σ (one seed: the run's own σ, the paper's ± term).
    """
    counts = counts if counts is not None else [1.0] * len(means)
    rows = []
    for m, s, n in zip(means, stds, counts, strict=True):
        try:
            m, s, n = float(m), float(s), float(n)
        except (TypeError, ValueError):
            continue
        if math.isfinite(m) and math.isfinite(s) and math.isfinite(n) and n > 0:
            rows.append((m, s, n))
    if not rows:
        return None
    total = sum(n for _, _, n in rows)
    mu = sum(n * m for m, _, n in rows) / total
    return math.sqrt(sum(n * (s * s + (m - mu) ** 2) for m, s, n in rows) / total)


def step_sigma(rows: Sequence[Mapping[str, Any]]) -> float | None:
    """The paper's σ of a cell: σ over all alive (env, step) samples of its runs (:func:`pooled_std`).

    None when any run's evaluation predates the σ over steps (its ``vx_std`` was the std of per-env means, another
    quantity; such an evaluation has no ``vx_env_std``): re-run ``morfic eval`` for those runs.
    """
    if any(r.get("vx_env_std") in (None, "") for r in rows):
        return None
    return pooled_std([r["vx_step_mean"] for r in rows], [r["vx_std"] for r in rows], [r["n_alive"] for r in rows])


def num(value: float | None, decimals: int) -> str:
    """``value`` with ``decimals`` decimals; "-" for None."""
    return "-" if value is None else f"{value:.{decimals}f}"
