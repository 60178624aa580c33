"""Tests, corrections, verdict rule and power of morfic_cli.report.stats on cases computed by hand; the rules'
simulated level and the intervals' coverage (morfic_cli.report.simulate)."""

import math

import numpy as np
import pytest
from scipy import stats as sst

from morfic_cli.report import simulate, stats


def test_welch_by_hand():
    # a = 1, 2, 3: mean 2, s² = 1; b = 2, 4, 6: mean 4, s² = 4. Effect -2.
    # SE² = 1/3 + 4/3 = 5/3 (SE 1.2910), t = -2 / 1.2910 = -1.5492;
    # df = (5/3)² / ((1/3)²/2 + (4/3)²/2) = (25/9) / (17/18) = 50/17 = 2.9412.
    e = stats.mean_difference([1, 2, 3], [2, 4, 6])
    assert e.estimate == pytest.approx(-2.0)
    assert e.se == pytest.approx(math.sqrt(5 / 3)) and e.df == pytest.approx(50 / 17)
    assert e.p == pytest.approx(2 * sst.t.sf(2 / math.sqrt(5 / 3), 50 / 17))
    half = sst.t.ppf(0.975, 50 / 17) * math.sqrt(5 / 3)  # 3.2188 x 1.2910 = 4.1554
    assert (e.lo, e.hi) == (pytest.approx(-2 - half), pytest.approx(-2 + half))
    assert e.lo == pytest.approx(-6.16, abs=0.01) and e.p == pytest.approx(0.22, abs=0.01)
    assert e.verdict(higher=False) == stats.CANNOT  # the interval holds 0
    assert e.unit_var == (1.0, 4.0)


def test_t_contrast_by_hand_and_welch_as_its_two_variant_case():
    # A: {1, 2, 3} (mean 2, s² 1) and {3, 4, 5} (mean 4, s² 1); B: {0, 2} (mean 1, s² 2); c = (1/2, 1/2, -1).
    # Effect (2 + 4)/2 - 1 = 2. SE² = (1/4)(1/3) + (1/4)(1/3) + (1)(2/2) = 7/6.
    # df = (7/6)² / ((1/12)²/2 + (1/12)²/2 + 1²/1) = (49/36) / (145/144) = 196/145 = 1.3517.
    e = stats.group_effect([[1, 2, 3], [3, 4, 5]], [[0, 2]])
    assert e.estimate == pytest.approx(2.0) and (e.n_a, e.n_b) == (6, 2)
    assert e.se == pytest.approx(math.sqrt(7 / 6)) and e.df == pytest.approx(196 / 145)
    assert e.p == pytest.approx(2 * sst.t.sf(2 / math.sqrt(7 / 6), 196 / 145))
    assert e.unit_var == pytest.approx((0.25, 0.25, 2.0))  # c_i² s_i²
    # the contrast of two variants is Welch's t, scipy's
    a, b = [0.3, 1.1, 0.4, 2.0], [0.1, -0.5, 0.2]
    r = sst.ttest_ind(a, b, equal_var=False)
    g = stats.group_effect([a], [b])
    ci = r.confidence_interval()
    assert (g.p, g.df, g.lo, g.hi) == pytest.approx((r.pvalue, r.df, ci.low, ci.high))
    assert stats.mean_difference(a, b).p == pytest.approx(r.pvalue)


def test_one_seed_has_no_test_and_says_why():
    e = stats.mean_difference([5.0], [0.0, 0.1, 0.2])
    assert e.estimate == pytest.approx(4.9)
    assert math.isnan(e.lo) and math.isnan(e.p) and not e.has_test
    assert e.why == stats.NO_TEST and e.verdict() == stats.CANNOT
    assert e.text() == "+4.90 (n 1 vs 3: no test)"
    assert stats.seeds_needed(e) is None
    # one variant with one seed: (1.5 + 3) / 2 - 0.5 = 1.75, but no contrast test
    g = stats.group_effect([[1.0, 2.0], [3.0]], [[0.0, 1.0]])
    assert g.estimate == pytest.approx(1.75) and not g.has_test


def test_zero_spread_is_an_exact_difference():
    # both sides repeat one value: no t (0 / 0 spread), the difference is exact: p 0, a point interval
    e = stats.mean_difference([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    assert (e.estimate, e.lo, e.hi, e.p, e.se) == (1.0, 1.0, 1.0, 0.0, 0.0)
    assert e.df == 4  # Σ (n_i - 1)
    assert e.verdict(higher=True) == stats.HOLDS and e.verdict(higher=False) == stats.NOT
    assert stats.seeds_needed(e) == 2
    tie = stats.mean_difference([0.0, 0.0], [0.0, 0.0, 0.0])  # both fall on every seed
    assert (tie.estimate, tie.p) == (0.0, 1.0) and tie.verdict() == stats.CANNOT
    # one side constant, the other not: Welch with the other side's spread alone, df = n - 1 = 2
    one = stats.mean_difference([1.0, 1.0, 1.0], [0.0, 1.0, 2.0])
    assert one.se == pytest.approx(math.sqrt(1 / 3)) and one.df == pytest.approx(2.0)


def test_nans_are_dropped():
    e = stats.mean_difference([0.0, 0.1, float("nan")], [1.0, 1.1])
    assert e.n_a == 2 and e.estimate == pytest.approx(-1.0)


def test_holm_by_hand():
    # sorted 0.01, 0.03, 0.04 and one untested (NaN, counted: m = 4): 4 x 0.01 = 0.04, 3 x 0.03 = 0.09,
    # 2 x 0.04 = 0.08 -> raised to the running max 0.09
    np.testing.assert_allclose(stats.holm([0.01, 0.04, 0.03, math.nan]), [0.04, 0.09, 0.09, math.nan])
    assert stats.holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])  # capped at 1
    np.testing.assert_allclose(stats.holm([[0.01, 0.02], [0.2, 0.01]]), [[0.02, 0.02], [0.2, 0.02]])  # per row


def test_the_verdict_rule_is_symmetric():
    F, A, N = stats.FOR, stats.AGAINST, stats.NONE
    assert stats.decide([F, F, F]) == stats.HOLDS
    assert stats.decide([A, A, A]) == stats.NOT
    assert stats.decide([F, N, N]) == stats.PARTLY
    assert stats.decide([A, N, N]) == stats.REVERSED  # one reversal of three is not "does not hold"
    assert stats.decide([F, A, N]) == stats.MIXED
    assert stats.decide([N, N]) == stats.CANNOT and stats.decide([]) == stats.CANNOT
    assert list(stats.decide([[F, F], [N, A]])) == [stats.HOLDS, stats.REVERSED]
    # outcome: significant (p < 0.05) in the claimed direction or against it
    assert stats.outcome(0.3, 0.01) == F and stats.outcome(0.3, 0.01, higher=False) == A
    assert stats.outcome(0.3, 0.05) == N and stats.outcome(0.3, math.nan) == N


def test_equivalence_by_hand():
    # a = 1.0, 1.2, 1.4 (mean 1.2, s² 0.04); b = 1.1, 1.3 (mean 1.2, s² 0.02): difference 0, SE² = 0.04/3 + 0.02/2
    # = 0.02333 (SE 0.1528); df = 0.02333² / ((0.01333)²/2 + 0.01²/1) = 0.000544 / 0.0001889 = 2.882.
    e = stats.mean_difference([1.0, 1.2, 1.4], [1.1, 1.3])
    assert e.se == pytest.approx(math.sqrt(0.04 / 3 + 0.01)) and e.df == pytest.approx(2.882, abs=1e-3)
    # tol 0.6: t against each bound 0.6 / 0.1528 = 3.93; p_eq = 2 x t.sf(3.93, 2.88) < 0.05 -> similar
    p, way = stats.equivalence_p(e, 0.6)
    assert way == stats.FOR and p == pytest.approx(2 * sst.t.sf(0.6 / e.se, e.df)) and p < 0.05
    # tol 0.3: t 1.96, p_eq 0.15: not shown similar, and not beyond (p_out 1)
    p, way = stats.equivalence_p(e, 0.3)
    assert way == stats.FOR and p == pytest.approx(2 * sst.t.sf(0.3 / e.se, e.df)) and p > 0.05
    # a difference far beyond the tolerance: the "beyond" p is the smaller
    far = stats.mean_difference([3.0, 3.2, 3.4], [1.1, 1.3])
    p, way = stats.equivalence_p(far, 0.3)
    assert way == stats.AGAINST and p == pytest.approx(2 * sst.t.sf((2.0 - 0.3) / far.se, far.df)) and p < 0.05


def test_seeds_needed_matches_the_textbook_sample_size():
    # sds 1 and 1, effect 1 (Cohen's d = 1): two-sided alpha 0.05 at 80 % power needs 17 per group (the noncentral-t
    # answer; the normal approximation gives 2 (1.96 + 0.84)² = 15.7)
    e = stats.mean_difference([1, 2, 3], [0, 1, 2])
    assert stats.seeds_needed(e) == 17
    assert stats.seeds_needed(e, alpha=0.05 / 9) > 17  # Holm's strictest step over 9 comparisons asks more
    assert stats.needed_text(17) == "17 seeds/side for 80% power"
    assert stats.seeds_needed(stats.mean_difference([0, 1, 2], [0, 1, 2])) is None  # no effect to detect
    tiny = stats.mean_difference([0, 10, 20], [0.001, 10.001, 20.001])
    assert stats.seeds_needed(tiny) == stats.MAX_SEEDS + 1 and "more than 1000" in stats.needed_text(1001)


def test_text_shows_interval_p_and_holm():
    e = stats.mean_difference([1, 2, 3], [2, 4, 6])
    assert e.text(p_holm=0.5) == "-2.00 [-6.16, +2.16] (n 3 vs 3, p 0.22, Holm 0.5)"


def test_mean_interval_by_hand():
    # 1, 2, 3: mean 2, s 1, half-width t(0.975, 2) / sqrt(3) = 4.303 / 1.732 = 2.484
    mean, lo, hi = stats.mean_interval([1, 2, 3])
    assert (
        mean == 2
        and hi - mean == pytest.approx(sst.t.ppf(0.975, 2) / math.sqrt(3))
        and lo == pytest.approx(2 - 2.484, abs=1e-3)
    )
    assert math.isnan(stats.mean_interval([1.0])[1])


def test_spearman_by_hand():
    assert stats.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert stats.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ranks x 1 2 3, y 1 3 2: rho = 1 - 6 * (0 + 1 + 1) / (3 * 8) = 0.5
    assert stats.spearman([1, 2, 3], [1, 3, 2]) == pytest.approx(0.5)
    assert math.isnan(stats.spearman([1, 2], [1, 2]))


def test_spearman_p_over_orderings_by_hand():
    # 3 pairs: the 6 orderings give rho 1, .5, .5, -.5, -.5, -1; |rho| >= 1 for 2 of them
    assert stats.spearman_p([1, 2, 3], [1, 2, 3]) == pytest.approx(2 / 6)
    assert stats.spearman_p([1, 2, 3], [1, 3, 2]) == pytest.approx(1.0)  # every ordering reaches |rho| >= 0.5
    # 4 pairs: only the identity and its reverse of the 24 reach |rho| = 1
    assert stats.spearman_p([1, 2, 3, 4], [8, 6, 4, 2]) == pytest.approx(2 / 24)
    assert math.isnan(stats.spearman_p([1, 2, 3], [5, 5, 5]))
    # above max_exact: scipy's t approximation, no generator
    x, y = [1, 2, 3, 4, 5], [2, 1, 4, 3, 5]
    assert stats.spearman_p(x, y, max_exact=10) == pytest.approx(sst.spearmanr(x, y).pvalue)
    # the null of 7 untied robots: 5040 orderings, 2 of which reach |rho| = 1
    null = stats.spearman_null(7)
    assert null.size == 5040 and np.sum(null >= 1 - 1e-12) == 2


@pytest.mark.parametrize("n", simulate.SEEDS)
def test_each_claims_rule_holds_its_level_under_the_null(n):
    # 2000 simulated stores per claim: a verdict other than "cannot tell" (for (d): a false one) in at most
    # alpha + 3 simulation standard errors of them (0.05 + 3 x 0.0049 = 0.065)
    draws = simulate.DRAWS
    bound = stats.ALPHA + 3 * simulate.simulation_se(stats.ALPHA, draws)
    rates = simulate.false_verdict_rates(n, draws)
    assert set(rates) == {"a", "b", "c", "d equal", "d boundary", "e"}
    assert all(r <= bound for r in rates.values()), rates


@pytest.mark.parametrize("n", simulate.SEEDS)
def test_intervals_cover_a_known_difference_at_their_nominal_rate(n):
    draws = simulate.DRAWS
    tol = 3 * simulate.simulation_se(0.95, draws)  # 0.0146
    cover = simulate.coverage(n, draws)
    assert abs(cover["welch"] - 0.95) <= tol and abs(cover["contrast"] - 0.95) <= tol, cover


def test_the_simulated_rule_is_the_claims_rule():
    # one simulated store of claim (b) (3 robots x film + 3 baselines x 3 seeds) through claims.claim_b and
    # through simulate.claim_b: the same verdict, for several draws with effects of every kind
    from morfic_cli.report import claims as C

    rng = np.random.default_rng(3)
    for shift in (0.0, 1.5, -1.5, 3.0):
        x = rng.normal(size=(1, 3, 4, 3))
        x[:, :, 0] += shift
        x[:, 1, 0] -= shift * (shift > 2)  # a mixed store: film better on two robots, not on mini_cheetah
        rows = [
            {
                "variant": v,
                "robot": r,
                "vx_mean": float(x[0, i, j, k]),
                "survival": 1.0,
                "seed": k,
                "mode": "descriptor",
                "command_vx": 2.0,
                "artifact": "x",
            }
            for i, r in enumerate(C.OOD_ROBOTS)
            for j, v in enumerate(("film", *C.BASELINES))
            for k in range(3)
        ]
        assert C.claim_b(rows).verdict == simulate.claim_b(x)[0]


def test_docs_report_shows_the_simulated_rates_as_the_code_gives_them():
    # docs/report.md's block is generated (scripts/stats_calibration.py): it must be what the code gives now
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "report.md").read_text()
    assert simulate.calibration_markdown() in text
