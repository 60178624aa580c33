"""``morfic bench``: throughput against the raw-physics floor (built by the env issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def bench(
    what: Annotated[str, typer.Argument(help="env or train.")],
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Measure env or training throughput on this machine.

    Example: morfic bench env
    """
    raise NotImplementedYetError(f"bench {what}")
