"""The paper's five claims, checked against the store's results: a verdict per claim, computed, never typed in.

Pure functions over the rows :func:`~morfic_cli.report.gather.gather` reads (eval.csv, calibration.csv and
fixed_rollout.csv rows, each with ``variant``, ``seed``, ``command_vx`` and ``artifact``). The rule (docs/report.md,
"How a verdict is read"; the statistics in :mod:`morfic_cli.report.stats`): each claim names its primary
comparisons; each has a test over seeds (Welch's t, a t-contrast, an equivalence test, or Spearman's rho over the
robots); their p-values are Holm-corrected together (:func:`judge`), and the verdict counts how many are
significant in the claimed direction and against it (:func:`~morfic_cli.report.stats.decide`). A variant with one
seed has no spread, so a comparison that needs it has no test. Each claim is judged at 2.0 m/s (the paper's
command) and at 1.0 m/s where the store holds results at that command (:func:`judged_commands`). The primary
comparisons:

- (a) per OOD robot: EV, the mean over the multiplicative variants (film, film-scaled, adaln, hyper) of their seed
  means minus the same over the additive ones (concat, ppo, actor-only), a t-contrast, claimed > 0 (m = 3);
- (b) per OOD robot and baseline (PPO, actor-only, concat): film's v_x x S (the speed kept over the episode) minus
  the baseline's, Welch, claimed > 0 (m = 9);
- (c) per robot (AlienGo, Mini Cheetah), baseline (the same three, the paper's Table "causal advantage") and metric,
  the film actor frozen: film's Flip minus the baseline's (claimed < 0) and its Cos minus theirs (> 0) (m = 12);
  the other critics are printed beside, not deciding;
- (d) per OOD robot and pair of multiplicative variants: the equivalence test of their v_x against ±
  :func:`tolerance` (m = 18);
- (e) per variant on 3 robots or more with 2 seeds each: Spearman's rho of v_x x S against d over the robots, its p
  exact over the robots' orderings, claimed < 0 (m = the variants).
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
#: Multiplicative and additive critics (claim (a)) among the paper's variants (tables main / ablation; not issue 58's
#: film-act, which shares film's critic but not its training distribution).
MULTIPLICATIVE: tuple[str, ...] = tuple(
    n for n, v in STOCK.items() if v.multiplicative and {"main", "ablation"} & set(v.tables)
)
#: The additive ones are the paper's PPO variants (Fig. 3); the external baselines (bot, genloco) are in neither.
ADDITIVE: tuple[str, ...] = ("ppo", "actor-only", "concat")
#: The paper's seven PPO variants: claim (e)'s variants.
PPO_VARIANTS: tuple[str, ...] = tuple(v for v in STOCK if v in ADDITIVE or v in MULTIPLICATIVE)
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
    "c": "film's critic has a lower Flip, higher Cos than ppo, actor-only, concat (fixed rollout)",
    "d": "the multiplicative variants transfer similarly",
    "e": "transfer degrades with d",
}

PARTLY, REVERSED, MIXED = stats.PARTLY, stats.REVERSED, stats.MIXED
#: Every verdict a claim can get, strongest for the claim first.
VERDICTS: tuple[str, ...] = (HOLDS, PARTLY, MIXED, REVERSED, NOT, CANNOT)


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
class Comparison:
    """One primary comparison of a claim, before and after Holm's correction.

    Attributes:
        unit: Where it is made (a robot; a variant for (e)).
        what: What is compared (``film - ppo``, ``film - ppo Flip``, ``film vs hyper``, ``rho``).
        estimate: The effect (rho for (e)).
        p: Its own two-sided p (NaN: no test).
        sign: +1 when the effect points the claimed way, -1 against it, 0 at none (or no test).
        effect: The t effect it comes from (None for (e)).
        why: Why there is no test (empty when there is one).
        delta: What :func:`~morfic_cli.report.stats.seeds_needed` detects ((d): the distance to the tolerance);
            None: ``|estimate|``.
        decimals: Decimals of its text.
        p_label: What ``p`` tests where it is not the effect's own t test (``similar``, ``beyond``: (d)).
        p_holm: The Holm-adjusted p over the claim's comparisons (set by :func:`judge`).
        outcome: FOR / AGAINST / NONE after Holm (set by :func:`judge`).
        need: Seeds per side for 80 % power at alpha / m where not significant (set by :func:`judge`).
    """

    unit: str
    what: str
    estimate: float
    p: float
    sign: int
    effect: stats.Effect | None = None
    why: str = ""
    delta: float | None = None
    decimals: int = 2
    p_label: str = ""
    p_holm: float = math.nan
    outcome: int = stats.NONE
    need: int | None = None

    def text(self) -> str:
        """``film - ppo +0.31 [+0.12, +0.50] (n 3 vs 3, p 0.021, Holm 0.063; 6 seeds/side for 80 % power)``."""
        if self.effect is not None and self.p_label and self.effect.has_test:
            e, d = self.effect, self.decimals
            body = (
                f"{e.estimate:+.{d}f} [{e.lo:+.{d}f}, {e.hi:+.{d}f}] (n {e.n_a} vs {e.n_b}, {self.p_label} p "
                f"{stats.p_text(self.p)}, Holm {stats.p_text(self.p_holm)})"
            )
        elif self.effect is not None:
            body = self.effect.text(self.decimals, self.p_holm)
        elif math.isnan(self.p):
            est = "" if math.isnan(self.estimate) else f"{self.estimate:+.{self.decimals}f} "
            body = f"{est}(no test: {self.why or 'no result'})"
        else:
            body = f"{self.estimate:+.{self.decimals}f} (p {stats.p_text(self.p)}, Holm {stats.p_text(self.p_holm)})"
        if self.why and self.why != stats.NO_TEST and self.effect is not None and not self.effect.has_test:
            body = body[:-1] + f"; {self.why})"
        need = stats.needed_text(self.need)
        return f"{self.what} {body}" + (f" [{need}]" if need else "")

    def row(self) -> dict[str, Any]:
        """The comparison as a flat row (None for a NaN): the verdict tables' columns."""
        e = self.effect

        def num(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "unit": self.unit,
            "comparison": self.what,
            "effect": num(self.estimate),
            "lo": num(e.lo) if e else None,
            "hi": num(e.hi) if e else None,
            "n_a": e.n_a if e else None,
            "n_b": e.n_b if e else None,
            "p": num(self.p),
            "p_holm": num(self.p_holm),
            "outcome": {stats.FOR: "for", stats.AGAINST: "against"}.get(self.outcome, "not significant"),
            "seeds_needed": self.need,
            "why": self.why,
        }


@dataclass
class Claim:
    """One claim's check at one command.

    Attributes:
        key: ``a`` .. ``e``.
        claim: What the paper claims (with the command it is judged at).
        paper: The paper's numbers for it.
        ours: Ours: each primary comparison with its 95 % interval, p and Holm p; then what is shown beside.
        verdict: One of :data:`VERDICTS`.
        reason: Why.
        artifacts: Ids of the artifacts the numbers come from.
        command_vx: The commanded forward speed (m/s) the claim is judged at.
        comparisons: The primary comparisons as rows (:meth:`Comparison.row`).
    """

    key: str
    claim: str
    paper: str
    ours: str
    verdict: str
    reason: str
    artifacts: list[str] = field(default_factory=list)
    command_vx: float = PAPER_COMMAND
    comparisons: list[dict[str, Any]] = field(default_factory=list)

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


def t_comparison(unit: str, what: str, effect: stats.Effect, higher: bool = True, decimals: int = 2) -> Comparison:
    """A comparison from a t effect, claimed ``> 0`` (``higher``) or ``< 0``."""
    sign = int(np.sign(effect.estimate)) * (1 if higher else -1) if effect.has_test else 0
    return Comparison(unit, what, effect.estimate, effect.p, sign, effect, effect.why, decimals=decimals)


def missing(unit: str, what: str, why: str) -> Comparison:
    """A primary comparison that has no result to compare: counted in m, never significant."""
    return Comparison(unit, what, math.nan, math.nan, 0, why=why)


def judge(comparisons: Sequence[Comparison], alpha: float = stats.ALPHA) -> str:
    """Holm over the claim's primary comparisons, each one's outcome and seeds needed; returns the verdict.

    Sets ``p_holm``, ``outcome`` and ``need`` of every comparison (seeds for 80 % power at alpha / m, Holm's
    strictest step, where not significant).
    """
    m = len(comparisons)
    adjusted = stats.holm([c.p for c in comparisons])
    for c, p in zip(comparisons, adjusted, strict=True):
        c.p_holm = float(p)
        c.outcome = int(stats.outcome(c.sign, p, True, alpha)) if c.sign else stats.NONE
        if c.outcome == stats.NONE and c.effect is not None:
            c.need = stats.seeds_needed(c.effect, alpha=alpha / m, delta=c.delta)
    return stats.decide([c.outcome for c in comparisons])


def judged_reason(comparisons: Sequence[Comparison], claimed: str) -> str:
    """Why: how many of the m primary comparisons are significant each way (named), and those without a test."""
    m = len(comparisons)
    if m and all(math.isnan(c.p) for c in comparisons) and any(c.why == stats.NO_TEST for c in comparisons):
        others = sorted({c.why for c in comparisons if c.why and c.why != stats.NO_TEST})
        return (
            "One seed per variant: no test (a comparison needs 2 seeds or more on each side to have a spread "
            f"to test against; {m} primary comparisons" + (f"; also: {'; '.join(others)}" if others else "") + ")."
        )
    f = [c for c in comparisons if c.outcome == stats.FOR]
    a = [c for c in comparisons if c.outcome == stats.AGAINST]
    untested = [c for c in comparisons if math.isnan(c.p)]
    text = (
        f"{len(f)} of {m} primary comparisons significant in the claimed direction ({claimed}), {len(a)} "
        f"against it (Holm over {m}, alpha {stats.ALPHA:g})"
    )
    if f:
        text += "; for: " + ", ".join(f"{c.unit} {c.what}" for c in f)
    if a:
        text += "; against: " + ", ".join(f"{c.unit} {c.what}" for c in a)
    if untested:
        whys = sorted({c.why or "no result" for c in untested})
        text += f"; {len(untested)} without a test ({'; '.join(whys)})"
    return text + "."


def _by_unit(comparisons: Sequence[Comparison], units: Sequence[str], note: dict[str, str] | None = None) -> str:
    """``aliengo: film - ppo ...; film - concat ... (note); mini_cheetah: ...``."""
    out = []
    for u in units:
        cs = [c.text() for c in comparisons if c.unit == u]
        if cs:
            out.append(f"{u}: " + "; ".join(cs) + (f" ({note[u]})" if note and note.get(u) else ""))
    return "; ".join(out)


def _ids(rows: Sequence[dict[str, Any]], variants: Iterable[str], robots: Iterable[str]) -> list[str]:
    vs, rs = set(variants), set(robots)
    return sorted(
        {str(r["artifact"]) for r in rows if r.get("variant") in vs and r.get("robot") in rs and r.get("artifact")}
    )


def _vx(command_vx: float) -> str:
    return f"{command_vx:.1f} m/s"


def _made(claim: Claim, comparisons: Sequence[Comparison]) -> Claim:
    claim.comparisons = [c.row() for c in comparisons]
    return claim


def claim_a(calibration: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(a) On each OOD robot, the t-contrast on EV: multiplicative critics minus additive ones, claimed > 0."""
    text = (
        "Multiplicative critics keep a higher EV than additive ones on out-of-distribution robots "
        f"(diagnosed at {_vx(command_vx)})."
    )
    rows = at_command(calibration, command_vx)
    comps, notes = [], {}
    for robot in OOD_ROBOTS:
        ev = per_seed(rows, "ev", robot)
        mult = {v: ev[v] for v in MULTIPLICATIVE if v in ev}
        add = {v: ev[v] for v in ADDITIVE if v in ev}
        what = "EV multiplicative - additive"
        if not mult or not add:
            which = "" if not mult and not add else "multiplicative " if not mult else "additive "
            comps.append(missing(robot, what, f"no {which}critic diagnosed at {_vx(command_vx)}"))
            continue
        comps.append(t_comparison(robot, what, stats.group_effect(list(mult.values()), list(add.values()))))
        notes[robot] = ", ".join(f"{v} {_mean(x)}" for v, x in (*mult.items(), *add.items()))
    verdict = judge(comps)
    return _made(
        Claim(
            "a",
            text,
            "Fig. 3 (EV, no numbers): additive critics lose calibration on the heavier and "
            "out-of-distribution robots; multiplicative ones keep it on Mini Cheetah and AlienGo.",
            _by_unit(comps, OOD_ROBOTS, notes),
            verdict,
            judged_reason(comps, "> 0"),
            _ids(rows, (*MULTIPLICATIVE, *ADDITIVE), OOD_ROBOTS),
            command_vx,
        ),
        comps,
    )


def with_speed_kept(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The eval rows with ``vx_s`` = v_x x S added: the speed a transfer keeps.

    A run that is fast until it falls scores its speed times the fraction of envs that survive.
    """
    return [
        {**r, "vx_s": float(r["vx_mean"]) * float(r["survival"])}
        for r in rows
        if r.get("vx_mean") not in (None, "") and r.get("survival") not in (None, "")
    ]


def claim_b(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(b) Per OOD robot, Welch: film's v_x x S (descriptor mode) minus each of PPO's, actor-only's and concat's."""
    text = (
        f"MorFiC-F transfers better than PPO, actor-only and concat (v_x x S at {_vx(command_vx)}, descriptor "
        "mode: the speed kept over the episode)."
    )
    rows = with_speed_kept(at_command(evals, command_vx, "descriptor"))
    comps, notes = [], {}
    for robot in OOD_ROBOTS:
        kept = per_seed(rows, "vx_s", robot)
        vx, s = per_seed(rows, "vx_mean", robot), per_seed(rows, "survival", robot)
        for b in BASELINES:
            what = f"film - {b}"
            if "film" not in kept or b not in kept:
                comps.append(missing(robot, what, f"{'film' if 'film' not in kept else b} not evaluated"))
            else:
                comps.append(t_comparison(robot, what, stats.mean_difference(kept["film"], kept[b])))
        notes[robot] = (
            ""
            if not kept
            else "v_x x S, seed mean: "
            + ", ".join(
                f"{v} {np.mean(kept[v]):.2f} (v_x {np.mean(vx[v]):.2f}, S {np.mean(s[v]):.2f}"
                + (f"; n={len(kept[v])})" if len(kept[v]) > 1 else ")")
                for v in ("film", *BASELINES)
                if v in kept
            )
        )
    paper_cells = []
    for v in ("film", *BASELINES):
        cell = paper.transfer_values(v, "aliengo", PAPER_COMMAND)
        if cell["vx"] is not None:
            paper_cells.append(f"{v} {cell['vx']:.2f} m/s, S {cell['survival']:.2f}")
    verdict = judge(comps)
    return _made(
        Claim(
            "b",
            text,
            "AlienGo at 2.0 m/s: " + "; ".join(paper_cells) + ' (Table "zero-shot transfer").',
            _by_unit(comps, OOD_ROBOTS, notes),
            verdict,
            judged_reason(comps, "film - baseline > 0"),
            _ids(rows, ("film", *BASELINES), OOD_ROBOTS),
            command_vx,
        ),
        comps,
    )


def claim_c(fixed: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(c) Film actor frozen: film's Flip minus each baseline's < 0 and its Cos minus theirs > 0 (Welch)."""
    text = (
        "With the film actor frozen, the film critic has a lower Flip and a higher Cos than PPO's, actor-only's "
        f"and concat's (AlienGo, Mini Cheetah; rollout at {_vx(command_vx)})."
    )
    # Only critics scored on the frozen film actor's rollouts compare (a store may hold analyses of other actors).
    rows = [
        r
        for r in at_command(fixed, command_vx)
        if r.get("variant") in STOCK and r.get("actor_variant") == FIXED_ROLLOUT_ACTOR
    ]
    comps: list[Comparison] = []
    beside: list[Comparison] = []
    notes: dict[str, str] = {}
    for robot in FIXED_ROBOTS:
        flip, cos = per_seed(rows, "flip", robot), per_seed(rows, "cos_grad", robot)
        for v in (v for v in STOCK if v != "film"):
            primary = v in BASELINES
            for metric, values, higher in (("Flip", flip, False), ("Cos", cos, True)):
                what = f"film - {v} {metric}"
                if "film" not in values or v not in values:
                    if primary:
                        comps.append(missing(robot, what, f"{'film' if 'film' not in values else v} not scored"))
                    continue
                c = t_comparison(robot, what, stats.mean_difference(values["film"], values[v]), higher, 3)
                (comps if primary else beside).append(c)
        notes[robot] = "Flip/Cos: " + ", ".join(
            f"{v} {np.mean(flip[v]):.3f}/{np.mean(cos[v]):.3f}" + (f" (n={len(flip[v])})" if len(flip[v]) > 1 else "")
            for v in STOCK
            if v in flip and v in cos
        )
    verdict = judge(comps)
    paper_cells = []
    for robot in FIXED_ROBOTS:
        cells = [(v, paper.fixed_rollout_values(v, robot)) for v in ("film", *BASELINES)]
        paper_cells.append(
            f"{robot}: "
            + ", ".join(
                f"{v} {c['flip']:.3f}/{c['cos_grad']:.3f}"
                for v, c in cells
                if c.get("flip") is not None and c.get("cos_grad") is not None
            )
        )
    ours = _by_unit(comps, FIXED_ROBOTS, notes)
    if beside:
        ours += "; beside (not deciding, no correction): " + "; ".join(
            f"{c.unit} {c.what} {c.effect.text(3)}" for c in beside if c.effect
        )
    return _made(
        Claim(
            "c",
            text,
            "Flip/Cos. " + "; ".join(paper_cells) + ' (Table "causal advantage").',
            ours,
            verdict,
            judged_reason(comps, "Flip < 0, Cos > 0"),
            _ids(rows, STOCK, FIXED_ROBOTS),
            command_vx,
        ),
        comps,
    )


def paper_spread(robot: str) -> float | None:
    """The max - min of the paper's v_x over its multiplicative variants at 2.0 m/s on ``robot`` (None: none)."""
    printed = [paper.transfer_values(v, robot, PAPER_COMMAND)["vx"] for v in MULTIPLICATIVE]
    vals = [x for x in printed if x is not None]
    return max(vals) - min(vals) if len(vals) >= 2 else None


def tolerance(robot: str, command_vx: float = PAPER_COMMAND) -> float:
    """Claim (d)'s bound on a pair's difference (m/s): max(:data:`SIMILAR_VX`, the paper's spread) x command / 2.0.

    The paper reports its ablation at 2.0 m/s only, so at another command its bound is scaled with the command (a
    spread is "similar" relative to the speed asked for).
    """
    return max(SIMILAR_VX, paper_spread(robot) or 0.0) * command_vx / PAPER_COMMAND


def equivalence_comparison(unit: str, what: str, effect: stats.Effect, tol: float) -> Comparison:
    """A (d) comparison: similar (interval inside ±tol) is the claimed way, wholly outside it the other."""
    p, way = stats.equivalence_p(effect, tol)
    delta = abs(tol - abs(effect.estimate)) if effect.has_test else None
    label = "similar" if way == stats.FOR else "beyond" if way == stats.AGAINST else ""
    return Comparison(unit, what, effect.estimate, p, way, effect, effect.why, delta=delta, p_label=label)


def claim_d(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(d) Every pair of multiplicative variants: equivalence of their v_x within ±:func:`tolerance`."""
    text = (
        "All multiplicative variants (film, film-scaled, hyper, adaln) transfer similarly (v_x at "
        f"{_vx(command_vx)}: every pair within the tolerance)."
    )
    rows = at_command(evals, command_vx, "descriptor")
    comps, notes = [], {}
    for robot in OOD_ROBOTS:
        vx = per_seed(rows, "vx_mean", robot)
        tol = tolerance(robot, command_vx)
        for i, a in enumerate(MULTIPLICATIVE):
            for b in MULTIPLICATIVE[i + 1 :]:
                what = f"{a} - {b}"
                if a not in vx or b not in vx:
                    comps.append(missing(robot, what, f"{a if a not in vx else b} not evaluated"))
                else:
                    comps.append(equivalence_comparison(robot, what, stats.mean_difference(vx[a], vx[b]), tol))
        got = {v: vx[v] for v in MULTIPLICATIVE if v in vx}
        spread = (max(np.mean(x) for x in got.values()) - min(np.mean(x) for x in got.values())) if got else math.nan
        notes[robot] = (
            (
                f"tolerance ±{tol:.2f} m/s; spread of the means {spread:.2f}; v_x "
                + ", ".join(f"{v} {_mean(x)}" for v, x in got.items())
            )
            if got
            else ""
        )
    paper_text = (
        'Spread of v_x over its multiplicative variants at 2.0 m/s (Table "critic conditioning '
        'ablation"): '
        + ", ".join(f"{r} {paper_spread(r):.2f}" if paper_spread(r) is not None else f"{r} -" for r in OOD_ROBOTS)
        + " m/s."
    )
    verdict = judge(comps)
    return _made(
        Claim(
            "d",
            text,
            paper_text,
            _by_unit(comps, OOD_ROBOTS, notes),
            verdict,
            judged_reason(comps, "95 % interval inside ±tolerance"),
            _ids(rows, MULTIPLICATIVE, OOD_ROBOTS),
            command_vx,
        ),
        comps,
    )


def spearman(xs: Sequence[float], ys: Sequence[float]) -> float | None:
    """Spearman's rank correlation (:func:`morfic_cli.report.stats.spearman`); None where that is NaN."""
    rho = stats.spearman(xs, ys)
    return None if math.isnan(rho) else rho


def claim_e(evals: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Claim:
    """(e) Per variant, Spearman's rho of the seed-mean v_x x S against d over the robots, claimed < 0."""
    text = (
        f"Transfer degrades with the normalised morphology distance d (v_x x S against d, {_vx(command_vx)}, "
        "descriptor mode)."
    )
    rows = with_speed_kept(at_command(evals, command_vx, "descriptor"))
    dist: dict[str, float] = {}
    for r in rows:
        if r.get("d") not in (None, ""):
            dist.setdefault(r["robot"], float(r["d"]))
    variants = [v for v in PPO_VARIANTS if any(r.get("variant") == v for r in rows)]
    comps = []
    for variant in variants:
        robots, means, seeds = [], [], []
        for robot in paper.ROBOTS:
            kept = per_seed(rows, "vx_s", robot).get(variant)
            if kept and robot in dist:
                robots.append(robot)
                means.append(float(np.mean(kept)))
                seeds.append(len(kept))
        what = f"rho over {len(robots)} robots (seeds {'/'.join(map(str, sorted(set(seeds)))) or '-'})"
        if len(robots) < 3:
            comps.append(missing(variant, what, f"{len(robots)} robots, too few"))
            continue
        rho = stats.spearman([dist[r] for r in robots], means)
        if min(seeds) < MIN_SEEDS:
            comps.append(Comparison(variant, what, rho, math.nan, 0, why=stats.NO_TEST))
            continue
        p = stats.spearman_p([dist[r] for r in robots], means)
        comps.append(Comparison(variant, what, rho, p, -int(np.sign(rho)) if not math.isnan(rho) else 0))
    verdict = judge(comps)
    rho_paper = _paper_rho()
    reason = (
        judged_reason(comps, "rho < 0")
        if comps
        else f"No descriptor-mode evaluation at {_vx(command_vx)} in the store."
    )
    return _made(
        Claim(
            "e",
            text,
            f'MorFiC-F at 2.0 m/s, from its zero-shot table: rho {rho_paper:+.2f} (Fig. "distance").'
            if rho_paper is not None
            else 'Fig. "distance".',
            "; ".join(f"{c.unit}: {c.text()}" for c in comps),
            verdict,
            reason,
            sorted({str(r["artifact"]) for r in rows if r.get("artifact")}),
            command_vx,
        ),
        comps,
    )


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
    return [
        ("Paper", claim.paper),
        ("Ours", claim.ours or "-"),
        ("Why", claim.reason),
        ("From", ", ".join(f"`{i[:12]}`" for i in claim.artifacts) or "-"),
    ]


def judged_commands(evals: Sequence[dict[str, Any]]) -> list[float]:
    """The commands of :data:`JUDGED_COMMANDS` to judge the claims at.

    The paper's always; another where the store holds descriptor-mode eval rows at it on an out-of-distribution
    robot (a walking check on Go2 alone is not enough).
    """
    present = {
        round(row_command(r), 6) for r in evals if r.get("mode") == "descriptor" and r.get("robot") in OOD_ROBOTS
    }
    return [c for c in JUDGED_COMMANDS if c == PAPER_COMMAND or round(c, 6) in present]


def check_claims(
    evals: Sequence[dict[str, Any]],
    calibration: Sequence[dict[str, Any]],
    fixed: Sequence[dict[str, Any]],
    commands: Sequence[float] | None = None,
) -> list[Claim]:
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
