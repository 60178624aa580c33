"""``morfic diagnose``: critic calibration per run and robot, and the fixed-rollout causality analysis."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    EnvsOpt,
    EvalMode,
    FormatOpt,
    ModeOpt,
    OutputFormat,
    QuietOpt,
    RobotsOpt,
    SeedOpt,
    StoreOpt,
    TrustOpt,
)
from morfic_cli.cli._progress import StepBar
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.cli.trust import note_skipped
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args


def _num(v: float | None) -> str:
    return "-" if v is None or v != v else f"{v:.3f}"


CALIBRATION_TABLE = [
    Column("run", "run"),
    Column("variant", "variant", drop=3),  # the run's name says it (runs/<variant>-<preset>-s<seed>)
    Column("robot", "robot"),
    Column("d", "d", fmt=_num, justify="right", drop=1),
    Column("ev", "EV", fmt=_num, justify="right"),
    Column("cell", "|NVB|/NVE/ASA", justify="right"),
    Column("flip", "Flip", fmt=_num, justify="right"),
    Column("cos_grad", "CosGrad", fmt=_num, justify="right"),
    Column("n_samples", "|I_eps|", justify="right", drop=2),
]
"""The calibration table's columns: at 80 columns variant, |I_eps| and d are left out (the caption says so) and a long
run name folds (:func:`~morfic_cli.cli._render.fit_columns`), so the metrics keep their width."""


def diagnose(
    runs: Annotated[
        list[str] | None,
        typer.Argument(help="Run refs (runs/film-cpu-s0 = its latest checkpoint), ref@N or checkpoint ids."),
    ] = None,
    robots: RobotsOpt = "all",
    fixed_rollout: Annotated[
        str | None,
        typer.Option(
            "--fixed-rollout",
            help="Target robot of the fixed-rollout analysis: one frozen actor, "
            "every critic scored on its rollout (Flip, Cos vs Monte Carlo).",
        ),
    ] = None,
    actor: Annotated[
        str | None, typer.Option("--actor", help="Actor run for --fixed-rollout (default: the newest film run).")
    ] = None,
    critics: Annotated[
        str | None,
        typer.Option(
            "--critics",
            help="Comma-separated critic runs for --fixed-rollout (default: the newest run of each variant).",
        ),
    ] = None,
    mode: ModeOpt = EvalMode.descriptor,
    command_vx: Annotated[float, typer.Option("--command-vx", help="Forward command in m/s.")] = 2.0,
    envs: EnvsOpt = 64,
    steps: Annotated[
        int,
        typer.Option(
            "--steps",
            min=1,
            help="Policy steps per rollout (50 per second); must exceed the horizon "
            "H_eps the returns need (299 at gamma 0.99, --trunc-eps 0.05).",
        ),
    ] = 800,
    trunc_eps: Annotated[
        float,
        typer.Option(
            "--trunc-eps",
            help="I_eps is the window t <= T - H_eps with gamma^H_eps <= this: a counted "
            "return misses at most this fraction of the return scale.",
        ),
    ] = 0.05,
    seed: SeedOpt = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", "-o", help="Also write the table CSV (calibration.csv or fixed_rollout.csv) into this directory."
        ),
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Critic calibration (EV, |NVB|/NVE/ASA, Flip, CosGrad) per run and robot, or the fixed-rollout analysis.

    Each run's actor collects rollouts on each robot (actions sampled from the policy, stored as MCAP and reused
    when asked again); its critic is scored against discounted Monte-Carlo returns (gamma of the run) on the
    samples of the fixed window t <= T - H_eps of every env (I_eps). CosGrad is the cosine between the PPO actor
    gradients with the critic's advantages G - V and with the Monte-Carlo ones G - mean(G). Stores the table and
    an EV figure (ref diagnoses/calibration). With --fixed-rollout ROBOT, one actor is frozen, its rollout
    collected once, and every critic scored on exactly those samples (ref diagnoses/fixed-rollout/ROBOT).

    Example: morfic diagnose runs/film-cpu-s0 runs/ppo-cpu-s0 --robots aliengo,mini_cheetah
    Example: morfic diagnose --fixed-rollout aliengo --actor runs/film-cpu-s0 --critics runs/film-cpu-s0,runs/ppo-cpu-s0
    """
    check_args(
        store=store,
        out_dir=out,
        seed=seed,
        envs=envs,
        steps=steps,
        command_vx=str(command_vx),
        specs=runs,
        trust=trust_variant,
    )
    from morfic_cli.diagnostics.samples import DiagnoseCfg
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.store import Store

    if not command_vx == command_vx:  # NaN
        raise MorficError("--command-vx must be a number in m/s, e.g. 2.0.")
    st = Store(store)
    settings = functools.partial(
        DiagnoseCfg, mode=mode.value, command_vx=command_vx, num_envs=envs, steps=steps, seed=seed, trunc_eps=trunc_eps
    )
    if fixed_rollout is None:
        if actor is not None or critics is not None:
            raise MorficError(
                "--actor and --critics belong to --fixed-rollout ROBOT; without it, name the runs to "
                "diagnose: morfic diagnose runs/film-cpu-s0 runs/ppo-cpu-s0."
            )
        if not runs:
            raise MorficError(
                "name the runs to diagnose (e.g. morfic diagnose runs/film-cpu-s0), or give "
                "--fixed-rollout ROBOT; see `morfic store ls --kind checkpoint` for runs."
            )
        if len(set(runs)) != len(runs):
            raise MorficError(f"a run is named twice: {' '.join(runs)}; give each run once.")
        names = parse_robot_list(robots)
        if not names:
            raise MorficError("--robots is empty; give 'all' or names such as go1,a1 (see `morfic robots ls`).")
        cfg = settings(robots=tuple(names))
        _calibration(st, list(runs), cfg, out, fmt, quiet)
    else:
        if runs:
            raise MorficError(
                "--fixed-rollout takes its critics from --critics, not as arguments: "
                f"morfic diagnose --fixed-rollout {fixed_rollout} --critics {','.join(runs)}."
            )
        targets = [] if fixed_rollout.strip().lower() == "all" else parse_robot_list(fixed_rollout)
        if len(targets) != 1:
            raise MorficError(f"--fixed-rollout takes one robot, got '{fixed_rollout}'; e.g. --fixed-rollout aliengo.")
        robot = targets[0]
        critic_specs = [c.strip() for c in critics.split(",") if c.strip()] if critics is not None else None
        if critics is not None and not critic_specs:
            raise MorficError(
                "--critics is empty; give runs such as runs/film-cpu-s0,runs/ppo-cpu-s0, or leave it out."
            )
        cfg = settings(robots=(robot,))
        _fixed(st, robot, actor, critic_specs, cfg, out, fmt, quiet)


def _calibration(st, specs: list[str], cfg, out: Path | None, fmt: OutputFormat, quiet: bool) -> None:
    from morfic_cli.diagnostics.calibration import CALIBRATION_COLUMNS, check_horizon, diagnose_runs
    from morfic_cli.rl.load import load_trained

    trained = [load_trained(st, s) for s in specs]  # bad refs fail here, before the progress bar starts
    for t in trained:
        check_horizon(t.cfg.ppo.gamma, cfg)
    with StepBar("diagnose", len(specs) * len(cfg.robots) * cfg.steps, quiet) as bar:
        result = diagnose_runs(st, specs, cfg, trained=trained, on_rollout_start=_describe(bar), on_step=bar.step)
    _write_out(out, "calibration.csv", result.rows, CALIBRATION_COLUMNS)
    if not quiet:
        reused = sum(r["reused"] for r in result.rows)
        info(
            f"stored {result.ref}@{result.version} ({result.id[:12]}): {len(result.rows)} rows, EV figure ev.png/"
            f"ev.pdf; {len(result.rows) - reused} rollouts collected, {reused} reused"
        )
    emit_rows(
        result.rows,
        fmt,
        columns=CALIBRATION_TABLE,
        title="critic calibration",
        caption="higher is better: EV, ASA, CosGrad; lower: |NVB|, NVE, Flip (over I_eps, vs Monte-Carlo G)",
    )


def _fixed(
    st, robot: str, actor: str | None, critics: list[str] | None, cfg, out: Path | None, fmt: OutputFormat, quiet: bool
) -> None:
    from morfic_cli.diagnostics.fixed_rollout import FIXED_ROLLOUT_COLUMNS, fixed_rollout, load_models

    # named bad refs and incompatible critics fail; the defaults leave them out with a note
    models = load_models(st, actor, critics, cfg, on_skip=note_skipped)
    with StepBar("diagnose", cfg.steps, quiet) as bar:
        result = fixed_rollout(st, robot, models, cfg, on_rollout_start=_describe(bar), on_step=bar.step)
    _write_out(out, "fixed_rollout.csv", result.rows, FIXED_ROLLOUT_COLUMNS)
    if not quiet:
        how = "reused" if result.rows[0]["reused"] else "collected"
        info(
            f"stored {result.ref}@{result.version} ({result.id[:12]}): actor {result.rows[0]['actor']}, "
            f"{len(result.rows) - 1} critics, rollout {how}"
        )
    emit_rows(
        result.rows,
        fmt,
        columns=[
            Column("critic", "critic"),
            Column("variant", "variant", drop=1),
            Column("flip", "Flip", fmt=_num, justify="right"),
            Column("cos_grad", "Cos.", fmt=_num, justify="right"),
            Column("asa", "ASA", fmt=_num, justify="right"),
            Column("ev", "EV", fmt=_num, justify="right"),
        ],
        title=f"fixed-rollout diagnostic on {robot} (actor {result.rows[0]['actor']})",
        caption="Flip: sign-flip rate vs the Monte-Carlo advantage (lower is better); Cos.: actor-gradient cosine "
        "vs MC (higher is better)",
    )


def _write_out(out: Path | None, name: str, rows: list[dict], columns: tuple[str, ...]) -> None:
    """``--out DIR``: the table as ``DIR/name`` (the directory is created)."""
    if out is None:
        return
    from morfic_cli.recording.tables import rows_to_csv

    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_bytes(rows_to_csv(rows, columns))


def _describe(bar: StepBar):
    """on_rollout_start(run, robot) -> the bar's description."""
    return lambda run, robot: bar.describe(f"{run} on {robot}")
