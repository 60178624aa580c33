"""Weights-only (shallow) bundles: which inputs an export may leave out, and where a store records them.

A training checkpoint names its trainer state (optimiser moments, env state, RNG; only ``--resume`` needs it)
as its input ``trainer_state``. ``morfic store export --without-trainer-state`` leaves those inputs out and
lists them in the tar's header (``"omitted": {id: "trainer_state"}``); the manifests themselves are unchanged,
so every id stays the same. An import of such a tar records each omitted id it does not hold as an empty
marker ``<store>/shallow/<id>``, and every walk over inputs (gc, verify, export, ``--resume``, rsl-rl export)
reads an input that is missing *and* marked, under an omittable role, as known-absent rather than damaged.
Importing the full bundle later brings the trainer state and drops its marker. docs/concepts.md.
"""

from __future__ import annotations

from pathlib import Path

from morfic_cli.store.manifest import ManifestIndex

TRAINER_STATE_ROLE = "trainer_state"
"""The checkpoint manifest's input role naming its trainer state (one ref update per checkpoint)."""

OMITTABLE_ROLES = frozenset({TRAINER_STATE_ROLE})
"""The only input roles a weights-only export may leave out; any other missing input is damage."""


class OmittedIndex(ManifestIndex):
    """``shallow/<id>``: one empty marker per manifest id that a weights-only import left out on purpose.

    A marker only counts while its object is absent (:meth:`morfic_cli.store.Store.is_omitted`); an import
    that brings the object drops it, and ``gc --yes`` drops markers that are filled or no longer reachable.
    """

    def __init__(self, root: Path) -> None:
        self.dir = root / "shallow"
