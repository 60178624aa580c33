"""``morfic eval``: the paper's zero-shot protocol on target robots."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    EvalMode,
    FormatOpt,
    OutputFormat,
    QuietOpt,
    RobotsOpt,
    SeedOpt,
    StoreOpt,
)
from morfic_cli.cli._progress import StepBar
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.errors import MorficError


def evaluate(
    run: Annotated[str, typer.Argument(help="Run ref (runs/film-s0 = its latest checkpoint), ref@N or checkpoint id.")],
    robots: RobotsOpt = "all",
    command_vx: Annotated[str, typer.Option("--command-vx", help="Forward command(s) in m/s, e.g. 2.0,2.5.")] = "2.0",
    mode: Annotated[
        str, typer.Option("--mode", help="descriptor (Go2 template with the target's descriptor, the paper's), full "
                          "(the target's own model), or both.")
    ] = EvalMode.descriptor.value,
    envs: Annotated[int, typer.Option("--envs", help="Parallel envs per robot.")] = 64,
    steps: Annotated[int, typer.Option("--steps", help="Policy steps per rollout (50 per second).")] = 500,
    seed: SeedOpt = 0,
    scene_envs: Annotated[
        str, typer.Option("--scene-envs", help="Envs (the first ones) whose 3D scene (geoms, body frames) goes in "
                          "each MCAP log for Foxglove: a number, or all. Frames roughly double a log's size.")
    ] = "4",
    video: Annotated[bool, typer.Option("--video", help="Render a few envs walking (MP4, or GIF without ffmpeg).")]
    = False,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Also write the table CSV here, and beside it a "
                                       "speed/survival figure per robot and command (and videos).")
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Zero-shot evaluation of a trained policy on each target robot (paper protocol by default).

    Per robot and command: v_x mean ± std over envs (alive steps only), v_x^max (best 1 s moving average),
    survival S (no termination in --steps), tracking ratio and a validity verdict (a survivor that stands
    still, lies down or drags its feet is not a transfer). Actions are the policy mean; no pushes or
    randomisation. Stores the table (ref evals/<run>) and, per robot and command, an MCAP log (numbers and a 3D
    scene for Foxglove, docs/mcap.md) and a figure of speed and survival over time.

    Example: morfic eval runs/film-s0 --robots go2,go1,a1 --command-vx 2.0,2.5 --format json
    """
    from morfic_cli.evaluation.protocol import EvalCfg, parse_commands
    from morfic_cli.evaluation.protocol import evaluate as run_eval
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.store import Store

    names = parse_robot_list(robots)
    if not names:
        raise MorficError("--robots is empty; give 'all' or names such as go1,a1 (see `morfic robots ls`).")
    modes = ("descriptor", "full") if mode == "both" else (mode,)
    if any(m not in ("descriptor", "full") for m in modes):
        raise MorficError(f"unknown --mode '{mode}'; valid modes are: descriptor, full, both.")
    try:
        commands = parse_commands(command_vx)
    except ValueError as exc:
        raise MorficError(f"--command-vx takes comma-separated numbers in m/s (e.g. 2.0,2.5), got '{command_vx}'.") \
            from exc
    if envs < 1 or steps < 1:
        raise MorficError("--envs and --steps must be positive integers.")
    if scene_envs != "all" and not (scene_envs.isdigit()):
        raise MorficError(f"--scene-envs takes a number of envs (0 for none) or 'all', got '{scene_envs}'.")
    n_scene = envs if scene_envs == "all" else min(int(scene_envs), envs)
    cfg = EvalCfg(robots=tuple(names), modes=modes, command_vx=commands, num_envs=envs, steps=steps, seed=seed,
                  scene_envs=n_scene)
    st = Store(store)
    from morfic_cli.rl.runner import load_trained

    trained = load_trained(st, run)  # bad refs fail here, before the progress bar starts

    with StepBar("eval", len(names) * len(modes) * len(commands) * steps, quiet) as bar:
        result = run_eval(st, run, cfg, on_rollout_start=lambda r, m, vx: bar.describe(f"{r} {m} vx={vx:g}"),
                          on_step=bar.step,
                          keep_models=4 if video else 0, trained=trained)
    if video:
        from morfic_cli.evaluation.media import store_videos

        for path in store_videos(st, result, out):
            info(f"video: {path}")
    if out is not None:
        from morfic_cli.evaluation.protocol import EVAL_COLUMNS
        from morfic_cli.recording.tables import rows_to_csv

        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(rows_to_csv(result.rows, EVAL_COLUMNS))
        from morfic_cli.evaluation.figures import write_figures

        for path in write_figures(st, result.id, out):
            info(f"figure: {path}")
    if not quiet:
        info(f"stored {result.ref}@{result.version} ({result.id[:12]}) with {len(result.rollouts)} MCAP rollout logs")
    emit_rows(
        result.rows,
        fmt,
        columns=[
            Column("robot", "robot"),
            Column("mode", "mode"),
            Column("command_vx", "vx_cmd", fmt=lambda v: f"{v:.1f}", justify="right"),
            Column("d", "d", fmt=lambda v: "-" if v is None else f"{v:.3f}", justify="right"),
            Column("cell", "v_x ± σ / S", justify="right"),
            Column("cell_max", "v_x^max ± σ / S", justify="right"),
            Column("tracking_ratio", "tracking", fmt=lambda v: f"{v:.2f}", justify="right"),
            Column("verdict", "validity"),
        ],
        title=f"zero-shot transfer of {run}",
        caption="v_x: mean forward velocity over alive steps; S: survival; validity: moving, upright, no dragging",
    )
