"""Saving a result: one manifest plus the ref it advances, in one place (:meth:`Store.publish`).

Every command that stores a result (eval, diagnose, export, compare-baselines, report, distance, bench, ...)
calls :func:`publish`: under the store's writer lock it stores the files and the manifest and points the ref at
it. With ``reuse=True`` a manifest of the same kind, config and inputs that the store already holds is taken
instead of a new one (the idempotence of ``reproduce`` and ``report``): the files are then never built, when
they are passed as a function. A thin layer over :meth:`Store.put_manifest` and :meth:`Store.set_ref`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from morfic_cli.store import Store

Files = dict[str, bytes | Path]


@dataclass(frozen=True)
class Published:
    """A stored result: the manifest id, the ref it advanced and that ref's version (None without a ref).

    Attributes:
        id: The manifest id.
        ref: The ref now pointing at it, or None.
        version: The ref's 1-based version, or None.
        reused: True when an existing manifest with the same kind, config and inputs was taken.
    """

    id: str
    ref: str | None
    version: int | None
    reused: bool = False

    def advanced(self) -> tuple[str, int]:
        """``(ref, version)`` of a result published under a ref.

        Raises:
            ValueError: It was published without one (``ref=None``).
        """
        if self.ref is None or self.version is None:
            raise ValueError(f"manifest {self.id} was published without a ref.")
        return self.ref, self.version


def find_manifest(
    store: Store,
    kind: str,
    config: dict[str, Any],
    inputs: dict[str, str] | None = None,
    *,
    inputs_subset: dict[str, str] | None = None,
    files: Iterable[str] = (),
) -> str | None:
    """The newest manifest of ``kind`` with exactly this config (and inputs, or at least ``inputs_subset``).

    This is how a step knows the store already holds its result: same config and inputs give the same result.
    """
    found = None
    want_files = set(files)
    for item in store.ls(kind):
        manifest = store.read_manifest(item["id"])
        if manifest.config != config or not want_files <= set(manifest.files):
            continue
        if inputs is not None and manifest.inputs != inputs:
            continue
        if inputs_subset is not None and any(manifest.inputs.get(k) != v for k, v in inputs_subset.items()):
            continue
        found = manifest.id
    return found


def publish(
    store: Store,
    kind: str,
    ref: str | None = None,
    *,
    config: dict[str, Any] | None = None,
    inputs: dict[str, str] | None = None,
    files: Files | Callable[[], Files] | None = None,
    meta: dict[str, Any] | None = None,
    reuse: bool = False,
) -> Published:
    """Store a result as one ``kind`` manifest and advance ``ref`` to it, under one writer lock.

    Args:
        store: The artifact store.
        kind: Manifest kind (``eval``, ``diagnosis``, ``table``, ...).
        ref: Ref to advance (``evals/film-cpu-s0``), or None for an artifact reached through its inputs only.
        config: The resolved configuration (JSON object).
        inputs: Role -> id (or ref) of each input artifact.
        files: Name -> bytes or Path, or a function returning them (called only when a manifest is written).
        meta: Free-form JSON metadata.
        reuse: Take an existing manifest of the same kind, config and inputs (and files' names, when given as a
            dict) instead of writing a new one.

    Returns:
        The :class:`Published` id, ref and version.

    Raises:
        StoreError: From :meth:`Store.put_manifest` / :meth:`Store.set_ref` (bad kind, input, name, ...).
    """
    with store.writing():
        mid = None
        if reuse:
            names = tuple(files) if isinstance(files, dict) else ()
            mid = find_manifest(store, kind, config or {}, inputs or {}, files=names)
        reused = mid is not None
        if mid is None:
            built = files() if callable(files) else files
            mid = store.put_manifest(kind, config=config, inputs=inputs, files=built, meta=meta)
        version = store.set_ref(ref, mid) if ref is not None else None
    return Published(mid, ref, version, reused)
