"""The artifact store: content-addressed objects, manifests and refs (docs/concepts.md).

:class:`Store` is the one entry point; the modules beside it do the file work:
``objects`` (immutable blobs), ``manifest`` (manifest schema and index), ``refs`` (named, versioned
pointers), ``lock`` (flock-based locks), ``gc`` (reachability, verify, gc), ``transfer``
(export/import tar files), ``shallow`` (what a weights-only or results-only bundle leaves out) and ``results``
(which refs hold a run's results).
``docs/concepts.md`` describes the layout and guarantees. The store knows nothing about RL beyond the
names of what a bundle may leave out (``shallow``) and which manifest kinds are results (``results``), and never
imports torch or mujoco.

Example::

    store = Store("artifacts")
    with store.writing():
        ckpt = store.put_manifest("checkpoint", files={"model.pt": Path("model.pt")})
        run = store.put_manifest("run", config={"variant": "film"}, inputs={"checkpoint": ckpt})
        store.set_ref("runs/film-cpu-s0", run)
    store.read_manifest("runs/film-cpu-s0@1").inputs["checkpoint"]
"""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from morfic_cli import __version__
from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store.gc import GcItem, GcReport, VerifyReport, collect_garbage, load_manifest_if_any, verify_store
from morfic_cli.store.lock import StoreLock, default_timeout
from morfic_cli.store.manifest import (
    MANIFEST_KINDS,
    FileEntry,
    Manifest,
    ManifestIndex,
    build_manifest,
    canonical_json,
    check_file_name,
    check_kind,
    manifest_problem,
    parse_manifest,
    utc_now,
)
from morfic_cli.store.objects import ObjectDB, store_os_error
from morfic_cli.store.publish import Published, publish
from morfic_cli.store.refs import ANY, RefDB, RefEntry, RefMovedError, check_ref_name, pick_version, split_spec
from morfic_cli.store.results import RUN_FILE
from morfic_cli.store.shallow import OMITTABLE_ROLES, OmittedIndex, omittable_file
from morfic_cli.store.transfer import AppendRule, ExportReport, ImportReport, export_tar, import_tar

__all__ = [
    "MANIFEST_KINDS",
    "ExportReport",
    "FileEntry",
    "GcItem",
    "GcReport",
    "ImportReport",
    "Manifest",
    "Published",
    "RefEntry",
    "RefMovedError",
    "Store",
    "VerifyReport",
]

#: Shortest id prefix accepted by :meth:`Store.resolve`.
MIN_PREFIX = 4

_HEX = re.compile(r"[0-9a-f]+")
_LAYOUT = ("objects", "manifests", "refs", "tmp", "locks")


class Store:
    """An artifact store rooted at a directory (created lazily on the first write).

    Args:
        root: Store root directory. A missing directory reads as an empty store.
        lock_timeout: Seconds to wait for a lock before raising :class:`StoreError` (default: env
            ``MORFIC_LOCK_TIMEOUT``, else :data:`~morfic_cli.store.lock.DEFAULT_TIMEOUT_S`, 60 s).

    Raises:
        StoreError: ``root`` (or a folder on its way) is an existing file, or ``MORFIC_LOCK_TIMEOUT`` is not a
            number of seconds.
    """

    def __init__(self, root: Path | str, *, lock_timeout: float | None = None) -> None:
        self.root = Path(root)
        for path in (self.root, *self.root.parents):
            if path.exists():
                if not path.is_dir():
                    raise StoreError(
                        f"store root {self.root}: {path} is a file, not a directory; pass a folder (or a "
                        "path that does not exist yet) to --store or MORFIC_STORE."
                    )
                break
        self.lock_timeout = default_timeout() if lock_timeout is None else lock_timeout
        self.objects = ObjectDB(self.root)
        self.index = ManifestIndex(self.root)
        self.refs = RefDB(self.root, self.lock_timeout)
        self.omitted = OmittedIndex(self.root)
        self._lock = StoreLock(self.root / "locks" / "store.lock", self.lock_timeout)

    def __repr__(self) -> str:
        return f"Store({str(self.root)!r})"

    # -- locking and layout -------------------------------------------------------------------

    @contextmanager
    def writing(self) -> Iterator[Store]:
        """Hold the store lock shared so ``gc`` cannot delete what you write before you name it.

        Wrap every sequence "put objects / manifests -> set_ref" in one ``with store.writing():``.
        Re-entrant; the single calls take it themselves too.
        """
        self._ensure_layout()
        with self._lock.shared():
            yield self

    @contextmanager
    def reading(self) -> Iterator[Store]:
        """Hold the store lock shared while reading many objects (no-op for a missing store)."""
        if not self.root.is_dir():
            yield self
            return
        with self._lock.shared():
            yield self

    def _ensure_layout(self) -> None:
        if self.root.exists() and not self.root.is_dir():
            raise StoreError(f"store root {self.root} exists but is not a directory; pass another --store.")
        try:
            for sub in _LAYOUT:
                (self.root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise store_os_error(exc, "creating the store layout", self.root) from exc

    # -- objects ------------------------------------------------------------------------------

    def put_bytes(self, data: bytes) -> str:
        """Store ``data`` as an object; return its id (sha256 hex). Idempotent."""
        if not isinstance(data, bytes | bytearray | memoryview):
            raise TypeError(f"put_bytes needs bytes, not {type(data).__name__}")
        with self.writing():
            return self.objects.put_bytes(bytes(data))

    def put_file(self, path: Path) -> str:
        """Stream the file at ``path`` into the store; return its id (same as ``put_bytes`` of it)."""
        with self.writing():
            return self.objects.put_file(Path(path))

    def has(self, oid: str) -> bool:
        """Whether object ``oid`` (a full id) is stored."""
        return self.objects.has(oid)

    def get_bytes(self, oid: str) -> bytes:
        """The bytes of object ``oid`` (a full id), checked against their hash.

        Raises:
            ArtifactNotFoundError: No such object.
            StoreError: The object is corrupt.
        """
        return self.objects.get_bytes(oid)

    def is_omitted(self, oid: str) -> bool:
        """Whether ``oid`` was left out of a weights- or results-only import (``shallow/<id>``) and is not stored."""
        return self.omitted.has(oid) and not self.objects.has(oid)

    def omitted_inputs(self, manifest: Manifest) -> dict[str, str]:
        """Role -> id of the inputs of ``manifest`` that a weights-only import left out (empty for a full store)."""
        return {role: oid for role, oid in manifest.inputs.items() if role in OMITTABLE_ROLES and self.is_omitted(oid)}

    def omitted_files(self, manifest: Manifest) -> dict[str, str]:
        """File name -> id of the files of ``manifest`` an import left out (weights, logs, curves, figures)."""
        return {
            name: entry.id
            for name, entry in manifest.files.items()
            if omittable_file(manifest.kind, name) and self.is_omitted(entry.id)
        }

    def weights_omitted(self, manifest: Manifest) -> bool:
        """Whether ``manifest``'s weights (``model.pt``) were left out (a run imported from a results-only bundle).

        False for a manifest without ``model.pt`` (not a checkpoint): whether it is one is the caller's check.
        """
        return RUN_FILE in self.omitted_files(manifest)

    def object_path(self, oid: str) -> Path:
        """Path of object ``oid`` (read-only; never write to it)."""
        return self.objects.path(oid)

    # -- manifests ----------------------------------------------------------------------------

    def put_manifest(
        self,
        kind: str,
        *,
        config: dict[str, Any] | None = None,
        inputs: dict[str, str] | None = None,
        files: Mapping[str, bytes | Path] | None = None,
        meta: dict[str, Any] | None = None,
    ) -> str:
        """Store the files and a manifest describing them; return the manifest id.

        Args:
            kind: One of :data:`MANIFEST_KINDS`.
            config: The resolved configuration (JSON object).
            inputs: Role -> id (or ref / prefix, resolved to the full id) of each input artifact.
            files: Name -> bytes, or Path of a file to stream in.
            meta: Free-form JSON metadata.

        Raises:
            StoreError: Unknown kind, missing input, bad file name, or data that is not JSON.
        """
        check_kind(kind)
        with self.writing():
            input_ids = {role: self._input_id(role, spec) for role, spec in (inputs or {}).items()}
            entries = {check_file_name(name): self._put_entry(name, value) for name, value in (files or {}).items()}
            doc = build_manifest(
                kind,
                created=utc_now(),
                morfic_version=__version__,
                config=config,
                inputs=input_ids,
                files=entries,
                meta=meta,
            )
            problem = manifest_problem(doc)
            if problem is not None:
                raise StoreError(f"cannot store this {kind} manifest: {problem}.")
            oid = self.objects.put_bytes(canonical_json(doc))
            self.index.add(oid)
        return oid

    def _input_id(self, role: str, spec: str) -> str:
        if not isinstance(spec, str):
            raise StoreError(f"manifest input '{role}' must be an artifact id or ref, not {type(spec).__name__}.")
        try:
            oid = self.resolve(spec)
        except ArtifactNotFoundError as exc:
            raise StoreError(f"manifest input '{role}': {exc}") from exc
        if not self.index.has(oid):
            raise StoreError(
                f"manifest input '{role}' must be a manifest, but {oid} is a plain object; give the "
                "id or ref of a manifest (see `morfic store ls`)."
            )
        return oid

    def _put_entry(self, name: str, value: bytes | Path) -> FileEntry:
        if isinstance(value, bytes | bytearray | memoryview):
            data = bytes(value)
            return FileEntry(id=self.objects.put_bytes(data), size=len(data))
        if isinstance(value, os.PathLike):
            oid = self.objects.put_file(Path(value))
            return FileEntry(id=oid, size=self.objects.size(oid))
        raise TypeError(f"manifest file '{name}' must be bytes or a pathlib.Path, not {type(value).__name__}")

    def read_manifest(self, spec_or_id: str) -> Manifest:
        """The manifest named by a ref, ``ref@N``, id or id prefix.

        Raises:
            ArtifactNotFoundError: Nothing matches.
            StoreError: The object is not a manifest, or is corrupt.
        """
        oid = self.resolve(spec_or_id)
        return parse_manifest(oid, self.objects.get_bytes(oid))

    def read_file(self, manifest_spec: str, name: str) -> bytes:
        """The bytes of file ``name`` of a manifest (checked against their hash)."""
        return self.objects.get_bytes(self._file_entry(manifest_spec, name).id)

    def file_path(self, manifest_spec: str, name: str) -> Path:
        """Read-only path of file ``name`` of a manifest, for readers that want a path (not rehashed)."""
        entry = self._file_entry(manifest_spec, name)
        if not self.objects.has(entry.id):
            raise ArtifactNotFoundError(
                f"file '{name}' ({entry.id}) of manifest {manifest_spec} is missing "
                "from the store; run `morfic store verify`."
            )
        return self.objects.path(entry.id)

    def _file_entry(self, manifest_spec: str, name: str) -> FileEntry:
        """File ``name`` of a manifest; one a results-only bundle left out is an error that says so."""
        manifest = self.read_manifest(manifest_spec)
        entry = manifest.file(name)
        if omittable_file(manifest.kind, name) and self.is_omitted(entry.id):
            raise ArtifactNotFoundError(
                f"file '{name}' ({entry.id[:12]}) of {manifest_spec} is not in store "
                f"{self.root}: a results-only bundle left it out (results without weights, "
                "rollout logs, rendered figures or other runs' curves); `morfic report` "
                "draws the figures from the tables, and a bundle that holds the file (the "
                "run's weights-only or full bundle) brings it."
            )
        return entry

    # -- refs ---------------------------------------------------------------------------------

    def set_ref(self, name: str, oid: str, *, expect: str | None | object = ANY) -> int:
        """Point ref ``name`` at a manifest, appending a version; return its 1-based version number.

        ``oid`` may be a full id, a prefix or another ref. Setting a ref to the manifest it already
        points at adds no version and returns the current one. ``expect`` makes it a compare-and-set: the
        full id the ref must point at now, or ``None`` for a ref that must not exist yet (how a training
        refuses to interleave its checkpoints with another process's in one run).

        Raises:
            StoreError: Invalid name, a name clash with a folder of refs, or ``oid`` is not a manifest.
            RefMovedError: ``expect`` was given and the ref points elsewhere; nothing was written.
        """
        check_ref_name(name)
        with self.writing():
            target = self.resolve(oid)
            if not self.index.has(target):
                raise StoreError(
                    f"refs name manifests, but {target} is not one; give the id of a manifest (see `morfic store ls`)."
                )
            return self.refs.append(name, target, utc_now(), expect=expect)

    def publish(self, kind: str, ref: str | None = None, **kwargs: Any) -> Published:
        """Store a result as one manifest and advance ``ref`` (see :func:`morfic_cli.store.publish.publish`)."""
        return publish(self, kind, ref, **kwargs)

    def ref_history(self, name: str) -> list[RefEntry]:
        """Every version of ref ``name``, oldest first.

        Raises:
            ArtifactNotFoundError: No such ref.
        """
        history = self.refs.history(check_ref_name(name))
        if not history:
            raise self._not_found(name)
        return history

    def has_ref(self, name: str) -> bool:
        """Whether ref ``name`` exists."""
        return self.refs.exists(name)

    def list_refs(self) -> list[str]:
        """Every ref name, sorted."""
        return self.refs.names()

    # -- resolution ---------------------------------------------------------------------------

    def resolve(self, spec: str) -> str:
        """The full id named by ``spec``.

        Tried in this order: ``name@N`` / ``name@-K`` (a ref version), a ref name (its current
        version), a full 64-hex id, a unique hex prefix of at least :data:`MIN_PREFIX` characters.

        Raises:
            ArtifactNotFoundError: Nothing matches, or the prefix is ambiguous (candidates listed).
            StoreError: A malformed ``@`` version.
        """
        text = spec.strip()
        name, version = split_spec(text)
        if version is not None:
            history = self.refs.history(check_ref_name(name))
            if not history:
                raise self._not_found(text)
            return pick_version(name, history, version).id
        if self.refs.exists(text):
            history = self.refs.history(text)
            if history:
                return history[-1].id
        lowered = text.lower()
        if text and _HEX.fullmatch(lowered):
            return self._resolve_hex(text, lowered)
        raise self._not_found(text)

    def _resolve_hex(self, text: str, hexid: str) -> str:
        if len(hexid) == 64:
            if self.objects.has(hexid):
                return hexid
            if self.is_omitted(hexid):
                raise ArtifactNotFoundError(
                    f"artifact {hexid} is not in store {self.root}: a weights-only bundle "
                    "left it out (a trainer state), or a results-only one (a trainer state, "
                    "weights, a rollout log or a figure); import the full bundle to get it."
                )
            raise self._not_found(text)
        if len(hexid) < MIN_PREFIX or len(hexid) > 64:
            raise ArtifactNotFoundError(
                f"id prefix '{text}' is too short: give at least {MIN_PREFIX} hex characters (see `morfic store ls`)."
            )
        matches = self.objects.find_prefix(hexid)
        if len(matches) == 1:
            return matches[0]
        if not matches:
            raise self._not_found(text)
        shown = ", ".join(f"{m} ({self._kind_of(m)})" for m in matches[:10])
        more = f" and {len(matches) - 10} more" if len(matches) > 10 else ""
        raise ArtifactNotFoundError(
            f"id prefix '{text}' is ambiguous: it matches {len(matches)} objects: {shown}{more}. Give more characters."
        )

    def _kind_of(self, oid: str) -> str:
        manifest = load_manifest_if_any(self, oid, strict=False)
        return manifest.kind if manifest is not None else "blob"

    def _not_found(self, spec: str) -> ArtifactNotFoundError:
        if not self.root.is_dir():
            return ArtifactNotFoundError(
                f"no artifact '{spec}': the store {self.root} does not exist yet "
                "(pass --store or set MORFIC_STORE); try `morfic store ls`."
            )
        close = difflib.get_close_matches(spec.split("@")[0], self.refs.names(), n=3)
        hint = f" Did you mean: {', '.join(close)}?" if close else ""
        return ArtifactNotFoundError(
            f"no artifact '{spec}' in store {self.root} (not a ref, a ref@version, "
            f"an id or a unique id prefix); try `morfic store ls`.{hint}"
        )

    # -- listing ------------------------------------------------------------------------------

    def ls(self, kind: str | None = None, *, include_superseded: bool = True) -> list[dict[str, Any]]:
        """One row per manifest, oldest first: ``ref``, ``id``, ``kind``, ``created``, ``files``, ``size``.

        ``size`` counts the files this store holds (a results-only import leaves weights and logs out).

        ``ref`` is the name of a ref whose current version is this manifest; else ``name@N`` for
        an old version of a ref; else ``None``.

        Args:
            kind: Only manifests of this kind.
            include_superseded: Include manifests reachable only as old ref versions (``name@N``).
        """
        if kind is not None:
            check_kind(kind)
        labels = self._ref_labels()
        rows = []
        for oid in self.index.ids():
            label = labels.get(oid, [None])[0]
            if not include_superseded and label is not None and "@" in label:
                continue
            row = self._ls_row(oid, label)
            if kind is None or row["kind"] == kind:
                rows.append(row)
        return sorted(rows, key=lambda r: (r["created"] or "", r["id"]))

    def _ls_row(self, oid: str, label: str | None) -> dict[str, Any]:
        try:
            manifest = parse_manifest(oid, self.objects.get_bytes(oid, verify=False))
        except StoreError:
            return {"ref": label, "id": oid, "kind": None, "created": None, "files": None, "size": None}
        absent = self.omitted_files(manifest)  # left out by a results-only import: not held, not counted
        return {
            "ref": label,
            "id": oid,
            "kind": manifest.kind,
            "created": manifest.created,
            "files": len(manifest.files),
            "size": sum(f.size for n, f in manifest.files.items() if n not in absent),
        }

    def _ref_labels(self) -> dict[str, list[str]]:
        """Id -> every ref label naming it: current names first (sorted), then ``name@N`` (newest first)."""
        current: dict[str, list[str]] = {}
        old: dict[str, list[str]] = {}
        for name in self.refs.names():
            try:
                history = self.refs.history(name)
            except StoreError:
                continue
            if history:
                current.setdefault(history[-1].id, []).append(name)
            for entry in reversed(history[:-1]):
                old.setdefault(entry.id, []).append(f"{name}@{entry.version}")
        ids = set(current) | set(old)
        return {oid: current.get(oid, []) + old.get(oid, []) for oid in ids}

    def describe(self, spec: str) -> dict[str, Any]:
        """What ``morfic store show`` prints: the manifest (or blob size) plus every ref label naming it."""
        oid = self.resolve(spec)
        refs = self._ref_labels().get(oid, [])
        if self.index.has(oid):
            manifest: Manifest | None = self.read_manifest(oid)
        else:
            manifest = load_manifest_if_any(self, oid, strict=False)
        if manifest is None:
            return {"id": oid, "kind": None, "size": self.objects.size(oid), "refs": refs}
        omitted, files = self.omitted_inputs(manifest), self.omitted_files(manifest)
        return {
            "id": oid,
            "refs": refs,
            **manifest.to_dict(),
            **({"omitted": omitted} if omitted else {}),
            **({"omitted_files": files} if files else {}),
        }

    # -- maintenance --------------------------------------------------------------------------

    def verify(self) -> VerifyReport:
        """Rehash every object and check the manifest index and every ref; see :class:`VerifyReport`."""
        with self.reading():
            return verify_store(self)

    def gc(self, dry_run: bool = True) -> GcReport:
        """Remove objects that no version of any ref reaches, and leftover temp files.

        Holds the store lock exclusively (waits for writers in ``store.writing()`` to finish).

        Args:
            dry_run: Only report what would be removed.
        """
        if not self.root.is_dir():
            return GcReport(dry_run=dry_run)
        with self._lock.exclusive():
            return collect_garbage(self, dry_run=dry_run)

    def export_tar(
        self,
        refs: list[str],
        out: Path,
        *,
        latest: bool = False,
        without_trainer_state: bool = False,
        results_only: bool = False,
    ) -> ExportReport:
        """Write the closure of ``refs`` (every version, or only the current one with ``latest``) to the tar ``out``.

        ``without_trainer_state``: a weights-only bundle; ``results_only``: ``refs`` are runs, and the bundle holds
        their results without weights or logs (see :func:`morfic_cli.store.transfer.export_tar`).
        """
        return export_tar(
            self, refs, Path(out), latest=latest, without_trainer_state=without_trainer_state, results_only=results_only
        )

    def import_tar(self, path: Path, *, append: AppendRule = False) -> ImportReport:
        """Import a tar made by :meth:`export_tar`; idempotent (see :class:`ImportReport`; ``append``: there)."""
        return import_tar(self, Path(path), append=append)
