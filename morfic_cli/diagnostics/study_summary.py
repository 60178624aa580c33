"""The critic study's table and verdicts: per-cell intervals over fit seeds, claims (a) and (c) with the actor fixed.

Pure functions over the rows of ``critic_study.csv`` (:data:`~morfic_cli.diagnostics.critic_study.STUDY_COLUMNS`).
Intervals, tests and verdicts use :mod:`morfic_cli.report.stats` with the rule of the report's claims
(docs/report.md "How a verdict is read"; the unit of replication here is the fit seed):

- a **cell** is one metric of one variant on one robot at one command: its mean over fit seeds with a 95 % t
  interval (:func:`~morfic_cli.report.stats.mean_interval`);
- claim **(a)** per robot: the t-contrast mean EV(multiplicative critics) - mean EV(additive critics)
  (:func:`~morfic_cli.report.stats.group_effect`, each variant's seed mean weighing the same), claimed > 0;
  a user's critic (``multiplicative`` None) is in neither group;
- claim **(c)** per robot and other critic: Welch on Flip (other - film, claimed > 0) and on CosGrad (film - other,
  claimed > 0).

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

SUMMARY_METRICS: tuple[str, ...] = ("ev", "abs_nvb", "nve", "flip", "cos_grad")
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


def _values(rows: Sequence[dict[str, Any]], metric: str, **match: Any) -> list[float]:
    """The metric of every row matching ``match`` (one per fit seed)."""
    return [math.nan if r[metric] is None else float(r[metric]) for r in rows
            if all(r[k] == v for k, v in match.items())]


def cell_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean and 95 % t interval over fit seeds of every (command, robot, variant, metric).

    Returns:
        Rows ``command_vx, robot, variant, multiplicative, metric, mean, lo, hi, n`` (NaN ends for one seed).
    """
    keys = list(dict.fromkeys((r["command_vx"], r["robot"], r["variant"]) for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}
    out = []
    for command, robot, variant in keys:
        for metric in SUMMARY_METRICS:
            vals = _values(rows, metric, command_vx=command, robot=robot, variant=variant)
            mean, lo, hi = stats.mean_interval(vals)
            out.append({"command_vx": command, "robot": robot, "variant": variant, "multiplicative": mult[variant],
                        "metric": metric, "mean": mean, "lo": lo, "hi": hi, "n": len(vals)})
    return out


def _judge(effects: Sequence[stats.Effect]) -> tuple[list[float], list[str], str]:
    """Holm over a claim's effects (each claimed > 0): (adjusted p's, each comparison's verdict, the claim's)."""
    adjusted = stats.holm([e.p for e in effects])
    outcomes = [int(stats.outcome(e.estimate, p)) if e.has_test else stats.NONE
                for e, p in zip(effects, adjusted, strict=True)]
    return [float(p) for p in adjusted], [_WORD[o] for o in outcomes], stats.decide(outcomes)


def _robot_verdict(verdicts: Sequence[str]) -> str:
    """A robot's verdict from its comparisons' (already corrected) verdicts."""
    inv = {v: k for k, v in _WORD.items()}
    return stats.decide([inv[v] for v in verdicts])


def claim_a(rows: Sequence[dict[str, Any]], command: float) -> dict[str, Any]:
    """Claim (a) at ``command``: per robot the EV effect multiplicative - additive, and the combined verdict."""
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}  # None (a user's critic): in neither group
    per_robot = []
    for robot in OOD_ROBOTS:
        side = {m: [_values(rows, "ev", command_vx=command, robot=robot, variant=v) for v in variants
                    if mult[v] is m] for m in (True, False)}
        effect = stats.group_effect(side[True], side[False])
        if effect.n_a and effect.n_b:
            per_robot.append({"robot": robot, "effect": effect})
    adjusted, verdicts, verdict = _judge([p["effect"] for p in per_robot])
    for p, adj, v in zip(per_robot, adjusted, verdicts, strict=True):
        p.update(p_holm=adj, verdict=v)
    return {"claim": "a", "command_vx": command, "robots": per_robot, "verdict": verdict}


def claim_c(rows: Sequence[dict[str, Any]], command: float) -> dict[str, Any]:
    """Claim (c) at ``command``: per robot film's Flip and CosGrad against every other critic's."""
    others = [v for v in dict.fromkeys(r["variant"] for r in rows) if v != FILM]
    per_robot = []
    for robot in FIXED_ROBOTS:
        film = {m: _values(rows, m, command_vx=command, robot=robot, variant=FILM) for m in ("flip", "cos_grad")}
        pairs = []
        for other in others:
            flip = stats.mean_difference(_values(rows, "flip", command_vx=command, robot=robot, variant=other),
                                         film["flip"])
            cos = stats.mean_difference(film["cos_grad"],
                                        _values(rows, "cos_grad", command_vx=command, robot=robot, variant=other))
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
    return {"claim": "c", "command_vx": command, "robots": per_robot, "verdict": verdict}


def study_claims(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Claims (a) and (c) at every command of the study."""
    commands = sorted({float(r["command_vx"]) for r in rows})
    return [claim(rows, c) for c in commands for claim in (claim_a, claim_c)]


def verdict_rows(claims: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims as flat rows (one per comparison) for ``verdicts.csv``."""
    out = []
    for c in claims:
        for r in c["robots"]:
            comparisons = ([("multiplicative - additive", "ev", r["effect"], r["p_holm"], r["verdict"])]
                           if c["claim"] == "a" else
                           [(f"{p['other']} - film" if m == "flip" else f"film - {p['other']}", m, p[m],
                             p[f"{m}_p_holm"], p[f"{m}_verdict"]) for p in r["pairs"] for m in ("flip", "cos_grad")])
            m = len(c["robots"]) if c["claim"] == "a" else sum(2 * len(x["pairs"]) for x in c["robots"])
            for what, metric, e, p_holm, verdict in comparisons:
                need = stats.seeds_needed(e, alpha=stats.ALPHA / max(m, 1)) if verdict == stats.CANNOT else None
                out.append({"claim": c["claim"], "command_vx": c["command_vx"], "robot": r["robot"],
                            "comparison": what, "metric": metric, "effect": e.estimate, "lo": e.lo, "hi": e.hi,
                            "p": e.p, "p_holm": p_holm, "n_a": e.n_a, "n_b": e.n_b, "verdict": verdict,
                            "seeds_needed": need, "robot_verdict": r["verdict"], "claim_verdict": c["verdict"]})
    return out


VERDICT_COLUMNS: tuple[str, ...] = ("claim", "command_vx", "robot", "comparison", "metric", "effect", "lo", "hi", "p",
                                    "p_holm", "n_a", "n_b", "verdict", "seeds_needed", "robot_verdict",
                                    "claim_verdict")
"""Columns of ``verdicts.csv``."""
SUMMARY_COLUMNS: tuple[str, ...] = ("command_vx", "robot", "variant", "multiplicative", "metric", "mean", "lo", "hi",
                                    "n")
"""Columns of ``summary.csv``."""
