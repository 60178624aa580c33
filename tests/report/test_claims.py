"""The paper's claims (a)-(e) on hand-made result rows, every verdict worked out by hand."""

from __future__ import annotations

import math

import pytest

from morfic_cli.report import claims as C


def _eval(variant, robot, vx, s=1.0, seed=0, d=0.3, mode="descriptor", command_vx=2.0):
    return {"variant": variant, "robot": robot, "vx_mean": vx, "survival": s, "seed": seed, "d": d, "mode": mode,
            "command_vx": command_vx, "artifact": f"e-{variant}-{seed}"}


def _calib(variant, robot, ev, seed=0):
    return {"variant": variant, "robot": robot, "ev": ev, "seed": seed, "artifact": f"c-{variant}-{seed}"}


def test_groups_follow_the_critic_conditioning():
    assert set(C.MULTIPLICATIVE) == {"film", "film-scaled", "hyper", "adaln"}
    assert set(C.ADDITIVE) == {"ppo", "actor-only", "concat"}


def test_seed_stat_and_better_use_the_seeds_spread():
    s = C.seed_stat([1.0, 2.0, 3.0])
    assert s.mean == 2.0 and s.std == pytest.approx(math.sqrt(2 / 3)) and s.n == 3
    # 2.0 +- 0.816 vs 1.0 +- 0.0: the difference 1.0 exceeds max std 0.816 -> True
    assert C.better(s, C.Stat(1.0, 0.0, 3)) is True
    # vs 1.5: difference 0.5 < 0.816 -> within noise
    assert C.better(s, C.Stat(1.5, 0.0, 3)) is None
    # one seed: any difference above the resolution counts; below it, a tie
    assert C.better(C.Stat(1.01, 0, 1), C.Stat(1.0, 0, 1)) is True
    assert C.better(C.Stat(1.01, 0, 1), C.Stat(1.0, 0, 1), resolution=0.05) is None
    assert C.better(C.Stat(1.10, 0, 1), C.Stat(1.0, 0, 1), resolution=0.05) is True
    assert C.better(C.Stat(0.2, 0, 1), C.Stat(0.3, 0, 1), higher=False) is True
    # one side over seeds, the other one seed: the seeded side's spread counts (ppo's EV over 2 seeds, -23.88 +- 9.93,
    # against a single-seed group mean of -28.27: the difference 4.39 is within 9.93 -> undecided)
    assert C.better(C.Stat(-28.27, 0.0, 1), C.Stat(-23.88, 9.93, 2)) is None
    assert C.better(C.Stat(-10.0, 0.0, 1), C.Stat(-23.88, 9.93, 2)) is True  # 13.88 > 9.93
    # a group's pool: mean of the variants' means, the seeded variants' largest std, the most seeds
    pooled = C._pool([C.Stat(-12.6, 12.94, 2), C.Stat(-0.55, 0.0, 1), C.Stat(-8.68, 0.0, 1)])
    assert pooled.mean == pytest.approx((-12.6 - 0.55 - 8.68) / 3) and pooled.std == 12.94 and pooled.n == 2


def test_all_of_loses_on_any_lost_comparison():
    assert C.all_of([True, None, False]) is False
    assert C.all_of([True, None]) is None
    assert C.all_of([True, True]) is True


def test_verdict_rules():
    assert C.verdict([True, True, True]) == C.HOLDS
    assert C.verdict([True, False, None]) == C.PARTLY
    assert C.verdict([False, None]) == C.NOT
    assert C.verdict([None, None]) == C.CANNOT


def test_claim_a_compares_group_means_of_ev():
    rows = []
    # aliengo: film 0.6, hyper 0.4 (mean 0.5) vs ppo 0.2, concat 0.4 (mean 0.3): holds
    rows += [_calib("film", "aliengo", 0.6), _calib("hyper", "aliengo", 0.4), _calib("ppo", "aliengo", 0.2),
             _calib("concat", "aliengo", 0.4)]
    # mini_cheetah: multiplicative 0.1 vs additive 0.5: does not
    rows += [_calib("film", "mini_cheetah", 0.1), _calib("ppo", "mini_cheetah", 0.5)]
    # anymal_c: no additive critic -> undecided
    rows += [_calib("film", "anymal_c", 0.9)]
    c = C.claim_a(rows)
    assert c.verdict == C.PARTLY
    assert "multiplicative 0.50 vs additive 0.30" in c.ours
    assert "not on mini_cheetah" in c.reason and "undecided on anymal_c" in c.reason
    assert c.reason.startswith("The multiplicative mean EV is higher on aliengo;")  # "EV", not "ev"
    assert c.artifacts == ["c-concat-0", "c-film-0", "c-hyper-0", "c-ppo-0"]


def test_claim_b_film_must_keep_more_speed_than_every_baseline():
    # v_x x S on aliengo: film 1.9 x 0.5 = 0.95 vs ppo 0.5 x 1 = 0.5 and concat 1.0 x 0.8 = 0.8 -> yes
    rows = [_eval("film", "aliengo", 1.9, s=0.5), _eval("ppo", "aliengo", 0.5), _eval("concat", "aliengo", 1.0, s=0.8),
            # mini_cheetah: film fast but falls (2.0 x 0 = 0) vs ppo slower and survives (1.2 x 1) -> no
            _eval("film", "mini_cheetah", 2.0, s=0.0), _eval("ppo", "mini_cheetah", 1.2),
            # anymal_c: 0.30 vs 0.28 -> within the resolution: a tie -> undecided
            _eval("film", "anymal_c", 0.30), _eval("ppo", "anymal_c", 0.28),
            _eval("ppo", "aliengo", 9.0, mode="full")]  # another mode never counts
    c = C.claim_b(rows)
    assert c.verdict == C.PARTLY
    assert "film 0.95 (v_x 1.90, S 0.50), ppo 0.50 (v_x 0.50, S 1.00), concat 0.80" in c.ours
    assert "not on mini_cheetah" in c.reason and "undecided on anymal_c" in c.reason
    assert "film 1.98 m/s, S 1.00" in c.paper and "ppo 0.27 m/s, S 0.00" in c.paper


def test_claim_b_with_seeds_inside_noise_cannot_tell():
    rows = [_eval("film", r, vx, seed=k) for r in C.OOD_ROBOTS for k, vx in enumerate((1.0, 2.0))]
    rows += [_eval("ppo", r, vx, seed=k) for r in C.OOD_ROBOTS for k, vx in enumerate((1.2, 1.4))]
    # v_x x S (S = 1): film 1.5 +- 0.5 vs ppo 1.3 +- 0.1: difference 0.2 < 0.5 on every robot
    c = C.claim_b(rows)
    assert c.verdict == C.CANNOT and "1.50 ± 0.50 (n=2)" in c.ours


def test_claim_c_lowest_flip_and_highest_cos():
    def fx(v, robot, flip, cos, actor="film"):
        return {"variant": v, "robot": robot, "flip": flip, "cos_grad": cos, "actor_variant": actor, "artifact": "f"}

    rows = [fx("film", "aliengo", 0.2, 0.9), fx("ppo", "aliengo", 0.3, 0.5),
            fx("film", "mini_cheetah", 0.2, 0.4), fx("ppo", "mini_cheetah", 0.3, 0.5),
            fx("film", "anymal_c", 0.0, 1.0),  # not a robot of claim (c)
            {"variant": "mc", "robot": "aliengo", "flip": 0.0, "cos_grad": 1.0, "artifact": "f"}]  # MC: reference
    c = C.claim_c(rows)
    assert c.verdict == C.PARTLY and "not on mini_cheetah" in c.reason
    # a critic scored on another actor's rollouts (concat's own) is not compared: it would win on AlienGo here
    c = C.claim_c([*rows, fx("concat", "aliengo", 0.1, 0.95, actor="concat")])
    assert c.verdict == C.PARTLY and "concat" not in c.ours


def test_claim_d_spread_against_the_tolerance():
    rows = []
    for robot, vals in (("aliengo", (1.0, 1.1, 1.2, 1.25)),  # spread 0.25 <= max(0.3, 0.23)
                        ("mini_cheetah", (0.5, 1.0, 1.0, 1.05)),  # spread 0.55 <= paper's 0.58
                        ("anymal_c", (0.1, 0.5, 0.5, 0.5))):  # spread 0.4 > max(0.3, 0.22)
        rows += [_eval(v, robot, x) for v, x in zip(C.MULTIPLICATIVE, vals, strict=True)]
    c = C.claim_d(rows)
    assert c.verdict == C.PARTLY and "not on anymal_c" in c.reason
    assert "spread 0.55 m/s, tolerance 0.58" in c.ours
    assert C.paper_spread("aliengo") == pytest.approx(0.23)


def test_claim_d_needs_every_multiplicative_variant():
    c = C.claim_d([_eval("film", r, 1.0) for r in C.OOD_ROBOTS])
    assert c.verdict == C.CANNOT and "film-scaled, hyper, adaln not evaluated" in c.ours


def test_spearman_by_hand():
    assert C.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ranks x 1,2,3 ; y 1,3,2 -> rho = 1 - 6*(0+1+1)/(3*8) = 0.5
    assert C.spearman([1, 2, 3], [10, 30, 20]) == pytest.approx(0.5)
    # ties get the average rank: y ranks 1.5,1.5,3 -> pearson of (1,2,3) and (1.5,1.5,3) = 0.866
    assert C.spearman([1, 2, 3], [5, 5, 9]) == pytest.approx(math.sqrt(3) / 2)
    assert C.spearman([1, 2], [1, 2]) is None and C.spearman([1, 2, 3], [1, 1, 1]) is None


def test_claim_e_rank_correlation_of_distance_and_speed_times_survival():
    robots = ("go2", "go1", "aliengo", "b1")
    # film: v_x x S falls with d -> rho -1 (holds); ppo: rises -> rho +1
    rows = [_eval("film", r, 2.0 - k * 0.5, d=0.1 * k) for k, r in enumerate(robots)]
    rows += [_eval("ppo", r, 0.5 + k * 0.5, d=0.1 * k) for k, r in enumerate(robots)]
    c = C.claim_e(rows)
    assert c.verdict == C.PARTLY
    assert "film: rho -1.00 over 4 robots" in c.ours and "ppo: rho +1.00" in c.ours
    assert "rho -0.82" in c.paper  # the paper's MorFiC-F zero-shot table against our distances


def test_no_results_cannot_tell_anything():
    assert [c.verdict for c in C.check_claims([], [], [])] == [C.CANNOT] * 5
