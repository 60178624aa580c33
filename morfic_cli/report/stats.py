"""Effects with 95 % t intervals over seeds, Holm-corrected tests and the verdict rule every claim is read from.

Pure functions on per-seed values (one number per trained run or per fitted critic: the seed is the unit of
replication). The method, stated once here and in docs/report.md ("How a verdict is read"):

- a **comparison** is a difference of means over seeds, tested with Welch's t (:func:`mean_difference`,
  ``scipy.stats.ttest_ind(equal_var=False)`` and its confidence interval), or a contrast of variants' seed means,
  each variant weighing the same (:func:`group_effect`: a t-contrast, SE² = Σ c_i² s_i² / n_i, Welch-Satterthwaite
  degrees of freedom); an equivalence reading against a tolerance τ (:func:`equivalence_p`) and a rank correlation
  over robots (:func:`spearman_p`, exact over the robots' orderings) are the two others;
- a claim's primary comparisons are corrected together with Holm's method (:func:`holm`); a comparison is
  significant when its adjusted p is below :data:`ALPHA`, in the direction of its effect (:func:`outcome`);
- the claim's verdict comes from how many are significant in the claimed direction and against it
  (:func:`decide`): holds / holds partly / mixed / partly reversed / does not hold / cannot tell;
- under a comparison that is not significant, :func:`seeds_needed` gives the seeds per side that would detect the
  observed effect with 80 % power at alpha / m (noncentral t).

No verdict depends on a random generator. A side with one seed has no spread, so no test (``cannot tell``); sides
whose seeds all repeat one value give an exact difference (p = 0, or 1 for a tie).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np
from scipy import stats as sst

ALPHA: float = 0.05
"""Two-sided level of every interval and test (95 % intervals), and the family-wise level of a claim."""
POWER: float = 0.8
"""The power :func:`seeds_needed` asks for."""
MAX_SEEDS: int = 1000
"""Largest seed count :func:`seeds_needed` searches; above it, "more than 1000"."""
MIN_SEEDS: int = 2
"""Fewest seeds a variant needs for a test (one seed: no spread, ``cannot tell``)."""
MAX_EXACT: int = 40_320
"""Largest number of orderings :func:`spearman_p` enumerates (8 robots); above it, the t approximation."""

HOLDS, NOT, CANNOT = "holds", "does not hold", "cannot tell"
PARTLY, REVERSED, MIXED = "holds partly", "partly reversed", "mixed"
FOR, AGAINST, NONE = 1, -1, 0
"""A comparison's outcome: significant in the claimed direction, against it, or not significant."""
NO_TEST = "one seed per variant: no test"
"""Why a comparison with a one-seed side has no test."""


@dataclass(frozen=True)
class Effect:
    """A difference of (group) means over seeds with its t interval and test.

    Attributes:
        estimate: The effect on the observed seeds.
        lo: Lower end of the 95 % t interval (NaN without a test).
        hi: Upper end.
        n_a: Seeds on side a (summed over its variants).
        n_b: Seeds on side b.
        p: Two-sided p of the t test (NaN without a test).
        df: Welch-Satterthwaite degrees of freedom (NaN without a test).
        se: Standard error of the estimate (NaN without a test; 0 when every side repeats one value).
        unit_var: Per variant c_i² s_i²: the estimate's variance at one seed per variant (SE_n² = Σ / n), which
            :func:`seeds_needed` scales to other seed counts.
        why: Why there is no test (empty when there is one).
    """

    estimate: float
    lo: float
    hi: float
    n_a: int
    n_b: int
    p: float = math.nan
    df: float = math.nan
    se: float = math.nan
    unit_var: tuple[float, ...] = ()
    why: str = ""

    @property
    def has_test(self) -> bool:
        """Whether the effect has a p-value (every variant of both sides has at least :data:`MIN_SEEDS` seeds)."""
        return not math.isnan(self.p)

    has_interval = has_test

    def verdict(self, higher: bool = True, alpha: float = ALPHA) -> str:
        """One comparison alone, uncorrected: ``holds`` / ``does not hold`` / ``cannot tell`` for "a > b"."""
        return {FOR: HOLDS, AGAINST: NOT, NONE: CANNOT}[outcome(self.estimate, self.p, higher, alpha)]

    def text(self, decimals: int = 2, p_holm: float | None = None) -> str:
        """``+0.31 [+0.12, +0.50] (n 3 vs 3, p 0.021, Holm 0.063)``, or ``+0.31 (n 1 vs 3: no test)``."""
        est = f"{self.estimate:+.{decimals}f}"
        n = f"n {self.n_a} vs {self.n_b}"
        if not self.has_test:
            return f"{est} ({n}: no test)"
        holm_text = "" if p_holm is None or math.isnan(p_holm) else f", Holm {p_text(p_holm)}"
        return f"{est} [{self.lo:+.{decimals}f}, {self.hi:+.{decimals}f}] ({n}, p {p_text(self.p)}{holm_text})"


def p_text(p: float) -> str:
    """``0.021``, ``0.0004``, ``<1e-06``, ``1``: two significant digits."""
    if p == 0:
        return "0"
    if p < 1e-6:
        return "<1e-06"
    return f"{p:.2g}"


def _clean(values: Sequence[float] | np.ndarray) -> np.ndarray:
    """The finite values as a float64 array."""
    a = np.asarray([float(v) for v in values], dtype=np.float64)
    return a[np.isfinite(a)]


def t_p(t: np.ndarray | float, df: np.ndarray | float) -> np.ndarray:
    """Two-sided p of a t statistic; ``t = ±inf`` (zero SE, nonzero effect) gives 0, ``t = NaN`` (0 / 0) gives 1."""
    t = np.asarray(t, dtype=np.float64)
    p = 2 * sst.t.sf(np.abs(t), df)
    return np.where(np.isnan(t), 1.0, np.where(np.isinf(t), 0.0, p))


def contrast(
    means: np.ndarray, variances: np.ndarray, ns: np.ndarray, c: np.ndarray, alpha: float = ALPHA
) -> tuple[np.ndarray, ...]:
    """The t-contrast Σ c_i m_i with Welch-Satterthwaite degrees of freedom, vectorised over leading axes.

    Args:
        means: Seed means m_i. Shape: (..., K).
        variances: Sample variances s_i² (ddof 1). Shape: (..., K).
        ns: Seed counts n_i (each >= 2). Shape: (..., K) or (K,).
        c: Contrast weights. Shape: (K,).
        alpha: Two-sided level of the interval.

    Returns:
        ``(estimate, se, df, p, lo, hi)``, each of shape (...). With zero SE the degrees of freedom are
        Σ (n_i - 1) (every term is 0) and the interval a point.
    """
    means, variances, ns = (np.asarray(x, dtype=np.float64) for x in (means, variances, ns))
    est = (c * means).sum(-1)
    terms = c**2 * variances / ns
    se2 = terms.sum(-1)
    den = (terms**2 / (ns - 1)).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        df = np.where(den > 0, se2**2 / np.where(den > 0, den, 1.0), (ns - 1).sum(-1) * np.ones_like(se2))
        se = np.sqrt(se2)
        t = est / se
    p = t_p(t, df)
    half = sst.t.ppf(1 - alpha / 2, df) * se
    return est, se, df, p, est - half, est + half


def group_effect(
    side_a: Sequence[Sequence[float] | np.ndarray],
    side_b: Sequence[Sequence[float] | np.ndarray],
    *,
    alpha: float = ALPHA,
) -> Effect:
    """Effect = mean over a's variants of their seed means - the same for b, with its t-contrast test.

    Args:
        side_a: One list of per-seed values per variant of side a (NaNs dropped; empty variants ignored).
        side_b: The same for side b.
        alpha: Two-sided level.

    Returns:
        The effect; no test (NaN p and ends, ``why`` = :data:`NO_TEST`) when a variant has fewer than
        :data:`MIN_SEEDS` seeds; a NaN estimate when a side has no values at all.
    """
    a = [x for x in (_clean(v) for v in side_a) if x.size]
    b = [x for x in (_clean(v) for v in side_b) if x.size]
    n_a, n_b = sum(v.size for v in a), sum(v.size for v in b)
    if not a or not b:
        return Effect(math.nan, math.nan, math.nan, n_a, n_b, why="a side has no values")
    groups = [*a, *b]
    c = np.array([1 / len(a)] * len(a) + [-1 / len(b)] * len(b))
    means = np.array([v.mean() for v in groups])
    estimate = float((c * means).sum())
    if min(v.size for v in groups) < MIN_SEEDS:
        return Effect(estimate, math.nan, math.nan, n_a, n_b, why=NO_TEST)
    variances = np.array([v.var(ddof=1) for v in groups])
    ns = np.array([v.size for v in groups], dtype=np.float64)
    _, se, df, p, lo, hi = contrast(means, variances, ns, c, alpha)
    return Effect(
        estimate,
        float(lo),
        float(hi),
        n_a,
        n_b,
        float(p),
        float(df),
        float(se),
        tuple(float(x) for x in c**2 * variances),
    )


def mean_difference(a: Sequence[float], b: Sequence[float], *, alpha: float = ALPHA) -> Effect:
    """Effect = mean(a) - mean(b) over seeds with Welch's t (``scipy.stats.ttest_ind(equal_var=False)``).

    Where a side repeats one value, :func:`contrast` computes the same Welch t (scipy warns of, or has no t for, a
    zero variance); where both do, the difference is exact (p 0, or 1 for a tie).
    """
    x, y = _clean(a), _clean(b)
    if x.size < MIN_SEEDS or y.size < MIN_SEEDS or x.var() == 0 or y.var() == 0:
        return group_effect([x], [y], alpha=alpha)
    r = sst.ttest_ind(x, y, equal_var=False)
    ci = r.confidence_interval(1 - alpha)
    est = float(x.mean() - y.mean())
    unit = (float(x.var(ddof=1)), float(y.var(ddof=1)))
    return Effect(
        est,
        float(ci.low),
        float(ci.high),
        x.size,
        y.size,
        float(r.pvalue),
        float(r.df),
        math.sqrt(unit[0] / x.size + unit[1] / y.size),
        unit,
    )


def paired_effect(differences: Sequence[float], *, alpha: float = ALPHA) -> Effect:
    """Effect = mean of per-unit differences (paired by unit: each frozen actor of the critic study), one-sample t.

    SE = s / sqrt(n), df = n - 1 (``n_a = n_b = n``, the units that have both sides); ``unit_var`` is (s²,), so
    :func:`seeds_needed` gives units (actors) for the paired test. No test below :data:`MIN_SEEDS` units; every
    difference equal: exact (p 0, or 1 for all zero).
    """
    d = _clean(differences)
    if d.size == 0:
        return Effect(math.nan, math.nan, math.nan, 0, 0, why="no unit has both sides")
    est = float(d.mean())
    if d.size < MIN_SEEDS:
        return Effect(est, math.nan, math.nan, d.size, d.size, why=NO_TEST)
    var = float(d.var(ddof=1))
    _, se, df, p, lo, hi = contrast(np.array([est]), np.array([var]), np.array([float(d.size)]), np.array([1.0]), alpha)
    return Effect(est, float(lo), float(hi), d.size, d.size, float(p), float(df), float(se), (var,))


def equivalence_p(effect: Effect, tol: float) -> tuple[float, int]:
    """(p, outcome) of "|difference| < tol": the equivalence p or the "beyond" p, whichever is smaller.

    Equivalent at level alpha when the (1 - alpha) t interval lies inside (-tol, tol): two one-sided tests at
    alpha / 2 each, p_eq = 2 max(p(Δ <= -tol), p(Δ >= tol)). Beyond when the interval lies wholly outside
    [-tol, tol]: p_out = 2 min(p(Δ <= tol), p(Δ >= -tol)). Returns (NaN, NONE) without a test; the outcome is
    :data:`FOR` when p_eq is the smaller, :data:`AGAINST` otherwise (significance is decided after Holm).
    """
    if not effect.has_test:
        return math.nan, NONE
    with np.errstate(divide="ignore", invalid="ignore"):
        z_lo = np.float64(effect.estimate + tol) / effect.se  # against Δ <= -tol
        z_hi = np.float64(effect.estimate - tol) / effect.se  # against Δ >= tol
    t_lo, t_hi = (0.0 if np.isnan(t) else float(t) for t in (z_lo, z_hi))
    p_eq = min(1.0, 2 * max(sst.t.sf(t_lo, effect.df), sst.t.cdf(t_hi, effect.df)))
    p_out = min(1.0, 2 * min(sst.t.sf(t_hi, effect.df), sst.t.cdf(t_lo, effect.df)))
    return (float(p_eq), FOR) if p_eq <= p_out else (float(p_out), AGAINST)


def holm(p: Sequence[float] | np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values over the last axis; NaN (no test) counts in m and stays NaN.

    p̃_(k) = max_{j <= k} min(1, (m - j + 1) p_(j)) over the sorted p's, m the number of comparisons (the
    untested included, which is conservative). Shape: (..., m) -> (..., m).
    """
    p = np.asarray(p, dtype=np.float64)
    m = p.shape[-1]
    if m == 0:
        return p
    filled = np.where(np.isnan(p), np.inf, p)
    order = np.argsort(filled, axis=-1, kind="stable")
    sorted_p = np.take_along_axis(filled, order, -1)
    adj = np.minimum(1.0, np.maximum.accumulate(sorted_p * (m - np.arange(m)), axis=-1))
    out = np.empty_like(adj)
    np.put_along_axis(out, order, adj, -1)
    return np.where(np.isnan(p), np.nan, out)


@overload
def outcome(estimate: float, p: float, higher: bool = True, alpha: float = ALPHA) -> int: ...
@overload
def outcome(
    estimate: np.ndarray, p: float | np.ndarray, higher: bool | np.ndarray = True, alpha: float = ALPHA
) -> np.ndarray: ...
def outcome(
    estimate: float | np.ndarray, p: float | np.ndarray, higher: bool | np.ndarray = True, alpha: float = ALPHA
) -> int | np.ndarray:
    """:data:`FOR` / :data:`AGAINST` / :data:`NONE`: significant (p < alpha) in the claimed direction or not."""
    sig = np.asarray(p) < alpha
    sign = np.where(np.asarray(higher), 1, -1) * np.sign(np.asarray(estimate, dtype=np.float64))
    out = np.where(sig & (sign > 0), FOR, np.where(sig & (sign < 0), AGAINST, NONE))
    return int(out) if out.ndim == 0 else out


@overload
def decide(outcomes: Sequence[int]) -> str: ...
@overload
def decide(outcomes: np.ndarray) -> str | np.ndarray: ...
def decide(outcomes: Sequence[int] | np.ndarray) -> str | np.ndarray:
    """A claim's verdict from its m primary comparisons' outcomes (after Holm), over the last axis.

    ``holds``: every one FOR; ``does not hold``: every one AGAINST; ``holds partly``: some FOR, none AGAINST;
    ``partly reversed``: some AGAINST, none FOR; ``mixed``: some of each; ``cannot tell``: none significant (or
    no comparison). Shape: (..., m) -> (...) of str.
    """
    o = np.asarray(outcomes, dtype=np.int64)
    if o.shape[-1] == 0:
        return CANNOT if o.ndim == 1 else np.full(o.shape[:-1], CANNOT, dtype=object)
    f, a, m = (o == FOR).sum(-1), (o == AGAINST).sum(-1), o.shape[-1]
    out = np.select(
        [f == m, a == m, (f > 0) & (a > 0), f > 0, a > 0], [HOLDS, NOT, MIXED, PARTLY, REVERSED], CANNOT
    ).astype(object)
    return str(out) if out.ndim == 0 else out


def seeds_needed(
    effect: Effect, *, alpha: float = ALPHA, power: float = POWER, delta: float | None = None
) -> int | None:
    """Seeds per variant that detect ``delta`` (default ``|estimate|``) with ``power`` at two-sided ``alpha``.

    For an equivalence reading ((d)) ``delta`` is the estimate's distance to the nearer bound of ±tol (each of its
    one-sided tests runs at alpha / 2, so the two-sided critical value is its own). With n seeds per variant
    SE_n² = Σ unit_var / n (the observed spreads) and df_n = (n - 1) (Σ unit_var)² / Σ unit_var²; power is
    P(T > t(1 - alpha/2, df_n)) + P(T < -t(...)) for T noncentral t(df_n, delta / SE_n) (``scipy.stats.nct``).
    Returns the smallest n >= 2 that reaches it, ``MAX_SEEDS + 1`` when none up to :data:`MAX_SEEDS` does, None
    without spreads (no test) or without an effect to detect.
    """
    if not effect.has_test or not effect.unit_var:
        return None
    delta = abs(effect.estimate) if delta is None else abs(delta)
    if not delta > 0:
        return None
    u = np.array(effect.unit_var)
    total = u.sum()
    if total == 0:
        return MIN_SEEDS
    ratio = total**2 / (u**2).sum()
    n = np.arange(MIN_SEEDS, MAX_SEEDS + 1, dtype=np.float64)
    df = (n - 1) * ratio
    nc = delta / np.sqrt(total / n)
    crit = sst.t.ppf(1 - alpha / 2, df)
    pw = sst.nct.sf(crit, df, nc) + sst.nct.cdf(-crit, df, nc)
    hit = np.nonzero(pw >= power)[0]
    return int(n[hit[0]]) if hit.size else MAX_SEEDS + 1


def needed_text(n: int | None) -> str:
    """``6 seeds/side for 80 %`` or ``more than 1000 seeds/side``; empty for None."""
    if n is None:
        return ""
    if n > MAX_SEEDS:
        return f"more than {MAX_SEEDS} seeds/side"
    return f"{n} seeds/side for {POWER:.0%} power"


def mean_interval(values: Sequence[float], *, alpha: float = ALPHA) -> tuple[float, float, float]:
    """``(mean, lo, hi)``: the seed mean with its (1 - alpha) t interval; NaN ends below :data:`MIN_SEEDS`."""
    x = _clean(values)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(x.mean())
    if x.size < MIN_SEEDS:
        return mean, math.nan, math.nan
    half = float(sst.t.ppf(1 - alpha / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, mean - half, mean + half


def spearman(xs: Sequence[float] | np.ndarray, ys: Sequence[float] | np.ndarray) -> float:
    """Spearman's rank correlation (average ranks for ties); NaN for fewer than 3 pairs or a constant side."""
    x, y = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
    if x.size < 3 or x.size != y.size:
        return math.nan
    rx, ry = _ranks(x), _ranks(y)
    if rx.std() == 0 or ry.std() == 0:
        return math.nan
    return float(np.corrcoef(rx, ry)[0, 1])


def spearman_p(xs: Sequence[float], ys: Sequence[float], *, max_exact: int = MAX_EXACT) -> float:
    """Two-sided p of Spearman's rho: the share of orderings of ``ys`` with |rho| >= observed.

    Every ordering is enumerated when there are at most ``max_exact`` (7 robots: 5,040, the observed one included);
    above, the t approximation of ``scipy.stats.spearmanr`` (no random generator either way). It asks whether the
    rank correlation over these units could come from pairing them at random. NaN where rho is NaN.
    """
    x, y = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
    observed = spearman(x, y)
    if math.isnan(observed):
        return math.nan
    if math.factorial(y.size) > max_exact:
        return float(sst.spearmanr(x, y).pvalue)
    rx, ry = _ranks(x), _ranks(y)
    rx = (rx - rx.mean()) / rx.std()
    orders = np.array(list(itertools.permutations(range(y.size))))
    rhos = ((ry[orders] - ry.mean()) / ry.std() * rx).mean(axis=1)
    return float(np.mean(np.abs(rhos) >= abs(observed) - 1e-12))


def spearman_null(n: int) -> np.ndarray:
    """Sorted |rho| over every ordering of n untied ranks: the exact null of :func:`spearman_p`. Shape: (n!,)."""
    r = np.arange(n, dtype=np.float64)
    z = (r - r.mean()) / r.std()
    orders = np.array(list(itertools.permutations(range(n))))
    return np.sort(np.abs((z[orders] * z).mean(axis=1)))


def _ranks(x: np.ndarray) -> np.ndarray:
    """1-based ranks, ties averaged. Shape: (n,) -> (n,)."""
    return sst.rankdata(x, method="average")
