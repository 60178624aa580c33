"""What ended each failed episode of an evaluation: per row, the envs each termination term ended (docs/eval.md).

A rollout records, per step, each termination term's mask (:data:`~morfic_cli.envs.terminations.TERMINATIONS`)
and ``nonfinite`` (the physics state became non-finite), as the env computed them before it reset the envs that
ended (``LocomotionEnv.last_terminations``). An env *failed* when its first episode ended by a termination, not by
the time-out. :func:`termination_counts` counts, per term, the failed envs whose fatal step tripped it: an env can
trip several terms on that step (a fall that tilts the base and drops it), and then counts once under each, so the
counts sum to at least the number of failed envs.

Stored beside ``eval.csv`` as ``terminations.csv`` (:data:`TERMINATION_COLUMNS`, one line per row and term, zeros
included) in every ``eval`` manifest; evaluations stored before the file existed have none, and
:func:`read_terminations` reads them as "not recorded" (no lines). ``eval.csv``'s columns and the eval's config
(and so its content address) are unchanged.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from morfic_cli.envs.terminations import NONFINITE, TERMINATIONS

if TYPE_CHECKING:
    from morfic_cli.store import Store

TERMINATIONS_CSV = "terminations.csv"
"""The file of an ``eval`` manifest that holds its termination counts."""

TERMINATION_COLUMNS = ("robot", "mode", "command_vx", "term", "envs")
"""Columns of :data:`TERMINATIONS_CSV`: the eval row's keys, the term, and how many envs it ended."""


def termination_names() -> tuple[str, ...]:
    """The terms a rollout records, in order: every termination term, then ``nonfinite``."""
    return (*TERMINATIONS, NONFINITE)


def termination_counts(
    done: np.ndarray, time_out: np.ndarray, masks: np.ndarray, names: Sequence[str]
) -> dict[str, int]:
    """How many envs' first episode each term ended (an env that tripped several terms counts under each).

    An env's first episode ends on its first ``done`` step; it failed when that end is not a time-out. Time-outs,
    envs still running at the end and anything after a first end are not counted.

    Args:
        done: Episode ended at this step. Shape: (T, N) bool.
        time_out: The end was a time-out. Shape: (T, N) bool.
        masks: Each term's mask on each step, as the env computed it before resetting. Shape: (T, N, K) bool.
        names: The K terms, in the order of ``masks``' last axis.

    Returns:
        Term -> envs, every name (0 included), in the order of ``names``.

    Raises:
        ValueError: ``masks`` is not (T, N, len(names)).

    E.g. with 3 steps, env 0 ending at step 1 by ``excessive_tilt`` and ``base_too_low`` at once, env 1 timing out
    at step 2 and env 2 never ending: ``excessive_tilt`` 1, ``base_too_low`` 1, the rest 0.
    """
    done = np.asarray(done, dtype=bool)
    masks = np.asarray(masks, dtype=bool)
    if masks.shape != (*done.shape, len(names)):
        raise ValueError(f"masks must have shape {(*done.shape, len(names))} (T, N, K), got {masks.shape}")
    ended = done.any(axis=0)
    first = done.argmax(axis=0)  # (N,) the first end (0 where none: masked below)
    envs = np.arange(done.shape[1])
    failed = ended & ~np.asarray(time_out, dtype=bool)[first, envs]
    fatal = masks[first, envs] & failed[:, None]  # (N, K)
    return {name: int(n) for name, n in zip(names, fatal.sum(axis=0), strict=True)}


def termination_lines(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The lines of :data:`TERMINATIONS_CSV` (:data:`TERMINATION_COLUMNS`): one per eval row and term.

    Args:
        rows: Eval rows with ``robot``, ``mode``, ``command_vx`` and ``terminations`` (term -> envs).
    """
    return [
        {"robot": r["robot"], "mode": r["mode"], "command_vx": float(r["command_vx"]), "term": term, "envs": int(n)}
        for r in rows
        for term, n in r["terminations"].items()
    ]


def parse_terminations(data: bytes) -> list[dict[str, Any]]:
    """The lines of a :data:`TERMINATIONS_CSV`, typed: ``command_vx`` float, ``envs`` int."""
    return [
        {
            "robot": r["robot"],
            "mode": r["mode"],
            "command_vx": float(r["command_vx"]),
            "term": r["term"],
            "envs": int(r["envs"]),
        }
        for r in csv.DictReader(io.StringIO(data.decode()))
    ]


def read_terminations(store: Store, eval_spec: str) -> list[dict[str, Any]]:
    """The termination counts of a stored evaluation: the lines of its :data:`TERMINATIONS_CSV`, typed.

    Reads only. An evaluation stored before the counts were recorded (or whose file a bundle left out) gives
    ``[]``: not recorded, which is not "no failures" (a recorded row without failures has its terms at 0).

    Args:
        store: The store.
        eval_spec: The ``eval`` manifest: ``evals/<run>``, ``evals/<run>@N`` or an id.

    Returns:
        Dicts with :data:`TERMINATION_COLUMNS`, in the eval's row order, then term order.

    Raises:
        ArtifactNotFoundError: ``eval_spec`` names nothing in the store.
    """
    manifest = store.read_manifest(eval_spec)
    if TERMINATIONS_CSV not in manifest.files or TERMINATIONS_CSV in store.omitted_files(manifest):
        return []
    return parse_terminations(store.read_file(manifest.id, TERMINATIONS_CSV))


def failure_text(counts: Mapping[str, int] | None) -> str:
    """The terms that ended envs, e.g. ``"illegal_contact 3, base_too_low 1"``; ``""`` when none did (or None)."""
    return ", ".join(f"{term} {n}" for term, n in (counts or {}).items() if n)
