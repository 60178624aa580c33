"""``morfic compare-baselines``: variants side by side, mean ± std over seeds, optionally beside the paper."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, QuietOpt, StoreOpt
from morfic_cli.cli._render import Column, emit_rows, info

_TITLES = {
    "transfer": "zero-shot transfer (mean over seeds; σ over envs pooled)",
    "calibration": "critic calibration (mean over seeds)",
    "fixed_rollout": "fixed-rollout diagnostic (critic variants on one frozen actor's rollouts)",
    "compute": "training compute (parameters: actor / critic, sum(p.numel()))",
    "verdicts": "the paper's claims: each primary comparison, Holm-corrected (docs/report.md)",
}


def _n(v, d: int = 3) -> str:
    return "-" if v is None or v != v else f"{v:.{d}f}"


def _pm(key: str, d: int = 3):
    return Column(key, key, fmt=lambda v: _n(v, d), justify="right")


def _seed_columns() -> list[Column]:
    """The transfer table's registered metric columns over seeds that have a header (docs/eval.md)."""
    from morfic_cli.evaluation.metric_terms import seed_columns

    def fmt(spec: str):
        return lambda v: "-" if v is None or v != v else format(v, spec)

    return [Column(c.name, c.header, fmt=fmt(c.fmt), justify="right") for c in seed_columns() if c.header]


def _columns(table: str, with_paper: bool) -> list[Column]:
    head = [Column("preset", "preset"), Column("variant", "variant")]
    command = Column("command_vx", "vx_cmd", fmt=lambda v: f"{v:g}", justify="right")
    if table == "verdicts":
        return [
            Column("claim", "claim"),
            command,
            Column("verdict", "verdict"),
            Column("unit", "on"),
            Column("comparison", "comparison"),
            Column("cell", "effect [95 %]", justify="right"),
            Column("p_holm", "Holm p", fmt=lambda v: _n(v, 4), justify="right"),
            Column("outcome", "outcome"),
            Column(
                "seeds_needed",
                "seeds for 80 %",
                fmt=lambda v: "-" if v is None else (f">{v - 1}" if v > 1000 else str(v)),
                justify="right",
            ),
        ]
    if table == "transfer":
        cols = [
            *head,
            Column("robot", "robot"),
            Column("mode", "mode"),
            command,
            Column("n_seeds", "seeds", justify="right"),
            Column("cell", "v_x ± σ / S", justify="right"),
            *_seed_columns(),
        ]
        if with_paper:
            cols += [
                Column("paper_quantity", "paper qty"),
                Column("paper_vx", "paper v", fmt=lambda v: _n(v, 3), justify="right"),
                Column("paper_vx_std", "paper σ", fmt=lambda v: _n(v, 3), justify="right"),
                Column("paper_survival", "paper S", fmt=lambda v: _n(v, 3), justify="right"),
            ]
        return cols
    if table == "calibration":
        cols = [
            *head,
            Column("robot", "robot"),
            command,
            Column("n_seeds", "seeds", justify="right"),
            _pm("ev"),
            Column("cell", "|NVB|/NVE/ASA", justify="right"),
            _pm("flip"),
            _pm("cos_grad"),
        ]
        if with_paper:
            cols += [
                Column("paper_abs_nvb", "paper |NVB|", fmt=_n, justify="right"),
                Column("paper_nve", "paper NVE", fmt=_n, justify="right"),
                Column("paper_asa", "paper ASA", fmt=_n, justify="right"),
            ]
        return cols
    if table == "fixed_rollout":
        cols = [
            *head,
            Column("robot", "robot"),
            command,
            Column("n_seeds", "critics", justify="right"),
            _pm("flip"),
            _pm("cos_grad"),
        ]
        if with_paper:
            cols += [
                Column("paper_flip", "paper Flip", fmt=_n, justify="right"),
                Column("paper_cos_grad", "paper Cos.", fmt=_n, justify="right"),
            ]
        return cols
    cols = [
        *head,
        Column("n_seeds", "seeds", justify="right"),
        Column("transitions", "transitions", fmt=lambda v: f"{v:,.0f}", justify="right"),
        Column("iterations", "iters", fmt=lambda v: f"{v:,.0f}", justify="right"),
        Column("s_per_iteration", "s/iter", fmt=lambda v: _n(v, 2), justify="right"),
        Column("device_hours", "device-h", fmt=lambda v: _n(v, 4), justify="right"),
        Column("device_hours_400m", "h@400M", fmt=lambda v: _n(v, 1), justify="right"),
        Column("device"),
        Column("actor_params", "params", fmt=lambda v: "-" if v is None else f"{v:,}", justify="right"),
        Column("critic_params", "/ critic", fmt=lambda v: "-" if v is None else f"{v:,}", justify="right"),
    ]
    if with_paper:
        cols += [
            Column("paper_s_per_iteration", "paper s/iter"),
            Column("paper_gpu_hours", "paper GPU-h"),
            Column("paper_gpu_hours_400m", "paper GPU-h@400M"),
        ]
    return cols


def _external_tables(rows: list[dict]) -> list[tuple[str, list[dict], list[Column]]]:
    """The ``external`` rows as the paper lays them out: per (mode, command) a table of methods x robots.

    Rows are the paper's group then ours (``group``), each cell ``v ± σ / S``.
    """
    from morfic_cli.report.compare import OURS_GROUP, PAPER_GROUP
    from morfic_cli.report.paper import ROBOT_LABELS, ROBOTS

    out = []
    for mode, command in sorted(
        {(r["mode"], r["command_vx"]) for r in rows}, key=lambda k: (k[0] != "descriptor", k[1])
    ):
        sel = [r for r in rows if (r["mode"], r["command_vx"]) == (mode, command)]
        robots = [*ROBOTS, *sorted({r["robot"] for r in sel} - set(ROBOTS))]
        wide: dict[tuple, dict] = {}
        for r in sel:
            key = (r["group"] != "paper", r["preset"] or "", r["label"])
            seeds = "-" if r["n_seeds"] is None else str(r["n_seeds"])
            row = wide.setdefault(
                key,
                {
                    "group": "paper" if r["group"] == "paper" else "ours",
                    "preset": r["preset"] or "-",
                    "label": r["label"],
                    "n_seeds": seeds,
                },
            )
            row[r["robot"]] = r["cell"]
        cols = [
            Column("group", "group"),
            Column("preset", "preset"),
            Column("label", "method"),
            Column("n_seeds", "seeds", justify="right"),
            *(
                Column(robot, ROBOT_LABELS.get(robot, robot), fmt=lambda v: v or "-", justify="right")
                for robot in robots
            ),
        ]
        title = (
            f"external baselines at {command:g} m/s, {mode} mode: {PAPER_GROUP[0].lower()}{PAPER_GROUP[1:]}, "
            f"then {OURS_GROUP.lower()}"
        )
        out.append((title, [wide[k] for k in sorted(wide, key=lambda k: k[:2])], cols))
    return out


def compare_baselines(
    runs: Annotated[
        list[str] | None,
        typer.Argument(help="Run refs (runs/film-cpu-s0) or checkpoint ids; none: every run in the store."),
    ] = None,
    with_paper: Annotated[
        bool, typer.Option("--with-paper", help="Add the paper's published numbers in paper_* columns.")
    ] = False,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Side-by-side tables over variants and seeds (mean ± std over seeds), from the store only.

    Runs are grouped by preset and variant; for each robot the stored evaluations (zero-shot transfer), critic
    diagnoses and fixed-rollout diagnoses of their checkpoints are aggregated over seeds, plus training compute.
    --with-paper adds the paper's numbers for the same variant and robot (paper_* columns; empty where the paper
    prints none). The external baselines (bot, urma, genloco) have their own table beside the paper's rows for
    them (table external: when one of them is among the runs, or with --with-paper). Last come the paper's claims'
    comparisons (Welch / t-contrast, Holm-corrected, with the seeds each undecided one would need). json/csv
    print every table's rows in one list, with a "table" column. The comparison is stored as a table artifact
    (ref tables/compare-baselines).

    Example: morfic compare-baselines runs/film-cpu-s0 runs/ppo-cpu-s0 --with-paper --format csv
    """
    from morfic_cli.report.compare import (
        PAPER_ONLY,
        TABLE_ORDER,
        compare_tables,
        external_note,
        flat_rows,
        store_comparison,
    )
    from morfic_cli.report.gather import gather, resolve_runs
    from morfic_cli.store import Store

    st = Store(store)
    found = resolve_runs(st, runs)
    data = gather(st, found, curves=False)
    tables = compare_tables(data, with_paper=with_paper)
    written, reused = store_comparison(st, data, tables, with_paper)
    if not quiet:
        info(
            f"{'found' if reused else 'stored'} {written.ref}@{written.version} ({written.id[:12]}): "
            f"{len(found)} runs, {', '.join(f'{k} {len(v)}' for k, v in tables.items()) or 'no results yet'}"
        )
    if fmt != OutputFormat.table:
        emit_rows(flat_rows(tables), fmt)
        return
    if not tables:
        info("no evaluations or diagnoses of these runs in the store yet; run `morfic eval` / `morfic diagnose`.")
    for name in TABLE_ORDER:
        if name == "external" and name in tables:
            for title, rows, columns in _external_tables(tables[name]):
                emit_rows(rows, fmt, columns=columns, title=title)
            if not any(r["group"] == "ours" for r in tables[name]):
                info(external_note(False))
            info(PAPER_ONLY["embodiment-scaling"])
        elif name in tables:
            emit_rows(tables[name], fmt, columns=_columns(name, with_paper), title=_TITLES[name])
