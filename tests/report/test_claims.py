"""The paper's claims (a)-(e) on hand-made result rows: every effect, interval and verdict worked out by hand.

Seeds that repeat one value give a point interval (every bootstrap resample has the same mean), so most cases below
are exact; the two-value cases list the resample means by hand.
"""

from __future__ import annotations

import math

import pytest

from morfic_cli.report import claims as C
from morfic_cli.report.stats import CANNOT, HOLDS, NOT


def _eval(variant, robot, vx, s=1.0, seed=0, d=0.3, mode="descriptor", command_vx=2.0):
    return {"variant": variant, "robot": robot, "vx_mean": vx, "survival": s, "seed": seed, "d": d, "mode": mode,
            "command_vx": command_vx, "artifact": f"e-{variant}-{seed}"}


def _evals(variant, robot, vx, seeds=(0, 1), **kw):
    """The same row for each seed: a point interval."""
    return [_eval(variant, robot, vx, seed=k, **kw) for k in seeds]


def _calib(variant, robot, ev, seeds=(0, 1), command_vx=2.0):
    return [{"variant": variant, "robot": robot, "ev": ev, "seed": k, "command_vx": command_vx,
             "artifact": f"c-{variant}-{k}"} for k in seeds]


def _fixed(v, robot, flip, cos, seeds=(0, 1), actor="film"):
    return [{"variant": v, "robot": robot, "flip": flip, "cos_grad": cos, "actor_variant": actor, "seed": k,
             "command_vx": 2.0, "artifact": f"f-{v}-{k}"} for k in seeds]


def test_groups_follow_the_critic_conditioning():
    assert set(C.MULTIPLICATIVE) == {"film", "film-scaled", "hyper", "adaln"}
    assert set(C.ADDITIVE) == {"ppo", "actor-only", "concat"}


def test_seed_stat_is_mean_and_population_std():
    s = C.seed_stat([1.0, 2.0, 3.0])
    assert s.mean == 2.0 and s.std == pytest.approx(math.sqrt(2 / 3)) and s.n == 3
    assert s.text() == "2.00 ± 0.82 (n=3)" and C.seed_stat([1.0]).text() == "1.00"
    assert C.seed_stat([float("nan")]) is None


def test_per_seed_keeps_the_last_row_of_a_seed_and_filters_the_command():
    rows = [*_evals("film", "aliengo", 1.0), _eval("film", "aliengo", 1.5, seed=1),  # seed 1 again: replaces
            _eval("film", "aliengo", float("nan"), seed=2), _eval("film", "go2", 9.0),
            _eval("film", "aliengo", 7.0, command_vx=1.0)]
    assert C.per_seed(C.at_command(rows, 2.0), "vx_mean", "aliengo") == {"film": [1.0, 1.5]}
    assert C.per_seed(C.at_command(rows, 1.0), "vx_mean", "aliengo") == {"film": [7.0]}
    # a row without command_vx was written at the paper's command
    assert C.row_command({}) == 2.0 and C.row_command({"command_vx": "1.0"}) == 1.0


def test_verdict_rules():
    # on one robot, several comparisons that must all hold
    assert C.all_beat([HOLDS, HOLDS]) == HOLDS
    assert C.all_beat([HOLDS, CANNOT]) == CANNOT
    assert C.all_beat([HOLDS, CANNOT, NOT]) == NOT  # one reversed comparison refutes "beats every one"
    assert C.all_beat([]) == CANNOT
    # over the robots
    assert C.aggregate([HOLDS, HOLDS, HOLDS]) == HOLDS
    assert C.aggregate([HOLDS, NOT, CANNOT]) == C.PARTLY
    assert C.aggregate([HOLDS, CANNOT]) == C.PARTLY
    assert C.aggregate([NOT, CANNOT]) == NOT
    assert C.aggregate([CANNOT, CANNOT]) == CANNOT and C.aggregate([]) == CANNOT
    # an interval against a bound: "below" (e), "at most" (d)
    assert C.below_verdict(-0.9, -0.2, 0.0) == HOLDS
    assert C.below_verdict(0.0, 0.6, 0.0) == NOT  # rho >= 0: no degradation
    assert C.below_verdict(-0.5, 0.1, 0.0) == CANNOT
    assert C.below_verdict(0.1, 0.3, 0.3, inclusive=True) == HOLDS
    assert C.below_verdict(0.3, 0.5, 0.3, inclusive=True) == CANNOT
    assert C.below_verdict(0.31, 0.5, 0.3, inclusive=True) == NOT
    assert C.below_verdict(math.nan, math.nan, 0.0) == CANNOT
    assert C.interval_text(-0.5, -0.9, -0.1) == "-0.50 [-0.90, -0.10]"
    assert C.interval_text(0.4, math.nan, math.nan, signed=False) == "0.40 (no interval)"


def test_claim_a_group_effect_of_ev():
    rows = []
    # aliengo: film 0.6, hyper 0.4 (group 0.5) vs ppo 0.2, concat 0.4 (group 0.3): +0.20 [+0.20, +0.20] holds
    rows += [*_calib("film", "aliengo", 0.6), *_calib("hyper", "aliengo", 0.4), *_calib("ppo", "aliengo", 0.2),
             *_calib("concat", "aliengo", 0.4)]
    # mini_cheetah: 0.1 vs 0.5: -0.40, reversed
    rows += [*_calib("film", "mini_cheetah", 0.1), *_calib("ppo", "mini_cheetah", 0.5)]
    # anymal_c: no additive critic
    rows += _calib("film", "anymal_c", 0.9)
    c = C.claim_a(rows)
    assert c.verdict == C.PARTLY and c.command_vx == 2.0 and c.label == "a@2.0"
    assert "aliengo: EV multiplicative - additive +0.20 [+0.20, +0.20] (n 4 vs 4)" in c.ours
    assert "mini_cheetah: EV multiplicative - additive -0.40 [-0.40, -0.40] (n 2 vs 2, p 0.33)" in c.ours
    assert "anymal_c: no additive critic diagnosed at 2.0 m/s" in c.ours
    assert c.reason.startswith("The multiplicative group's EV is higher (interval above 0) on aliengo;")
    assert "does not hold on mini_cheetah" in c.reason and "cannot tell on anymal_c" in c.reason
    assert c.artifacts == ["c-concat-0", "c-concat-1", "c-film-0", "c-film-1", "c-hyper-0", "c-hyper-1", "c-ppo-0",
                           "c-ppo-1"]


def test_claim_a_a_variant_with_one_seed_leaves_no_interval():
    rows = [*_calib("film", "aliengo", 0.6), *_calib("hyper", "aliengo", 0.4, seeds=(0,)),
            *_calib("ppo", "aliengo", 0.2)]
    c = C.claim_a(rows)
    # (0.6 + 0.4) / 2 - 0.2 = +0.30 without interval; film - ppo alone (both seeded) +0.40, shown, not the verdict
    assert c.verdict == CANNOT
    assert "+0.30 (n 3 vs 2: no interval); film - ppo alone (the variants with seeds, not the verdict): " \
           "+0.40 [+0.40, +0.40]" in c.ours
    assert "hyper has one seed" in c.reason


def test_claim_b_film_minus_every_baseline():
    rows = []
    # aliengo: film 1.9 x 0.5 = 0.95 vs ppo 0.5, actor-only 0.6, concat 1.0 x 0.8 = 0.8: every effect > 0 -> holds
    rows += [*_evals("film", "aliengo", 1.9, s=0.5), *_evals("ppo", "aliengo", 0.5),
             *_evals("actor-only", "aliengo", 0.6), *_evals("concat", "aliengo", 1.0, s=0.8)]
    # mini_cheetah: film falls (2.0 x 0 = 0) vs ppo 1.2 -> reversed (the others missing: cannot tell) -> not
    rows += [*_evals("film", "mini_cheetah", 2.0, s=0.0), *_evals("ppo", "mini_cheetah", 1.2)]
    # anymal_c: both fall: 0 - 0 = [0, 0], a tie -> cannot tell
    rows += [r for v in ("film", *C.BASELINES) for r in _evals(v, "anymal_c", 0.5, s=0.0)]
    rows += [_eval("ppo", "aliengo", 9.0, mode="full")]  # another mode never counts
    c = C.claim_b(rows)
    assert c.verdict == C.PARTLY
    assert ("aliengo: film - ppo +0.45 [+0.45, +0.45] (n 2 vs 2, p 0.33); film - actor-only +0.35 [+0.35, +0.35] "
            "(n 2 vs 2, p 0.33); film - concat +0.15 [+0.15, +0.15]") in c.ours
    assert "(v_x x S, seed mean: film 0.95 (v_x 1.90, S 0.50; n=2), ppo 0.50 (v_x 0.50, S 1.00; n=2)" in c.ours
    assert "mini_cheetah: film - ppo -1.20 [-1.20, -1.20] (n 2 vs 2, p 0.33); actor-only not evaluated" in c.ours
    assert "anymal_c: film - ppo +0.00 [+0.00, +0.00]" in c.ours
    assert "on aliengo; does not hold on mini_cheetah; cannot tell on anymal_c" in c.reason
    assert "film 1.98 m/s, S 1.00" in c.paper and "ppo 0.27 m/s, S 0.00" in c.paper


def test_claim_b_seeds_whose_interval_contains_zero_cannot_tell():
    # film v_x x S {1.0, 2.0}: resample means 1.0 / 1.5 / 2.0 (1/4, 1/2, 1/4); ppo {1.2, 1.4}: 1.2 / 1.3 / 1.4.
    # Effect 1.5 - 1.3 = +0.20; the extremes -0.40 and +0.80 each have probability 1/16 > 2.5 %: [-0.40, +0.80].
    # Permutation: every split of {1, 2, 1.2, 1.4} gives |diff| >= 0.2 -> p = 1.
    rows = [_eval("film", r, vx, seed=k) for r in C.OOD_ROBOTS for k, vx in enumerate((1.0, 2.0))]
    rows += [_eval(b, r, vx, seed=k) for b in C.BASELINES for r in C.OOD_ROBOTS for k, vx in enumerate((1.2, 1.4))]
    c = C.claim_b(rows)
    assert c.verdict == CANNOT
    assert "film - ppo +0.20 [-0.40, +0.80] (n 2 vs 2, p 1)" in c.ours


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
    assert got["a@1.0"].verdict == CANNOT and "aliengo: no critic diagnosed at 1.0 m/s" in got["a@1.0"].ours
    # 1.0 m/s is judged only where an out-of-distribution robot was evaluated there (not a Go2 walking check)
    assert [c.label for c in C.check_claims([_eval("film", "go2", 1.0, command_vx=1.0)], [], [])] == [
        f"{k}@2.0" for k in "abcde"]
    assert [c.command_vx for c in C.check_claims(rows, [], [], commands=[1.0])] == [1.0] * 5


def test_claim_c_lowest_flip_and_highest_cos_against_every_critic():
    rows = [*_fixed("film", "aliengo", 0.2, 0.9), *_fixed("ppo", "aliengo", 0.3, 0.5),
            *_fixed("film", "mini_cheetah", 0.2, 0.4), *_fixed("ppo", "mini_cheetah", 0.3, 0.5),  # Cos reversed
            *_fixed("film", "anymal_c", 0.0, 1.0),  # not a robot of claim (c)
            {"variant": "mc", "robot": "aliengo", "flip": 0.0, "cos_grad": 1.0, "artifact": "f"}]  # MC: reference
    c = C.claim_c(rows)
    assert c.verdict == C.PARTLY and "does not hold on mini_cheetah" in c.reason
    assert "aliengo: film - ppo Flip -0.100 [-0.100, -0.100] (n 2 vs 2, p 0.33), Cos +0.400 [+0.400, +0.400]" in c.ours
    assert "(Flip/Cos: film 0.200/0.900 (n=2), ppo 0.300/0.500 (n=2))" in c.ours
    # a critic scored on another actor's rollouts (concat's own) is not compared: it would win on AlienGo here
    c = C.claim_c([*rows, *_fixed("concat", "aliengo", 0.1, 0.95, actor="concat")])
    assert c.verdict == C.PARTLY and "concat" not in c.ours
    # a critic with one seed has no interval: film cannot be shown to beat it -> cannot tell on aliengo
    c = C.claim_c([*rows, *_fixed("hyper", "aliengo", 0.25, 0.6, seeds=(0,))])
    assert c.verdict == NOT and "film - hyper Flip -0.050 (n 2 vs 1: no interval)" in c.ours
    assert "cannot tell on aliengo" in c.reason


def test_claim_d_spread_interval_against_the_tolerance():
    rows = []
    for robot, vals in (("aliengo", (1.0, 1.1, 1.2, 1.25)),  # spread 0.25 [0.25, 0.25] <= max(0.3, 0.23)
                        ("mini_cheetah", (0.5, 1.0, 1.0, 1.05)),  # 0.55 <= the paper's 0.58
                        ("anymal_c", (0.1, 0.5, 0.5, 0.5))):  # 0.40 > max(0.3, 0.22): its lower end too
        for v, x in zip(C.MULTIPLICATIVE, vals, strict=True):
            rows += _evals(v, robot, x)
    c = C.claim_d(rows)
    assert c.verdict == C.PARTLY and "does not hold on anymal_c" in c.reason
    assert "mini_cheetah: spread 0.55 [0.55, 0.55] m/s against tolerance 0.58" in c.ours
    assert C.paper_spread("aliengo") == pytest.approx(0.23)
    # the tolerance scales with the command: at 1.0 m/s half of 2.0 m/s's
    assert C.tolerance("aliengo", 1.0) == pytest.approx(0.15) and C.tolerance("mini_cheetah", 1.0) == pytest.approx(
        0.29)


def test_claim_d_an_interval_straddling_the_tolerance_cannot_tell():
    # film {0.8, 1.6}: resample means 0.8 / 1.2 / 1.6 (1/4, 1/2, 1/4); the others 1.0, 1.1, 1.0 -> spread
    # 0.3 / 0.2 / 0.6: estimate (film 1.2) 0.2, interval [0.2, 0.6] around the tolerance 0.3 -> cannot tell
    rows = [_eval("film", "aliengo", 0.8, seed=0), _eval("film", "aliengo", 1.6, seed=1)]
    for v, x in zip([v for v in C.MULTIPLICATIVE if v != "film"], (1.0, 1.1, 1.0), strict=True):
        rows += _evals(v, "aliengo", x)
    c = C.claim_d(rows)
    assert "aliengo: spread 0.20 [0.20, 0.60] m/s against tolerance 0.30" in c.ours
    assert c.verdict == CANNOT


def test_claim_d_needs_every_multiplicative_variant_with_seeds():
    c = C.claim_d([r for robot in C.OOD_ROBOTS for r in _evals("film", robot, 1.0)])
    assert c.verdict == CANNOT and "film-scaled, hyper, adaln not evaluated" in c.ours
    rows = [r for v in C.MULTIPLICATIVE for r in _evals(v, "aliengo", 1.0, seeds=(0,) if v == "hyper" else (0, 1))]
    c = C.claim_d(rows)
    assert "spread 0.00 (no interval)" in c.ours and "hyper has one seed" in c.reason


def test_spearman_by_hand():
    assert C.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ranks x 1,2,3 ; y 1,3,2 -> rho = 1 - 6*(0+1+1)/(3*8) = 0.5
    assert C.spearman([1, 2, 3], [10, 30, 20]) == pytest.approx(0.5)
    # ties get the average rank: y ranks 1.5,1.5,3 -> pearson of (1,2,3) and (1.5,1.5,3) = 0.866
    assert C.spearman([1, 2, 3], [5, 5, 9]) == pytest.approx(math.sqrt(3) / 2)
    assert C.spearman([1, 2], [1, 2]) is None and C.spearman([1, 2, 3], [1, 1, 1]) is None


def test_claim_e_rho_interval_per_variant():
    robots = ("go2", "go1", "a1", "aliengo", "b1")
    rows = []
    for k, r in enumerate(robots):
        rows += _evals("film", r, 2.0 - k * 0.4, d=0.1 * k)  # falls with d, seeds alike: rho -1 [-1, -1]
        rows += _evals("ppo", r, 0.5 + k * 0.4, d=0.1 * k)  # rises: +1 [+1, +1]
        rows += _evals("hyper", r, 2.0 - k * 0.4, d=0.1 * k, seeds=(0,))  # one seed: no interval
    c = C.claim_e(rows)
    assert c.verdict == C.PARTLY
    # 5 robots: only the identity and its reverse of the 120 orderings reach |rho| = 1 -> p = 2/120 = 0.017
    assert "film: rho -1.00 [-1.00, -1.00] over 5 robots (seeds 2; p 0.017 over the robots' orderings)" in c.ours
    assert "ppo: rho +1.00 [+1.00, +1.00]" in c.ours and "hyper: rho -1.00 (no interval)" in c.ours
    assert "p < 0.05 on film; does not hold on ppo; cannot tell on hyper" in c.reason
    assert "rho -0.82" in c.paper  # the paper's MorFiC-F zero-shot table against our distances


def test_claim_e_an_interval_below_zero_needs_p_over_the_orderings_too():
    # 4 robots, rho -1 on every resample, but 2 of the 24 orderings reach |rho| = 1: p = 0.083 >= 0.05
    rows = [r for k, robot in enumerate(("go2", "go1", "a1", "aliengo"))
            for r in _evals("film", robot, 2.0 - k * 0.5, d=0.1 * k)]
    c = C.claim_e(rows)
    assert c.verdict == CANNOT
    assert "film: rho -1.00 [-1.00, -1.00] over 4 robots (seeds 2; p 0.083" in c.ours
    assert "On film the interval lies below 0 but p >= 0.05" in c.reason


def test_claim_e_needs_three_robots():
    c = C.claim_e([*_evals("film", "go2", 2.0, d=0.0), *_evals("film", "go1", 1.0, d=0.1)])
    assert c.verdict == CANNOT and "film: 2 robots, too few" in c.ours


def test_no_results_cannot_tell_anything():
    claims = C.check_claims([], [], [])
    assert [c.verdict for c in claims] == [CANNOT] * 5 and {c.command_vx for c in claims} == {2.0}
