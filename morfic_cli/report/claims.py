"""The paper's five claims, checked against the store's results: a verdict per claim, computed, never typed in.

Pure functions over the rows :func:`~morfic_cli.report.gather.gather` reads (eval.csv, calibration.csv and
fixed_rollout.csv rows, each with ``variant``, ``seed``, ``command_vx`` and ``artifact``). Every comparison is an
effect over seeds with a 95 % bootstrap interval from :mod:`morfic_cli.report.stats` (the method is stated there
and in docs/report.md, "How a verdict is read"): the verdict on a robot is read from the interval (for (e) with
the p over the robots' orderings too), never from a fixed tolerance, and the permutation p-value stands beside it.
A variant with one seed has no interval, so a comparison that needs it cannot tell.

On one robot (one variant for (e)) a comparison gives ``holds``, ``does not hold`` or ``cannot tell``. A claim that
needs several comparisons on a robot ("film beats every baseline") holds there when every one holds, does not hold
when any one does not (the interval lies wholly on the wrong side), and cannot tell otherwise. Over the robots
(:func:`aggregate`): ``holds`` when it holds on every robot the claim names, ``holds partly`` when on some but not
all, ``does not hold`` when on none and it does not hold on at least one, ``cannot tell`` when it cannot tell on
every robot. The claims (paper Sec. "Results" and the abstract), each judged at 2.0 m/s (the paper's command) and
at 1.0 m/s where the store holds results at that command (:func:`judged_commands`):

- (a) multiplicative critics (film, film-scaled, adaln, hyper) keep a higher EV than the additive ones
  (concat, ppo, actor-only) on the out-of-distribution robots: the group effect (mean over the multiplicative
  variants of their seed means minus the same over the additive ones), interval above 0;
- (b) MorFiC-F transfers better than PPO, actor-only and concat (1.98 m/s on AlienGo against below 0.65), compared
  as v_x x S, the speed kept over the episode: film minus each baseline, every interval above 0;
- (c) in the fixed-rollout analysis the film critic has the lowest Flip and the highest Cos on AlienGo and
  Mini Cheetah: film minus every other critic, each Flip interval below 0 and each Cos interval above 0;
- (d) all multiplicative variants transfer similarly (the ablation), an equivalence reading: the spread (max - min
  of the variants' mean v_x) with its bootstrap interval, holds when the interval's upper end is within the
  tolerance (:func:`tolerance`), does not hold when its lower end is above it;
- (e) transfer degrades with the normalised morphology distance d: Spearman's rho of v_x x S against d over the
  robots, per variant, with its bootstrap interval over each robot's seeds; does not hold when the interval's
  lower end is >= 0. The robots are fixed, so that interval carries seed noise only: it holds when the interval
  lies below 0 *and* the permutation p over the robots' orderings (:func:`~morfic_cli.report.stats.spearman_p`) is
  below alpha, i.e. the correlation also beats a random pairing of robots and distances (7 robots without ties:
  p < 0.05 needs |rho| >= 0.79; the paper's -0.82 passes); else it cannot tell.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from morfic_cli.report import paper, stats
from morfic_cli.report.stats import CANNOT, HOLDS, MIN_SEEDS, NOT
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, STOCK

#: The out-of-distribution targets of claims (a), (b) and (d) (the paper's "heavier and out of distribution
#: robots"; its transfer claim is about AlienGo, its calibration claim about Cheetah and AlienGo).
OOD_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah", "anymal_c")
#: The robots of the fixed-rollout claim (c) (paper Table "causal advantage").
FIXED_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah")
#: Multiplicative and additive critics (claim (a)) among the stock variants.
MULTIPLICATIVE: tuple[str, ...] = tuple(n for n, v in STOCK.items() if v.multiplicative)
ADDITIVE: tuple[str, ...] = tuple(n for n, v in STOCK.items() if not v.multiplicative)
#: Claim (b): the additive baselines MorFiC-F is compared with.
BASELINES: tuple[str, ...] = ("ppo", "actor-only", "concat")
#: Claim (d): "similar" transfer at the paper's command = the multiplicative variants' v_x within this many m/s of
#: each other on a robot, or within the paper's own spread there where that is larger (0.23 / 0.58 / 0.22 m/s on
#: AlienGo / Mini Cheetah / ANYmal-C, :func:`paper_spread`); scaled by the command at other commands
#: (:func:`tolerance`).
SIMILAR_VX: float = 0.3
#: The paper's evaluation command (m/s): its numbers, and the command every claim is judged at.
PAPER_COMMAND: float = 2.0
#: The trained regime's command (m/s): where every run but adaln's seeds 0 and 2 walks on its own template (Go2).
TRAINED_COMMAND: float = 1.0
#: The commands the claims are judged at, in the order they are reported: the paper's, then the trained regime
#: (:data:`TRAINED_COMMAND`), the latter only where the store has results at it.
JUDGED_COMMANDS: tuple[float, ...] = (PAPER_COMMAND, TRAINED_COMMAND)


def is_paper_command(command_vx: float) -> bool:
    """Whether ``command_vx`` (m/s) is :data:`PAPER_COMMAND`, the one command the paper reports numbers at."""
    return abs(command_vx - PAPER_COMMAND) < 1e-9


def command_suffix(command_vx: float) -> str:
    """How a result at ``command_vx`` is named beside the paper's: ``""`` at 2.0 m/s, ``"-1.0"`` at 1.0 m/s.

    docs/results/ names a run's results at another command than the paper's ``<run>-eval-1.0.csv``,
    ``<run>-calibration-1.0.csv`` and ``fixed-rollout-1.0-<robot>.csv``, their ids ``eval-1.0``, ``diagnosis-1.0``
    and ``fixed_rollout-1.0`` in ``<run>-artifacts.json``.
    """
    return "" if is_paper_command(command_vx) else f"-{command_vx:.1f}"


#: Each claim in a few words (a verdict table's rows).
SHORT: dict[str, str] = {
    "a": "multiplicative critics keep a higher EV (OOD robots)",
    "b": "MorFiC-F transfers better than ppo, actor-only, concat",
    "c": "film's critic has the lowest Flip, highest Cos (fixed rollout)",
    "d": "the multiplicative variants transfer similarly",
    "e": "transfer degrades with d",
}

PARTLY = "holds partly"
#: What a ``cannot tell`` on one robot means, said once in a claim's reason.
CANNOT_WHY = "the interval contains the bound, a side has fewer than 2 seeds, or a result is missing"


@dataclass(frozen=True)
class Stat:
    """A seed mean: ``mean`` and ``std`` (population std over ``n`` seeds; 0 for one seed)."""

    mean: float
    std: float
    n: int

    def text(self, decimals: int = 2) -> str:
        """``1.23`` or ``1.23 ± 0.04 (n=3)``."""
        if self.n <= 1:
            return f"{self.mean:.{decimals}f}"
        return f"{self.mean:.{decimals}f} ± {self.std:.{decimals}f} (n={self.n})"


@dataclass
class Claim:
    """One claim's check at one command.

    Attributes:
        key: ``a`` .. ``e``.
        claim: What the paper claims (with the command it is judged at).
        paper: The paper's numbers for it.
        ours: Ours, per robot: each comparison's effect with its 95 % interval (:meth:`Effect.text`).
        verdict: holds, holds partly, does not hold, cannot tell.
        reason: Why.
        artifacts: Ids of the artifacts the numbers come from.
        command_vx: The commanded forward speed (m/s) the claim is judged at.
    """

    key: str
    claim: str
    paper: str
    ours: str
    verdict: str
    reason: str
    artifacts: list[str] = field(default_factory=list)
    command_vx: float = PAPER_COMMAND

    @property
    def label(self) -> str:
        """``b@2.0``: the claim and its command."""
        return f"{self.key}@{self.command_vx:.1f}"


def seed_stat(values: Iterable[float]) -> Stat | None:
    """Mean and population std of finite values (None when there are none)."""
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not xs:
        return None
    mean = sum(xs) / len(xs)
    return Stat(mean, math.sqrt(sum((x - mean) ** 2 for x in xs) / len(xs)), len(xs))


def row_command(row: dict[str, Any]) -> float:
    """A row's ``command_vx`` (m/s); :data:`PAPER_COMMAND` for a row without one (written before the column)."""
    value = row.get("command_vx")
    try:
        return float(value) if value not in (None, "") else PAPER_COMMAND
    except (TypeError, ValueError):
        return PAPER_COMMAND


def at_command(rows: Sequence[dict[str, Any]], command_vx: float, mode: str | None = None) -> list[dict[str, Any]]:
    """The rows at ``command_vx`` (and in ``mode`` when given)."""
    return [r for r in rows if abs(row_command(r) - command_vx) < 1e-9 and (mode is None or r.get("mode") == mode)]


def per_seed(rows: Sequence[dict[str, Any]], metric: str, robot: str) -> dict[str, list[float]]:
    """Variant -> the finite values of ``metric`` on ``robot``, one per seed in seed order.

    A seed's later row replaces an earlier one; rows without the metric (or with a NaN) are skipped.
    """
    seeds: dict[str, dict[Any, float]] = {}
    for r in rows:
        if r.get("robot") != robot or r.get(metric) in (None, ""):
            continue
        value = float(r[metric])
        if math.isfinite(value):
            seeds.setdefault(str(r["variant"]), {})[r.get("seed", 0)] = value
    return {v: [s[k] for k in sorted(s, key=str)] for v, s in seeds.items()}


def _mean(values: Sequence[float]) -> str:
    """``0.46 (n=3)``, or ``0.46`` for one seed."""
    return f"{np.mean(values):.2f}" + (f" (n={len(values)})" if len(values) > 1 else "")


def all_beat(verdicts: Sequence[str]) -> str:
    """One robot's verdict from several comparisons that must all hold (film against each baseline).

    ``does not hold`` when any does not, ``holds`` when every one holds (and there is one), else ``cannot tell``.
    """
    if any(v == NOT for v in verdicts):
        return NOT
    return HOLDS if verdicts and all(v == HOLDS for v in verdicts) else CANNOT


def aggregate(outcomes: Sequence[str]) -> str:
    """A claim's verdict from its per-robot (per-variant for (e)) verdicts.

    ``holds`` (holds on every one), ``holds partly`` (on some, not all), ``does not hold`` (on none, and does not
    hold on at least one), ``cannot tell`` (cannot tell on every one, or there is none).
    """
    if not outcomes or all(o == CANNOT for o in outcomes):
        return CANNOT
    if all(o == HOLDS for o in outcomes):
        return HOLDS
    return PARTLY if any(o == HOLDS for o in outcomes) else NOT


def below_verdict(lo: float, hi: float, bound: float, *, inclusive: bool = False) -> str:
    """The verdict on "the statistic is below ``bound``" (``<=`` with ``inclusive``) from its interval ``[lo, hi]``.

    ``holds`` when the interval lies wholly on the claimed side of ``bound``, ``does not hold`` when wholly on the
    other side, ``cannot tell`` when it straddles the bound or has no ends (NaN). E.g. (e): rho < 0 holds for
    ``[-0.9, -0.2]``, does not for ``[0.0, 0.6]``; (d): spread <= 0.3 holds for ``[0.1, 0.3]``.
    """
    if math.isnan(lo) or math.isnan(hi):
        return CANNOT
    if hi <= bound if inclusive else hi < bound:
        return HOLDS
    if lo > bound if inclusive else lo >= bound:
        return NOT
    return CANNOT


def interval_text(estimate: float, lo: float, hi: float, decimals: int = 2, signed: bool = True) -> str:
    """``-0.71 [-0.93, -0.21]``, or ``-0.71 (no interval)`` when the ends are NaN."""
    f = f"{{:{'+' if signed else ''}.{decimals}f}}"
    if math.isnan(lo) or math.isnan(hi):
        return f"{f.format(estimate)} (no interval)"
    return f"{f.format(estimate)} [{f.format(lo)}, {f.format(hi)}]"


def _ids(rows: Sequence[dict[str, Any]], variants: Iterable[str], robots: Iterable[str]) -> list[str]:
    vs, rs = set(variants), set(robots)
    return sorted({str(r["artifact"]) for r in rows if r.get("variant") in vs and r.get("robot") in rs
                   and r.get("artifact")})


def _reason(outcomes: Sequence[str], units: Sequence[str], what: str) -> str:
    """``What on aliengo; does not hold on mini_cheetah; cannot tell on anymal_c (...)``."""
    groups = {o: [u for u, x in zip(units, outcomes, strict=True) if x == o] for o in (HOLDS, NOT, CANNOT)}
    parts = []
    if groups[HOLDS]:
        parts.append(f"{what} on {', '.join(groups[HOLDS])}")
    if groups[NOT]:
        parts.append(f"does not hold on {', '.join(groups[NOT])}")
    if groups[CANNOT]:
        parts.append(f"cannot tell on {', '.join(groups[CANNOT])} ({CANNOT_WHY})")
    text = "; ".join(parts)
    return text[:1].upper() + text[1:] + "." if parts else "Nothing to compare."  # not capitalize(): "EV" stays


def _vx(command_vx: float) -> str:
    return f"{command_vx:.1f} m/s"


def _one_seed_note(rows: Sequence[dict[str, Any]], metric: str, among: Iterable[str], what: str) -> str:
    """The note naming the one-seed variants of ``among`` (fewer than MIN_SEEDS on an OOD robot), else ``""``.

    E.g. `` adaln, hyper have one seed: <what>``.
    """
    among = set(among)
    one_seed = sorted({v for robot in OOD_ROBOTS for v, x in per_seed(rows, metric, robot).items()
                       if len(x) < MIN_SEEDS and v in among})
    if not one_seed:
        return ""
    return f" {', '.join(one_seed)} {'has' if len(one_seed) == 1 else 'have'} one seed: {what}"


def claim_a(calibration: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(a) On each OOD robot, the group effect on EV: multiplicative critics minus additive ones, interval > 0."""
    text = ("Multiplicative critics keep a higher EV than additive ones on out-of-distribution robots "
            f"(diagnosed at {_vx(command_vx)}).")
    rows = at_command(calibration, command_vx)
    per_robot, outcomes = [], []
    for robot in OOD_ROBOTS:
        ev = per_seed(rows, "ev", robot)
        mult = {v: ev[v] for v in MULTIPLICATIVE if v in ev}
        add = {v: ev[v] for v in ADDITIVE if v in ev}
        if not mult or not add:
            outcomes.append(CANNOT)
            which = "" if not mult and not add else "multiplicative " if not mult else "additive "
            per_robot.append(f"{robot}: no {which}critic diagnosed at {_vx(command_vx)}")
            continue
        effect = stats.group_effect(list(mult.values()), list(add.values()))
        outcomes.append(effect.verdict(higher=True))
        line = f"{robot}: EV multiplicative - additive {effect.text()}"
        seeded_m = {v: x for v, x in mult.items() if len(x) >= MIN_SEEDS}
        seeded_a = {v: x for v, x in add.items() if len(x) >= MIN_SEEDS}
        if seeded_m and seeded_a and (len(seeded_m) < len(mult) or len(seeded_a) < len(add)):
            sub = stats.group_effect(list(seeded_m.values()), list(seeded_a.values()))
            line += (f"; {', '.join(seeded_m)} - {', '.join(seeded_a)} alone (the variants with seeds, not the "
                     f"verdict): {sub.text()}")
        per_robot.append(line + " (" + ", ".join(f"{v} {_mean(x)}" for v, x in (*mult.items(), *add.items())) + ")")
    v = aggregate(outcomes)
    reason = _reason(outcomes, OOD_ROBOTS, "the multiplicative group's EV is higher (interval above 0)")
    reason += _one_seed_note(rows, "ev", STOCK, "the group effect has no interval until every variant of both "
                             "groups has at least 2.")
    return Claim("a", text, "Fig. 3 (EV, no numbers): additive critics lose calibration on the heavier and "
                 "out-of-distribution robots; multiplicative ones keep it on Mini Cheetah and AlienGo.",
                 "; ".join(per_robot), v, reason, _ids(rows, (*MULTIPLICATIVE, *ADDITIVE), OOD_ROBOTS), command_vx)


def with_speed_kept(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The eval rows with ``vx_s`` = v_x x S added: the speed a transfer keeps.

    A run that is fast until it falls scores its speed times the fraction of envs that survive.
    """
    return [{**r, "vx_s": float(r["vx_mean"]) * float(r["survival"])} for r in rows
            if r.get("vx_mean") not in (None, "") and r.get("survival") not in (None, "")]


def claim_b(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(b) Per OOD robot, film's v_x x S (descriptor mode) minus each of PPO's, actor-only's and concat's."""
    text = (f"MorFiC-F transfers better than PPO, actor-only and concat (v_x x S at {_vx(command_vx)}, descriptor "
            "mode: the speed kept over the episode).")
    rows = with_speed_kept(at_command(evals, command_vx, "descriptor"))
    per_robot, outcomes = [], []
    for robot in OOD_ROBOTS:
        kept = per_seed(rows, "vx_s", robot)
        vx, s = per_seed(rows, "vx_mean", robot), per_seed(rows, "survival", robot)
        if "film" not in kept:
            outcomes.append(CANNOT)
            per_robot.append(f"{robot}: film not evaluated")
            continue
        parts, verdicts = [], []
        for b in BASELINES:
            if b not in kept:
                verdicts.append(CANNOT)
                parts.append(f"{b} not evaluated")
                continue
            effect = stats.mean_difference(kept["film"], kept[b])
            verdicts.append(effect.verdict(higher=True))
            parts.append(f"film - {b} {effect.text()}")
        outcomes.append(all_beat(verdicts))
        means = ", ".join(f"{v} {np.mean(kept[v]):.2f} (v_x {np.mean(vx[v]):.2f}, S {np.mean(s[v]):.2f}"
                          + (f"; n={len(kept[v])})" if len(kept[v]) > 1 else ")")
                          for v in ("film", *BASELINES) if v in kept)
        per_robot.append(f"{robot}: " + "; ".join(parts) + f" (v_x x S, seed mean: {means})")
    paper_cells = []
    for v in ("film", *BASELINES):
        cell = paper.transfer_values(v, "aliengo", PAPER_COMMAND)
        if cell["vx"] is not None:
            paper_cells.append(f"{v} {cell['vx']:.2f} m/s, S {cell['survival']:.2f}")
    reason = _reason(outcomes, OOD_ROBOTS, "film keeps more speed than every baseline (every interval above 0)")
    return Claim("b", text, "AlienGo at 2.0 m/s: " + "; ".join(paper_cells) + " (Table \"zero-shot transfer\").",
                 "; ".join(per_robot), aggregate(outcomes), reason, _ids(rows, ("film", *BASELINES), OOD_ROBOTS),
                 command_vx)


def claim_c(fixed: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(c) In the fixed-rollout analysis, film's Flip minus every other critic's < 0 and its Cos minus theirs > 0."""
    text = ("With the film actor frozen, the film critic has the lowest Flip and the highest Cos (AlienGo, Mini "
            f"Cheetah; rollout at {_vx(command_vx)}).")
    # Only critics scored on the frozen film actor's rollouts compare (a store may hold analyses of other actors).
    rows = [r for r in at_command(fixed, command_vx)
            if r.get("variant") in STOCK and r.get("actor_variant") == FIXED_ROLLOUT_ACTOR]
    per_robot, outcomes = [], []
    for robot in FIXED_ROBOTS:
        flip, cos = per_seed(rows, "flip", robot), per_seed(rows, "cos_grad", robot)
        others = [v for v in STOCK if v != "film" and v in flip]
        if "film" not in flip or not others:
            outcomes.append(CANNOT)
            per_robot.append(f"{robot}: {'no film critic' if 'film' not in flip else 'no other critic'} scored")
            continue
        parts, verdicts = [], []
        for v in others:
            e_flip = stats.mean_difference(flip["film"], flip[v])
            verdicts.append(e_flip.verdict(higher=False))
            part = f"film - {v} Flip {e_flip.text(3)}"
            if "film" in cos and v in cos:
                e_cos = stats.mean_difference(cos["film"], cos[v])
                verdicts.append(e_cos.verdict(higher=True))
                part += f", Cos {e_cos.text(3)}"
            else:
                verdicts.append(CANNOT)
            parts.append(part)
        outcomes.append(all_beat(verdicts))
        means = ", ".join(f"{v} {np.mean(flip[v]):.3f}/{np.mean(cos[v]):.3f}" + (
            f" (n={len(flip[v])})" if len(flip[v]) > 1 else "") for v in ("film", *others) if v in cos)
        per_robot.append(f"{robot}: " + "; ".join(parts) + f" (Flip/Cos: {means})")
    paper_cells = []
    for robot in FIXED_ROBOTS:
        cells = [(v, paper.fixed_rollout_values(v, robot)) for v in ("film", *BASELINES)]
        paper_cells.append(f"{robot}: " + ", ".join(f"{v} {c['flip']:.3f}/{c['cos_grad']:.3f}" for v, c in cells
                                                    if c.get("flip") is not None and c.get("cos_grad") is not None))
    reason = _reason(outcomes, FIXED_ROBOTS, "film has the lowest Flip and the highest Cos (every interval on the "
                                             "claimed side of 0)")
    return Claim("c", text, "Flip/Cos. " + "; ".join(paper_cells) + " (Table \"causal advantage\").",
                 "; ".join(per_robot), aggregate(outcomes), reason, _ids(rows, STOCK, FIXED_ROBOTS), command_vx)


def paper_spread(robot: str) -> float | None:
    """The max - min of the paper's v_x over its multiplicative variants at 2.0 m/s on ``robot`` (None: none)."""
    vals = [paper.transfer_values(v, robot, PAPER_COMMAND)["vx"] for v in MULTIPLICATIVE]
    vals = [x for x in vals if x is not None]
    return max(vals) - min(vals) if len(vals) >= 2 else None


def tolerance(robot: str, command_vx: float = PAPER_COMMAND) -> float:
    """Claim (d)'s bound on the spread (m/s): max(:data:`SIMILAR_VX`, the paper's spread) x command / 2.0.

    The paper reports its ablation at 2.0 m/s only, so at another command its bound is scaled with the command (a
    spread is "similar" relative to the speed asked for).
    """
    return max(SIMILAR_VX, paper_spread(robot) or 0.0) * command_vx / PAPER_COMMAND


def _spread(means: np.ndarray) -> float:
    return float(np.max(means) - np.min(means))


def claim_d(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(d) The spread of the multiplicative variants' mean v_x, its interval's upper end within :func:`tolerance`."""
    text = ("All multiplicative variants (film, film-scaled, adaln, hyper) transfer similarly (v_x at "
            f"{_vx(command_vx)}).")
    rows = at_command(evals, command_vx, "descriptor")
    per_robot, outcomes = [], []
    for robot in OOD_ROBOTS:
        vx = per_seed(rows, "vx_mean", robot)
        got = {v: vx[v] for v in MULTIPLICATIVE if v in vx}
        if len(got) < len(MULTIPLICATIVE):
            outcomes.append(CANNOT)
            missing = [v for v in MULTIPLICATIVE if v not in got]
            per_robot.append(f"{robot}: {', '.join(missing)} not evaluated")
            continue
        est, lo, hi = stats.bootstrap_statistic(list(got.values()), _spread)
        tol = tolerance(robot, command_vx)
        outcomes.append(below_verdict(lo, hi, tol, inclusive=True))
        per_robot.append(f"{robot}: spread {interval_text(est, lo, hi, signed=False)} m/s against tolerance "
                         f"{tol:.2f} (" + ", ".join(f"{v} {_mean(x)}" for v, x in got.items()) + ")")
    paper_text = ("Spread of v_x over its multiplicative variants at 2.0 m/s (Table \"critic conditioning "
                  "ablation\"): " + ", ".join(f"{r} {paper_spread(r):.2f}" if paper_spread(r) is not None
                                              else f"{r} -" for r in OOD_ROBOTS) + " m/s.")
    reason = _reason(outcomes, OOD_ROBOTS, "the spread's interval lies below the tolerance")
    reason += _one_seed_note(rows, "vx_mean", MULTIPLICATIVE, "the spread has no interval until every "
                             "multiplicative variant has at least 2.")
    return Claim("d", text, paper_text, "; ".join(per_robot), aggregate(outcomes), reason,
                 _ids(rows, MULTIPLICATIVE, OOD_ROBOTS), command_vx)


def spearman(xs: Sequence[float], ys: Sequence[float]) -> float | None:
    """Spearman's rank correlation (:func:`morfic_cli.report.stats.spearman`); None where that is NaN."""
    rho = stats.spearman(xs, ys)
    return None if math.isnan(rho) else rho


def claim_e(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(e) Per variant, Spearman's rho of v_x x S against d over the robots, its interval below 0."""
    text = (f"Transfer degrades with the normalised morphology distance d (v_x x S against d, {_vx(command_vx)}, "
            "descriptor mode).")
    rows = with_speed_kept(at_command(evals, command_vx, "descriptor"))
    dist = {}
    for r in rows:
        if r.get("d") not in (None, ""):
            dist.setdefault(r["robot"], float(r["d"]))
    variants = [v for v in STOCK if any(r.get("variant") == v for r in rows)]
    per_variant, outcomes, weak = [], [], []
    for variant in variants:
        robots, samples = [], []
        for robot in paper.ROBOTS:
            kept = per_seed(rows, "vx_s", robot).get(variant)
            if kept and robot in dist:
                robots.append(robot)
                samples.append(kept)
        if len(robots) < 3:
            outcomes.append(CANNOT)
            per_variant.append(f"{variant}: {len(robots)} robots, too few")
            continue
        ds = [dist[r] for r in robots]
        est, lo, hi = stats.bootstrap_statistic(samples, lambda m, ds=ds: stats.spearman(ds, m))
        p = stats.spearman_p(ds, [float(np.mean(x)) for x in samples])
        outcome = below_verdict(lo, hi, 0.0)
        # Below 0 over the seeds is not enough: the rank correlation must also beat a random pairing of the robots
        # with their distances (seven fixed robots: the seeds' interval says nothing about that).
        if outcome == HOLDS and not p < stats.ALPHA:
            outcome = CANNOT
            weak.append(variant)
        outcomes.append(outcome)
        n = sorted({len(s) for s in samples})
        per_variant.append(f"{variant}: rho {interval_text(est, lo, hi)} over {len(robots)} robots "
                           f"(seeds {'/'.join(map(str, n))}" + ("" if math.isnan(p) else f"; p {p:.2g} over the "
                                                                "robots' orderings") + ")")
    rho_paper = _paper_rho()
    reason = (_reason(outcomes, variants, "rho's interval lies below 0 and p < 0.05") if outcomes
              else f"No descriptor-mode evaluation at {_vx(command_vx)} in the store.")
    if weak:
        reason += (f" On {', '.join(weak)} the interval lies below 0 but p >= 0.05 over the robots' orderings: no "
                   "stronger than a random pairing of robots and distances.")
    return Claim("e", text, f"MorFiC-F at 2.0 m/s, from its zero-shot table: rho {rho_paper:+.2f} (Fig. "
                 "\"distance\")." if rho_paper is not None else "Fig. \"distance\".", "; ".join(per_variant),
                 aggregate(outcomes), reason, sorted({str(r["artifact"]) for r in rows if r.get("artifact")}),
                 command_vx)


def _paper_rho() -> float | None:
    from morfic_cli.morphology.distance import distance_table

    dist = {r.robot: r.d for r in distance_table(paper.ROBOTS)}
    pts = []
    for robot in paper.ROBOTS:
        cell = paper.transfer_values("film", robot, PAPER_COMMAND)
        if cell["vx"] is not None and cell["survival"] is not None and robot in dist:
            pts.append((dist[robot], cell["vx"] * cell["survival"]))
    return spearman([p[0] for p in pts], [p[1] for p in pts])


def claim_parts(claim: Claim) -> list[tuple[str, str]]:
    """What a report prints under a claim, as (label, plain text): the paper's numbers, ours, why, the ids."""
    return [("Paper", claim.paper), ("Ours", claim.ours or "-"), ("Why", claim.reason),
            ("From", ", ".join(f"`{i[:12]}`" for i in claim.artifacts) or "-")]


def judged_commands(evals: Sequence[dict[str, Any]]) -> list[float]:
    """The commands of :data:`JUDGED_COMMANDS` to judge the claims at.

    The paper's always; another where the store holds descriptor-mode eval rows at it on an out-of-distribution
    robot (a walking check on Go2 alone is not enough).
    """
    present = {round(row_command(r), 6) for r in evals if r.get("mode") == "descriptor" and r.get("robot")
               in OOD_ROBOTS}
    return [c for c in JUDGED_COMMANDS if c == PAPER_COMMAND or round(c, 6) in present]


def check_claims(evals: Sequence[dict[str, Any]], calibration: Sequence[dict[str, Any]],
                 fixed: Sequence[dict[str, Any]], commands: Sequence[float] | None = None) -> list[Claim]:
    """Claims (a)-(e) on the store's results, at each command of ``commands`` (default :func:`judged_commands`).

    Args:
        evals: eval.csv rows (as :class:`~morfic_cli.report.gather.StoreData` holds them).
        calibration: calibration.csv rows.
        fixed: fixed_rollout.csv rows.
        commands: The commanded speeds (m/s) to judge at, in order.

    Returns:
        Claims (a)-(e) at the first command, then (a)-(e) at the next, and so on.
    """
    out = []
    for c in judged_commands(evals) if commands is None else commands:
        out += [claim_a(calibration, c), claim_b(evals, c), claim_c(fixed, c), claim_d(evals, c), claim_e(evals, c)]
    return out

