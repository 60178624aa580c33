"""``morfic compare-baselines``: tables over variants and seeds (built by the reports issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def compare_baselines(
    runs: Annotated[list[str] | None, typer.Argument(help="Run refs or ids to compare.")] = None,
    with_paper: Annotated[bool, typer.Option("--with-paper", help="Add the paper's published numbers.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Side-by-side tables over variants and seeds (mean ± std over seeds).

    Example: morfic compare-baselines runs/film-s0 runs/ppo-s0 --with-paper
    """
    raise NotImplementedYetError("compare-baselines")
