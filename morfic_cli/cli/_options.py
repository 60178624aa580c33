"""Shared option types for the CLI (``Annotated`` aliases, one place for help text and defaults)."""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Annotated

import typer


class OutputFormat(str, enum.Enum):
    """How a command prints its data on stdout."""

    table = "table"
    json = "json"
    csv = "csv"


class Preset(str, enum.Enum):
    """Training/pipeline budget presets (SPEC section 4)."""

    smoke = "smoke"
    cpu = "cpu"
    paper = "paper"


class EvalMode(str, enum.Enum):
    """Zero-shot evaluation modes (SPEC section 2)."""

    descriptor = "descriptor"
    full = "full"


class Device(str, enum.Enum):
    """Compute device for training and evaluation."""

    cpu = "cpu"
    cuda = "cuda"


class Normalize(str, enum.Enum):
    """Per-dimension min-max normalisation for the morphology distance, eq. (morph_dist)."""

    span = "span"
    support = "support"


StoreOpt = Annotated[
    Path,
    typer.Option(
        "--store",
        envvar="MORFIC_STORE",
        help="Artifact store root (env MORFIC_STORE).",
        show_default=True,
    ),
]
FormatOpt = Annotated[
    OutputFormat,
    typer.Option("--format", "-f", help="Output format on stdout: table, json or csv."),
]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="No progress or messages on stderr.")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Random seed.")]
DeviceOpt = Annotated[Device, typer.Option("--device", help="cpu, or cuda where a GPU is present.")]
RobotsOpt = Annotated[
    str,
    typer.Option("--robots", help="Comma-separated robot names, or 'all'. See `morfic robots ls`."),
]
ModeOpt = Annotated[EvalMode, typer.Option("--mode", help="descriptor: Go2 template with the target's "
                                           "11-D descriptor (paper); full: the target's own model.")]

DEFAULT_STORE = Path("artifacts")
