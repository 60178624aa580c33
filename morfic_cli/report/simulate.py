"""How often each claim's verdict rule speaks when it should not, and how often the intervals cover: simulated.

Vectorised over draws with numpy; each draw is one hypothetical store of normal seed values, and each claim's
rule (:mod:`morfic_cli.report.claims`: its primary comparisons, Holm over them, :func:`~morfic_cli.report.stats.
decide`) is applied with the same functions of :mod:`morfic_cli.report.stats` the report uses:

- **null** ((a), (b), (c), (e)): every variant on every robot drawn from one distribution, N(0, 1), ``n`` seeds
  each: any verdict but ``cannot tell`` is false;
- **(d), equal**: the four multiplicative variants alike (the claim true): a verdict with a reversal (``does not
  hold``, ``partly reversed``, ``mixed``) is false;
- **(d), boundary**: one variant (adaln) a tolerance τ = 1 sd away from the others on every robot, the least
  favourable case for "similar": ``holds`` is false too;
- **coverage**: Welch's 95 % interval of a known difference (0.5, sds 1 and 2) and the t-contrast's of (a)'s shape
  (4 against 3 variants, sds 0.5 to 2, known contrast 0.3): the share of draws whose interval holds the truth.

The numbers of docs/report.md ("How a verdict is read") come from :func:`calibration_markdown`
(``scripts/stats_calibration.py``); ``tests/report/test_stats.py`` checks them against alpha and 95 %.
"""

from __future__ import annotations

import math

import numpy as np

from morfic_cli.report import stats

DRAWS: int = 2000
"""Simulated stores per rate."""
SEED: int = 0
"""Generator seed of the simulation (the report's verdicts use no generator)."""
SEEDS: tuple[int, ...] = (3, 5)
"""Seeds per variant the rates are simulated at."""


def _welch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
    """Welch's (estimate, se, df, p, lo, hi) of mean(a) - mean(b) over the last axis, vectorised."""
    means = np.stack(np.broadcast_arrays(a.mean(-1), b.mean(-1)), -1)
    var = np.stack(np.broadcast_arrays(a.var(-1, ddof=1), b.var(-1, ddof=1)), -1)
    ns = np.array([a.shape[-1], b.shape[-1]], dtype=np.float64)
    return stats.contrast(means, var, ns, np.array([1.0, -1.0]))


def _verdicts(est: np.ndarray, p: np.ndarray, higher: np.ndarray | bool = True) -> np.ndarray:
    """Holm over the last axis, then each draw's verdict. Shapes: (D, m) -> (D,)."""
    return np.asarray(stats.decide(stats.outcome(est, stats.holm(p), higher)), dtype=object)


def claim_a(x: np.ndarray) -> np.ndarray:
    """(a): x (D, 3 robots, 7 variants: 4 multiplicative then 3 additive, n) -> verdicts (D,)."""
    n = x.shape[-1]
    c = np.array([1 / 4] * 4 + [-1 / 3] * 3)
    est, _, _, p, _, _ = stats.contrast(x.mean(-1), x.var(-1, ddof=1), np.full(7, float(n)), c)
    return _verdicts(est, p)


def claim_b(x: np.ndarray) -> np.ndarray:
    """(b): x (D, 3 robots, 4 variants: film then 3 baselines, n) -> verdicts (D,) over the 9 comparisons."""
    est, _, _, p, _, _ = _welch(x[:, :, :1], x[:, :, 1:])  # (D, 3, 3)
    return _verdicts(est.reshape(len(x), -1), p.reshape(len(x), -1))


def claim_c(x: np.ndarray) -> np.ndarray:
    """(c): x (D, 2 robots, 2 metrics, 4 critics: film then 3 baselines, n) -> verdicts (D,) over 12."""
    est, _, _, p, _, _ = _welch(x[..., :1, :], x[..., 1:, :])  # (D, 2, 2, 3)
    higher = np.array([False, True])[None, None, :, None] * np.ones(est.shape, dtype=bool)  # Flip < 0, Cos > 0
    return _verdicts(est.reshape(len(x), -1), p.reshape(len(x), -1), higher.reshape(len(x), -1))


def claim_d(x: np.ndarray, tol: float) -> np.ndarray:
    """(d): x (D, 3 robots, 4 multiplicative variants, n) -> verdicts (D,) over the 18 pairs' equivalence tests."""
    i, j = np.triu_indices(4, 1)
    est, se, df, _, _, _ = _welch(x[:, :, i], x[:, :, j])  # (D, 3, 6)
    from scipy import stats as sst

    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo, t_hi = (est + tol) / se, (est - tol) / se
    p_eq = np.minimum(1.0, 2 * np.maximum(sst.t.sf(t_lo, df), sst.t.cdf(t_hi, df)))
    p_out = np.minimum(1.0, 2 * np.minimum(sst.t.sf(t_hi, df), sst.t.cdf(t_lo, df)))
    way = np.where(p_eq <= p_out, 1.0, -1.0)
    p = np.minimum(p_eq, p_out)
    return _verdicts(way.reshape(len(x), -1), p.reshape(len(x), -1))


def claim_e(x: np.ndarray) -> np.ndarray:
    """(e): x (D, 7 variants, 7 robots ordered by d, n) -> verdicts (D,): Spearman of the means, exact p."""
    null = stats.spearman_null(x.shape[2])
    means = x.mean(-1)
    ranks = means.argsort(-1).argsort(-1).astype(np.float64)
    z = (ranks - ranks.mean(-1, keepdims=True)) / ranks.std(-1, keepdims=True)
    d = np.arange(x.shape[2], dtype=np.float64)
    rho = (z * (d - d.mean()) / d.std()).mean(-1)  # (D, 7)
    p = (null.size - np.searchsorted(null, np.abs(rho) - 1e-12, "left")) / null.size
    return _verdicts(rho, p, False)


def false_verdict_rates(n: int, draws: int = DRAWS, seed: int = SEED, tol: float = 1.0) -> dict[str, float]:
    """Share of simulated stores where each claim's rule gives a false verdict (module docstring).

    Returns:
        ``{"a": .., "b": .., "c": .., "d equal": .., "d boundary": .., "e": ..}``.
    """
    rng = np.random.default_rng(seed)
    out = {
        "a": np.mean(claim_a(rng.normal(size=(draws, 3, 7, n))) != stats.CANNOT),
        "b": np.mean(claim_b(rng.normal(size=(draws, 3, 4, n))) != stats.CANNOT),
        "c": np.mean(claim_c(rng.normal(size=(draws, 2, 2, 4, n))) != stats.CANNOT),
    }
    reversal = (stats.NOT, stats.REVERSED, stats.MIXED)
    out["d equal"] = np.mean(np.isin(claim_d(rng.normal(size=(draws, 3, 4, n)), tol), reversal))
    shifted = rng.normal(size=(draws, 3, 4, n)) + np.array([0, 0, 0, tol])[None, None, :, None]
    out["d boundary"] = np.mean(np.isin(claim_d(shifted, tol), (*reversal, stats.HOLDS)))
    out["e"] = np.mean(claim_e(rng.normal(size=(draws, 7, 7, n))) != stats.CANNOT)
    return {k: float(v) for k, v in out.items()}


def coverage(n: int, draws: int = DRAWS, seed: int = SEED) -> dict[str, float]:
    """Share of draws whose 95 % interval holds the true difference: ``{"welch": .., "contrast": ..}``."""
    rng = np.random.default_rng(seed + 1)
    a, b = rng.normal(0.5, 1.0, (draws, n)), rng.normal(0.0, 2.0, (draws, n))
    _, _, _, _, lo, hi = _welch(a, b)
    sds = np.array([0.5, 1.0, 1.5, 2.0, 0.5, 1.0, 2.0])
    mu = np.array([0.3, 0.3, 0.3, 0.3, 0.0, 0.0, 0.0])
    c = np.array([1 / 4] * 4 + [-1 / 3] * 3)
    x = rng.normal(size=(draws, 7, n)) * sds[:, None] + mu[:, None]
    _, _, _, _, clo, chi = stats.contrast(x.mean(-1), x.var(-1, ddof=1), np.full(7, float(n)), c)
    truth = float((c * mu).sum())
    return {
        "welch": float(np.mean((lo <= 0.5) & (0.5 <= hi))),
        "contrast": float(np.mean((clo <= truth) & (truth <= chi))),
    }


def simulation_se(rate: float, draws: int = DRAWS) -> float:
    """Binomial standard error of a simulated rate."""
    return math.sqrt(rate * (1 - rate) / draws)


def calibration_markdown(ns: tuple[int, ...] = SEEDS, draws: int = DRAWS, seed: int = SEED) -> str:
    """The false-verdict rates and coverages at each n as a markdown table (docs/report.md's generated block)."""
    rates = {n: false_verdict_rates(n, draws, seed) for n in ns}
    cover = {n: coverage(n, draws, seed) for n in ns}
    head = " | ".join(f"n = {n}" for n in ns)
    lines = [
        f"Simulated with `morfic_cli/report/simulate.py` ({draws} draws per cell, generator seed {seed}; one "
        f"simulation standard error is about {simulation_se(stats.ALPHA, draws):.3f} at a rate of "
        f"{stats.ALPHA:g} and {simulation_se(0.95, draws):.3f} at 95 %; `python scripts/stats_calibration.py "
        "--write docs/report.md` regenerates this block):",
        "",
        f"| rule, simulated case | should be | {head} |",
        "|---|---|" + "---|" * len(ns),
    ]
    label = {
        "a": "(a) null: no variant differs; any verdict",
        "b": "(b) null; any verdict",
        "c": "(c) null; any verdict",
        "d equal": "(d) the four alike; a verdict with a reversal",
        "d boundary": "(d) adaln one tolerance away; holds or a reversal",
        "e": "(e) null: no robot differs; any verdict",
    }
    for key, text in label.items():
        lines.append(f"| {text} | <= {stats.ALPHA:g} | " + " | ".join(f"{rates[n][key]:.3f}" for n in ns) + " |")
    lines.append(
        "| Welch 95 % interval holds the true difference (sds 1 and 2) | 0.95 | "
        + " | ".join(f"{cover[n]['welch']:.3f}" for n in ns)
        + " |"
    )
    lines.append(
        "| t-contrast 95 % interval holds the true contrast ((a)'s 4 against 3 variants, sds 0.5-2) | 0.95 | "
        + " | ".join(f"{cover[n]['contrast']:.3f}" for n in ns)
        + " |"
    )
    return "\n".join(lines)
