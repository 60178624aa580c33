"""The critic study's table and verdicts: per-cell intervals over fit seeds, claims (a) and (c) with the actor fixed.

Pure functions over the rows of ``critic_study.csv`` (:data:`~morfic_cli.diagnostics.critic_study.STUDY_COLUMNS`).
Intervals and verdicts use :mod:`morfic_cli.report.stats` (95 % percentile bootstrap over fit seeds, the verdict
read from the interval; docs/report.md "How a verdict is read"):

- a **cell** is one metric of one variant on one robot at one command: its mean over fit seeds with an interval;
- claim **(a)** per robot: the effect mean EV(multiplicative critics) - mean EV(additive critics)
  (:func:`~morfic_cli.report.stats.group_effect`, each variant's seed mean weighing the same), higher is the claim;
  a user's critic (``multiplicative`` None) is in neither group;
- claim **(c)** per robot: film's Flip against every other critic's (other - film, the claim: > 0) and its CosGrad
  (film - other, the claim: > 0); it holds on a robot when every one of those comparisons holds, does not hold when
  one of them is reversed, else cannot tell.

A claim over several robots: ``holds`` when it holds on every robot, ``holds partly`` when it holds on some and is
reversed on none, ``mixed`` when it holds on some and is reversed on others, ``does not hold`` when it holds on none
and is reversed on at least one, else ``cannot tell`` (the rule of :mod:`morfic_cli.report.claims`, with ``mixed``
split out of ``holds partly``).
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
PARTLY, MIXED = "holds partly", "mixed"


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
    """Mean and 95 % bootstrap interval over fit seeds of every (command, robot, variant, metric).

    Returns:
        Rows ``command_vx, robot, variant, multiplicative, metric, mean, lo, hi, n`` (NaN ends for one seed).
    """
    keys = list(dict.fromkeys((r["command_vx"], r["robot"], r["variant"]) for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}
    out = []
    for command, robot, variant in keys:
        for metric in SUMMARY_METRICS:
            vals = _values(rows, metric, command_vx=command, robot=robot, variant=variant)
            mean, lo, hi = stats.bootstrap_statistic([vals], lambda m: float(m[0]))
            out.append({"command_vx": command, "robot": robot, "variant": variant, "multiplicative": mult[variant],
                        "metric": metric, "mean": mean, "lo": lo, "hi": hi, "n": len(vals)})
    return out


def combine(verdicts: Sequence[str]) -> str:
    """One verdict over robots from each robot's (module docstring)."""
    holds, reversed_ = verdicts.count(stats.HOLDS), verdicts.count(stats.NOT)
    if verdicts and holds == len(verdicts):
        return stats.HOLDS
    if holds and reversed_:
        return MIXED
    if holds:
        return PARTLY
    if reversed_:
        return stats.NOT
    return stats.CANNOT


def _all_pairs(verdicts: Sequence[str]) -> str:
    """A robot's verdict of claim (c) from its pairwise comparisons."""
    if verdicts and all(v == stats.HOLDS for v in verdicts):
        return stats.HOLDS
    if stats.NOT in verdicts:
        return stats.NOT
    return stats.CANNOT


def claim_a(rows: Sequence[dict[str, Any]], command: float) -> dict[str, Any]:
    """Claim (a) at ``command``: per robot the EV effect multiplicative - additive, and the combined verdict."""
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    mult = {r["variant"]: group_of(r["multiplicative"]) for r in rows}  # None (a user's critic): in neither group
    per_robot = []
    for robot in OOD_ROBOTS:
        side = {m: [_values(rows, "ev", command_vx=command, robot=robot, variant=v) for v in variants
                    if mult[v] is m] for m in (True, False)}
        effect = stats.group_effect(side[True], side[False])
        per_robot.append({"robot": robot, "effect": effect, "verdict": effect.verdict(higher=True)})
    return {"claim": "a", "command_vx": command, "robots": per_robot,
            "verdict": combine([p["verdict"] for p in per_robot if p["effect"].n_a and p["effect"].n_b])}


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
        verdicts = [p[m].verdict(higher=True) for p in pairs for m in ("flip", "cos_grad")]
        per_robot.append({"robot": robot, "pairs": pairs, "verdict": _all_pairs(verdicts) if film["flip"] else
                          stats.CANNOT})
    return {"claim": "c", "command_vx": command, "robots": per_robot,
            "verdict": combine([p["verdict"] for p in per_robot])}


def study_claims(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Claims (a) and (c) at every command of the study."""
    commands = sorted({float(r["command_vx"]) for r in rows})
    return [claim(rows, c) for c in commands for claim in (claim_a, claim_c)]


def verdict_rows(claims: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims as flat rows (one per comparison) for ``verdicts.csv``."""
    out = []
    for c in claims:
        for r in c["robots"]:
            comparisons = ([("multiplicative - additive", "ev", r["effect"])] if c["claim"] == "a" else
                           [(f"{p['other']} - film" if m == "flip" else f"film - {p['other']}", m, p[m])
                            for p in r["pairs"] for m in ("flip", "cos_grad")])
            for what, metric, e in comparisons:
                out.append({"claim": c["claim"], "command_vx": c["command_vx"], "robot": r["robot"],
                            "comparison": what, "metric": metric, "effect": e.estimate, "lo": e.lo, "hi": e.hi,
                            "p": e.p, "n_a": e.n_a, "n_b": e.n_b, "verdict": e.verdict(higher=True),
                            "robot_verdict": r["verdict"], "claim_verdict": c["verdict"]})
    return out


VERDICT_COLUMNS: tuple[str, ...] = ("claim", "command_vx", "robot", "comparison", "metric", "effect", "lo", "hi", "p",
                                    "n_a", "n_b", "verdict", "robot_verdict", "claim_verdict")
"""Columns of ``verdicts.csv``."""
SUMMARY_COLUMNS: tuple[str, ...] = ("command_vx", "robot", "variant", "multiplicative", "metric", "mean", "lo", "hi",
                                    "n")
"""Columns of ``summary.csv``."""
