"""docs/results.md's tables, claims and figures, from the run CSVs under docs/results/, beside the paper's.

Inputs (written by scripts/experiment_tables.py from the experiment store, each CSV the artifact's file verbatim):
``<run>-eval.csv``, ``<run>-calibration.csv``, their 1.0 m/s counterparts ``<run>-eval-1.0.csv`` and (where the
run's weights were at hand) ``<run>-calibration-1.0.csv``, ``<run>-artifacts.json`` (the ids of the run's checkpoint,
evals, diagnoses and fixed-rollout analyses) and ``fixed-rollout-<robot>.csv`` (every critic scored on the frozen film
actor's one rollout of the robot at 2.0 m/s; ``fixed-rollout-1.0-<robot>.csv`` the same at 1.0 m/s, the critics whose
weights a store held); where the evals recorded them, ``<run>-terminations.csv`` and ``<run>-terminations-1.0.csv``
(the two evals' termination counts: what ended each failed episode, docs/eval.md).

Outputs:

- the transfer and calibration tables: one column per variant (the paper's order), its seeds pooled: with one seed
  the run's own cell (v̄x ± σ over the alive env-steps / S), with several the mean ± std over the seeds of each
  number (n = seeds); then the paper's columns for each trained variant it reports;
- the fixed-rollout tables (Flip / Cos per critic, beside the paper's at 2.0 m/s; then at 1.0 m/s);
- every run's walking check (``<run>-walk.json``: Go2 at 1.0 m/s, bar v_x >= 0.8 m/s and S >= 0.9) and when its
  command curriculum opened (from ``<run>-curve.csv``);
- the paper's claims (a)-(e), computed by ``morfic_cli.report.claims.check_claims`` from the same rows (never
  typed in), each with the artifact ids its numbers come from;
- the shipped bundles' weight (``--bundles``, default artifacts/bundles): every tar, what it ships and its size in
  MiB, and the total, measured from the files (the repository's bundle weight that docs/results.md reports);
- the external baselines in our pipeline (issue 57): the paper's row group (its released-weights numbers) and ours
  (``urma``, ``bot``, ``genloco``, ``film``; "not trained yet" where no run is here) at 2.0 and 2.5 m/s (and 1.0 m/s
  where rows exist) in descriptor and full mode, their compute (parameters, transitions, wall time from
  ``<run>-curve.csv``), what each changes on AlienGo, Mini Cheetah and ANYmal-C against film, and what ended their
  failed episodes there (the termination counts, where recorded);
- film and each actuation variant (table ``actuation``) against issue 58's goal (``morfic_cli/report/goal.py``),
  with what ended the failed episodes in full mode (where recorded; else a line saying they come with the next
  evaluations);
- with ``--figures DIR``: ``results-ev.png`` (EV per variant per robot), ``results-distance.png`` (speed against
  the normalised distance d, the paper's points beside ours) and ``results-curves.png`` (every run's training curve,
  from ``<run>-curve.csv``).

With ``--write FILE`` the tables replace what stands between ``<!-- results-tables:begin -->`` and
``<!-- results-tables:end -->`` in FILE, the claims what stands between ``<!-- results-claims:begin -->`` and
``<!-- results-claims:end -->``, the walking checks ``<!-- results-walk:begin -->`` ... ``end``, the bundles
``<!-- results-bundles:begin -->`` ... ``end``, the critic study (``critic-study.csv`` and ``.json``, when there)
``<!-- results-study:begin -->`` ... ``end``, the external baselines ``<!-- results-external:begin -->`` ... ``end``
and the goal ``<!-- results-goal:begin -->`` ... ``end`` (the last three only where FILE has their markers); without
it the tables, claims, walking checks and bundles go to stdout. ``--only NAME`` (with ``--write``; ``goal``,
``external``, ``study`` or ``answer``, repeatable) replaces only those blocks and leaves the rest of FILE as it is.

Usage: python scripts/results_tables.py [--results docs/results] [--write docs/results.md] [--figures docs/img]
                                        [--bundles artifacts/bundles] [--only goal ...]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

from morfic_cli.report.claims import PAPER_COMMAND, TRAINED_COMMAND, command_suffix, is_paper_command
from morfic_cli.report.tables import robot_label

BEGIN, END = "<!-- results-tables:begin -->", "<!-- results-tables:end -->"
CLAIMS_BEGIN, CLAIMS_END = "<!-- results-claims:begin -->", "<!-- results-claims:end -->"
WALK_BEGIN, WALK_END = "<!-- results-walk:begin -->", "<!-- results-walk:end -->"
BUNDLES_BEGIN, BUNDLES_END = "<!-- results-bundles:begin -->", "<!-- results-bundles:end -->"
STUDY_BEGIN, STUDY_END = "<!-- results-study:begin -->", "<!-- results-study:end -->"
ANSWER_BEGIN, ANSWER_END = "<!-- generated: answer -->", "<!-- /generated: answer -->"
HEADLINE_BEGIN, HEADLINE_END = "<!-- generated: headline -->", "<!-- /generated: headline -->"
STUDY_CSV, STUDY_JSON = "critic-study.csv", "critic-study.json"
"""The critic study's rows (its ``critic_study.csv`` verbatim) and its id, settings and timings."""
MIB = 2**20
ROBOTS = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c")
FIXED_ROBOTS = ("aliengo", "mini_cheetah")
RUN_NAME = re.compile(r"^(?P<variant>.+)-cpu-s(?P<seed>\d+)$")


def parse_run(name: str) -> tuple[str, int] | None:
    """``(variant, seed)`` of an experiment run name (``film-scaled-cpu-s1`` -> ``("film-scaled", 1)``), else None."""
    m = RUN_NAME.match(name)
    return (m["variant"], int(m["seed"])) if m else None


def load(results: Path, kind: str) -> pd.DataFrame:
    """Every ``<run>-<kind>.csv`` in ``results`` in one frame with ``run``, ``variant`` and ``seed`` columns.

    Rows are in the paper's variant order, then by seed.
    """
    from morfic_cli.rl.variants import variant_order

    frames = []
    for path in sorted(results.glob(f"*-cpu-s*-{kind}.csv")):
        run = path.name[: -len(f"-{kind}.csv")]
        parsed = parse_run(run)
        if parsed is None:
            continue
        frame = pd.read_csv(path)
        frame["run"], frame["variant"], frame["seed"] = run, parsed[0], parsed[1]
        frames.append(frame)
    if not frames:
        return pd.DataFrame()
    out = pd.concat(frames, ignore_index=True)
    out["_order"] = [(variant_order(v), s) for v, s in zip(out["variant"], out["seed"], strict=True)]
    return out.sort_values("_order", kind="stable").drop(columns="_order").reset_index(drop=True)


def load_artifacts(results: Path) -> dict[str, dict[str, Any]]:
    """Run name -> its ``<run>-artifacts.json`` (ids of checkpoint, eval, diagnosis, fixed rollouts)."""
    return {
        p.name[: -len("-artifacts.json")]: json.loads(p.read_text()) for p in sorted(results.glob("*-artifacts.json"))
    }


def load_fixed_all(results: Path) -> pd.DataFrame:
    """Every row of every ``fixed-rollout-[1.0-]<robot>.csv``, with ``samples``, ``reference``, ``seed`` and command.

    ``samples``: the content id of the samples a row was scored on (rows written before that column: the reference
    samples of the file's sidecar ``.json``); ``reference``: scored on those; ``seed``: the critic run's;
    ``command_vx``: the rollout's command (rows written before that column: the paper's 2.0 m/s).
    """
    frames = []
    for p in sorted(results.glob("fixed-rollout-*.csv")):
        frame = pd.read_csv(p, dtype={"samples": str})
        side = p.with_suffix(".json")
        ref = json.loads(side.read_text())["samples"] if side.is_file() else ""
        frame["samples"] = frame["samples"].fillna(ref) if "samples" in frame else ref
        frame["reference"] = frame["samples"] == ref
        frame["command_vx"] = frame["command_vx"].fillna(PAPER_COMMAND) if "command_vx" in frame else PAPER_COMMAND
        frames.append(frame)
    if not frames:
        return pd.DataFrame()
    out = pd.concat(frames, ignore_index=True)
    out["seed"] = [parsed[1] if (parsed := parse_run(str(c))) else 0 for c in out["critic"]]
    return out


def load_fixed(results: Path) -> pd.DataFrame:
    """One row per (command, robot, critic) and the MC reference, the row on the reference samples where there is one.

    A critic without one keeps its row on other samples (``reference`` False: the frozen actor's rollout collected
    again where the reference samples were not at hand).
    """
    rows = load_fixed_all(results)
    if rows.empty:
        return rows
    rows = rows.sort_values("reference", ascending=False, kind="stable")
    mc = rows[rows["variant"] == "mc"].drop_duplicates(["command_vx", "robot"])  # Flip 0, Cos 1 on any samples
    critics = rows[rows["variant"] != "mc"].drop_duplicates(["command_vx", "robot", "critic"])
    return pd.concat([mc, critics]).sort_index()


def sample_effect(results: Path) -> pd.DataFrame:
    """What collecting the frozen actor's rollout again changes, from the critics scored on both samples.

    One row per critic and other samples: command_vx, robot, critic, samples, ``d_flip`` and ``d_cos`` (other minus
    reference, at the same command).
    """
    rows = load_fixed_all(results)
    if rows.empty:
        return rows
    rows = rows[rows["variant"] != "mc"]
    both = rows[~rows["reference"]].merge(
        rows[rows["reference"]], on=["command_vx", "robot", "critic"], suffixes=("", "_ref")
    )
    both["d_flip"] = both["flip"] - both["flip_ref"]
    both["d_cos"] = both["cos_grad"] - both["cos_grad_ref"]
    return both[["command_vx", "robot", "critic", "samples", "d_flip", "d_cos"]]


# ----------------------------------------------------------------------------------------------- pooled cells
def _pm(values: pd.Series, decimals: int) -> str:
    """``mean ± std`` over seeds (population std, as the claims compute it: ``claims.seed_stat``)."""
    from morfic_cli.report.claims import seed_stat

    stat = seed_stat(values)
    return f"{stat.mean:.{decimals}f} ± {stat.std:.{decimals}f}"


def _pooled(values: pd.Series, decimals: int) -> str:
    """One seed's value as it is; several seeds' as :func:`_pm`'s ``mean ± std``."""
    return f"{values.iloc[0]:.{decimals}f}" if len(values) == 1 else _pm(values, decimals)


def _n(rows: pd.DataFrame) -> str:
    """`` (n=k)`` after a cell pooled over k > 1 seeds; nothing after one seed's."""
    return "" if len(rows) == 1 else f" (n={len(rows)})"


def transfer_cell(rows: pd.DataFrame) -> str:
    """One variant's cell on one robot: the run's own ``v̄x ± σ / S (verdict)``, or over seeds ``v̄x / S (n=k)``."""
    if rows.empty:
        return "-"
    if len(rows) == 1:
        r = rows.iloc[0]
        return f"{r['vx_mean']:.2f} ± {r['vx_std']:.2f} / {r['survival']:.3f} ({r['verdict']})"
    return f"{_pm(rows['vx_mean'], 2)} / {_pm(rows['survival'], 3)} (n={len(rows)})"


def _paper_cell(vx: float | None, vx_std: float | None, survival: float | None) -> str:
    """The paper's ``v_x ± σ / S``; a part the paper does not print (GenLoco's σ, say) is left out."""
    if vx is None:
        return "-"
    std = f" ± {vx_std:.2f}" if vx_std is not None else ""
    return f"{vx:.2f}{std}" + (f" / {survival:.3f}" if survival is not None else "")


def _seeds_label(frame: pd.DataFrame, variant: str) -> str:
    """```film` (s0)`` for one seed, ```film` (n=3)`` for several."""
    seeds = sorted(set(frame.loc[frame["variant"] == variant, "seed"]))
    return f"`{variant}` (s{seeds[0]})" if len(seeds) == 1 else f"`{variant}` (n={len(seeds)})"


def transfer_table(ev: pd.DataFrame, mode: str, command_vx: float) -> list[str]:
    """Robots x variants (ours, seeds pooled), then the paper's columns in descriptor mode."""
    from morfic_cli.report.paper import transfer_values

    rows = frame_at(ev[ev["mode"] == mode], command_vx)
    variants = list(dict.fromkeys(rows["variant"]))
    paper = [
        v
        for v in variants
        if mode == "descriptor" and any(transfer_values(v, r, command_vx)["vx"] is not None for r in ROBOTS)
    ]
    head = ["robot", "d", *[_seeds_label(rows, v) for v in variants], *[f"paper {v}" for v in paper]]
    lines = ["| " + " | ".join(head) + " |", "|---|---:|" + "---|" * (len(head) - 2)]
    for robot in ROBOTS:
        at = rows[rows["robot"] == robot]
        if at.empty:
            continue
        cells = [transfer_cell(at[at["variant"] == v]) for v in variants]
        cells += [_paper_cell(**transfer_values(v, robot, command_vx)) for v in paper]
        lines.append(f"| {robot} | {float(at['d'].iloc[0]):.3f} | " + " | ".join(cells) + " |")
    return lines


def calibration_table(cal: pd.DataFrame) -> list[str]:
    """Robots x variants: EV and |NVB|/NVE/ASA (seeds pooled), then the paper's |NVB|/NVE/ASA where it has them."""
    from morfic_cli.report.paper import critic_values

    variants = list(dict.fromkeys(cal["variant"]))
    paper = [v for v in variants if critic_values(v, "go2")["abs_nvb"] is not None]
    head = [
        "robot",
        *[f"{_seeds_label(cal, v)} EV" for v in variants],
        *[f"{_seeds_label(cal, v)} \\|NVB\\|/NVE/ASA" for v in variants],
        *[f"paper {v} \\|NVB\\|/NVE/ASA" for v in paper],
    ]
    lines = [
        "| " + " | ".join(head) + " |",
        "|---|" + "---:|" * len(variants) + "---|" * (len(head) - 1 - len(variants)),
    ]
    for robot in ROBOTS:
        at = cal[cal["robot"] == robot]
        if at.empty:
            continue
        evs, trio = [], []
        for v in variants:
            mine = at[at["variant"] == v]
            if mine.empty:
                evs.append("-")
                trio.append("-")
            else:  # the trio pooled as means only: three ± in one cell would not read
                evs.append(f"{_pooled(mine['ev'], 3)}{_n(mine)}")
                trio.append("/".join(f"{mine[m].mean():.3f}" for m in ("abs_nvb", "nve", "asa")) + _n(mine))
        ours = []
        for v in paper:
            p = critic_values(v, robot)
            ours.append("-" if p["abs_nvb"] is None else f"{p['abs_nvb']:.3f}/{p['nve']:.3f}/{p['asa']:.3f}")
        lines.append(f"| {robot} | " + " | ".join(evs + trio + ours) + " |")
    return lines


def frame_at(frame: pd.DataFrame, command_vx: float) -> pd.DataFrame:
    """The rows of ``frame`` at ``command_vx`` (m/s)."""
    return frame[(frame["command_vx"] - command_vx).abs() < 1e-9]


def fixed_table(fixed: pd.DataFrame, command_vx: float = PAPER_COMMAND) -> list[str]:
    """Critics x robots: Flip / Cos on the frozen film actor's rollout at ``command_vx`` (seeds pooled).

    At the paper's command the paper's Flip / Cos follow (it reports none at another).
    """
    from morfic_cli.report.paper import fixed_rollout_values
    from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, variant_order

    rows = frame_at(fixed[fixed["actor_variant"] == FIXED_ROLLOUT_ACTOR], command_vx)
    variants = sorted(dict.fromkeys(rows["variant"]), key=lambda v: (v != "mc", variant_order(v)))
    robots = [r for r in FIXED_ROBOTS if r in set(rows["robot"])]
    paper = robots if is_paper_command(command_vx) else []
    head = ["critic", *[f"{r} Flip / Cos" for r in robots], *[f"paper {r}" for r in paper]]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---|" * (len(head) - 1)]
    for v in variants:
        cells = []
        for robot in robots:
            mine = rows[(rows["variant"] == v) & (rows["robot"] == robot)]
            if mine.empty:
                cells.append("-")
            else:
                mark = "" if mine["reference"].all() else " †" * (v != "mc")
                cells.append(f"{_pooled(mine['flip'], 3)} / {_pooled(mine['cos_grad'], 3)}{_n(mine)}{mark}")
        for robot in paper:
            p = fixed_rollout_values(v, robot)
            cells.append("-" if p.get("flip") is None else f"{p['flip']:.3f} / {p['cos_grad']:.3f}")
        name = "MC (reference)" if v == "mc" else _seeds_label(rows, v)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def sample_note(results: Path, fixed: pd.DataFrame) -> list[str]:
    """The paragraph under the fixed-rollout table when some critic (†) was scored on other samples.

    It names those critics and what the samples change (:func:`sample_effect`); empty when every row is a reference
    row.
    """
    other = fixed[(~fixed["reference"]) & (fixed["variant"] != "mc")]
    if other.empty:
        return []
    effect = sample_effect(results)
    effect = effect[effect["command_vx"].isin(set(other["command_vx"]))] if not effect.empty else effect
    who = ", ".join(f"`{c}` ({', '.join(sorted(set(g['robot'])))})" for c, g in other.groupby("critic", sort=True))
    text = (
        f"† scored on another rollout of the same frozen actor (same config, collected again on another machine: "
        f"the reference rollout's log is not shipped and another CPU's rounding does not reproduce it): {who}."
    )
    parts = [
        f"on {robot} ({len(g)} critics) by {g['d_flip'].mean():+.3f} on average (|Δ| at most "
        f"{g['d_flip'].abs().max():.3f}) and Cos by {g['d_cos'].mean():+.3f} (|Δ| at most "
        f"{g['d_cos'].abs().max():.3f})"
        for robot, g in effect.groupby("robot", sort=True)
    ]
    if parts:
        text += " Scored on both, a critic's Flip changes " + "; ".join(parts) + "."
    return [text, ""]


#: The fixed-rollout tables' titles, per command (m/s).
FIXED_TITLES = {
    PAPER_COMMAND: "Fixed rollout (`morfic diagnose --fixed-rollout ROBOT`: the film actor frozen, every "
    "critic scored on its one rollout), 2.0 m/s",
    TRAINED_COMMAND: "Fixed rollout at 1.0 m/s (the trained regime; the critics whose weights a store "
    "held, `fixed-rollout-1.0-<robot>.csv`; the paper reports none)",
}


def render(results: Path) -> str:
    """All tables as one markdown block (without the markers)."""
    ev, cal, fixed = load_evals(results), load(results, "calibration"), load_fixed(results)
    out: list[str] = []
    titles = {
        ("descriptor", 1.0): "Descriptor mode, 1.0 m/s (the trained regime: every run, `<run>-eval-1.0.csv`; "
        "the paper reports none)",
        ("descriptor", 2.0): "Descriptor mode (the paper's protocol), 2.0 m/s",
        ("descriptor", 2.5): "Descriptor mode, 2.5 m/s (the paper reports only MorFiC-F, as v_x^max)",
        ("full", 2.0): "Full mode (the targets' own models; a morfic extension, no paper column), 2.0 m/s",
        ("full", 2.5): "Full mode, 2.5 m/s",
    }
    if not ev.empty:
        for (mode, vx), title in titles.items():
            out += [f"### {title}", "", *transfer_table(ev, mode, vx), ""]
    if not cal.empty:
        out += [
            "### Critic calibration (`morfic diagnose RUN`: descriptor mode, 2.0 m/s, 64 envs x 800 steps)",
            "",
            *calibration_table(cal),
            "",
        ]
    slow = load(results, "calibration-1.0")
    if not slow.empty:
        out += [
            "### Critic calibration at 1.0 m/s (the trained regime; the runs whose weights a store held, "
            "`<run>-calibration-1.0.csv`; the paper reports none)",
            "",
            *calibration_table(slow),
            "",
        ]
    if not fixed.empty:
        for vx, title in FIXED_TITLES.items():
            if not frame_at(fixed, vx).empty:
                out += [f"### {title}", "", *fixed_table(fixed, vx), "", *sample_note(results, frame_at(fixed, vx))]
    return "\n".join(out).rstrip() + "\n"


#: The walking check's bar (issue 17): on Go2 at 1.0 m/s, 16 envs x 250 steps.
WALK_VX, WALK_S = 0.8, 0.9
#: The paper's evaluation command (m/s), shown on the template beside the walking check.
TEMPLATE_VX = 2.0


def walk_table(results: Path) -> list[str]:
    """Every run's walking check, its curriculum, and its own template at the paper's command.

    From ``<run>-walk.json`` (the check), ``<run>-curve.csv`` (when the command curriculum opened, how far it
    reached) and ``<run>-eval.csv`` (Go2, descriptor mode, 2.0 m/s: a command that a run whose curriculum stopped
    short of it never trained for).
    """
    from morfic_cli.envs.locomotion import TEMPLATE
    from morfic_cli.rl.variants import variant_order

    evals = load(results, "eval")
    if not evals.empty:
        at = (evals["command_vx"] - TEMPLATE_VX).abs() < 1e-9
        evals = evals[(evals["robot"] == TEMPLATE) & (evals["mode"] == "descriptor") & at].set_index("run")
    runs = sorted(
        (
            p.name[: -len("-walk.json")]
            for p in results.glob("*-cpu-s*-walk.json")
            if parse_run(p.name[: -len("-walk.json")])
        ),
        key=lambda n: (variant_order(parse_run(n)[0]), parse_run(n)[1]),
    )
    lines = [
        "| run | v_x ± σ (m/s) | S | verdict | walks (v_x >= 0.8, S >= 0.9) | curriculum past 1 m/s at iteration "
        "| final vx range | Go2 at 2.0 m/s: v_x / S |",
        "|---|---:|---:|---|---|---:|---:|---|",
    ]
    for run in runs:
        row = json.loads((results / f"{run}-walk.json").read_text())[0]
        walks = row["vx_mean"] >= WALK_VX and row["survival"] >= WALK_S
        opened, top = "-", "-"
        curve = results / f"{run}-curve.csv"
        if curve.is_file():
            c = pd.read_csv(curve)
            wide = c[c["curriculum.vx_max"] > 1.0 + 1e-9]
            opened = str(int(wide["iteration"].iloc[0])) if not wide.empty else "never"
            top = f"{c['curriculum.vx_max'].iloc[-1]:g} m/s"
        at_cmd = "-"
        if run in evals.index:
            hit = evals.loc[run]
            at_cmd = f"{hit['vx_mean']:.2f} / {hit['survival']:.3f}"
        lines.append(
            f"| `{run}` | {row['vx_mean']:.2f} ± {row['vx_std']:.2f} | {row['survival']:.3f} | "
            f"{row['verdict']} | {'yes' if walks else '**no**'} | {opened} | {top} | {at_cmd} |"
        )
    return lines


def bundle_table(bundles: Path) -> list[str]:
    """The shipped bundles under ``bundles``: one row per tar (its path, what it ships, MiB), then the totals.

    ``<run>.tar`` directly under ``bundles`` ships a seed-0 run's weights (``--without-trainer-state``; what
    ``reproduce --preset shipped`` imports), ``weights/<run>.tar`` another seed's weights the same way,
    ``results/<run>.tar`` a run's results only, ``partial/<run>.tar`` an unfinished run with its trainer state. Sizes
    are the files' own, in MiB (2^20 bytes), so the total is what git carries.
    """
    kinds = (
        ("", "weights-only"),
        ("weights/", "weights-only (seed >= 1)"),
        ("results/", "results only"),
        ("partial/", "partial, with trainer state"),
    )
    rows, totals = [], {}
    for sub, kind in kinds:
        for tar in sorted((bundles / sub).glob("*.tar")):
            size = tar.stat().st_size / MIB
            rows.append(f"| `{tar.as_posix()}` | {kind} | {size:.1f} |")
            totals[kind] = totals.get(kind, 0.0) + size
    if not rows:
        return [f"No bundle under {bundles}."]
    lines = ["| bundle | ships | MiB |", "|---|---|---:|", *rows]
    lines += [
        f"| {len(rows)} tars | {', '.join(f'{k} {v:.1f}' for k, v in totals.items())} | "
        f"**{sum(totals.values()):.1f}** |"
    ]
    return lines


# ----------------------------------------------------------------------------------------------- claims
#: The extra eval and diagnosis files the claims read beside ``<run>-eval.csv`` and ``<run>-calibration.csv``:
#: ``<run>-<kind>-<vx>.csv``, a run evaluated or diagnosed at another command (same columns, ``command_vx`` = vx; the
#: trained regime at 1.0 m/s). Their ids are the ``<kind>-<vx>`` entries of ``<run>-artifacts.json``.
EXTRA_EVALS: tuple[str, ...] = ("eval-1.0",)
EXTRA_CALIBRATIONS: tuple[str, ...] = ("calibration-1.0",)


def _load_all(results: Path, kinds: tuple[str, ...]) -> pd.DataFrame:
    frames = [f for f in (load(results, kind) for kind in kinds) if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def load_evals(results: Path) -> pd.DataFrame:
    """Every run's eval rows: ``<run>-eval.csv`` and each of :data:`EXTRA_EVALS` (``<run>-eval-1.0.csv``)."""
    return _load_all(results, ("eval", *EXTRA_EVALS))


#: Each run's termination counts (scripts/experiment_tables.py, where the eval recorded them):
#: ``<run>-terminations.csv`` (the 2.0/2.5 m/s eval's) and ``<run>-terminations-1.0.csv`` (the 1.0 m/s eval's).
TERMINATION_KINDS: tuple[str, ...] = ("terminations", "terminations-1.0")
NO_COUNTS = (
    "no termination counts in these runs' evals yet: evals made before `terminations.csv` existed did not record "
    'them; they come with the next evaluations (docs/eval.md, "Termination counts").'
)


def load_terminations(results: Path) -> pd.DataFrame:
    """Every run's termination lines (``robot``, ``mode``, ``command_vx``, ``term``, ``envs`` + run, variant, seed)."""
    return _load_all(results, TERMINATION_KINDS)


def goal_kinds(kind: str = "eval") -> tuple[str, ...]:
    """The files of the evals issue 58's goal needs beyond the runs' own, ``<run>-<kind>.csv`` (goal section only).

    ``("eval-1.0-full",)`` (``kind`` ``terminations``: ``("terminations-1.0-full",)``): film's full-mode eval at
    1.0 m/s (:func:`morfic_cli.report.goal.goal_evals`, written by scripts/experiment_tables.py).
    """
    from morfic_cli.report.goal import GOAL, goal_eval_name, goal_evals

    return tuple(goal_eval_name(c, kind) for c in goal_evals(GOAL.reference))


def load_calibrations(results: Path) -> pd.DataFrame:
    """Every run's diagnosis rows: ``<run>-calibration.csv`` and each of :data:`EXTRA_CALIBRATIONS`."""
    return _load_all(results, ("calibration", *EXTRA_CALIBRATIONS))


def claim_rows(results: Path) -> tuple[list[dict], list[dict], list[dict]]:
    """The eval, calibration and fixed-rollout rows as ``check_claims`` reads them, each with its ``artifact`` id.

    The eval and calibration rows are :func:`load_evals`' and :func:`load_calibrations`' (2.0 / 2.5 m/s and, where a
    run has them, 1.0 m/s); a row's id is the run's ``<run>-artifacts.json`` entry of the file it came from
    (``<run>-eval-1.0.csv``: ``eval-1.0``; ``<run>-calibration-1.0.csv``: ``diagnosis-1.0``), else that file's name.
    """
    ids = load_artifacts(results)
    fixed = load_fixed(results)

    def records(kinds: tuple[str, ...]) -> list[dict]:
        out = []
        for kind in kinds:
            key = kind.replace("calibration", "diagnosis")  # artifacts.json names a diagnosis's id "diagnosis"
            for r in load(results, kind).to_dict("records"):
                r["artifact"] = ids.get(r["run"], {}).get(key) or f"{r['run']}-{kind}.csv"
                out.append(r)
        return out

    fixed_rows = []
    if not fixed.empty:
        for r in fixed.to_dict("records"):
            owner = r["critic"] if r["variant"] != "mc" else str(r["actor"])
            suffix = command_suffix(float(r["command_vx"]))  # the 1.0 m/s analyses: fixed_rollout-1.0, ...-1.0-<robot>
            r["artifact"] = (
                ids.get(owner, {}).get(f"fixed_rollout{suffix}", {}).get(r["robot"])
                or f"fixed-rollout{suffix}-{r['robot']}.csv"
            )
            fixed_rows.append(r)
    return (
        paper_only(records(("eval", *EXTRA_EVALS))),
        paper_only(records(("calibration", *EXTRA_CALIBRATIONS))),
        paper_only(fixed_rows),
    )


def paper_only(rows: list[dict]) -> list[dict]:
    """The rows of the paper's own seven variants (and the Monte-Carlo reference): the claims are about them only."""
    from morfic_cli.report.compare import PAPER_VARIANTS

    return [r for r in rows if r.get("variant") in PAPER_VARIANTS or r.get("variant") == "mc"]


def _short(artifact: str) -> str:
    """An artifact id's 12-character prefix (as ``morfic store show`` takes it); a file name as it is."""
    return artifact[:12] if re.fullmatch(r"[0-9a-f]{12,}", artifact) else artifact


#: The title of each command's block of claims.
COMMAND_TITLES = {
    2.0: "At 2.0 m/s (the paper's command)",
    1.0: "At 1.0 m/s (the trained regime, where every run but "
    "adaln's seeds 0 and 2 walks on Go2; the paper reports no numbers there)",
}


def render_claims(results: Path) -> str:
    """The claims (a)-(e) as markdown: a verdict table (claims x commands), then one block per command.

    Each claim gives the paper's numbers, ours (every effect with its 95 % interval), the verdict and why, and the
    artifact ids; the commands are ``check_claims``' (2.0 m/s, and 1.0 m/s where a run has ``<run>-eval-1.0.csv``).
    """
    from morfic_cli.report.claims import SHORT, check_claims

    claims = check_claims(*claim_rows(results))
    commands = list(dict.fromkeys(c.command_vx for c in claims))
    verdicts = {(c.key, c.command_vx): c.verdict for c in claims}
    titles = {c.key: SHORT.get(c.key, c.claim) for c in claims}
    lines = ["| claim | " + " | ".join(f"{vx:.1f} m/s" for vx in commands) + " |", "|---|" + "---|" * len(commands)]
    for key, title in titles.items():
        lines.append(
            f"| ({key}) {title} | " + " | ".join(f"**{verdicts.get((key, vx), '-')}**" for vx in commands) + " |"
        )
    lines.append("")
    for vx in commands:
        lines += [f"### {COMMAND_TITLES.get(vx, f'At {vx:.1f} m/s')}", ""]
        for claim in (c for c in claims if c.command_vx == vx):
            lines += [
                f"**({claim.key}) {claim.claim}** Verdict: **{claim.verdict}**.",
                "",
                f"- Paper: {claim.paper}",
                f"- Ours: {claim.ours or '-'}",
                f"- Why: {claim.reason}",
                "- From: " + (", ".join(f"`{_short(i)}`" for i in claim.artifacts) or "-"),
                "",
            ]
    return "\n".join(lines).rstrip() + "\n"


# ----------------------------------------------------------------------------------------------- the answer
def _keys(keys: list[str]) -> str:
    """``(a)``, ``(a) and (b)``, ``(b), (c) and (e)``."""
    k = [f"({x})" for x in keys]
    return k[0] if len(k) == 1 else ", ".join(k[:-1]) + " and " + k[-1]


def verdict_groups(claims: list[Any], command_vx: float) -> str:
    """``(a) holds partly; (b), (c), (d) and (e) cannot tell``: the claims at one command, grouped by verdict."""
    from morfic_cli.report.claims import VERDICTS

    at = [c for c in claims if c.command_vx == command_vx]
    return "; ".join(
        f"{_keys([c.key for c in at if c.verdict == v])} {v}" for v in VERDICTS if any(c.verdict == v for c in at)
    )


def _decided(c: Any) -> list[str]:
    """The claim's significant comparisons, each as ``<robot> <comparison> <effect> [<interval>] (Holm p, way)``."""
    out = []
    for r in c.comparisons:
        if r["outcome"] in ("for", "against"):
            ci = f" [{r['lo']:+.2f}, {r['hi']:+.2f}]" if r["lo"] is not None else ""
            out.append(
                f"{robot_label(r['unit'])} {r['comparison']} {r['effect']:+.2f}{ci} (Holm p {r['p_holm']:.2g}, "
                f"{r['outcome']} the claim)"
            )
    return out


def _closest(c: Any) -> str:
    """The undecided comparison that the fewest seeds would decide: ``film - actor-only Flip on mini_cheetah: 4``."""
    from morfic_cli.report.stats import MAX_SEEDS

    if c.key == "e":
        return "none: its test is over the robots, and seeds add no robots"
    cands = [r for r in c.comparisons if r["outcome"] == "not significant" and r["seeds_needed"] is not None]
    if not cands:
        return "no seed count would (no effect to detect, or no test)"
    r = min(cands, key=lambda x: x["seeds_needed"])
    n = r["seeds_needed"]
    return f"{r['comparison']} on {robot_label(r['unit'])}: " + (f"more than {MAX_SEEDS}" if n > MAX_SEEDS else str(n))


def _runs_text(results: Path) -> str:
    """``7 variants x 3 seeds`` (or ``1-3 seeds``) from the runs under ``results``."""
    from morfic_cli.report.compare import PAPER_VARIANTS

    runs = load(results, "eval")
    runs = runs[runs["variant"].isin(PAPER_VARIANTS)] if not runs.empty else runs
    if runs.empty:
        return "no runs"
    seeds = runs.groupby("variant")["seed"].nunique()
    n = f"{seeds.min()}" if seeds.min() == seeds.max() else f"{seeds.min()}-{seeds.max()}"
    return f"{len(seeds)} variants x {n} seed{'s' if seeds.max() > 1 else ''}"


def _study_verdicts(results: Path) -> str:
    """``(a) mixed at 1.0 m/s, mixed at 2.0 m/s; (c) ...`` from the critic study's rows, or ``""``."""
    path = results / STUDY_CSV
    if not path.exists():
        return ""
    from morfic_cli.diagnostics.study_summary import study_claims

    claims = study_claims(pd.read_csv(path).to_dict("records"))
    by_key: dict[str, list[str]] = {}
    for c in claims:
        by_key.setdefault(c["claim"], []).append(f"{c['verdict']} at {c['command_vx']:.1f} m/s")
    return "; ".join(f"({k}) {', '.join(v)}" for k, v in by_key.items())


def _study_design(results: Path) -> str:
    """How the critic study's rows replicate: over actors (layout 2), or one actor's fit seeds (layout 1)."""
    from morfic_cli.diagnostics.study_summary import ACTOR, study_unit

    rows = pd.read_csv(results / STUDY_CSV).to_dict("records")
    if study_unit(rows) == ACTOR:
        return f"its unit is the frozen actor, {len({r['actor'] for r in rows})} of them, converged fits only"
    return (
        "its unit is the fit seed of one actor's critics, fitted for a fixed epoch count (the study's layout 1, "
        "before issue 54), so it speaks of that actor only"
    )


def render_answer(results: Path) -> str:
    """docs/results.md's "The answer": the claims' verdicts at each command, what decided them, what it would take.

    Every sentence is built from :func:`~morfic_cli.report.claims.check_claims` over the run CSVs (and the critic
    study's rows), so no number in it can drift from the tables below it.
    """
    from morfic_cli.report.claims import SHORT, check_claims

    claims = check_claims(*claim_rows(results))
    commands = list(dict.fromkeys(c.command_vx for c in claims))
    lines = [
        f"*Generated by `scripts/results_tables.py` from the run CSVs under [results/](results/) "
        f'({_runs_text(results)}); the rule: docs/report.md "How a verdict is read" (Welch and t-contrast '
        "tests over training seeds, Holm-corrected per claim).*",
        "",
    ]
    paper_note = " (the paper's command)"
    lines.append(
        "**"
        + " ".join(
            f"At {vx:.1f} m/s{paper_note if is_paper_command(vx) else ''}: {verdict_groups(claims, vx)}."
            for vx in commands
        )
        + "**"
    )
    lines += [
        "",
        "| claim | "
        + " | ".join(f"{vx:.1f} m/s" for vx in commands)
        + " | significant comparisons | the undecided comparison closest to an answer (seeds per side for "
        "80 % power) |",
        "|---|" + "---|" * len(commands) + "---|---|",
    ]
    for key in dict.fromkeys(c.key for c in claims):
        mine = [c for c in claims if c.key == key]
        decided = [f"{d} at {c.command_vx:.1f} m/s" for c in mine for d in _decided(c)]
        closest = "; ".join(f"{c.command_vx:.1f} m/s: {_closest(c)}" for c in mine)
        lines.append(
            f"| ({key}) {SHORT.get(key, key)} | "
            + " | ".join(f"**{c.verdict}**" for c in mine)
            + f" | {'; '.join(decided) or 'none'} | {closest} |"
        )
    study = _study_verdicts(results)
    if study:
        lines += [
            "",
            "With the actor fixed ([the critic study](#the-critic-study-the-conditioning-alone-the-actor-"
            f"fixed); {_study_design(results)}): {study}.",
        ]
    lines += [
        "",
        "Every comparison, with its interval, p, Holm p and the seeds it would need: "
        "[the paper's claims](#the-papers-claims). The dated lab notes: "
        "[results-history.md](results-history.md).",
    ]
    return "\n".join(lines) + "\n"


def render_headline(results: Path) -> str:
    """README's "What the experiment found": the verdicts at each command, the significant findings, the cost."""
    from morfic_cli.report.claims import check_claims

    claims = check_claims(*claim_rows(results))
    commands = list(dict.fromkeys(c.command_vx for c in claims))
    decided = [f"{d} at {c.command_vx:.1f} m/s" for c in claims for d in _decided(c)]
    lines = [
        f"- The paper's five claims on the trained policies ({_runs_text(results)}, the `cpu` preset), read "
        "with Holm-corrected Welch and t-contrast tests over seeds: "
        + "; ".join(f"at {vx:.1f} m/s {verdict_groups(claims, vx)}" for vx in commands)
        + ".",
        "- Significant: " + ("; ".join(decided) if decided else "no comparison") + ".",
    ]
    study = _study_verdicts(results)
    if study:
        lines.append(f"- With the actor fixed (`morfic critic-study`; {_study_design(results)}): {study}.")
    lines.append(
        "- Every comparison, the seeds an undecided one would need, and the artifact ids: "
        "[docs/results.md](docs/results.md)."
    )
    return "\n".join(lines) + "\n"


def study_block(results: Path) -> str:
    """The critic study (``critic-study.csv``, ``critic-study.json``): verdicts of (a) and (c), then its tables."""
    from morfic_cli.report.markdown import table_markdown
    from morfic_cli.report.study import study_tables, study_text

    path = results / STUDY_CSV
    if not path.exists():
        return "No critic study under results/ yet (`morfic critic-study`, then copy its critic_study.csv).\n"
    rows = pd.read_csv(path).to_dict("records")
    meta = json.loads((results / STUDY_JSON).read_text())
    out = [study_text(rows, meta["actor"], meta["id"], meta["seconds"]), ""]
    out += [table_markdown(t) + "\n" for t in study_tables(rows)]
    return "\n".join(out).rstrip() + "\n"


# ----------------------------------------------------------------------------------------------- external baselines
EXTERNAL_BEGIN, EXTERNAL_END = "<!-- results-external:begin -->", "<!-- results-external:end -->"
GOAL_BEGIN, GOAL_END = "<!-- results-goal:begin -->", "<!-- results-goal:end -->"
ARCH_ROBOTS = ("aliengo", "mini_cheetah", "anymal_c")
"""The robots on which issue 57 asks what each architecture changes."""
EXTERNAL_COMMANDS = (PAPER_COMMAND, 2.5)
"""The external baselines' tables' commands (m/s): the paper's two; 1.0 m/s is added where a run has rows there."""
STANDS_STILL = "stands still"


def external_table_md(ev: pd.DataFrame, mode: str, command_vx: float) -> list[str]:
    """Methods x the seven robots at one mode and command: the paper's row group (descriptor mode), then ours.

    The paper's rows are :func:`~morfic_cli.report.compare.paper_external_rows` (its released-weights numbers, as
    printed); ours are every variant of ``EXTERNAL_TABLE_VARIANTS`` with :func:`transfer_cell`'s cells, or
    "not trained yet" where no run of it is under results/. Empty when neither group has a row here.
    """
    from morfic_cli.report.compare import (
        EXTERNAL_TABLE_VARIANTS,
        OURS_GROUP,
        PAPER_GROUP,
        method_name,
        paper_external_rows,
    )

    paper_rows = [
        r
        for r in paper_external_rows()
        if r["mode"] == mode and abs(r["command_vx"] - command_vx) < 1e-9 and r["robot"] in ROBOTS
    ]
    rows = frame_at(ev[ev["mode"] == mode], command_vx) if not ev.empty else ev
    if not paper_rows and rows.empty:
        return []
    width = len(ROBOTS)
    lines = [
        "| method | " + " | ".join(robot_label(r) for r in ROBOTS) + " |",
        "|---|" + "---|" * width,
    ]
    if paper_rows:
        lines.append(f"| *{PAPER_GROUP}* |" + " |" * width)
        by = {(r["label"], r["robot"]): r for r in paper_rows}
        for label in dict.fromkeys(r["label"] for r in paper_rows):
            cells = [by.get((label, robot)) for robot in ROBOTS]
            text = [_paper_cell(c["vx"], c["vx_std"], c["survival"]) if c else "-" for c in cells]
            lines.append(f"| {label} (paper) | " + " | ".join(text) + " |")
    lines.append(f"| *{OURS_GROUP}* |" + " |" * width)
    trained = set(ev["variant"]) if not ev.empty else set()
    for v in EXTERNAL_TABLE_VARIANTS:
        if v not in trained:
            lines.append(f"| {method_name(v)} `{v}`: not trained yet |" + " - |" * width)
            continue
        mine = rows[rows["variant"] == v] if not rows.empty else rows
        label = f"{method_name(v)} {_seeds_label(ev, v)}"
        if mine.empty:
            lines.append(f"| {label}: no {mode}-mode rows at {command_vx:.1f} m/s yet |" + " - |" * width)
            continue
        lines.append(f"| {label} | " + " | ".join(transfer_cell(mine[mine["robot"] == r]) for r in ROBOTS) + " |")
    return lines


def _curve_compute(results: Path, variant: str) -> dict[str, Any] | None:
    """Over ``variant``'s runs: seeds, mean transitions, iterations and wall time (s), from ``<run>-curve.csv``."""
    last, seeds = [], []
    for path in sorted(results.glob(f"{variant}-cpu-s*-curve.csv")):
        parsed = parse_run(path.name[: -len("-curve.csv")])
        if parsed is None or parsed[0] != variant:
            continue
        curve = pd.read_csv(path)
        if not curve.empty:
            last.append(curve.iloc[-1])
            seeds.append(parsed[1])
    if not last:
        return None
    frame = pd.DataFrame(last)
    return {
        "n": len(frame),
        "seeds": seeds,
        "transitions": float(frame["env_steps"].mean()),
        "iterations": float(frame["iteration"].mean()),
        "wall_time_s": float(frame["wall_time_s"].mean()),
        "wall_min_s": float(frame["wall_time_s"].min()),
        "wall_max_s": float(frame["wall_time_s"].max()),
    }


def parameter_counts(variant: str) -> tuple[int, int]:
    """(actor, critic) parameters of a stock variant at the ``cpu`` preset.

    ``sum(p.numel())`` of the models its config builds (:func:`~morfic_cli.rl.build.build_models`), as the report's
    compute table counts them.
    """
    from morfic_cli.rl.build import build_models
    from morfic_cli.rl.config import preset_cfg

    actor, critic = build_models(preset_cfg("cpu", variant))
    return sum(p.numel() for p in actor.parameters()), sum(p.numel() for p in critic.parameters())


def external_compute_md(results: Path, params: Any = None) -> list[str]:
    """One line per external-table variant (and Embodiment Scaling): parameters, transitions, wall time here.

    Transitions, iterations and the wall time are the last row of each run's ``<run>-curve.csv``, mean over seeds
    (the range over seeds beside it); ``params(variant)`` gives the parameter counts (default
    :func:`parameter_counts`); the paper's hours are its Table "Training compute"'s
    (:func:`~morfic_cli.report.compare.paper_hours`).
    """
    from morfic_cli.report.compare import EXTERNAL_TABLE_VARIANTS, PAPER_ONLY, method_name, paper_hours
    from morfic_cli.report.tables import _duration, _si

    count = params or parameter_counts
    lines = [
        "| method | actor / critic parameters | runs | transitions | iterations | training wall time here "
        "(mean over seeds) | s / iteration | the paper's GPU-hours |",
        "|---|---:|---|---:|---:|---|---:|---|",
    ]
    for v in EXTERNAL_TABLE_VARIANTS:
        actor, critic = count(v)
        c = _curve_compute(results, v)
        hours = paper_hours(v) or "-"
        if c is None:
            lines.append(
                f"| {method_name(v)} `{v}` | {actor:,} / {critic:,} | not trained yet | - | - | - | - | {hours} |"
            )
            continue
        runs = f"s{c['seeds'][0]}" if c["n"] == 1 else f"n={c['n']}"
        spread = f" ({_duration(c['wall_min_s'])}-{_duration(c['wall_max_s'])})" if c["n"] > 1 else ""
        lines.append(
            f"| {method_name(v)} `{v}` | {actor:,} / {critic:,} | {runs} | "
            f"{_si(c['transitions'])} | {c['iterations']:,.0f} | {_duration(c['wall_time_s'])}{spread} | "
            f"{c['wall_time_s'] / c['iterations']:.2f} | {hours} |"
        )
    for method in PAPER_ONLY:
        lines.append(f"| {method_name(method)} (paper only) | - | - | - | - | - | - | {paper_hours(method) or '-'} |")
    return lines


def _verdicts_text(rows: pd.DataFrame) -> str:
    """``stands still on 6 of 7 robots, falls on 1 (B1)``: a run's (or seeds') validity verdicts over the robots.

    Each robot counts once, under its most common verdict over the seeds.
    """
    per_robot = {
        robot: g["verdict"].astype(str).value_counts().index[0] for robot, g in rows.groupby("robot", sort=False)
    }
    counts: dict[str, list[str]] = {}
    for robot in ROBOTS:
        if robot in per_robot:
            counts.setdefault(per_robot[robot], []).append(robot)
    n = len(per_robot)
    parts: list[str] = []
    for verdict, robots in sorted(counts.items(), key=lambda kv: -len(kv[1])):
        names = f" ({', '.join(robot_label(r) for r in robots)})" if len(robots) <= 2 and len(robots) < n else ""
        parts.append(f"{verdict} on {len(robots)}" + (f" of {n} robots" if not parts else "") + names)
    return ", ".join(parts)


def _difference(effect: Any, p_holm: float, decimals: int) -> str:
    """``+0.31 [+0.12, +0.50] (n 3 vs 3, p 0.021, Holm 0.063)`` with a test; the difference alone without."""
    return effect.text(decimals, p_holm) if effect.has_test else f"{effect.estimate:+.{decimals}f}"


def architecture_text(ev: pd.DataFrame, reference: str = "film") -> list[str]:
    """What each external baseline changes on AlienGo, Mini Cheetah and ANYmal-C against ``reference`` (film).

    Per baseline: its seeds, its validity verdicts over the seven robots at 2.0 m/s (a baseline that stands
    still is said to); then, at 2.0 m/s and 1.0 m/s (where rows exist) and in descriptor and full mode, its v_x and
    S on each of :data:`ARCH_ROBOTS` beside film's and the difference. With two seeds or more on both sides the
    difference has its Welch t interval and p, Holm-corrected over the baseline's comparisons at that command
    (:mod:`morfic_cli.report.stats`, as the claims); with one seed it has none ("one seed: no interval").
    """
    from morfic_cli.report.compare import EXTERNAL_TABLE_VARIANTS, method_name
    from morfic_cli.report.stats import holm, mean_difference

    out = []
    for v in (x for x in EXTERNAL_TABLE_VARIANTS if x != reference):
        mine = ev[ev["variant"] == v] if not ev.empty else ev
        if mine.empty:
            out.append(f"- **{method_name(v)}** (`{v}`): not trained yet (no `{v}-cpu-s*-eval.csv` under results/).")
            continue
        seeds = sorted(set(mine["seed"]))
        one = len(seeds) == 1
        head = f"- **{method_name(v)}** (`{v}`, " + (
            f"s{seeds[0]}; one seed: no interval" if one else f"n={len(seeds)}"
        )
        at2 = frame_at(mine, PAPER_COMMAND)
        modes = [m for m in ("descriptor", "full") if not at2[at2["mode"] == m].empty]
        verdicts = "; ".join(f"{m} mode: {_verdicts_text(at2[at2['mode'] == m])}" for m in modes)
        still = any((at2[at2["mode"] == m]["verdict"].astype(str) == STANDS_STILL).mean() > 0.5 for m in modes)
        lines = [
            head
            + "). "
            + ("It stands still. " if still else "")
            + (f"Its validity verdicts at {PAPER_COMMAND:.1f} m/s: {verdicts}." if verdicts else "")
        ]
        for command in (PAPER_COMMAND, TRAINED_COMMAND):
            base_at, ref_at = frame_at(mine, command), frame_at(ev[ev["variant"] == reference], command)
            if base_at.empty:
                continue
            found = []  # (mode, robot, metric, effect, values)
            missing = []
            for mode in ("descriptor", "full"):
                b, r = base_at[base_at["mode"] == mode], ref_at[ref_at["mode"] == mode]
                if b.empty or r.empty:
                    missing.append((mode, v if b.empty else reference))
                    continue
                for robot in ARCH_ROBOTS:
                    bb, rr = b[b["robot"] == robot], r[r["robot"] == robot]
                    if bb.empty or rr.empty:
                        continue
                    for metric in ("vx_mean", "survival"):
                        found.append((mode, robot, metric, mean_difference(bb[metric], rr[metric]), (bb, rr)))
            adjusted = holm([f[3].p for f in found])
            for mode in ("descriptor", "full"):
                parts = []
                for robot in ARCH_ROBOTS:
                    cells = [(f, p) for f, p in zip(found, adjusted, strict=True) if f[0] == mode and f[1] == robot]
                    if not cells:
                        continue
                    text = []
                    for (_, _, metric, effect, (bb, rr)), p in cells:
                        name, dec = ("v_x", 2) if metric == "vx_mean" else ("S", 3)
                        text.append(
                            f"{name} {bb[metric].mean():.{dec}f} vs {rr[metric].mean():.{dec}f}: "
                            f"{_difference(effect, p, dec)}"
                        )
                    stood = (cells[0][0][4][0]["verdict"].astype(str) == STANDS_STILL).mean() > 0.5
                    parts.append(f"{robot_label(robot)} " + ", ".join(text) + (" (stands still)" if stood else ""))
                if parts:
                    lines.append(
                        f"  - {command:.1f} m/s, {mode} mode, against `{reference}`: " + "; ".join(parts) + "."
                    )
            for mode, whose in missing:
                lines.append(f"  - {command:.1f} m/s, {mode} mode: no rows of `{whose}` yet.")
        out += lines
    return out


def external_block(results: Path, params: Any = None) -> str:
    """docs/results.md's "External baselines in our pipeline": tables, compute, and what each architecture changes."""
    from morfic_cli.report.compare import EXTERNAL_TABLE_VARIANTS, PAPER_ONLY

    ev = load_evals(results)
    ev = ev[ev["variant"].isin(EXTERNAL_TABLE_VARIANTS)] if not ev.empty else ev
    out = [
        "*Generated by `scripts/results_tables.py` from the run CSVs under [results/](results/) and the paper's "
        "numbers (`morfic_cli/report/paper.py`).* The paper's rows are its released-weights numbers, each method "
        "in its own simulator with its own robots, rewards and commands (at 2.5 m/s its speed is v_x^max); ours "
        "re-implement each approach in morfic's pipeline at MorFiC-F's budget (docs/training.md, \"External "
        "baselines\"). Ours: one seed as the run's v_x ± σ / S (verdict), several as mean ± std over seeds. "
        + " ".join(PAPER_ONLY.values()),
        "",
    ]
    commands = list(EXTERNAL_COMMANDS)
    if not ev.empty and not frame_at(ev, TRAINED_COMMAND).empty:
        commands.append(TRAINED_COMMAND)
    for command in commands:
        for mode in ("descriptor", "full"):
            table = external_table_md(ev, mode, command)
            if table:
                where = (
                    "the target descriptor on the Go2 template" if mode == "descriptor" else "the targets' own models"
                )
                out += [f"### {mode.capitalize()} mode, {command:.1f} m/s ({where})", "", *table, ""]
    out += [
        "### Compute",
        "",
        *external_compute_md(results, params),
        "",
        "### What each architecture changes on AlienGo, Mini Cheetah and ANYmal-C",
        "",
        *architecture_text(_load_all(results, ("eval", *EXTRA_EVALS, *goal_kinds()))),
        "",
        "### What ended the failed episodes on AlienGo, Mini Cheetah and ANYmal-C",
        "",
        *ended_by_md(load_terminations(results), EXTERNAL_TABLE_VARIANTS, [*EXTERNAL_COMMANDS, TRAINED_COMMAND]),
    ]
    return "\n".join(out).rstrip() + "\n"


def ended_by_md(
    ended: pd.DataFrame, variants: tuple[str, ...], commands: list[float], robots: tuple[str, ...] = ARCH_ROBOTS
) -> list[str]:
    """Methods x modes x commands against ``robots``: what ended the failed episodes (:func:`load_terminations`).

    One row per variant, mode and command with counts on one of ``robots``; each cell the terms that ended envs,
    summed over the seeds the row names (:func:`~morfic_cli.report.goal.ended_by_text`). One line
    (:data:`NO_COUNTS`) where none exist.
    """
    from morfic_cli.report.compare import method_name
    from morfic_cli.report.goal import ended_by_counts, ended_by_text

    ended = ended[ended["variant"].isin(list(variants))] if not ended.empty else ended
    if ended.empty:
        return [NO_COUNTS[0].upper() + NO_COUNTS[1:]]
    lines = ended.to_dict("records")
    out = [
        'The envs each termination term ended, summed over the seeds named (docs/eval.md, "Termination counts"); '
        "an env counts under every term it tripped on its fatal step. `none`: no env failed; `-`: no counts.",
        "",
        "| method, mode, command | " + " | ".join(robot_label(r) for r in robots) + " |",
        "|---|" + "---:|" * len(robots),
    ]
    for v in variants:
        mine = [r for r in lines if r["variant"] == v and r["robot"] in robots]
        for command in commands:
            for mode in ("descriptor", "full"):
                counts = ended_by_counts(mine, mode, command, lambda r: str(r["variant"]))
                if not counts:
                    continue
                at = {int(r["seed"]) for r in mine if r["mode"] == mode and abs(r["command_vx"] - command) < 1e-9}
                seeds = ", ".join(f"s{s}" for s in sorted(at))
                cells = [ended_by_text(counts[(v, r)][0]) if (v, r) in counts else "-" for r in robots]
                out.append(
                    f"| {method_name(v)} `{v}` ({seeds}), {mode}, {command:.1f} m/s | " + " | ".join(cells) + " |"
                )
    return out


# ----------------------------------------------------------------------------------------------- issue 58's goal
def goal_block(results: Path) -> str:
    """docs/results.md's "One policy for seven robots": film and each actuation variant against issue 58's goal.

    The goal's bars are :data:`morfic_cli.report.goal.GOAL`'s; the tables :func:`~morfic_cli.report.goal.goal_table`'s
    (full mode at each goal command, then descriptor and actuation-matched mode beside them); per column the robots
    meeting the goal at both commands (k of 7) and, for an actuation variant, Go2, Go1 and A1 against film; what
    ended the failed episodes in full mode (:func:`~morfic_cli.report.goal.ended_by_table`, from
    :func:`load_terminations`), or :data:`NO_COUNTS` where no eval recorded them. Besides the runs' own evals it
    reads the goal's extra ones (:func:`goal_kinds`: film's full mode at 1.0 m/s).
    """
    from morfic_cli.report.goal import (
        GOAL,
        ended_by_table,
        goal_eval_name,
        goal_evals,
        goal_table,
        reference_effects,
        reference_text,
        robots_meeting,
    )
    from morfic_cli.report.markdown import table_markdown
    from morfic_cli.rl.variants import table_variants

    ev = _load_all(results, ("eval", *EXTRA_EVALS, *goal_kinds()))
    present = set(ev["variant"]) if not ev.empty else set()
    act = [v for v in table_variants("actuation") if v in present]
    rows = ev[ev["variant"].isin([GOAL.reference, *act])].to_dict("records") if not ev.empty else []
    frame = pd.DataFrame(rows)
    label = {v: _seeds_label(frame, v) for v in dict.fromkeys(str(r["variant"]) for r in rows)}
    if GOAL.reference in label:
        label[GOAL.reference] = label[GOAL.reference].replace("` (", "` (today, ", 1)
    columns = [(v, label[v]) for v in (GOAL.reference, *act) if v in label]

    def column(r: Any) -> str:
        return str(r["variant"])

    out = [
        "*Generated by `scripts/results_tables.py` from the run CSVs under [results/](results/); the goal's bars "
        "are `GOAL` in `morfic_cli/report/goal.py`, the one place they live.* The goal (issue 58): "
        f"{GOAL.text()}.",
        "",
    ]
    extra = goal_evals(GOAL.reference)
    if extra:
        at = " and ".join(f"{c:.1f}" for c in extra)
        files = ", ".join(f"`<run>-{goal_eval_name(c)}.csv`" for c in extra)
        how = "; ".join(f"`morfic eval runs/RUN --command-vx {c:.1f} --mode {GOAL.mode}`" for c in extra)
        out += [
            f"`{GOAL.reference}`'s own evals have no {GOAL.mode}-mode rows at {at} m/s (their configs, and so the "
            f"shipped ids, stay); its {GOAL.mode}-mode rows there come from one more eval of each run, {files}, "
            f"made and copied by `scripts/experiment_tables.py RUN --goal-evals-only` ({how}).",
            "",
        ]
    if not act:
        out += [
            "No run of the actuation variants yet: `morfic train --variant film-act --preset cpu` (likewise "
            '`ppo-act`; docs/training.md, "Actuation variants"). Below, today\'s film against the goal.',
            "",
        ]
    for mode in (GOAL.mode, "descriptor", "actuation-matched"):
        tables = {c: goal_table(rows, mode, c, columns, column) for c in GOAL.commands}
        if mode != GOAL.mode and all(t is None for t in tables.values()):
            out += [f"**{mode.capitalize()} mode:** no rows of these runs yet.", ""]
            continue
        for command, table in tables.items():
            if table is not None:
                out += [table_markdown(table)]
            elif mode == GOAL.mode:
                have = sorted({str(r["mode"]) for r in rows if abs(float(r["command_vx"]) - command) < 1e-9})
                out += [
                    f"**{mode.capitalize()} mode at {command:.1f} m/s:** no rows yet"
                    + (f" (at {command:.1f} m/s these runs have {' and '.join(have)} mode only so far)" if have else "")
                    + ".",
                    "",
                ]
    ended = _load_all(results, (*TERMINATION_KINDS, *goal_kinds("terminations")))
    lines = ended[ended["variant"].isin([GOAL.reference, *act])].to_dict("records") if not ended.empty else []
    ended_tables = {c: ended_by_table(lines, rows, GOAL.mode, c, columns, column) for c in GOAL.commands}
    if not any(ended_tables.values()):
        out += [f"**What ended the failed episodes:** {NO_COUNTS}", ""]
    for command, table in ended_tables.items():
        if table is not None:
            out += [table_markdown(table)]
        elif any(ended_tables.values()):
            out += [f"**What ended the failed episodes at {command:.1f} m/s:** no counts in {GOAL.mode} mode yet.", ""]
    for v, head in columns:
        met, missing = robots_meeting(rows, v, column)
        line = f"- {head}: robots meeting the goal (both commands, every seed): **{len(met)} of {len(ROBOTS)}**"
        line += f" ({', '.join(robot_label(r) for r in met)})" if met else ""
        if missing:
            line += f"; no {GOAL.mode}-mode rows at {' and '.join(f'{c:.1f}' for c in missing)} m/s yet"
        vs = reference_text(reference_effects(rows, v, column)) if v != GOAL.reference else ""
        out.append(line + (f". Go2, Go1 and A1 against today's film: {vs}" if vs else "") + ".")
    return "\n".join(out).rstrip() + "\n"


# ----------------------------------------------------------------------------------------------- figures
def write_figures(results: Path, out: Path) -> list[Path]:
    """Write the figures into ``out``; return their paths.

    ``results-ev.png`` (EV per variant and robot, seeds pooled), ``results-distance.png`` (v_x against d) and
    ``results-curves.png`` (training curves).
    """
    from morfic_cli.diagnostics.figures import ev_figure
    from morfic_cli.report.figures import distance_figure
    from morfic_cli.report.paper import ROBOT_LABELS

    out.mkdir(parents=True, exist_ok=True)
    written = []
    cal = load(results, "calibration")
    if not cal.empty:
        pooled = cal.groupby(["variant", "robot"], sort=False).agg(ev=("ev", "mean"), n=("seed", "nunique"))
        rows = [
            {
                "run": f"{v}, {n} seed{'s' if n > 1 else ''}",
                "variant": v,
                "robot": ROBOT_LABELS.get(robot, robot),
                "ev": float(e),
            }
            for (v, robot), e, n in zip(pooled.index, pooled["ev"], pooled["n"], strict=True)
        ]
        png, _ = ev_figure(rows)
        (out / "results-ev.png").write_bytes(png)
        written.append(out / "results-ev.png")
    curves = {
        p.name[: -len("-curve.csv")]: pd.read_csv(p).to_dict("records")
        for p in sorted(results.glob("*-cpu-s*-curve.csv"))
    }
    if curves:
        from morfic_cli.report.figures import curves_figure

        png, _ = curves_figure(curves, {name: parse_run(name)[0] for name in curves})
        (out / "results-curves.png").write_bytes(png)
        written.append(out / "results-curves.png")
    ev = load(results, "eval")
    if not ev.empty:
        sel = ev[ev["mode"] == "descriptor"]
        pooled = (
            sel.groupby(["variant", "robot", "mode", "command_vx"], sort=False)
            .agg(vx=("vx_mean", "mean"), vx_std=("vx_std", "mean"), d=("d", "first"))
            .reset_index()
        )
        rows = [{**r, "preset": "cpu"} for r in pooled.to_dict("records")]
        png, _ = distance_figure(rows, command_vx=2.0, with_paper=True)
        (out / "results-distance.png").write_bytes(png)
        written.append(out / "results-distance.png")
    return written


def write_between_markers(path: Path, block: str, begin: str = BEGIN, end: str = END) -> None:
    """Replace the text between ``begin`` and ``end`` in ``path`` with ``block``."""
    text = path.read_text()
    if begin not in text or end not in text:
        raise SystemExit(f"Error: {path} has no {begin} ... {end} markers; add them where the block goes.")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{begin}\n{block}{end}{tail}")


ONLY_BLOCKS: dict[str, tuple[str, str, Callable[[Path], str]]] = {
    "answer": (ANSWER_BEGIN, ANSWER_END, render_answer),
    "study": (STUDY_BEGIN, STUDY_END, study_block),
    "external": (EXTERNAL_BEGIN, EXTERNAL_END, external_block),
    "goal": (GOAL_BEGIN, GOAL_END, goal_block),
}
"""The blocks ``--only`` writes alone, each (begin marker, end marker, what renders it from ``--results``):
``--write docs/results.md --only goal`` rewrites issue 58's goal section and nothing else of the file."""


def main(argv: list[str] | None = None) -> int:
    """Print the tables and claims, or write them into ``--write``'s marked blocks (``--only``: just those); 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", type=Path, default=Path("docs/results"))
    p.add_argument("--write", type=Path, default=None, help="markdown file whose marked blocks to replace")
    p.add_argument("--figures", type=Path, default=None, help="folder for the results-*.png figures")
    p.add_argument("--bundles", type=Path, default=Path("artifacts/bundles"), help="the shipped bundles' folder")
    p.add_argument("--readme", type=Path, default=None, help="README whose headline block to replace")
    p.add_argument(
        "--only",
        choices=sorted(ONLY_BLOCKS),
        action="append",
        default=None,
        help="with --write: replace only this marked block (repeatable), leave the rest of FILE as it is",
    )
    args = p.parse_args(argv)
    if args.only:
        if args.write is None or args.readme is not None or args.figures is not None:
            p.error("--only goes with --write alone (no --readme or --figures)")
        for name in dict.fromkeys(args.only):
            begin, end, render_block = ONLY_BLOCKS[name]
            write_between_markers(args.write, render_block(args.results), begin, end)
            print(f"{args.write}: {name} block written")
        return 0
    block, claims = render(args.results), render_claims(args.results)
    if args.write is None:
        tables = (walk_table(args.results), bundle_table(args.bundles))
        sys.stdout.write(block + "\n" + claims + "\n" + "".join("\n".join(t) + "\n" for t in tables))
    else:
        write_between_markers(args.write, block)
        write_between_markers(args.write, claims, CLAIMS_BEGIN, CLAIMS_END)
        write_between_markers(args.write, "\n".join(walk_table(args.results)) + "\n", WALK_BEGIN, WALK_END)
        write_between_markers(args.write, "\n".join(bundle_table(args.bundles)) + "\n", BUNDLES_BEGIN, BUNDLES_END)
        if STUDY_BEGIN in args.write.read_text():
            write_between_markers(args.write, study_block(args.results), STUDY_BEGIN, STUDY_END)
        if ANSWER_BEGIN in args.write.read_text():
            write_between_markers(args.write, render_answer(args.results), ANSWER_BEGIN, ANSWER_END)
        if EXTERNAL_BEGIN in args.write.read_text():
            write_between_markers(args.write, external_block(args.results), EXTERNAL_BEGIN, EXTERNAL_END)
        if GOAL_BEGIN in args.write.read_text():
            write_between_markers(args.write, goal_block(args.results), GOAL_BEGIN, GOAL_END)
    if args.readme is not None:
        write_between_markers(args.readme, render_headline(args.results), HEADLINE_BEGIN, HEADLINE_END)
        print(f"{args.readme}: headline written")
        print(f"{args.write}: tables and claims of {load(args.results, 'eval')['run'].nunique()} run(s) written")
    if args.figures is not None:
        for path in write_figures(args.results, args.figures):
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
