"""Effects, intervals and verdicts of morfic_cli.report.stats on cases computed by hand."""

import math

import numpy as np
import pytest

from morfic_cli.report import stats


def test_constant_sides_give_a_point_interval_and_hold():
    e = stats.mean_difference([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    assert e.estimate == 1.0
    assert (e.lo, e.hi) == (1.0, 1.0)
    assert e.verdict(higher=True) == stats.HOLDS
    assert e.verdict(higher=False) == stats.NOT
    # 6 values, C(6,3) = 20 splits; only the observed split and its mirror reach |diff| = 1: p = 2/20.
    assert e.p == pytest.approx(0.1)


def test_bootstrap_interval_of_two_values_spans_their_range():
    # mean of a resample of [0, 2] is 0 (1/4), 1 (1/2) or 2 (1/4): the 2.5 % and 97.5 % quantiles are 0 and 2.
    e = stats.mean_difference([0.0, 2.0], [0.0, 0.0])
    assert e.estimate == 1.0
    assert (e.lo, e.hi) == (0.0, 2.0)
    assert e.verdict() == stats.CANNOT  # the interval touches 0: not wholly above it


def test_permutation_p_by_enumeration():
    # a = {3, 4}, b = {1, 2}: observed diff 2; the 6 splits give diffs 2, -2, 1, -1, 0, 0 -> p = 2/6.
    assert stats.permutation_p([3, 4], [1, 2]) == pytest.approx(1 / 3)
    # with 3 seeds a side the smallest reachable p is 2 / C(6, 3) = 0.1
    assert stats.permutation_p([10, 11, 12], [0, 1, 2]) == pytest.approx(0.1)
    # 3 against 2: the observed split is the only one of C(5, 2) = 10 with |diff| >= 10.5 (no mirror split of
    # unequal sizes), so p = 1/10, again 0.1 (docs/report.md, the caveat)
    assert stats.permutation_p([10, 11, 12], [0, 1]) == pytest.approx(0.1)


def test_one_seed_has_no_interval_and_cannot_tell():
    e = stats.mean_difference([5.0], [0.0, 0.1, 0.2])
    assert e.estimate == pytest.approx(4.9)
    assert math.isnan(e.lo) and math.isnan(e.hi)
    assert e.verdict() == stats.CANNOT
    assert "no interval" in e.text()


def test_group_effect_weighs_variants_not_seeds():
    # side a: variant 1 mean 1 (2 seeds), variant 2 mean 3 (4 seeds) -> group mean 2, not (2*1 + 4*3)/6 = 2.33
    a = [[1.0, 1.0], [3.0, 3.0, 3.0, 3.0]]
    b = [[0.5, 0.5]]
    e = stats.group_effect(a, b)
    assert e.estimate == pytest.approx(1.5)
    assert (e.lo, e.hi) == (pytest.approx(1.5), pytest.approx(1.5))  # no spread anywhere
    assert math.isnan(e.p)  # a pooled side: no single-variant permutation test


def test_reversed_effect_does_not_hold_and_nans_are_dropped():
    e = stats.mean_difference([0.0, 0.1, float("nan")], [1.0, 1.1])
    assert e.n_a == 2
    assert e.hi < 0
    assert e.verdict(higher=True) == stats.NOT


def test_interval_is_reproducible_and_covers_the_estimate():
    rng = np.random.default_rng(1)
    a, b = rng.normal(1.0, 1.0, 5), rng.normal(0.0, 1.0, 5)
    e1, e2 = stats.mean_difference(a, b), stats.mean_difference(a, b)
    assert e1 == e2
    assert e1.lo <= e1.estimate <= e1.hi


def test_spearman_by_hand():
    assert stats.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert stats.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ranks x 1 2 3, y 1 3 2: rho = 1 - 6 * (0 + 1 + 1) / (3 * 8) = 0.5
    assert stats.spearman([1, 2, 3], [1, 3, 2]) == pytest.approx(0.5)
    assert math.isnan(stats.spearman([1, 2], [1, 2]))


def test_bootstrap_statistic_of_seed_means():
    est, lo, hi = stats.bootstrap_statistic([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]],
                                            lambda m: stats.spearman([0, 1, 2], m))
    assert (est, lo, hi) == (pytest.approx(1.0), pytest.approx(1.0), pytest.approx(1.0))
    est, lo, hi = stats.bootstrap_statistic([[1.0], [2.0, 2.0], [3.0, 3.0]], lambda m: float(m.mean()))
    assert est == pytest.approx(2.0) and math.isnan(lo)


def test_spearman_p_over_orderings_by_hand():
    # 3 pairs: the 6 orderings give rho 1, .5, .5, -.5, -.5, -1; |rho| >= 1 for 2 of them
    assert stats.spearman_p([1, 2, 3], [1, 2, 3]) == pytest.approx(2 / 6)
    assert stats.spearman_p([1, 2, 3], [1, 3, 2]) == pytest.approx(1.0)  # every ordering reaches |rho| >= 0.5
    # 4 pairs: only the identity and its reverse of the 24 reach |rho| = 1
    assert stats.spearman_p([1, 2, 3, 4], [8, 6, 4, 2]) == pytest.approx(2 / 24)
    assert math.isnan(stats.spearman_p([1, 2, 3], [5, 5, 5]))
    # above max_exact the orderings are drawn at random: still about 2/24, and reproducible
    p = stats.spearman_p([1, 2, 3, 4], [8, 6, 4, 2], max_exact=2000)
    assert p == stats.spearman_p([1, 2, 3, 4], [8, 6, 4, 2], max_exact=2000) and abs(p - 2 / 24) < 0.03
