"""``morfic report``: the paper's tables and figures from the store (built by the reports issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def report(
    latex: Annotated[bool, typer.Option("--latex", help="Write LaTeX tables.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Write Markdown tables.")] = False,
    figures: Annotated[bool, typer.Option("--figures", help="Write figures (PNG/PDF).")] = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Build the paper's tables and figures from what is in the store.

    Example: morfic report --latex --figures
    """
    raise NotImplementedYetError("report")
