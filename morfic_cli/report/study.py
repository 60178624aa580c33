"""The report's critic-study section: intervals over actors per robot, NVB and NVE beside EV, the verdicts of (a), (c).

Built from the rows of a stored ``critic_study.csv`` (``morfic critic-study``; :mod:`~morfic_cli.diagnostics.
critic_study`) with :mod:`~morfic_cli.diagnostics.study_summary`: one table per command and metric (EV, NVB, NVE,
Flip, CosGrad), robots x variants, each cell the mean over the study's unit (actors, their converged fits averaged
first; the fit seed for a one-actor study) with its 95 % t interval and how many fits were left out unconverged;
then the claims' verdicts as text, claim (a)'s EV contrast with its NVE and NVB contrasts beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from morfic_cli.diagnostics.figures import STUDY_LABELS
from morfic_cli.diagnostics.study_summary import ACTOR, cell_summary, convergence_text, study_claims, study_unit
from morfic_cli.report.model import Part, Row, Table
from morfic_cli.report.tables import robot_label, robot_order
from morfic_cli.rl.variants import variant_label, variant_order

STUDY_TABLE_METRICS: tuple[tuple[str, str], ...] = (
    ("ev", "EV"),
    ("nvb", "NVB"),
    ("nve", "NVE"),
    ("flip", "Flip"),
    ("cos_grad", "Cos."),
)
"""The metrics of the study's tables, one table each per command."""
_BETTER = {
    "ev": "higher is better",
    "nvb": "0 is best (> 0 overestimates G)",
    "nve": "lower is better",
    "flip": "lower is better",
    "cos_grad": "higher is better",
}


def _num(x: float) -> str:
    """Two decimals, or three significant digits past 100 (EV runs to -10^5 where the returns barely vary)."""
    return f"{x:.2f}" if abs(x) < 100 else f"{x:.3g}"


def _cell(c: dict[str, Any] | None) -> tuple[Part, ...]:
    """``0.41 [0.30, 0.52]``, with ``†k`` when k fits were left out unconverged; ``† all k`` when every one was."""
    if c is None:
        return (Part(None),)
    bad = int(c.get("n_flagged") or 0)
    mark = f" †{bad}" if bad else ""
    if c["mean"] is None or not math.isfinite(c["mean"]):
        return (Part(None, text=f"– † all {bad}") if bad else Part(None),)
    if c["lo"] is None or not math.isfinite(c["lo"]):
        return (Part(None, text=_num(c["mean"]) + mark),)
    return (Part(None, text=f"{_num(c['mean'])} [{_num(c['lo'])}, {_num(c['hi'])}]{mark}"),)


def _unit_words(rows: Sequence[dict[str, Any]]) -> str:
    """``5 actors (each its 2 fit seeds averaged first)`` or ``the fit seeds of one actor``."""
    if study_unit(rows) == ACTOR:
        actors = len({r.get("actor") for r in rows})
        seeds = len({r["fit_seed"] for r in rows})
        if seeds == 1:
            return f"{actors} actors (one fit a critic and actor)"
        return f"{actors} actors (each actor's converged fits, {seeds} fit seeds, averaged first)"
    return "the fit seeds of one actor (a one-actor study: it speaks of that actor only)"


def study_tables(rows: Sequence[dict[str, Any]]) -> list[Table]:
    """One table per command and metric (EV, NVB, NVE, Flip, Cos.): robots (``train`` first) x variants."""
    if not rows:
        return []
    summary = cell_summary(rows)
    by = {(r["command_vx"], r["robot"], r["variant"], r["metric"]): r for r in summary}
    variants = sorted({r["variant"] for r in summary}, key=variant_order)
    robots = sorted({r["robot"] for r in summary}, key=lambda r: (r != "train", robot_order(r) if r != "train" else 0))
    metrics = [(m, name) for m, name in STUDY_TABLE_METRICS if any(r["metric"] == m for r in summary)]
    unit = _unit_words(rows)
    flags = "; †k: k fits left out as unconverged" if "converged" in rows[0] else ""
    tables = []
    for command in sorted({r["command_vx"] for r in summary}):
        for metric, name in metrics:
            out = [
                Row(
                    "train (held out)" if robot == "train" else robot_label(robot),
                    tuple(_cell(by.get((command, robot, v, metric))) for v in variants),
                )
                for robot in robots
            ]
            caption = (
                f"{name} of every critic fitted from scratch on a frozen actor's rollouts of the training "
                f"distribution, scored on that actor's rollouts at {command:g} m/s: mean over {unit} "
                f"[95 % t interval]{flags}; {_BETTER[metric]}."
            )
            key = f"critic_study_{metric}_{command:g}".replace(".", "_")
            tables.append(
                Table(
                    key,
                    f"Critic study: {name} at {command:g} m/s",
                    caption,
                    "Target",
                    tuple(STUDY_LABELS.get(v, variant_label(v)) for v in variants),
                    tuple(out),
                    math=False,
                )
            )
    return tables


def study_text(rows: Sequence[dict[str, Any]], actor: str, artifact: str, seconds: dict[str, float]) -> str:
    """The design (unit, convergence) and the verdicts of claims (a) and (c), each robot's effect with its interval.

    Claim (a)'s EV contrast carries the NVE and NVB contrasts beside it, and a robot where the multiplicative
    critics explain more variance with a larger total error is named as such (their values are biased).
    """
    unit = study_unit(rows)
    lines = [
        f"The conditioning alone: frozen actors ({actor}), every critic fitted from scratch on its actor's "
        f"training-distribution data (`morfic critic-study`, artifact `{artifact[:12]}`; fits "
        f"{seconds.get('fits', math.nan):.0f} s, rollouts {seconds.get('rollouts', math.nan):.0f} s, scoring "
        f"{seconds.get('scoring', math.nan):.0f} s). The unit: {_unit_words(rows)}; {convergence_text(rows)}. "
        + (
            "Verdicts from t tests over actors, paired by actor, "
            if unit == ACTOR
            else "Verdicts from Welch and t-contrast tests over fit seeds, "
        )
        + "Holm-corrected per claim (docs/report.md).",
        "",
    ]
    for c in study_claims(rows):
        if c["claim"] == "a":
            parts = []
            for r in c["robots"]:
                text = (
                    f"{r['robot']} {r['effect'].text(p_holm=r['p_holm'])} ({r['verdict']}); NVE "
                    f"{r['nve'].text()}, NVB {r['nvb'].text()}"
                )
                if r["effect"].estimate > 0 and r["nve"].estimate > 0:
                    (nve_m, nve_a), (nvb_m, nvb_a) = r["levels"]["nve"], r["levels"]["nvb"]
                    text += (
                        f": higher EV with a larger total error (NVE {nve_m:.1f} against {nve_a:.1f}; NVB "
                        f"{nvb_m:+.1f} against {nvb_a:+.1f}: the multiplicative critics' values sit "
                        f"{abs(nvb_m):.1f} σ_G {'above' if nvb_m > 0 else 'below'} the returns on average, a "
                        "bias EV does not see)"
                    )
                parts.append(text)
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
    cands = [
        (p[m].lo if math.isfinite(p[m].lo) else p[m].estimate, p["other"], m, p[m], p.get(f"{m}_p_holm"))
        for p in pairs
        for m in ("flip", "cos_grad")
        if math.isfinite(p[m].estimate)
    ]
    if not cands:
        return ""
    _, other, m, e, p_holm = min(cands, key=lambda t: t[0])
    what = f"{other} - film Flip" if m == "flip" else f"film - {other} Cos."
    return f"{what} {e.text(3, p_holm)}"
