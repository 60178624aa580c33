"""Bundles that leave inputs out on purpose (weights-only, results-only): what may be left out, and the records.

What a bundle may leave out comes in two forms, both named here and nowhere else:

- an *input* under an omittable role (:data:`OMITTABLE_ROLES`): the whole input manifest and what only it reaches.
  A training checkpoint names its trainer state (optimiser moments, env state, RNG; only ``--resume`` needs it)
  as its input ``trainer_state``.
- a *file* under an omittable name (:data:`OMITTABLE_FILES`): the file's object, while its manifest (and every
  other file of it) stays: a checkpoint's weights ``model.pt``, a rollout's log ``rollout.mcap`` and its
  observations ``obs.npz``; a checkpoint's training curve (``curve.csv``, ``curve.png``,
  :data:`FOREIGN_FILES`), ``curve.csv`` only where the checkpoint is not one the bundle is about; and a rendered
  figure of a result (:func:`is_figure`: a ``.png``, ``.pdf``, ``.gif`` or ``.mp4`` file of a manifest of a kind in
  :data:`FIGURE_KINDS`, e.g. a rollout's ``speed.png``, a diagnosis's ``ev.pdf``). Which files may be left out
  depends on the manifest's kind: :func:`omittable_file`.

``morfic store export --without-trainer-state`` leaves out the trainer-state inputs (:data:`WEIGHTS_ONLY`);
``--results-only`` also the weight and log files, every rendered figure (``morfic report`` draws its figures from
the tables; a rollout's speed figure it draws from the eval table, docs/concepts.md) and the curves of every
checkpoint but the exported runs' own (:data:`RESULTS_ONLY` with :meth:`LeaveOut.keeping`): other runs' checkpoints
come into a results bundle as the frozen actor of a fixed-rollout diagnosis or through a shared ref's earlier
versions, and their curves (1.5 MiB a run with the ``cpu`` preset) are in those runs' own bundles. The tar's header
lists what it left out (``"omitted": {id: role}``, ``"omitted_files": {id: file name}``); the manifests themselves
are unchanged, so every id stays the same. An import records each listed id it does not hold as an empty marker
``<store>/shallow/<id>``, and every walk over manifests (gc, verify, export, ``--resume``, eval, rsl-rl export)
reads an input or file that is missing *and* marked, under an omittable role or name, as known-absent rather than
damaged. Importing a bundle that holds it later brings it and drops its marker. docs/concepts.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from morfic_cli.store.manifest import ManifestIndex

TRAINER_STATE_ROLE = "trainer_state"
"""The checkpoint manifest's input role naming its trainer state (one ref update per checkpoint)."""

OMITTABLE_ROLES = frozenset({TRAINER_STATE_ROLE})
"""The only input roles a bundle may leave out (the input manifest); any other missing input is damage."""

FOREIGN_FILES = frozenset({"curve.csv", "curve.png"})
"""A checkpoint's training curve: a results-only bundle leaves it out of the checkpoints other than its runs'."""

OMITTABLE_FILES = frozenset({"model.pt", "rollout.mcap", "obs.npz"}) | FOREIGN_FILES
"""The file names a bundle may leave out of any manifest (the file's object; its manifest stays): a checkpoint's
weights, a rollout's MCAP log and its observation arrays, a training curve (:data:`FOREIGN_FILES`). Besides these,
only rendered figures of results (:func:`omittable_file`); any other missing file is damage."""

FIGURE_SUFFIXES = (".png", ".pdf", ".gif", ".mp4")
"""File name endings of a rendered figure (or video): drawn from a manifest's tables or logs, never read back."""

FIGURE_KINDS = frozenset({"rollout", "eval", "diagnosis", "report"})
"""Manifest kinds whose rendered figures a results-only bundle leaves out: an eval's rollouts (``speed.png`` /
``speed.pdf``), diagnoses (``ev.png``, ``critic_study.png``) and reports. A checkpoint's ``curve.png`` is in
:data:`OMITTABLE_FILES`; a ``media`` manifest (videos) never goes into a results-only bundle."""


def is_figure(name: str) -> bool:
    """Whether file ``name`` is a rendered figure by its ending (:data:`FIGURE_SUFFIXES`), e.g. ``figures/ev.pdf``."""
    return name.lower().endswith(FIGURE_SUFFIXES)


def omittable_file(kind: str, name: str) -> bool:
    """Whether file ``name`` of a manifest of kind ``kind`` may be missing on purpose (left out of a bundle).

    ``model.pt``, ``rollout.mcap``, ``obs.npz``, ``curve.csv`` and ``curve.png`` of any manifest, and the rendered
    figures (:func:`is_figure`) of the kinds in :data:`FIGURE_KINDS`; nothing else.
    """
    return name in OMITTABLE_FILES or (kind in FIGURE_KINDS and is_figure(name))


@dataclass(frozen=True)
class LeaveOut:
    """What one export leaves out: input roles, file names, figures, and file names left out of other runs' manifests.

    The inputs under ``roles`` and the files named ``files`` stay out everywhere, and with ``figures`` every
    rendered figure of a manifest of a kind in :data:`FIGURE_KINDS`; the files named ``foreign_files`` stay out of
    every manifest but those in ``own``.

    Attributes:
        roles: Input roles (a subset of :data:`OMITTABLE_ROLES`).
        files: File names (a subset of :data:`OMITTABLE_FILES`).
        foreign_files: File names left out of the manifests not in ``own`` (a subset of :data:`OMITTABLE_FILES`).
        own: Manifest ids whose ``foreign_files`` stay in (the exported runs' checkpoints).
        figures: Leave out the rendered figures of results (:func:`omittable_file`).
    """

    roles: frozenset[str] = frozenset()
    files: frozenset[str] = frozenset()
    foreign_files: frozenset[str] = frozenset()
    own: frozenset[str] = frozenset()
    figures: bool = False

    def __post_init__(self) -> None:
        assert self.roles <= OMITTABLE_ROLES and self.files | self.foreign_files <= OMITTABLE_FILES, self

    def keeping(self, own: frozenset[str]) -> LeaveOut:
        """The same, keeping every file of the manifests ``own``, e.g. ``RESULTS_ONLY.keeping({checkpoint id})``."""
        return replace(self, own=own)

    def leaves_out(self, manifest_id: str, file_name: str, kind: str = "") -> bool:
        """Whether file ``file_name`` of manifest ``manifest_id`` (of kind ``kind``) stays out."""
        if self.figures and kind in FIGURE_KINDS and is_figure(file_name):
            return True
        return file_name in self.files or (file_name in self.foreign_files and manifest_id not in self.own)


NOTHING = LeaveOut()
"""A full export."""
WEIGHTS_ONLY = LeaveOut(roles=OMITTABLE_ROLES)
"""``--without-trainer-state``: the weights and everything else, no trainer states (evaluates, cannot resume)."""
RESULTS_ONLY = LeaveOut(
    roles=OMITTABLE_ROLES,
    files=frozenset({"model.pt", "rollout.mcap", "obs.npz", "curve.png"}),
    foreign_files=frozenset({"curve.csv"}),
    figures=True,
)
"""``--results-only``: tables, configs and the runs' own curve tables (:meth:`LeaveOut.keeping` their
checkpoints); no trainer states, weights, rollout logs, rendered figures (``curve.png`` included) or other
checkpoints' curves."""


class OmittedIndex(ManifestIndex):
    """``shallow/<id>``: one empty marker per id (an input manifest or a file's object) an import left out on purpose.

    A marker only counts while its object is absent (:meth:`morfic_cli.store.Store.is_omitted`); an import
    that brings the object drops it, and ``gc --yes`` drops markers that are filled or no longer reachable.
    """

    def __init__(self, root: Path) -> None:
        self.dir = root / "shallow"
