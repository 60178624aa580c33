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


class ExportTo(str, enum.Enum):
    """``morfic export --to``: the model format (docs/deploy.md)."""

    onnx = "onnx"
    torchscript = "torchscript"
    rsl_rl = "rsl-rl"


class Logger(str, enum.Enum):
    """``morfic train --logger``: where live curves go (``morfic_cli.rl.live_log.LOGGERS``)."""

    tensorboard = "tensorboard"
    wandb = "wandb"
    none = "none"


class Preset(str, enum.Enum):
    """Training/pipeline budget presets (docs/training.md)."""

    smoke = "smoke"
    cpu = "cpu"
    paper = "paper"


class EvalMode(str, enum.Enum):
    """Zero-shot evaluation modes (docs/robots.md)."""

    descriptor = "descriptor"
    full = "full"


class EvalModes(str, enum.Enum):
    """``morfic eval --mode``: one evaluation mode, or both (descriptor and full; docs/eval.md)."""

    descriptor = "descriptor"
    full = "full"
    actuation_matched = "actuation-matched"
    both = "both"

    def modes(self) -> tuple[str, ...]:
        """The evaluation modes this choice runs."""
        return ("descriptor", "full") if self is EvalModes.both else (self.value,)


class Backend(str, enum.Enum):
    """Simulation backend (``SimCfg.backend``): MuJoCo C, or MuJoCo Warp (``gpu`` is an alias of ``warp``)."""

    cpu = "cpu"
    warp = "warp"
    gpu = "gpu"


class Benchmark(str, enum.Enum):
    """What ``morfic bench`` measures."""

    env = "env"
    train = "train"


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
ModeOpt = Annotated[
    EvalMode,
    typer.Option(
        "--mode",
        help="descriptor (Go2 template with the target's 11-D "
        "descriptor, the paper's) or full (the target's own model).",
    ),
]
EnvsOpt = Annotated[int, typer.Option("--envs", min=1, help="Parallel envs per rollout.")]

TrustOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--trust-variant",
        metavar="MODULE:CLASS",
        help="Import this user variant (module.path:Class, or an entry-point name) when a stored run names "
        "it; repeatable. A stored run's own code is imported only when named here or listed by `morfic "
        "trust` (docs/extending.md).",
    ),
]

DEFAULT_STORE = Path("artifacts")
