"""The report's critic-study section: the fits' intervals per robot and the verdicts of (a) and (c), actor fixed.

Built from the rows of a stored ``critic_study.csv`` (``morfic critic-study``; :mod:`~morfic_cli.diagnostics.
critic_study`) with :mod:`~morfic_cli.diagnostics.study_summary`: one table per command and metric (EV, Flip,
CosGrad), robots x variants, each cell the mean over fit seeds with its 95 % t interval, and the claims'
verdicts as text.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from morfic_cli.diagnostics.figures import STUDY_LABELS
from morfic_cli.diagnostics.study_summary import cell_summary, study_claims
from morfic_cli.report.model import Part, Row, Table
from morfic_cli.report.tables import robot_label, robot_order
from morfic_cli.rl.variants import variant_label, variant_order

STUDY_TABLE_METRICS: tuple[tuple[str, str], ...] = (("ev", "EV"), ("flip", "Flip"), ("cos_grad", "Cos."))
"""The metrics of the study's tables, one table each per command."""


def _num(x: float) -> str:
    """Two decimals, or three significant digits past 100 (EV runs to -10^5 where the returns barely vary)."""
    return f"{x:.2f}" if abs(x) < 100 else f"{x:.3g}"


def _cell(c: dict[str, Any] | None) -> tuple[Part, ...]:
    if c is None or c["mean"] is None or not math.isfinite(c["mean"]):
        return (Part(None),)
    if c["lo"] is None or not math.isfinite(c["lo"]):
        return (Part(None, text=_num(c["mean"])),)
    return (Part(None, text=f"{_num(c['mean'])} [{_num(c['lo'])}, {_num(c['hi'])}]"),)


def study_tables(rows: Sequence[dict[str, Any]]) -> list[Table]:
    """One table per command and metric (EV, Flip, Cos.): robots (``train`` first) x variants, with intervals."""
    if not rows:
        return []
    summary = cell_summary(rows)
    by = {(r["command_vx"], r["robot"], r["variant"], r["metric"]): r for r in summary}
    variants = sorted({r["variant"] for r in summary}, key=variant_order)
    robots = sorted({r["robot"] for r in summary}, key=lambda r: (r != "train", robot_order(r) if r != "train" else 0))
    seeds = max(r["n"] for r in summary)
    tables = []
    for command in sorted({r["command_vx"] for r in summary}):
        for metric, name in STUDY_TABLE_METRICS:
            out = [Row("train (held out)" if robot == "train" else robot_label(robot),
                       tuple(_cell(by.get((command, robot, v, metric))) for v in variants)) for robot in robots]
            better = "lower" if metric == "flip" else "higher"
            caption = (f"{name} of every critic fitted from scratch on one frozen actor's rollouts of the training "
                       f"distribution ({seeds} fit seeds each), scored on that actor's rollouts at {command:g} m/s: "
                       f"mean over the fits [95 % t interval]; {better} is better.")
            key = f"critic_study_{metric}_{command:g}".replace(".", "_")
            tables.append(Table(key, f"Critic study: {name} at {command:g} m/s", caption, "Target",
                                tuple(STUDY_LABELS.get(v, variant_label(v)) for v in variants), tuple(out),
                                math=False))
    return tables


def study_text(rows: Sequence[dict[str, Any]], actor: str, artifact: str, seconds: dict[str, float]) -> str:
    """The verdicts of claims (a) and (c) with the actor fixed, each robot's effect with its interval."""
    lines = [f"The conditioning alone: one frozen actor ({actor}), every critic fitted from scratch on the same "
             f"training-distribution data (`morfic critic-study`, artifact `{artifact[:12]}`; fits "
             f"{seconds.get('fits', math.nan):.0f} s, rollouts {seconds.get('rollouts', math.nan):.0f} s, scoring "
             f"{seconds.get('scoring', math.nan):.0f} s). Verdicts from Welch and t-contrast tests over fit seeds, "
             "Holm-corrected per claim (docs/report.md).", ""]
    for c in study_claims(rows):
        if c["claim"] == "a":
            parts = [f"{r['robot']} {r['effect'].text(p_holm=r['p_holm'])} ({r['verdict']})" for r in c["robots"]]
            what = "EV multiplicative - additive"
        else:
            parts = []
            for r in c["robots"]:
                worst = _worst_pair(r["pairs"])
                parts.append(f"{r['robot']} {r['verdict']}" + (f" (weakest: {worst})" if worst else ""))
            what = "film's Flip lowest and Cos. highest"
        lines.append(f"- ({c['claim']}) at {c['command_vx']:g} m/s, {what}: **{c['verdict']}**; " + "; ".join(parts))
    return "\n".join(lines)


def _worst_pair(pairs: Sequence[dict[str, Any]]) -> str:
    """The comparison whose interval lies lowest (the weakest for the claim), as text, with its Holm p."""
    cands = [(p[m].lo if math.isfinite(p[m].lo) else p[m].estimate, p["other"], m, p[m], p.get(f"{m}_p_holm"))
             for p in pairs for m in ("flip", "cos_grad") if math.isfinite(p[m].estimate)]
    if not cands:
        return ""
    _, other, m, e, p_holm = min(cands, key=lambda t: t[0])
    what = f"{other} - film Flip" if m == "flip" else f"film - {other} Cos."
    return f"{what} {e.text(3, p_holm)}"
