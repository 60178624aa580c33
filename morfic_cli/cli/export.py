"""``morfic export``: deployable policies (built by the export issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def export(
    run: Annotated[str, typer.Argument(help="Run ref or checkpoint id.")],
    robot: Annotated[str, typer.Option("--robot", help="Target robot whose descriptor is baked in.")] = "go2",
    to: Annotated[str, typer.Option("--format", help="onnx or torchscript.")] = "onnx",
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Export a deployable policy with the metadata a robot stack needs.

    Example: morfic export runs/film-s0 --robot go1 --format onnx
    """
    raise NotImplementedYetError("export")
