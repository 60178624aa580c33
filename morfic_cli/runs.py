"""Run names: the one rule for naming a training run and for finding the run a checkpoint belongs to.

A run named ``NAME`` is the ref ``runs/NAME`` (its checkpoints; :data:`RUNS_PREFIX`) with its trainer state under
``resume/NAME`` (:data:`RESUME_PREFIX`). Imports nothing heavy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

RUNS_PREFIX = "runs/"
"""Ref prefix of training runs: ``runs/NAME`` -> the run's checkpoint manifests."""
RESUME_PREFIX = "resume/"
"""Ref prefix of the trainer states: ``resume/NAME`` -> what ``--resume`` continues from."""


def run_name(variant: str, seed: int, preset: str | None = None) -> str:
    """The default name of a new run: ``<variant>-s<seed>`` (train), ``<variant>-<preset>-s<seed>`` (reproduce).

    A user variant's import path becomes a valid ref segment by writing its ``:`` as ``.``
    (``my_lab.critics:GatedCritic`` -> ``my_lab.critics.GatedCritic-s0``).
    """
    slug = variant.replace(":", ".")
    return f"{slug}-{preset}-s{seed}" if preset else f"{slug}-s{seed}"


def run_of(spec: str, meta: Mapping[str, Any] | None = None) -> str:
    """The run a checkpoint belongs to: its manifest's ``meta.run``, else the name in ``spec``.

    ``runs/NAME``, ``runs/NAME@3`` and ``NAME`` give ``NAME``; a checkpoint id without ``meta.run`` gives the id.
    """
    if meta and meta.get("run"):
        return str(meta["run"])
    return spec.split("@")[0].removeprefix(RUNS_PREFIX)
