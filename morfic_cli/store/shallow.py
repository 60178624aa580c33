"""Bundles that leave inputs out on purpose (weights-only, results-only): what may be left out, and the records.

What a bundle may leave out comes in two forms, both named here and nowhere else:

- an *input* under an omittable role (:data:`OMITTABLE_ROLES`): the whole input manifest and what only it reaches.
  A training checkpoint names its trainer state (optimiser moments, env state, RNG; only ``--resume`` needs it)
  as its input ``trainer_state``.
- a *file* under an omittable name (:data:`OMITTABLE_FILES`): the file's object, while its manifest (and every
  other file of it) stays: a checkpoint's weights ``model.pt``, a rollout's log ``rollout.mcap`` and its
  observations ``obs.npz``.

``morfic store export --without-trainer-state`` leaves out the trainer-state inputs (:data:`WEIGHTS_ONLY`);
``--results-only`` also the weight and log files (:data:`RESULTS_ONLY`). The tar's header lists what it left out
(``"omitted": {id: role}``, ``"omitted_files": {id: file name}``); the manifests themselves are unchanged, so
every id stays the same. An import records each listed id it does not hold as an empty marker
``<store>/shallow/<id>``, and every walk over manifests (gc, verify, export, ``--resume``, eval, rsl-rl export)
reads an input or file that is missing *and* marked, under an omittable role or name, as known-absent rather than
damaged. Importing a bundle that holds it later brings it and drops its marker. docs/concepts.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from morfic_cli.store.manifest import ManifestIndex

TRAINER_STATE_ROLE = "trainer_state"
"""The checkpoint manifest's input role naming its trainer state (one ref update per checkpoint)."""

OMITTABLE_ROLES = frozenset({TRAINER_STATE_ROLE})
"""The only input roles a bundle may leave out (the input manifest); any other missing input is damage."""

OMITTABLE_FILES = frozenset({"model.pt", "rollout.mcap", "obs.npz"})
"""The only file names a bundle may leave out (the file's object; its manifest stays): a checkpoint's weights, a
rollout's MCAP log and its observation arrays. Any other missing file is damage."""


@dataclass(frozen=True)
class LeaveOut:
    """What one export leaves out: the inputs under ``roles`` and the files named ``files``.

    Attributes:
        roles: Input roles (a subset of :data:`OMITTABLE_ROLES`).
        files: File names (a subset of :data:`OMITTABLE_FILES`).
    """

    roles: frozenset[str] = frozenset()
    files: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        assert self.roles <= OMITTABLE_ROLES and self.files <= OMITTABLE_FILES, self


NOTHING = LeaveOut()
"""A full export."""
WEIGHTS_ONLY = LeaveOut(roles=OMITTABLE_ROLES)
"""``--without-trainer-state``: the weights and everything else, no trainer states (evaluates, cannot resume)."""
RESULTS_ONLY = LeaveOut(roles=OMITTABLE_ROLES, files=OMITTABLE_FILES)
"""``--results-only``: tables, figures, curves and configs; no trainer states, weights or rollout logs."""


class OmittedIndex(ManifestIndex):
    """``shallow/<id>``: one empty marker per id (an input manifest or a file's object) an import left out on purpose.

    A marker only counts while its object is absent (:meth:`morfic_cli.store.Store.is_omitted`); an import
    that brings the object drops it, and ``gc --yes`` drops markers that are filled or no longer reachable.
    """

    def __init__(self, root: Path) -> None:
        self.dir = root / "shallow"
