"""Effect sizes with 95 % intervals over seeds: the statistics every verdict of docs/results.md is read from.

Pure functions on per-seed values (one number per trained run or per fitted critic). The method, stated once here
and in docs/report.md ("How a verdict is read"):

- the **effect** of a comparison is a difference of means over seeds (``mean(a) - mean(b)``), or of group means
  where a side pools several variants (:func:`group_effect`: the mean over the side's variants of each variant's
  seed mean, so a variant with more seeds does not weigh more);
- its **interval** is the percentile bootstrap over seeds: each variant's seeds are resampled with replacement,
  independently, :data:`N_BOOT` times from a fixed generator, and the interval is the (alpha/2, 1 - alpha/2)
  quantile pair of the resampled effects, :data:`ALPHA` = 0.05;
- the **verdict** is read from the interval alone: ``holds`` when it lies wholly on the claimed side of 0,
  ``does not hold`` when it lies wholly on the other side, ``cannot tell`` when it contains 0 or a side has fewer
  than :data:`MIN_SEEDS` seeds (one seed has no spread to resample, so its interval would be a point);
- beside it, the exact two-sided **permutation** p-value of the difference of means (:func:`permutation_p`) over
  every relabelling of the pooled seeds (Monte Carlo above :data:`MAX_EXACT` relabellings): with 3 seeds a side the
  smallest reachable p is 0.1, which says how little 3 seeds can decide; the percentile bootstrap is known to be
  too narrow at such n, so a ``holds`` from n = 3 is weaker than the same interval from n = 10.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

ALPHA: float = 0.05
"""Two-sided level of every interval and test (95 % intervals)."""
N_BOOT: int = 10_000
"""Bootstrap resamples per interval."""
MIN_SEEDS: int = 2
"""Fewest seeds a side needs for an interval (one seed: ``cannot tell``)."""
MAX_EXACT: int = 20_000
"""Largest number of relabellings the permutation test enumerates; above it, that many random ones."""
BOOT_SEED: int = 0
"""Seed of the bootstrap and Monte-Carlo permutation generators (so a verdict is reproducible)."""

HOLDS, NOT, CANNOT = "holds", "does not hold", "cannot tell"


@dataclass(frozen=True)
class Effect:
    """A difference of (group) means over seeds with its bootstrap interval.

    Attributes:
        estimate: The effect on the observed seeds.
        lo: Lower end of the (1 - alpha) interval (NaN when a side has fewer than MIN_SEEDS seeds).
        hi: Upper end.
        n_a: Seeds on side a (summed over its variants).
        n_b: Seeds on side b.
        p: Two-sided permutation p-value of the difference of pooled means (NaN where not computed).
    """

    estimate: float
    lo: float
    hi: float
    n_a: int
    n_b: int
    p: float = math.nan

    @property
    def has_interval(self) -> bool:
        """Whether both ends are numbers."""
        return not (math.isnan(self.lo) or math.isnan(self.hi))

    def verdict(self, higher: bool = True) -> str:
        """``holds`` / ``does not hold`` / ``cannot tell`` for the claim "a > b" (``higher``) or "a < b"."""
        if not self.has_interval:
            return CANNOT
        lo, hi = (self.lo, self.hi) if higher else (-self.hi, -self.lo)
        if lo > 0:
            return HOLDS
        if hi < 0:
            return NOT
        return CANNOT

    def text(self, decimals: int = 2) -> str:
        """``+0.31 [0.12, 0.50] (n 3 vs 3, p 0.10)``, or ``+0.31 (n 1 vs 3: no interval)``."""
        est = f"{self.estimate:+.{decimals}f}"
        n = f"n {self.n_a} vs {self.n_b}"
        if not self.has_interval:
            return f"{est} ({n}: no interval)"
        p = "" if math.isnan(self.p) else f", p {self.p:.2g}"
        return f"{est} [{self.lo:+.{decimals}f}, {self.hi:+.{decimals}f}] ({n}{p})"


def _clean(values: Sequence[float]) -> np.ndarray:
    """The finite values as a float64 array."""
    a = np.asarray([float(v) for v in values], dtype=np.float64)
    return a[np.isfinite(a)]


def bootstrap_means(values: Sequence[float], n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """Means of ``n_boot`` resamples (with replacement, same size) of ``values``. Shape: (n_boot,)."""
    a = _clean(values)
    idx = rng.integers(0, a.size, size=(n_boot, a.size))
    return a[idx].mean(axis=1)


def group_effect(
    side_a: Sequence[Sequence[float]],
    side_b: Sequence[Sequence[float]],
    *,
    alpha: float = ALPHA,
    n_boot: int = N_BOOT,
    seed: int = BOOT_SEED,
) -> Effect:
    """Effect = mean over a's variants of their seed means - the same for b, with its bootstrap interval.

    Args:
        side_a: One list of per-seed values per variant of side a (NaNs dropped).
        side_b: The same for side b.
        alpha: Two-sided level.
        n_boot: Resamples.
        seed: Generator seed.

    Returns:
        The effect; no interval (NaN ends) when any variant of either side has fewer than :data:`MIN_SEEDS` seeds,
        and a NaN estimate when a side has no values at all.
    """
    a = [_clean(v) for v in side_a if _clean(v).size]
    b = [_clean(v) for v in side_b if _clean(v).size]
    n_a, n_b = sum(v.size for v in a), sum(v.size for v in b)
    if not a or not b:
        return Effect(math.nan, math.nan, math.nan, n_a, n_b)
    estimate = float(np.mean([v.mean() for v in a]) - np.mean([v.mean() for v in b]))
    p = permutation_p(np.concatenate(a), np.concatenate(b), seed=seed) if len(a) == 1 and len(b) == 1 else math.nan
    if min(v.size for v in (*a, *b)) < MIN_SEEDS:
        return Effect(estimate, math.nan, math.nan, n_a, n_b, p)
    rng = np.random.default_rng(seed)
    boot = np.mean([bootstrap_means(v, n_boot, rng) for v in a], axis=0) - np.mean(
        [bootstrap_means(v, n_boot, rng) for v in b], axis=0
    )
    lo, hi = np.quantile(boot, [alpha / 2, 1 - alpha / 2])
    return Effect(estimate, float(lo), float(hi), n_a, n_b, p)


def mean_difference(a: Sequence[float], b: Sequence[float], **kwargs) -> Effect:
    """Effect = mean(a) - mean(b) over seeds, with its bootstrap interval and permutation p (:func:`group_effect`)."""
    return group_effect([a], [b], **kwargs)


def permutation_p(
    a: Sequence[float], b: Sequence[float], *, seed: int = BOOT_SEED, max_exact: int = MAX_EXACT
) -> float:
    """Two-sided permutation p-value of mean(a) - mean(b): the share of relabellings at least as extreme.

    Every split of the pooled values into groups of |a| and |b| is enumerated when there are at most ``max_exact``
    of them (the observed one included, so p >= 1 / #splits); otherwise ``max_exact`` random relabellings plus the
    observed one. NaN when a side is empty.
    """
    x, y = _clean(a), _clean(b)
    if x.size == 0 or y.size == 0:
        return math.nan
    pooled = np.concatenate([x, y])
    n, k = pooled.size, x.size
    observed = abs(x.mean() - y.mean())
    tol = 1e-12 * max(1.0, float(np.abs(pooled).max()))
    total = pooled.sum()
    if math.comb(n, k) <= max_exact:
        sums = np.array([pooled[list(c)].sum() for c in itertools.combinations(range(n), k)])
    else:
        rng = np.random.default_rng(seed)
        perms = np.array([rng.permutation(n)[:k] for _ in range(max_exact)])
        sums = np.concatenate([[x.sum()], pooled[perms].sum(axis=1)])
    diffs = np.abs(sums / k - (total - sums) / (n - k))
    return float(np.mean(diffs >= observed - tol))


def spearman(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Spearman's rank correlation (average ranks for ties); NaN for fewer than 3 pairs or a constant side."""
    x, y = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
    if x.size < 3 or x.size != y.size:
        return math.nan
    rx, ry = _ranks(x), _ranks(y)
    if rx.std() == 0 or ry.std() == 0:
        return math.nan
    return float(np.corrcoef(rx, ry)[0, 1])


def spearman_p(xs: Sequence[float], ys: Sequence[float], *, seed: int = BOOT_SEED,
               max_exact: int = MAX_EXACT) -> float:
    """Two-sided permutation p-value of Spearman's rho: the share of orderings of ``ys`` with |rho| >= observed.

    Every ordering is enumerated when there are at most ``max_exact`` (7 robots: 5,040, the observed one included);
    otherwise ``max_exact`` random ones plus the observed. It asks whether the rank correlation over these units
    could come from pairing them at random, a question the bootstrap over seeds (:func:`bootstrap_statistic`)
    does not ask. NaN where rho is NaN.
    """
    x, y = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
    observed = spearman(x, y)
    if math.isnan(observed):
        return math.nan
    rx, ry = _ranks(x), _ranks(y)
    rx = (rx - rx.mean()) / rx.std()
    if math.factorial(y.size) <= max_exact:
        orders = np.array(list(itertools.permutations(range(y.size))))
    else:
        rng = np.random.default_rng(seed)
        orders = np.concatenate([np.arange(y.size)[None], [rng.permutation(y.size) for _ in range(max_exact)]])
    ryp = ry[orders]  # (P, n)
    rhos = ((ryp - ry.mean()) / ry.std() * rx).mean(axis=1)
    tol = 1e-12
    return float(np.mean(np.abs(rhos) >= abs(observed) - tol))


def _ranks(x: np.ndarray) -> np.ndarray:
    """1-based ranks, ties averaged. Shape: (n,) -> (n,)."""
    order = np.argsort(x, kind="stable")
    ranks = np.empty(x.size)
    ranks[order] = np.arange(1, x.size + 1)
    for v in np.unique(x):
        tie = x == v
        ranks[tie] = ranks[tie].mean()
    return ranks


def bootstrap_statistic(
    samples: Sequence[Sequence[float]],
    statistic,
    *,
    alpha: float = ALPHA,
    n_boot: int = N_BOOT,
    seed: int = BOOT_SEED,
) -> tuple[float, float, float]:
    """A statistic of per-unit seed means with a bootstrap interval over each unit's seeds.

    ``statistic`` maps one mean per unit (an array, shape (U,)) to a number; each bootstrap draw resamples every
    unit's seeds and applies it to the resampled means (e.g. the Spearman correlation of speed against distance,
    a unit being a robot). Returns ``(estimate, lo, hi)``; NaN ends when a unit has fewer than :data:`MIN_SEEDS`.
    """
    units = [_clean(s) for s in samples]
    estimate = float(statistic(np.array([u.mean() if u.size else math.nan for u in units])))
    if any(u.size < MIN_SEEDS for u in units):
        return estimate, math.nan, math.nan
    rng = np.random.default_rng(seed)
    means = np.stack([bootstrap_means(u, n_boot, rng) for u in units], axis=1)  # (n_boot, U)
    stats = np.array([statistic(row) for row in means])
    stats = stats[np.isfinite(stats)]
    if stats.size == 0:
        return estimate, math.nan, math.nan
    lo, hi = np.quantile(stats, [alpha / 2, 1 - alpha / 2])
    return estimate, float(lo), float(hi)
