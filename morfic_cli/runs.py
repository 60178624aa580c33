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


def run_name(variant: str, seed: int, preset: str) -> str:
    """The default name of a new run, the one rule of ``train``, ``reproduce`` and the shipped bundles.

    ``<variant>-<preset>-s<seed>``: ``film-smoke-s0`` (``train --variant film``, smoke is the default preset),
    ``film-cpu-s0`` (``--preset cpu``; the shipped runs), so that runs of different budgets never collide. Runs
    named otherwise (``--name``, or ``film-s0`` by an earlier ``train``) are read the same way: the name is only a ref,
    what a run is comes from its manifest.

    A user variant's import path becomes a valid ref segment by writing its ``:`` as ``.``
    (``my_lab.critics:GatedCritic`` -> ``my_lab.critics.GatedCritic-smoke-s0``).
    """
    return f"{variant.replace(':', '.')}-{preset}-s{seed}"


def run_of(spec: str, meta: Mapping[str, Any] | None = None) -> str:
    """The run a checkpoint belongs to: its manifest's ``meta.run``, else the name in ``spec``.

    ``runs/NAME``, ``runs/NAME@3`` and ``NAME`` give ``NAME``; a checkpoint id without ``meta.run`` gives the id.
    """
    if meta and meta.get("run"):
        return str(meta["run"])
    return spec.split("@")[0].removeprefix(RUNS_PREFIX)
