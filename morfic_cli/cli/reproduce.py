"""``morfic reproduce``: the whole pipeline in one command (built by the reports issue)."""

from __future__ import annotations

from morfic_cli.cli._options import DEFAULT_STORE, Preset, PresetOpt, StoreOpt
from morfic_cli.errors import NotImplementedYetError


def reproduce(preset: PresetOpt = Preset.smoke, store: StoreOpt = DEFAULT_STORE) -> None:
    """Train all variants, evaluate, diagnose, compare and report.

    Example: morfic reproduce --preset smoke
    """
    raise NotImplementedYetError("reproduce")
