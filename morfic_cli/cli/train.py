"""``morfic train``: PPO training with one conditioning variant (built by the training issue)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, Device, DeviceOpt, Preset, PresetOpt, SeedOpt, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def train(
    variant: Annotated[
        str, typer.Option("--variant", help="ppo, actor-only, concat, film, film-scaled, adaln, hyper.")
    ] = "film",
    preset: PresetOpt = Preset.smoke,
    seed: SeedOpt = 0,
    name: Annotated[str | None, typer.Option("--name", help="Run ref name (default <variant>-s<seed>).")] = None,
    resume: Annotated[str | None, typer.Option("--resume", help="Run ref or checkpoint id to continue.")] = None,
    device: DeviceOpt = Device.cpu,
    overrides: Annotated[
        list[str] | None, typer.Option("--set", help="Config override key=value (repeatable).")
    ] = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Train a policy with one critic-conditioning variant.

    Example: morfic train --variant film --preset smoke --seed 0
    """
    raise NotImplementedYetError("train")
