"""The paper's claims (a)-(e) on hand-made result rows: every effect, test and verdict worked out by hand.

Seeds that repeat one value have zero spread, so their difference is exact (p 0, a point interval; p 1 for a tie):
most cases below are decided that way; the cases with spread give Welch's numbers by hand.
"""

from __future__ import annotations

import math

import pytest

from morfic_cli.report import claims as C
from morfic_cli.report.stats import CANNOT, HOLDS, MIXED, NOT, PARTLY, REVERSED


def _eval(variant, robot, vx, s=1.0, seed=0, d=0.3, mode="descriptor", command_vx=2.0):
    return {
        "variant": variant,
        "robot": robot,
        "vx_mean": vx,
        "survival": s,
        "seed": seed,
        "d": d,
        "mode": mode,
        "command_vx": command_vx,
        "artifact": f"e-{variant}-{seed}",
    }


def _evals(variant, robot, vx, seeds=(0, 1), **kw):
    """The same row for each seed: a point interval."""
    return [_eval(variant, robot, vx, seed=k, **kw) for k in seeds]


def _calib(variant, robot, ev, seeds=(0, 1), command_vx=2.0):
    return [
        {
            "variant": variant,
            "robot": robot,
            "ev": ev,
            "seed": k,
            "command_vx": command_vx,
            "artifact": f"c-{variant}-{k}",
        }
        for k in seeds
    ]


def _fixed(v, robot, flip, cos, seeds=(0, 1), actor="film"):
    return [
        {
            "variant": v,
            "robot": robot,
            "flip": flip,
            "cos_grad": cos,
            "actor_variant": actor,
            "seed": k,
            "command_vx": 2.0,
            "artifact": f"f-{v}-{k}",
        }
        for k in seeds
    ]


def test_groups_follow_the_critic_conditioning():
    assert set(C.MULTIPLICATIVE) == {"film", "film-scaled", "hyper", "adaln"}
    assert set(C.ADDITIVE) == {"ppo", "actor-only", "concat"}


def test_seed_stat_is_mean_and_population_std():
    s = C.seed_stat([1.0, 2.0, 3.0])
    assert s.mean == 2.0 and s.std == pytest.approx(math.sqrt(2 / 3)) and s.n == 3
    assert s.text() == "2.00 ± 0.82 (n=3)" and C.seed_stat([1.0]).text() == "1.00"
    assert C.seed_stat([float("nan")]) is None


def test_per_seed_keeps_the_last_row_of_a_seed_and_filters_the_command():
    rows = [
        *_evals("film", "aliengo", 1.0),
        _eval("film", "aliengo", 1.5, seed=1),  # seed 1 again: replaces
        _eval("film", "aliengo", float("nan"), seed=2),
        _eval("film", "go2", 9.0),
        _eval("film", "aliengo", 7.0, command_vx=1.0),
    ]
    assert C.per_seed(C.at_command(rows, 2.0), "vx_mean", "aliengo") == {"film": [1.0, 1.5]}
    assert C.per_seed(C.at_command(rows, 1.0), "vx_mean", "aliengo") == {"film": [7.0]}
    # a row without command_vx was written at the paper's command
    assert C.row_command({}) == 2.0 and C.row_command({"command_vx": "1.0"}) == 1.0


def test_judge_corrects_over_the_claims_comparisons():
    # three comparisons with p 0.01, 0.02, 0.04, all pointing the claimed way: Holm 0.03, 0.04, 0.04 -> all < 0.05
    e = C.stats.mean_difference([1, 2, 3], [0, 1, 2])
    comps = [C.Comparison("r", f"c{k}", 1.0, p, 1, e) for k, p in enumerate((0.01, 0.02, 0.04))]
    assert C.judge(comps) == HOLDS
    assert [c.p_holm for c in comps] == pytest.approx([0.03, 0.04, 0.04])
    # p 0.01 for, 0.03 against: Holm 0.02 and 0.03 -> one each way: mixed
    comps = [C.Comparison("r", "x", 1.0, 0.01, 1, e), C.Comparison("r", "y", -1.0, 0.03, -1, e)]
    assert C.judge(comps) == MIXED
    # a missing comparison counts in m: 0.02 x 2 = 0.04 still decides, but "holds" needs the missing one too
    comps = [C.Comparison("r", "x", 1.0, 0.02, 1, e), C.missing("r", "y", "ppo not evaluated")]
    assert C.judge(comps) == PARTLY and comps[0].p_holm == pytest.approx(0.04)
    # not significant: the seeds that would decide it, at alpha / m (here 0.05 / 2; sds 1 and 1, effect 1: 21,
    # against 17 at 0.05)
    comps = [C.Comparison("r", "x", 1.0, 0.2, 1, e), C.Comparison("r", "y", 1.0, 0.3, 1, e)]
    assert C.judge(comps) == CANNOT and comps[0].need == C.stats.seeds_needed(e, alpha=0.025) == 21
    assert "[21 seeds/side for 80% power]" in comps[0].text()


def test_claim_a_t_contrast_of_ev():
    rows = []
    # aliengo: film 0.6, hyper 0.4 (group 0.5) vs ppo 0.2, concat 0.4 (group 0.3): +0.20, zero spread: p 0 -> for
    rows += [
        *_calib("film", "aliengo", 0.6),
        *_calib("hyper", "aliengo", 0.4),
        *_calib("ppo", "aliengo", 0.2),
        *_calib("concat", "aliengo", 0.4),
    ]
    # mini_cheetah: 0.1 vs 0.5: -0.40, against
    rows += [*_calib("film", "mini_cheetah", 0.1), *_calib("ppo", "mini_cheetah", 0.5)]
    # anymal_c: no additive critic (counted in m = 3, no test); genloco is in neither group
    rows += [*_calib("film", "anymal_c", 0.9), *_calib("genloco", "anymal_c", 0.0)]
    c = C.claim_a(rows)
    assert c.verdict == MIXED and c.command_vx == 2.0 and c.label == "a@2.0"
    assert "aliengo: EV multiplicative - additive +0.20 [+0.20, +0.20] (n 4 vs 4, p 0, Holm 0)" in c.ours
    assert "mini_cheetah: EV multiplicative - additive -0.40 [-0.40, -0.40] (n 2 vs 2, p 0, Holm 0)" in c.ours
    assert "anymal_c: EV multiplicative - additive (no test: no additive critic diagnosed at 2.0 m/s)" in c.ours
    assert c.reason.startswith("1 of 3 primary comparisons significant in the claimed direction (> 0), 1 against")
    assert "for: aliengo EV multiplicative - additive; against: mini_cheetah" in c.reason
    assert [r["outcome"] for r in c.comparisons] == ["for", "against", "not significant"]
    assert c.artifacts == [
        "c-concat-0",
        "c-concat-1",
        "c-film-0",
        "c-film-1",
        "c-hyper-0",
        "c-hyper-1",
        "c-ppo-0",
        "c-ppo-1",
    ]


def test_claim_a_a_variant_with_one_seed_has_no_test():
    rows = [
        *_calib("film", "aliengo", 0.6),
        *_calib("hyper", "aliengo", 0.4, seeds=(0,)),
        *_calib("ppo", "aliengo", 0.2),
    ]
    c = C.claim_a(rows)
    # (0.6 + 0.4) / 2 - 0.2 = +0.30, no test: hyper has one seed
    assert c.verdict == CANNOT
    assert "aliengo: EV multiplicative - additive +0.30 (n 3 vs 2: no test)" in c.ours
    assert c.reason.startswith("One seed per variant: no test")


def test_a_store_of_one_seed_per_variant_cannot_tell_any_claim():
    evals = [
        _eval(v, r, 1.0 + 0.1 * k, seed=0, d=0.1 * i)
        for k, v in enumerate(C.STOCK)
        for i, r in enumerate(("go2", "go1", "a1", "aliengo", "mini_cheetah", "anymal_c", "b1"))
    ]
    calib = [r for v in C.STOCK for robot in C.OOD_ROBOTS for r in _calib(v, robot, 0.5, seeds=(0,))]
    fixed = [r for v in C.STOCK for robot in C.FIXED_ROBOTS for r in _fixed(v, robot, 0.2, 0.5, seeds=(0,))]
    claims = C.check_claims(evals, calib, fixed)
    assert [c.verdict for c in claims] == [CANNOT] * 5
    assert all(c.reason.startswith("One seed per variant: no test") for c in claims), [c.reason for c in claims]


def test_claim_b_film_minus_every_baseline():
    rows = []
    # aliengo: film 1.9 x 0.5 = 0.95 vs ppo 0.5, actor-only 0.6, concat 1.0 x 0.8 = 0.8: every effect > 0, exact
    rows += [
        *_evals("film", "aliengo", 1.9, s=0.5),
        *_evals("ppo", "aliengo", 0.5),
        *_evals("actor-only", "aliengo", 0.6),
        *_evals("concat", "aliengo", 1.0, s=0.8),
    ]
    # mini_cheetah: film falls (2.0 x 0 = 0) vs ppo 1.2 -> against (the others missing)
    rows += [*_evals("film", "mini_cheetah", 2.0, s=0.0), *_evals("ppo", "mini_cheetah", 1.2)]
    # anymal_c: both fall: 0 - 0, a tie: p 1
    rows += [r for v in ("film", *C.BASELINES) for r in _evals(v, "anymal_c", 0.5, s=0.0)]
    rows += [_eval("ppo", "aliengo", 9.0, mode="full")]  # another mode never counts
    c = C.claim_b(rows)
    assert c.verdict == MIXED  # 3 for, 1 against, 5 not significant
    assert (
        "aliengo: film - ppo +0.45 [+0.45, +0.45] (n 2 vs 2, p 0, Holm 0); film - actor-only +0.35 [+0.35, "
        "+0.35] (n 2 vs 2, p 0, Holm 0); film - concat +0.15 [+0.15, +0.15]"
    ) in c.ours
    assert "(v_x x S, seed mean: film 0.95 (v_x 1.90, S 0.50; n=2), ppo 0.50 (v_x 0.50, S 1.00; n=2)" in c.ours
    assert (
        "mini_cheetah: film - ppo -1.20 [-1.20, -1.20] (n 2 vs 2, p 0, Holm 0); film - actor-only (no test: "
        "actor-only not evaluated)"
    ) in c.ours
    assert "anymal_c: film - ppo +0.00 [+0.00, +0.00] (n 2 vs 2, p 1, Holm 1)" in c.ours
    assert c.reason.startswith("3 of 9 primary comparisons significant in the claimed direction")
    assert "film 1.98 m/s, S 1.00" in c.paper and "ppo 0.27 m/s, S 0.00" in c.paper


def test_claim_b_one_reversal_is_not_does_not_hold():
    # film loses to concat on aliengo, nothing else significant (ties elsewhere): partly reversed, the mirror of
    # "holds partly"; "does not hold" needs every comparison reversed
    rows = [r for robot in C.OOD_ROBOTS for v in ("film", *C.BASELINES) for r in _evals(v, robot, 1.0)]
    rows = [r for r in rows if not (r["robot"] == "aliengo" and r["variant"] == "concat")]
    rows += _evals("concat", "aliengo", 1.5)
    assert C.claim_b(rows).verdict == REVERSED
    every = [
        r
        for robot in C.OOD_ROBOTS
        for r in (*_evals("film", robot, 0.5), *[x for b in C.BASELINES for x in _evals(b, robot, 1.0)])
    ]
    assert C.claim_b(every).verdict == NOT


def test_claim_b_welch_by_hand():
    # film v_x x S {1.0, 2.0} (mean 1.5, s² 0.5); each baseline {1.2, 1.4} (mean 1.3, s² 0.02). Effect +0.20;
    # SE² = 0.5/2 + 0.02/2 = 0.26 (SE 0.510); df = 0.26² / (0.25² + 0.01²) = 1.080; t = 0.392, p = 0.76;
    # interval 0.20 ± t(0.975, 1.08) x 0.510 = [-5.25, +5.65]. Holm over 9 equal p's: min(1, 9 x 0.76) = 1.
    rows = [_eval("film", r, vx, seed=k) for r in C.OOD_ROBOTS for k, vx in enumerate((1.0, 2.0))]
    rows += [_eval(b, r, vx, seed=k) for b in C.BASELINES for r in C.OOD_ROBOTS for k, vx in enumerate((1.2, 1.4))]
    c = C.claim_b(rows)
    assert c.verdict == CANNOT
    assert "film - ppo +0.20 [-5.25, +5.65] (n 2 vs 2, p 0.76, Holm 1) [" in c.ours
    assert c.comparisons[0]["p"] == pytest.approx(0.758, abs=1e-3) and c.comparisons[0]["seeds_needed"] > 50


def test_claims_are_judged_at_each_command_apart():
    # at 2.0 m/s film loses to every baseline; at 1.0 m/s it beats them
    rows = []
    for robot in C.OOD_ROBOTS:
        rows += _evals("film", robot, 0.5)
        rows += _evals("film", robot, 1.0, command_vx=1.0)
        for b in C.BASELINES:
            rows += _evals(b, robot, 1.5)
            rows += _evals(b, robot, 0.8, command_vx=1.0)
    got = {c.label: c for c in C.check_claims(rows, [], [])}
    assert list(got) == [f"{k}@{vx}" for vx in ("2.0", "1.0") for k in "abcde"]
    assert got["b@2.0"].verdict == NOT and "film - ppo -1.00 [-1.00, -1.00]" in got["b@2.0"].ours
    assert got["b@1.0"].verdict == HOLDS and "film - ppo +0.20 [+0.20, +0.20]" in got["b@1.0"].ours
    assert "at 1.0 m/s" in got["b@1.0"].claim and "at 2.0 m/s" in got["b@2.0"].claim
    assert (
        got["a@1.0"].verdict == CANNOT
        and "aliengo: EV multiplicative - additive (no test: no critic diagnosed at 1.0 m/s)" in got["a@1.0"].ours
    )
    # 1.0 m/s is judged only where an out-of-distribution robot was evaluated there (not a Go2 walking check)
    assert [c.label for c in C.check_claims([_eval("film", "go2", 1.0, command_vx=1.0)], [], [])] == [
        f"{k}@2.0" for k in "abcde"
    ]
    assert [c.command_vx for c in C.check_claims(rows, [], [], commands=[1.0])] == [1.0] * 5


def test_claim_c_film_against_the_papers_three_baselines():
    rows = [
        *_fixed("film", "aliengo", 0.2, 0.9),
        *_fixed("ppo", "aliengo", 0.3, 0.5),
        *_fixed("film", "mini_cheetah", 0.2, 0.4),
        *_fixed("ppo", "mini_cheetah", 0.3, 0.5),  # Cos reversed
        *_fixed("film", "anymal_c", 0.0, 1.0),  # not a robot of claim (c)
        {"variant": "mc", "robot": "aliengo", "flip": 0.0, "cos_grad": 1.0, "artifact": "f"},
    ]  # MC: reference
    c = C.claim_c(rows)
    # 12 primary comparisons: 3 for (both aliengo, mini_cheetah's Flip), 1 against, 8 without a test
    assert c.verdict == MIXED and "against: mini_cheetah film - ppo Cos" in c.reason
    assert (
        "aliengo: film - ppo Flip -0.100 [-0.100, -0.100] (n 2 vs 2, p 0, Holm 0); film - ppo Cos +0.400 "
        "[+0.400, +0.400]"
    ) in c.ours
    assert "(Flip/Cos: ppo 0.300/0.500 (n=2), film 0.200/0.900 (n=2))" in c.ours
    assert len(c.comparisons) == 12
    # a critic scored on another actor's rollouts (concat's own) is not compared: it would win on AlienGo here
    c = C.claim_c([*rows, *_fixed("concat", "aliengo", 0.1, 0.95, actor="concat")])
    assert c.verdict == MIXED and "concat 0." not in c.ours
    # a multiplicative critic is printed beside, deciding nothing (hyper beats film here)
    c = C.claim_c([*rows, *_fixed("hyper", "aliengo", 0.1, 0.95)])
    assert c.verdict == MIXED and "beside (not deciding, no correction): aliengo film - hyper Flip +0.100" in c.ours


def test_claim_d_every_pair_against_the_tolerance():
    rows = []
    for robot, vals in (
        ("aliengo", (1.0, 1.1, 1.2, 1.25)),  # every pair within 0.25 < max(0.3, 0.23): similar
        ("mini_cheetah", (0.5, 1.0, 1.0, 1.05)),  # at most 0.55 < the paper's 0.58
        ("anymal_c", (0.1, 0.5, 0.5, 0.5)),
    ):  # film 0.40 from each > 0.3: 3 pairs beyond
        for v, x in zip(C.MULTIPLICATIVE, vals, strict=True):
            rows += _evals(v, robot, x)
    c = C.claim_d(rows)
    assert c.verdict == MIXED and len(c.comparisons) == 18
    assert c.reason.startswith("15 of 18 primary comparisons significant in the claimed direction")
    assert "against: anymal_c film - film-scaled, anymal_c film - hyper, anymal_c film - adaln" in c.reason
    assert "tolerance ±0.58 m/s; spread of the means 0.55" in c.ours
    assert C.paper_spread("aliengo") == pytest.approx(0.23)
    # the tolerance scales with the command: at 1.0 m/s half of 2.0 m/s's
    assert C.tolerance("aliengo", 1.0) == pytest.approx(0.15) and C.tolerance("mini_cheetah", 1.0) == pytest.approx(
        0.29
    )
    similar = [r for robot in C.OOD_ROBOTS for v in C.MULTIPLICATIVE for r in _evals(v, robot, 1.0)]
    assert C.claim_d(similar).verdict == HOLDS


def test_claim_d_a_pair_with_spread_gets_the_equivalence_test():
    # film {0.8, 1.6} (mean 1.2, s² 0.32) against the others' constant 1.0 / 1.1 / 1.0: SE² = 0.16, SE 0.4, df 1;
    # film - hyper = +0.1, its 95 % interval 0.1 ± 12.71 x 0.4 = [-4.98, +5.18], far outside ±0.3: not similar
    # (p_eq = 2 x max(t.sf(0.4 / 0.4, 1), t.cdf(-0.2 / 0.4, 1)) = 2 x 0.352 = 0.70), not beyond either; the pairs
    # without film are exact
    # (p 0): 3 of the 6 aliengo pairs similar
    rows = [_eval("film", "aliengo", 0.8, seed=0), _eval("film", "aliengo", 1.6, seed=1)]
    for v, x in zip([v for v in C.MULTIPLICATIVE if v != "film"], (1.0, 1.1, 1.0), strict=True):
        rows += _evals(v, "aliengo", x)
    c = C.claim_d(rows)
    assert "film - hyper +0.10 [-4.98, +5.18] (n 2 vs 2, similar p 0.7, Holm 1)" in c.ours
    assert "hyper - adaln +0.10 [+0.10, +0.10] (n 2 vs 2, similar p 0, Holm 0)" in c.ours
    assert c.verdict == PARTLY and c.reason.startswith("3 of 18")


def test_claim_d_needs_every_multiplicative_variant_with_seeds():
    c = C.claim_d([r for robot in C.OOD_ROBOTS for r in _evals("film", robot, 1.0)])
    assert c.verdict == CANNOT and "film - film-scaled (no test: film-scaled not evaluated)" in c.ours
    rows = [r for v in C.MULTIPLICATIVE for r in _evals(v, "aliengo", 1.0, seeds=(0,) if v == "hyper" else (0, 1))]
    c = C.claim_d(rows)
    assert "film - hyper +0.00 (n 2 vs 1: no test)" in c.ours


def test_spearman_by_hand():
    assert C.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ranks x 1,2,3 ; y 1,3,2 -> rho = 1 - 6*(0+1+1)/(3*8) = 0.5
    assert C.spearman([1, 2, 3], [10, 30, 20]) == pytest.approx(0.5)
    # ties get the average rank: y ranks 1.5,1.5,3 -> pearson of (1,2,3) and (1.5,1.5,3) = 0.866
    assert C.spearman([1, 2, 3], [5, 5, 9]) == pytest.approx(math.sqrt(3) / 2)
    assert C.spearman([1, 2], [1, 2]) is None and C.spearman([1, 2, 3], [1, 1, 1]) is None


def test_claim_e_rho_per_variant_with_holm_over_the_variants():
    robots = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah")
    rows = []
    for k, r in enumerate(robots):
        rows += _evals("film", r, 2.0 - k * 0.3, d=0.1 * k)  # falls with d: rho -1
        rows += _evals("ppo", r, 0.5 + k * 0.3, d=0.1 * k)  # rises: +1
        rows += _evals("hyper", r, 2.0 - k * 0.3, d=0.1 * k, seeds=(0,))  # one seed: no test
    c = C.claim_e(rows)
    # 6 robots: only the identity and its reverse of the 720 orderings reach |rho| = 1 -> p = 2/720 = 0.0028;
    # Holm over the 3 variants: 3 x 0.0028 = 0.0083 (film), 2 x 0.0028 = 0.0056 -> 0.0083 (ppo): both decide
    assert c.verdict == MIXED
    assert "film: rho over 6 robots (seeds 2) -1.00 (p 0.0028, Holm 0.0083)" in c.ours
    assert "ppo: rho over 6 robots (seeds 2) +1.00 (p 0.0028, Holm 0.0083)" in c.ours
    assert "hyper: rho over 6 robots (seeds 1) -1.00 (no test: one seed per variant: no test)" in c.ours
    assert "rho -0.82" in c.paper  # the paper's MorFiC-F zero-shot table against our distances


def test_claim_e_five_robots_cannot_pass_holm_over_three_variants():
    # 5 robots: p = 2/120 = 0.0167 each; Holm over film, ppo, hyper: 3 x 0.0167 = 0.05, not below 0.05
    robots = ("go2", "go1", "a1", "aliengo", "b1")
    rows = [
        r
        for k, robot in enumerate(robots)
        for v in ("film", "ppo", "hyper")
        for r in _evals(v, robot, 2.0 - k * 0.3, d=0.1 * k)
    ]
    c = C.claim_e(rows)
    assert c.verdict == CANNOT and "(p 0.017, Holm 0.05)" in c.ours


def test_claim_e_needs_three_robots():
    c = C.claim_e([*_evals("film", "go2", 2.0, d=0.0), *_evals("film", "go1", 1.0, d=0.1)])
    assert c.verdict == CANNOT and "film: rho over 2 robots (seeds 2) (no test: 2 robots, too few)" in c.ours


def test_no_results_cannot_tell_anything():
    claims = C.check_claims([], [], [])
    assert [c.verdict for c in claims] == [CANNOT] * 5 and {c.command_vx for c in claims} == {2.0}
