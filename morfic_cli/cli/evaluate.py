"""``morfic eval``: the paper's zero-shot protocol on target robots (built by the eval issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    EvalMode,
    FormatOpt,
    ModeOpt,
    OutputFormat,
    RobotsOpt,
    StoreOpt,
)
from morfic_cli.errors import NotImplementedYetError


def evaluate(
    run: Annotated[str, typer.Argument(help="Run ref or checkpoint id.")],
    robots: RobotsOpt = "all",
    command_vx: Annotated[str, typer.Option("--command-vx", help="Forward command(s) in m/s, e.g. 2.0,2.5.")] = "2.0",
    mode: ModeOpt = EvalMode.descriptor,
    envs: Annotated[int, typer.Option("--envs", help="Parallel envs per robot.")] = 64,
    steps: Annotated[int, typer.Option("--steps", help="Policy steps per rollout.")] = 500,
    video: Annotated[bool, typer.Option("--video", help="Render an MP4 of a few envs.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Zero-shot evaluation of a trained policy on each target robot.

    Example: morfic eval runs/film-s0 --robots go1,a1 --command-vx 2.0
    """
    raise NotImplementedYetError("eval")
