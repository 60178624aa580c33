"""``morfic diagnose``: critic calibration metrics (built by the diagnose issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, RobotsOpt, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def diagnose(
    runs: Annotated[list[str] | None, typer.Argument(help="Run refs or checkpoint ids.")] = None,
    robots: RobotsOpt = "all",
    fixed_rollout: Annotated[
        str | None, typer.Option("--fixed-rollout", help="Target robot for the fixed-rollout analysis.")
    ] = None,
    actor: Annotated[str | None, typer.Option("--actor", help="Actor run for --fixed-rollout.")] = None,
    critics: Annotated[
        str | None, typer.Option("--critics", help="Comma-separated critic runs for --fixed-rollout.")
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Critic calibration (EV, NVB, NVE, ASA, Flip, CosGrad) per robot.

    Example: morfic diagnose runs/film-s0 runs/ppo-s0 --robots aliengo
    """
    raise NotImplementedYetError("diagnose")
