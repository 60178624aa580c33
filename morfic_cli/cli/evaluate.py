"""``morfic eval``: the paper's zero-shot protocol on target robots."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    EvalModes,
    FormatOpt,
    OutputFormat,
    QuietOpt,
    RobotsOpt,
    SeedOpt,
    StoreOpt,
    TrustOpt,
)
from morfic_cli.cli._progress import StepBar
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args

if TYPE_CHECKING:
    from morfic_cli.evaluation.metric_terms import MetricTerm


def evaluate(
    run: Annotated[
        str, typer.Argument(help="Run ref (runs/film-cpu-s0 = its latest checkpoint), ref@N or checkpoint id.")
    ],
    robots: RobotsOpt = "all",
    command_vx: Annotated[
        str | None,
        typer.Option(
            "--command-vx",
            help="Forward command(s) in m/s, e.g. 2.0,2.5. Default 2.0; with --training-conditions it is 1.0.",
        ),
    ] = None,
    mode: Annotated[
        EvalModes,
        typer.Option(
            "--mode",
            help="descriptor (Go2 template with the target's descriptor, the paper's), "
            "full (the target's own model), actuation-matched (descriptor mode with Kp, Kd and "
            "torque limits x the target's mass / Go2's), or both (descriptor and full).",
        ),
    ] = EvalModes.descriptor,
    envs: Annotated[int, typer.Option("--envs", min=1, help="Parallel envs per robot.")] = 64,
    steps: Annotated[
        int | None, typer.Option("--steps", min=1, help="Policy steps per rollout (50 per second) [default: 500].")
    ] = None,
    seed: SeedOpt = 0,
    scene_envs: Annotated[
        str,
        typer.Option(
            "--scene-envs",
            help="Envs (the first ones) whose 3D scene (geoms, body frames) goes in "
            "each MCAP log for Foxglove: a number, or all. Frames roughly double a log's size.",
        ),
    ] = "4",
    video: Annotated[
        bool, typer.Option("--video", help="Render a few envs walking (MP4, or GIF without ffmpeg).")
    ] = False,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Also write eval.csv and, per robot and command, the MCAP "
            "rollout log, a speed/survival figure (and the video) into this directory.",
        ),
    ] = None,
    training_conditions: Annotated[
        bool,
        typer.Option(
            "--training-conditions",
            help="Instead of the protocol: run the checkpoint under its own training conditions (randomisation, "
            "sampled actions, latent dropout, curriculum commands, one episode length) and compare its episode "
            "length with the training curve's; then change one condition at a time toward the protocol "
            "(--robots: one robot, default go2; --command-vx: one command, default 1.0).",
        ),
    ] = False,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Zero-shot evaluation of a trained policy on each target robot (paper protocol by default).

    Per robot and command: v_x ± σ (σ over all alive env-steps, the paper's; the std of the per-env means is
    vx_env_std in JSON), survival S (no termination in --steps), the best 1 s moving average (peak, an extra; the
    paper's v_x^max is the v_x at 2.5 m/s), tracking ratio, a validity verdict (a survivor that stands still,
    lies down or drags its feet is not a transfer) and what ended the failed episodes (envs per termination term;
    an env that tripped two counts under both). Actions are the policy mean; no pushes or
    randomisation. Stores the table (ref evals/<run>) and, per robot and command, an MCAP log (numbers and a 3D
    scene for Foxglove, docs/mcap.md) and a figure of speed and survival over time.

    With --training-conditions: does evaluation agree with training? (docs/eval.md, "Training conditions").

    Example: morfic eval runs/film-cpu-s0 --robots go2,go1,a1 --command-vx 2.0,2.5 --format json
    """
    check_args(
        store=store,
        out_dir=out,
        seed=seed,
        envs=envs,
        steps=steps,
        command_vx=command_vx,
        robots=robots,
        specs=[run],
        trust=trust_variant,
    )
    if training_conditions:
        _training_check(run, robots, command_vx, mode, envs, steps, seed, video, out, fmt, quiet, store)
        return
    steps = 500 if steps is None else steps
    command_vx = "2.0" if command_vx is None else command_vx
    from morfic_cli.evaluation.protocol import EvalCfg, parse_commands
    from morfic_cli.evaluation.protocol import evaluate as run_eval
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.store import Store

    names = parse_robot_list(robots)
    if not names:
        raise MorficError("--robots is empty; give 'all' or names such as go1,a1 (see `morfic robots ls`).")
    modes = mode.modes()
    try:
        commands = parse_commands(command_vx)
    except ValueError as exc:
        raise MorficError(
            f"--command-vx takes comma-separated numbers in m/s (e.g. 2.0,2.5), got '{command_vx}'."
        ) from exc
    if scene_envs != "all" and not (scene_envs.isdigit()):
        raise MorficError(f"--scene-envs takes a number of envs (0 for none) or 'all', got '{scene_envs}'.")
    n_scene = envs if scene_envs == "all" else min(int(scene_envs), envs)
    cfg = EvalCfg(
        robots=tuple(names), modes=modes, command_vx=commands, num_envs=envs, steps=steps, seed=seed, scene_envs=n_scene
    )
    st = Store(store)
    from morfic_cli.rl.load import load_trained

    trained = load_trained(st, run)  # bad refs fail here, before the progress bar starts

    with StepBar("eval", len(names) * len(modes) * len(commands) * steps, quiet) as bar:
        result = run_eval(
            st,
            run,
            cfg,
            on_rollout_start=lambda r, m, vx: bar.describe(f"{r} {m} vx={vx:g}"),
            on_step=bar.step,
            keep_models=4 if video else 0,
            trained=trained,
        )
        if video:  # minutes in software GL: a phase of its own, counted in frames
            from morfic_cli.evaluation.media import store_videos, video_frames

            bar.phase("videos", video_frames(result))
            videos = store_videos(
                st, result, out, on_video=lambda name: bar.describe(f"videos {name}"), on_frame=bar.step
            )
    if video:
        for path in videos:
            info(f"video: {path}")
    if out is not None:
        from morfic_cli.evaluation.protocol import eval_columns
        from morfic_cli.evaluation.terminations import TERMINATION_COLUMNS, TERMINATIONS_CSV, termination_lines
        from morfic_cli.recording.tables import rows_to_csv

        out.mkdir(parents=True, exist_ok=True)
        (out / "eval.csv").write_bytes(rows_to_csv(result.rows, eval_columns()))
        (out / TERMINATIONS_CSV).write_bytes(rows_to_csv(termination_lines(result.rows), TERMINATION_COLUMNS))
        from morfic_cli.evaluation.figures import write_figures

        for path in write_figures(st, result.id, out):
            info(f"figure: {path}")
        from morfic_cli.evaluation.media import write_logs

        for path in write_logs(st, result.id, out):
            info(f"rollout log (MCAP, open in Foxglove): {path}")
    if not quiet:
        info(f"stored {result.ref}@{result.version} ({result.id[:12]}) with {len(result.rollouts)} MCAP rollout logs")
    from morfic_cli.evaluation.metric_terms import shown_terms
    from morfic_cli.evaluation.terminations import failure_text

    shown = shown_terms()  # the registered metrics the table shows (docs/eval.md)
    rows = result.rows  # json: "terminations" {term: envs}; csv: that as one text cell
    if fmt == OutputFormat.csv:
        rows = [{**r, "terminations": failure_text(r["terminations"])} for r in rows]
    emit_rows(
        rows,
        fmt,
        columns=[
            Column("robot", "robot"),
            Column("mode", "mode"),
            Column("command_vx", "cmd", fmt=lambda v: f"{v:.1f}", justify="right"),
            Column("d", "d", fmt=lambda v: "-" if v is None else f"{v:.3f}", justify="right", drop=1),
            *(metric_column(t) for t in shown),
            Column("terminations", "ended by", fmt=lambda v: failure_text(v) or "-", drop=4),
        ],
        title=f"zero-shot transfer of {run}",
        caption="; ".join(
            [
                "cmd: commanded v_x (m/s)",
                *(t.legend for t in shown if t.legend),
                "ended by: failed envs per termination term (an env can trip several)",
            ]
        ),
    )


def metric_column(term: MetricTerm) -> Column:
    """The ``morfic eval`` table's column of a registered metric (header, format, alignment, drop order)."""
    spec = term.fmt
    return Column(
        term.name,
        term.header or term.name,
        fmt=None if spec is None else (lambda v: "-" if v is None else format(v, spec)),
        justify=term.align,
        no_wrap=spec is None,
        drop=term.drop,
    )


def _training_check(
    run: str,
    robots: str,
    command_vx: str | None,
    mode: str,
    envs: int,
    steps: int | None,
    seed: int,
    video: bool,
    out: Path | None,
    fmt: OutputFormat,
    quiet: bool,
    store: Path,
) -> None:
    """``morfic eval RUN --training-conditions``."""
    from morfic_cli.evaluation.training_check import CHECK_COLUMNS, CheckCfg, check_rows, steps_per_row, training_check
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.rl.load import load_trained
    from morfic_cli.store import Store

    if steps is not None or video or mode != EvalModes.descriptor:
        raise MorficError(
            "--training-conditions runs one episode length of the run's own training env; it takes "
            "no --steps, --video or --mode (use --envs, --seed, --robots, --command-vx)."
        )
    names = ["go2"] if robots == "all" else parse_robot_list(robots)
    if len(names) != 1:
        raise MorficError(f"--training-conditions compares on one robot; give --robots with one name, got '{robots}'.")
    try:
        values = [1.0] if command_vx is None else [float(x) for x in command_vx.split(",") if x.strip()]
    except ValueError:
        values = []
    if len(values) != 1:
        raise MorficError(f"--training-conditions takes one --command-vx value in m/s (e.g. 1.0), got '{command_vx}'.")
    if envs < 1:
        raise MorficError("--envs must be a positive integer.")
    cfg = CheckCfg(num_envs=envs, seed=seed, robot=names[0], command_vx=values[0])
    st = Store(store)
    trained = load_trained(st, run)
    with StepBar("check", len(check_rows(cfg)) * steps_per_row(trained), quiet) as bar:
        result = training_check(st, run, cfg, trained=trained, on_row_start=bar.describe, on_step=bar.step)
    if out is not None:
        from morfic_cli.recording.tables import rows_to_csv

        out.mkdir(parents=True, exist_ok=True)
        (out / "training-check.csv").write_bytes(rows_to_csv(result.rows, CHECK_COLUMNS))
    ref = result.reference
    if not quiet:
        info(
            f"training: {ref.length_s:.2f} ± {ref.sd_s:.2f} s mean episode length over iterations "
            f"{ref.iterations[0]}-{ref.iterations[1]}; commands vx in [{result.vx_range[0]:g}, "
            f"{result.vx_range[1]:g}]"
        )
        info(f"stored {result.ref}@{result.version} ({result.id[:12]})")
    emit_rows(
        result.rows,
        fmt,
        columns=[
            Column("conditions", "conditions"),
            Column("length_s", "episode s", fmt=lambda v: f"{v:.2f}", justify="right"),
            Column("length_se_s", "± se", fmt=lambda v: f"{v:.2f}", justify="right"),
            Column("agrees", "= training", fmt=lambda v: "yes" if v else "NO"),
            Column("time_out_fraction", "survived ep.", fmt=lambda v: f"{v:.3f}", justify="right"),
            Column("survival_5s", "S at 5 s", fmt=lambda v: f"{v:.3f}", justify="right"),
            Column("change", "change from training"),
        ],
        title=f"{run} under its training conditions, then one change at a time",
        caption=f"training: {ref.length_s:.2f} ± {ref.sd_s:.2f} s (episode_length_s, last {cfg.window} iterations); "
        "'= training': within 2 combined standard errors",
    )
