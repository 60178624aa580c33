"""The critic study's table and verdicts: per-cell intervals over actors, claims (a) and (c) with the actor fixed.

Pure functions over the rows of ``critic_study.csv`` (:data:`~morfic_cli.diagnostics.critic_study.STUDY_COLUMNS`).
Intervals, tests and verdicts use :mod:`morfic_cli.report.stats` with the rule of the report's claims
(docs/report.md "How a verdict is read"). The **unit** of replication is the frozen actor (:func:`study_unit`):

- a fit flagged unconverged (``converged`` False) is left out of every average, and counted (``n_flagged``);
- a cell's kept fits are averaged within each actor first, then the actors' means are the units
  (:func:`unit_values`; an actor none of whose fits converged drops out of that cell);
- a study of one actor (layout 1, or ``--actors`` naming one run) has no spread over actors: its unit is the fit
  seed, and every text says so (it speaks of that actor only);

then:

- a **cell** is one metric of one variant on one robot at one command: its mean over the units with a 95 % t
  interval (:func:`~morfic_cli.report.stats.mean_interval`);
- claim **(a)** per robot: mean EV(multiplicative critics) - mean EV(additive critics), each variant weighing the
  same, claimed > 0; a user's critic (``multiplicative`` None) is in neither group; the same contrasts of NVE and
  NVB are reported beside it (not tested: whether a higher EV comes with a smaller total error or with a bias);
- claim **(c)** per robot and other critic: Flip (other - film, claimed > 0) and CosGrad (film - other, claimed > 0).

Over actors every comparison is **paired by actor** (each actor's difference, then a one-sample t over actors,
n = actors: :func:`contrast_effect`); a one-actor study keeps the independent Welch / t-contrast over fit seeds.

A claim's comparisons (over its robots) are Holm-corrected together; a comparison's ``verdict`` is read from its
adjusted p (:func:`~morfic_cli.report.stats.outcome`), a robot's and the claim's from those outcomes with
:func:`~morfic_cli.report.stats.decide` (holds / holds partly / mixed / partly reversed / does not hold / cannot
tell). A robot without rows is left out of the claim.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from morfic_cli.report import stats

SUMMARY_METRICS: tuple[str, ...] = ("ev", "nvb", "abs_nvb", "nve", "flip", "cos_grad")
"""The metrics the summary gives an interval for."""
OOD_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah", "anymal_c")
"""Claim (a)'s robots (the paper's out-of-distribution targets)."""
FIXED_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah")
"""Claim (c)'s robots (paper Table "causal advantage")."""
FILM = "film"
PARTLY, MIXED = stats.PARTLY, stats.MIXED
_WORD = {stats.FOR: stats.HOLDS, stats.AGAINST: stats.NOT, stats.NONE: stats.CANNOT}


def group_of(value: Any) -> bool | None:
    """A row's ``multiplicative`` as read back from a CSV: True, False, or None (a user's critic: no group)."""
    if isinstance(value, str):
        return {"true": True, "false": False}.get(value.strip().lower())
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    return bool(value)


ACTOR, FIT_SEED = "actor", "fit seed"
"""The units of replication: the frozen actor (two or more actors), or the fit seed (a one-actor study)."""


def fit_kept(row: dict[str, Any]) -> bool:
    """Whether a row's fit counts: ``converged`` True, or not recorded (layout 1: every fit counts)."""
    return group_of(row.get("converged")) is not False


def study_unit(rows: Sequence[dict[str, Any]]) -> str:
    """:data:`ACTOR` when the rows come from two or more actors, else :data:`FIT_SEED`."""
    return ACTOR if len({r.get("actor") for r in rows}) >= 2 else FIT_SEED


def unit_values(rows: Sequence[dict[str, Any]], metric: str, unit: str | None = None, **match: Any) -> list[float]:
    """The metric of the kept fits matching ``match``, one value per unit (actor means, or one per fit seed).

    Args:
        rows: Study rows.
        metric: Column.
        unit: :data:`ACTOR` (average each actor's kept fits, NaNs skipped; actors in order of appearance) or
            :data:`FIT_SEED`; default :func:`study_unit` of ``rows``.
        match: Column -> value the rows must have.
    """
    unit = unit or study_unit(rows)
    by: dict[Any, list[float]] = {}
    for i, r in enumerate(rows):
        if fit_kept(r) and all(r[k] == v for k, v in match.items()):
            value = math.nan if r[metric] is None else float(r[metric])
            by.setdefault(r.get("actor") if unit == ACTOR else i, []).append(value)
    out = []
    for vals in by.values():
        finite = [v for v in vals if math.isfinite(v)]
        out.append(sum(finite) / len(finite) if finite else math.nan)
    return out


def _values(rows: Sequence[dict[str, Any]], metric: str, **match: Any) -> list[float]:
    """:func:`unit_values` with the rows' own unit."""
    return unit_values(rows, metric, None, **match)


def flagged(rows: Sequence[dict[str, Any]], **match: Any) -> list[tuple[Any, Any, Any]]:
    """The (actor, variant, fit seed) of every fit flagged unconverged among the rows matching ``match``."""
    return sorted(
        {
            (r.get("actor"), r["variant"], r["fit_seed"])
            for r in rows
            if not fit_kept(r) and all(r[k] == v for k, v in match.items())
        },
        key=str,
    )


def convergence_text(rows: Sequence[dict[str, Any]]) -> str:
    """``3 of 60 fits unconverged (val EV < threshold), left out: film-cpu-s1 adaln x2, ...`` or the layout-1 note."""
    if not rows or "converged" not in rows[0] or group_of(rows[0].get("converged")) is None:
        return "fits of a fixed epoch count, convergence not checked (the study's layout 1)"
    fits = {(r.get("actor"), r["variant"], r["fit_seed"]) for r in rows}
    bad = flagged(rows)
    if not bad:
        return f"all {len(fits)} fits converged"
    counts: dict[str, int] = {}
    for actor, variant, _ in bad:
        counts[f"{actor} {variant}"] = counts.get(f"{actor} {variant}", 0) + 1
    which = ", ".join(f"{k} x{n}" if n > 1 else k for k, n in counts.items())
    return f"{len(bad)} of {len(fits)} fits unconverged and left out of every average ({which})"


def cell_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean and 95 % t interval over the units (:func:`unit_values`) of every (command, robot, variant, metric).

    Returns:
        Rows ``command_vx, robot, variant, multiplicative, metric, mean, lo, hi, n, n_fits, n_flagged, unit``: ``n``
        units, ``n_fits`` kept fits, ``n_flagged`` fits left out; NaN ends below two units.
    """
    keys = list(dict.fromkeys((r["command_vx"], r["robot"], r["variant"]) for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}
    unit = study_unit(rows)
    out = []
    for command, robot, variant in keys:
        mine = [r for r in rows if (r["command_vx"], r["robot"], r["variant"]) == (command, robot, variant)]
        kept, bad = sum(fit_kept(r) for r in mine), len(flagged(mine))
        for metric in SUMMARY_METRICS:
            vals = unit_values(mine, metric, unit)
            mean, lo, hi = stats.mean_interval(vals)
            out.append(
                {
                    "command_vx": command,
                    "robot": robot,
                    "variant": variant,
                    "multiplicative": mult[variant],
                    "metric": metric,
                    "mean": mean,
                    "lo": lo,
                    "hi": hi,
                    "n": len([v for v in vals if v == v]),
                    "n_fits": kept,
                    "n_flagged": bad,
                    "unit": unit,
                }
            )
    return out


def _judge(effects: Sequence[stats.Effect]) -> tuple[list[float], list[str], str]:
    """Holm over a claim's effects (each claimed > 0): (adjusted p's, each comparison's verdict, the claim's)."""
    adjusted = stats.holm([e.p for e in effects])
    outcomes = [
        int(stats.outcome(e.estimate, p)) if e.has_test else stats.NONE for e, p in zip(effects, adjusted, strict=True)
    ]
    return [float(p) for p in adjusted], [_WORD[o] for o in outcomes], stats.decide(outcomes)


def _robot_verdict(verdicts: Sequence[str]) -> str:
    """A robot's verdict from its comparisons' (already corrected) verdicts."""
    inv = {v: k for k, v in _WORD.items()}
    return stats.decide([inv[v] for v in verdicts])


def actor_means(rows: Sequence[dict[str, Any]], metric: str, **match: Any) -> dict[Any, float]:
    """Actor -> mean of the metric over its kept fits matching ``match`` (actors with no finite value left out)."""
    by: dict[Any, list[float]] = {}
    for r in rows:
        if fit_kept(r) and all(r[k] == v for k, v in match.items()) and r[metric] is not None:
            value = float(r[metric])
            if math.isfinite(value):
                by.setdefault(r.get("actor"), []).append(value)
    return {a: sum(v) / len(v) for a, v in by.items()}


def contrast_effect(
    rows: Sequence[dict[str, Any]], metric: str, side_a: Sequence[str], side_b: Sequence[str], **match: Any
) -> stats.Effect:
    """Mean over ``side_a``'s variants - mean over ``side_b``'s, tested over the study's unit.

    Over actors (:data:`ACTOR`): paired by actor, each actor's difference of its variants' means (an actor that
    lacks a variant, every fit of it flagged, is left out), a one-sample t (:func:`~morfic_cli.report.stats.
    paired_effect`, n = actors). Over fit seeds (a one-actor study): Welch's t for one variant a side
    (:func:`~morfic_cli.report.stats.mean_difference`), else the t-contrast of :func:`~morfic_cli.report.stats.
    group_effect`.
    """
    if study_unit(rows) == ACTOR:
        per = {v: actor_means(rows, metric, variant=v, **match) for v in (*side_a, *side_b)}
        if not side_a or not side_b:
            return stats.Effect(math.nan, math.nan, math.nan, 0, 0, why="a side has no values")
        actors = [x for x in dict.fromkeys(r.get("actor") for r in rows) if all(x in per[v] for v in per)]
        diffs = [
            sum(per[v][x] for v in side_a) / len(side_a) - sum(per[v][x] for v in side_b) / len(side_b) for x in actors
        ]
        return stats.paired_effect(diffs)
    a = [_values(rows, metric, variant=v, **match) for v in side_a]
    b = [_values(rows, metric, variant=v, **match) for v in side_b]
    if len(a) == 1 and len(b) == 1:
        return stats.mean_difference(a[0], b[0])
    return stats.group_effect(a, b)


def group_means(rows: Sequence[dict[str, Any]], metric: str, variants: Sequence[str], **match: Any) -> float:
    """Mean over ``variants`` of each variant's mean over the units (the level a contrast's side sits at)."""
    means = [
        m
        for v in variants
        if (vals := [x for x in _values(rows, metric, variant=v, **match) if x == x])
        for m in [sum(vals) / len(vals)]
    ]
    return sum(means) / len(means) if means else math.nan


def claim_a(rows: Sequence[dict[str, Any]], command: float) -> dict[str, Any]:
    """Claim (a) at ``command``: per robot the EV effect multiplicative - additive, and the combined verdict.

    Each robot also carries ``nve`` and ``nvb`` (the same contrast of NVE and of NVB: shown, not tested) and
    ``levels`` (metric -> (multiplicative side's mean, additive side's) for NVB and NVE).
    """
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}  # None (a user's critic): in neither group
    sides = [[v for v in variants if mult[v] is g] for g in (True, False)]
    per_robot: list[dict[str, Any]] = []
    for robot in OOD_ROBOTS:
        where: dict[str, Any] = {"command_vx": command, "robot": robot}
        if not any(r["robot"] == robot and r["command_vx"] == command for r in rows):
            continue
        effect = contrast_effect(rows, "ev", *sides, **where)
        if effect.n_a and effect.n_b:
            beside = {m: contrast_effect(rows, m, *sides, **where) for m in ("nve", "nvb")}
            levels = {m: tuple(group_means(rows, m, side, **where) for side in sides) for m in ("nve", "nvb")}
            per_robot.append({"robot": robot, "effect": effect, **beside, "levels": levels})
    adjusted, verdicts, verdict = _judge([p["effect"] for p in per_robot])
    for p, adj, v in zip(per_robot, adjusted, verdicts, strict=True):
        p.update(p_holm=adj, verdict=v)
    return {"claim": "a", "command_vx": command, "unit": study_unit(rows), "robots": per_robot, "verdict": verdict}


def claim_c(rows: Sequence[dict[str, Any]], command: float) -> dict[str, Any]:
    """Claim (c) at ``command``: per robot film's Flip and CosGrad against every other critic's."""
    others = [v for v in dict.fromkeys(r["variant"] for r in rows) if v != FILM]
    per_robot: list[dict[str, Any]] = []
    for robot in FIXED_ROBOTS:
        film = {m: _values(rows, m, command_vx=command, robot=robot, variant=FILM) for m in ("flip", "cos_grad")}
        pairs: list[dict[str, Any]] = []
        for other in others:
            flip = contrast_effect(rows, "flip", [other], [FILM], command_vx=command, robot=robot)
            cos = contrast_effect(rows, "cos_grad", [FILM], [other], command_vx=command, robot=robot)
            pairs.append({"other": other, "flip": flip, "cos_grad": cos})
        if film["flip"]:
            per_robot.append({"robot": robot, "pairs": pairs})
    effects = [p[m] for r in per_robot for p in r["pairs"] for m in ("flip", "cos_grad")]
    adjusted, verdicts, verdict = _judge(effects)
    k = 0
    for r in per_robot:
        for p in r["pairs"]:
            for m in ("flip", "cos_grad"):
                p[f"{m}_p_holm"], p[f"{m}_verdict"] = adjusted[k], verdicts[k]
                k += 1
        r["verdict"] = _robot_verdict([p[f"{m}_verdict"] for p in r["pairs"] for m in ("flip", "cos_grad")])
    return {"claim": "c", "command_vx": command, "unit": study_unit(rows), "robots": per_robot, "verdict": verdict}


def study_claims(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Claims (a) and (c) at every command of the study."""
    commands = sorted({float(r["command_vx"]) for r in rows})
    return [claim(rows, c) for c in commands for claim in (claim_a, claim_c)]


def verdict_rows(claims: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims as flat rows (one per comparison) for ``verdicts.csv``."""
    out = []
    for c in claims:
        for r in c["robots"]:
            comparisons = (
                [("multiplicative - additive", "ev", r["effect"], r["p_holm"], r["verdict"])]
                if c["claim"] == "a"
                else [
                    (
                        f"{p['other']} - film" if m == "flip" else f"film - {p['other']}",
                        m,
                        p[m],
                        p[f"{m}_p_holm"],
                        p[f"{m}_verdict"],
                    )
                    for p in r["pairs"]
                    for m in ("flip", "cos_grad")
                ]
            )
            m = len(c["robots"]) if c["claim"] == "a" else sum(2 * len(x["pairs"]) for x in c["robots"])
            for what, metric, e, p_holm, verdict in comparisons:
                need = stats.seeds_needed(e, alpha=stats.ALPHA / max(m, 1)) if verdict == stats.CANNOT else None
                out.append(
                    {
                        "claim": c["claim"],
                        "command_vx": c["command_vx"],
                        "unit": c.get("unit", ""),
                        "robot": r["robot"],
                        "comparison": what,
                        "metric": metric,
                        "effect": e.estimate,
                        "lo": e.lo,
                        "hi": e.hi,
                        "p": e.p,
                        "p_holm": p_holm,
                        "n_a": e.n_a,
                        "n_b": e.n_b,
                        "verdict": verdict,
                        "seeds_needed": need,
                        "robot_verdict": r["verdict"],
                        "claim_verdict": c["verdict"],
                    }
                )
    return out


VERDICT_COLUMNS: tuple[str, ...] = (
    "claim",
    "command_vx",
    "unit",
    "robot",
    "comparison",
    "metric",
    "effect",
    "lo",
    "hi",
    "p",
    "p_holm",
    "n_a",
    "n_b",
    "verdict",
    "seeds_needed",
    "robot_verdict",
    "claim_verdict",
)
"""Columns of ``verdicts.csv``."""
SUMMARY_COLUMNS: tuple[str, ...] = (
    "command_vx",
    "robot",
    "variant",
    "multiplicative",
    "metric",
    "mean",
    "lo",
    "hi",
    "n",
    "n_fits",
    "n_flagged",
    "unit",
)
"""Columns of ``summary.csv``."""
