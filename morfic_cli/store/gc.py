"""Store maintenance: reachability, ``verify`` and ``gc``.

Reachability (like git): the roots are *every version of every ref*; from a manifest, its files and
its inputs are reachable, recursively; an input or file a weights-only or results-only import left out on
purpose (:mod:`morfic_cli.store.shallow`) is known-absent, not damage. ``gc`` deletes every object outside
that closure, the index markers of deleted manifests, and leftover temp files, under the exclusive
store lock so no writer can be between "object written" and "ref updated" while it runs.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from morfic_cli.errors import StoreError
from morfic_cli.store.manifest import MANIFEST_MAGIC, Manifest, parse_manifest
from morfic_cli.store.objects import CHUNK_SIZE, unlink_quiet
from morfic_cli.store.shallow import NOTHING, OMITTABLE_ROLES, LeaveOut, omittable_file

if TYPE_CHECKING:
    from morfic_cli.store import Store


@dataclass
class VerifyReport:
    """What ``verify`` checked and every problem it found.

    Attributes:
        objects: Objects rehashed.
        bytes: Total bytes rehashed.
        manifests: Index entries checked.
        refs: Refs checked.
        temp_files: Leftover temp files (harmless; ``gc`` removes them).
        omitted: Manifest inputs known to be absent (trainer states left out of a weights-only or results-only
            import).
        omitted_files: Manifest files known to be absent (weights, rollout logs and figures left out of a
            results-only import).
        problems: One line per problem; empty for a healthy store.
    """

    objects: int = 0
    bytes: int = 0
    manifests: int = 0
    refs: int = 0
    temp_files: int = 0
    omitted: int = 0
    omitted_files: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Whether no problem was found."""
        return not self.problems


@dataclass(frozen=True)
class GcItem:
    """One unreachable object.

    Attributes:
        id: Object id.
        kind: The manifest kind, or ``"blob"`` for a plain object.
        size: Size in bytes.
    """

    id: str
    kind: str
    size: int


@dataclass
class GcReport:
    """What ``gc`` removed (or, in a dry run, would remove).

    Attributes:
        dry_run: True if nothing was deleted (only reported).
        reachable: Objects reachable from some version of some ref (kept).
        removed: The unreachable objects, by id.
        temp_files: Leftover temp files under ``tmp/``.
        omitted: Reachable inputs and files known to be absent (left out of a weights-only or results-only
            import: trainer states, weights, rollout logs).
    """

    dry_run: bool
    reachable: int = 0
    removed: list[GcItem] = field(default_factory=list)
    temp_files: int = 0
    omitted: int = 0

    @property
    def removed_bytes(self) -> int:
        """Total size of the unreachable objects."""
        return sum(item.size for item in self.removed)


def load_manifest_if_any(store: Store, oid: str, *, strict: bool) -> Manifest | None:
    """``oid`` parsed as a manifest, or ``None`` for a plain blob.

    Args:
        store: The store.
        oid: An existing object id.
        strict: Raise if an indexed manifest cannot be read (gc must not guess).
    """
    indexed = store.index.has(oid)
    if not indexed and store.objects.read_head(oid, len(MANIFEST_MAGIC)) != MANIFEST_MAGIC:
        return None
    try:
        return parse_manifest(oid, store.objects.get_bytes(oid))
    except StoreError as exc:
        if indexed and strict:
            raise StoreError(
                f"manifest {oid} cannot be read ({exc}); refusing to decide what is "
                "reachable. Run `morfic store verify` and repair the store first."
            ) from exc
        return None


@dataclass
class Walk:
    """What :func:`walk` reached.

    Attributes:
        ids: Every id reachable, stored or not, except the known-absent inputs and files.
        absent: Known-absent inputs (id -> role): left out of an import (``shallow/``) or, by the walk's
            ``leave_out``, left out of this walk (and reached by nothing else).
        absent_files: Known-absent files (id -> file name), the same way.
    """

    ids: set[str] = field(default_factory=set)
    absent: dict[str, str] = field(default_factory=dict)
    absent_files: dict[str, str] = field(default_factory=dict)

    def left_out(self) -> set[str]:
        """Every known-absent id, input or file."""
        return set(self.absent) | set(self.absent_files)


def walk(store: Store, roots: Iterable[str], *, strict: bool = True, leave_out: LeaveOut = NOTHING) -> Walk:
    """Every id reachable from ``roots`` (manifest -> files and inputs, recursively), and the known-absent ones.

    Roots and inputs must be manifests. Ids that are not stored are included (they are referenced) but not
    followed. An input under a role of :data:`~morfic_cli.store.shallow.OMITTABLE_ROLES`, or a file its manifest
    may lack (:func:`~morfic_cli.store.shallow.omittable_file`), that is missing but marked omitted
    (``shallow/<id>``) is known-absent, not damage; inputs under ``leave_out.roles`` and the files it leaves out
    (:meth:`~morfic_cli.store.shallow.LeaveOut.leaves_out`) are not followed (a weights-only or results-only export)
    unless something else reaches them.

    Args:
        store: The store.
        roots: Manifest ids (every version of the refs).
        strict: Raise when a root or input is missing (and not known-absent) or is not a readable manifest:
            what it names is then unknown, so gc and export must not guess.
        leave_out: What to leave out of this walk.

    Raises:
        StoreError: ``strict`` and some reachable manifest cannot be read; the message lists them.
    """
    seen: set[str] = set()
    manifests: set[str] = set()
    damaged: dict[str, str] = {}
    absent: dict[str, str] = {}
    absent_files: dict[str, str] = {}
    skipped: dict[str, str] = {}
    skipped_files: dict[str, str] = {}
    # (id, role, file name, kind): role "" a root, None a file (then its name and its manifest's kind)
    stack: list[tuple[str, str | None, str, str]] = [(oid, "", "", "") for oid in roots]
    while stack:
        while stack:
            oid, role, name, kind = stack.pop()
            must_be_manifest = role is not None
            if oid in seen and not (must_be_manifest and oid not in manifests and oid not in damaged):
                continue
            if not store.objects.has(oid) and store.omitted.has(oid):
                if must_be_manifest and role in OMITTABLE_ROLES:
                    absent[oid] = role
                    continue
                if not must_be_manifest and omittable_file(kind, name):
                    absent_files.setdefault(oid, name)
                    continue
            seen.add(oid)
            if not store.objects.has(oid):
                if must_be_manifest:
                    damaged[oid] = "missing"
                continue
            expected = must_be_manifest or store.index.has(oid)
            if not expected and store.objects.read_head(oid, len(MANIFEST_MAGIC)) != MANIFEST_MAGIC:
                continue
            try:
                manifest = parse_manifest(oid, store.objects.get_bytes(oid))
            except StoreError as exc:
                if expected:
                    damaged[oid] = "corrupt" if "corrupt" in str(exc) else "not a readable manifest"
                continue
            manifests.add(oid)
            for file_name, entry in manifest.files.items():
                if leave_out.leaves_out(oid, file_name, manifest.kind):
                    skipped_files.setdefault(entry.id, file_name)
                else:
                    stack.append((entry.id, None, file_name, manifest.kind))
            for input_role, input_id in manifest.inputs.items():
                if input_role in leave_out.roles:
                    skipped.setdefault(input_id, input_role)
                else:
                    stack.append((input_id, input_role, "", ""))
        # an omitted input that something else reaches (seen, say, as a plain file) is walked after all
        stack = [(oid, skipped.pop(oid), "", "") for oid in sorted(skipped) if oid in seen and oid not in manifests]
    absent.update((oid, role) for oid, role in skipped.items() if oid not in seen)
    absent_files.update((oid, name) for oid, name in skipped_files.items() if oid not in seen and oid not in absent)
    for oid in seen & set(absent_files):  # reached as something kept after all
        del absent_files[oid]
    if strict and damaged:
        listed = ", ".join(f"{oid} ({why})" for oid, why in sorted(damaged.items())[:10])
        more = f" and {len(damaged) - 10} more" if len(damaged) > 10 else ""
        raise StoreError(
            f"{len(damaged)} manifest(s) reachable from refs cannot be read: {listed}{more}; what "
            "they name is unknown, so refusing to delete or export anything. Run `morfic store "
            "verify`, restore them (`morfic store import` of an export that holds them), then retry."
        )
    return Walk(ids=seen - set(absent), absent=absent, absent_files=absent_files)


def closure(store: Store, roots: Iterable[str], *, strict: bool = True) -> set[str]:
    """Every id reachable from ``roots`` (:attr:`Walk.ids` of :func:`walk`: known-absent inputs left out)."""
    return walk(store, roots, strict=strict).ids


def ref_roots(store: Store, names: Iterable[str] | None = None) -> list[str]:
    """Ids of every version of the given refs (default: every ref)."""
    names = store.refs.names() if names is None else names
    return [entry.id for name in names for entry in store.refs.history(name)]


def temp_files(store: Store) -> list[str]:
    """Names of files left in ``tmp/`` by interrupted writes (and staging folders of killed imports)."""
    tmp = store.root / "tmp"
    return sorted(os.listdir(tmp)) if tmp.is_dir() else []


def collect_garbage(store: Store, *, dry_run: bool = True) -> GcReport:
    """Find (and unless ``dry_run``, delete) what no version of any ref reaches.

    Call with the exclusive store lock held.
    """
    report = GcReport(dry_run=dry_run)
    reached = walk(store, ref_roots(store))
    keep = reached.ids
    report.reachable = sum(1 for oid in keep if store.objects.has(oid))
    for oid in store.objects.iter_ids():
        if oid not in keep:
            manifest = load_manifest_if_any(store, oid, strict=False)
            kind = manifest.kind if manifest is not None else "blob"
            report.removed.append(GcItem(id=oid, kind=kind, size=store.objects.size(oid)))
    leftovers = temp_files(store)
    report.temp_files = len(leftovers)
    report.omitted = len(reached.left_out())
    if not dry_run:
        _delete(store, [item.id for item in report.removed], leftovers, reached.left_out())
    return report


def _delete(store: Store, oids: list[str], leftovers: list[str], absent: set[str]) -> None:
    for oid in oids:
        store.index.remove(oid)
        store.objects.remove(oid)
    for oid in list(store.index.ids()):
        if not store.objects.has(oid):
            store.index.remove(oid)
    for oid in list(store.omitted.ids()):
        if oid not in absent:  # filled since, or no longer reached: the marker says nothing any more
            store.omitted.remove(oid)
    for name in leftovers:
        path = store.root / "tmp" / name
        if path.is_dir() and not path.is_symlink():  # the staging folder of an import killed mid-way
            shutil.rmtree(path, ignore_errors=True)
        else:
            unlink_quiet(path)


def _rehash(path: os.PathLike[str]) -> tuple[str, int]:
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(CHUNK_SIZE), b""):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size


def verify_store(store: Store) -> VerifyReport:
    """Rehash every object and check that the index and every ref point at existing objects."""
    report = VerifyReport()
    _verify_objects(store, report)
    _verify_index(store, report)
    _verify_refs(store, report)
    report.temp_files = len(temp_files(store))
    return report


def _verify_objects(store: Store, report: VerifyReport) -> None:
    for oid in store.objects.iter_ids():
        try:
            actual, size = _rehash(store.objects.path(oid))
        except OSError as exc:
            report.problems.append(f"object {oid} cannot be read: {exc.strerror or exc}")
            continue
        report.objects += 1
        report.bytes += size
        if actual != oid:
            report.problems.append(f"object {oid} is corrupt: its bytes hash to {actual}")
    for path in store.objects.stray_files():
        report.problems.append(f"unexpected file in objects/: {path.relative_to(store.root)}")


def _verify_index(store: Store, report: VerifyReport) -> None:
    for name in store.index.stray():
        report.problems.append(f"unexpected file in manifests/: {name}")
    for name in store.omitted.stray():
        report.problems.append(f"unexpected file in shallow/: {name}")
    for oid in store.index.ids():
        report.manifests += 1
        if not store.objects.has(oid):
            report.problems.append(f"manifest index entry {oid} has no object")
            continue
        try:
            manifest = parse_manifest(oid, store.objects.get_bytes(oid, verify=False))
        except StoreError as exc:
            report.problems.append(f"manifest index entry {oid} is not a readable manifest: {exc}")
            continue
        _verify_manifest_links(store, manifest, report)


def _verify_manifest_links(store: Store, manifest: Manifest, report: VerifyReport) -> None:
    for name, entry in manifest.files.items():
        if omittable_file(manifest.kind, name) and store.is_omitted(entry.id):
            report.omitted_files += 1
        elif not store.objects.has(entry.id):
            report.problems.append(f"manifest {manifest.id}: file '{name}' object {entry.id} is missing")
        elif store.objects.size(entry.id) != entry.size:
            report.problems.append(
                f"manifest {manifest.id}: file '{name}' size {entry.size} does not "
                f"match its object ({store.objects.size(entry.id)} bytes)"
            )
    for role, oid in manifest.inputs.items():
        if role in OMITTABLE_ROLES and store.is_omitted(oid):
            report.omitted += 1
        elif not store.objects.has(oid):
            report.problems.append(f"manifest {manifest.id}: input '{role}' {oid} is missing")
        elif not store.index.has(oid):
            report.problems.append(f"manifest {manifest.id}: input '{role}' {oid} is not an indexed manifest")


def _verify_refs(store: Store, report: VerifyReport) -> None:
    for name in store.refs.names():
        report.refs += 1
        try:
            history = store.refs.history(name)
        except StoreError as exc:
            report.problems.append(str(exc))
            continue
        if not history:
            report.problems.append(f"ref '{name}' has an empty history")
        head = store.refs.head_problem(name, history)
        if head is not None:
            report.problems.append(head)
        for entry in history:
            if not store.objects.has(entry.id):
                report.problems.append(f"ref '{name}@{entry.version}' points at missing object {entry.id}")
            elif not store.index.has(entry.id):
                report.problems.append(
                    f"ref '{name}@{entry.version}' points at {entry.id}, which is not an indexed manifest"
                )
