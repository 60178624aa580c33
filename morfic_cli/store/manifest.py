"""Manifests: canonical-JSON objects that describe one artifact, plus the ``manifests/`` index.

A manifest is stored as an ordinary object, so its id is the sha256 of its canonical JSON bytes
(``sort_keys=True``, ``separators=(",", ":")``, ``ensure_ascii=True``, no NaN/Inf). Its fields:

* ``schema`` -- manifest schema version (:data:`SCHEMA_VERSION`).
* ``kind`` -- one of :data:`MANIFEST_KINDS`.
* ``morfic_version`` -- the morfic version that wrote it.
* ``created`` -- UTC ISO-8601 time, e.g. ``2025-01-02T03:04:05.123456Z``.
* ``config`` -- the resolved configuration (any JSON object).
* ``inputs`` -- role -> id of every artifact it was made from.
* ``files`` -- name -> ``{"id": object id, "size": bytes}``.
* ``meta`` -- free-form JSON object (metrics, host, notes).

The index ``manifests/<id>`` holds one empty marker file per manifest so ``ls`` can list manifests
without scanning every object.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store.objects import is_object_id

#: Current manifest schema version.
SCHEMA_VERSION = 1

#: Valid values of a manifest's ``kind``.
MANIFEST_KINDS = ("run", "checkpoint", "eval", "diagnosis", "rollout", "table", "report", "export", "media")

#: The exact key set of a manifest document.
MANIFEST_KEYS = frozenset({"schema", "kind", "morfic_version", "created", "config", "inputs", "files", "meta"})

#: Every canonical manifest starts with these bytes ("config" sorts first among its keys).
MANIFEST_MAGIC = b'{"config":'

_FILE_NAME = re.compile(r"[^\x00-\x1f\\]+")


@dataclass(frozen=True)
class FileEntry:
    """One file of a manifest.

    Attributes:
        id: Object id of the file's bytes.
        size: Size in bytes.
    """

    id: str
    size: int


@dataclass(frozen=True)
class Manifest:
    """A parsed manifest (see the module docstring for the meaning of each field).

    Attributes:
        id: The manifest's own object id.
        kind: One of :data:`MANIFEST_KINDS`.
        schema: Manifest schema version.
        morfic_version: morfic version that wrote it.
        created: UTC ISO-8601 creation time.
        config: Resolved configuration.
        inputs: Role -> id of the artifacts it was made from.
        files: Name -> :class:`FileEntry`.
        meta: Free-form metadata.
    """

    id: str
    kind: str
    schema: int
    morfic_version: str
    created: str
    config: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    files: dict[str, FileEntry] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The manifest document (without ``id``), exactly as stored."""
        return {
            "schema": self.schema,
            "kind": self.kind,
            "morfic_version": self.morfic_version,
            "created": self.created,
            "config": self.config,
            "inputs": dict(self.inputs),
            "files": {n: {"id": f.id, "size": f.size} for n, f in self.files.items()},
            "meta": self.meta,
        }

    def file(self, name: str) -> FileEntry:
        """The entry of file ``name``.

        Raises:
            ArtifactNotFoundError: No such file; the message lists the files it has.
        """
        if name not in self.files:
            have = ", ".join(sorted(self.files)) or "none"
            raise ArtifactNotFoundError(f"{self.kind} manifest {self.id[:12]} has no file '{name}'; "
                                        f"its files are: {have}.")
        return self.files[name]

    def referenced_ids(self) -> list[str]:
        """Ids this manifest points at: its files, then its inputs (for gc and export closure)."""
        return [f.id for f in self.files.values()] + list(self.inputs.values())


def utc_now() -> str:
    """Current UTC time as ISO-8601 with microseconds and a ``Z`` suffix."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def canonical_json(doc: Any) -> bytes:
    """Canonical JSON bytes: sorted keys, no spaces, ASCII only, NaN/Inf refused.

    Raises:
        StoreError: ``doc`` holds something JSON cannot represent exactly.
    """
    try:
        text = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise StoreError(f"cannot store this manifest as canonical JSON: {exc} (config and meta must "
                         "hold only dicts with str keys, lists, str, int, finite float, bool, None).") from exc
    return text.encode("ascii")


def check_kind(kind: str) -> str:
    """Return ``kind`` if it is one of :data:`MANIFEST_KINDS`.

    Raises:
        StoreError: Unknown kind; the message lists the valid ones.
    """
    if kind not in MANIFEST_KINDS:
        raise StoreError(f"unknown manifest kind '{kind}'; valid kinds are: {', '.join(MANIFEST_KINDS)}.")
    return kind


def check_file_name(name: str) -> str:
    """Return ``name`` if it is a valid relative file name inside a manifest (``a.csv``, ``x/y.pt``).

    Raises:
        StoreError: Empty, absolute, with a ``.``/``..`` segment, a backslash or control characters.
    """
    segments = name.split("/") if isinstance(name, str) else []
    if not (isinstance(name, str) and _FILE_NAME.fullmatch(name)) or any(s in ("", ".", "..") for s in segments):
        raise StoreError(f"invalid manifest file name {name!r}: use a relative name like 'curves.csv' "
                         "or 'ckpt/model.pt' (no leading '/', no '.' or '..' segments).")
    return name


def build_manifest(
    kind: str,
    *,
    created: str,
    morfic_version: str,
    config: dict[str, Any] | None = None,
    inputs: dict[str, str] | None = None,
    files: dict[str, FileEntry] | None = None,
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The manifest document for already-stored files and inputs (pure; nothing is written)."""
    for what, value in (("config", config), ("meta", meta), ("inputs", inputs), ("files", files)):
        if value is not None and not isinstance(value, dict):
            raise StoreError(f"manifest {what} must be a dict, not {type(value).__name__}.")
    return {
        "schema": SCHEMA_VERSION,
        "kind": check_kind(kind),
        "morfic_version": morfic_version,
        "created": created,
        "config": dict(config or {}),
        "inputs": dict(sorted((inputs or {}).items())),
        "files": {check_file_name(n): {"id": f.id, "size": f.size} for n, f in sorted((files or {}).items())},
        "meta": dict(meta or {}),
    }


def parse_manifest(oid: str, data: bytes) -> Manifest:
    """Parse the bytes of object ``oid`` as a manifest.

    Raises:
        StoreError: The object is not a manifest (not JSON, wrong keys, bad ids or schema).
    """
    not_manifest = StoreError(f"object {oid} is not a manifest (a {len(data)}-byte blob); give the id "
                              "or ref of a manifest, see `morfic store ls`.")
    if not data.startswith(MANIFEST_MAGIC):
        raise not_manifest
    try:
        doc = json.loads(data)
    except ValueError:
        raise not_manifest from None
    if not isinstance(doc, dict) or set(doc) != MANIFEST_KEYS:
        raise not_manifest
    if doc["schema"] != SCHEMA_VERSION:
        raise StoreError(f"manifest {oid} has schema {doc['schema']!r}; this morfic reads schema "
                         f"{SCHEMA_VERSION}. Upgrade morfic to read it.")
    try:
        return _from_doc(oid, doc)
    except (TypeError, KeyError, AttributeError, ValueError):
        raise not_manifest from None


def _from_doc(oid: str, doc: dict[str, Any]) -> Manifest:
    files = {str(n): FileEntry(id=str(f["id"]), size=int(f["size"])) for n, f in doc["files"].items()}
    inputs = {str(r): str(i) for r, i in doc["inputs"].items()}
    if not all(is_object_id(i) for i in [*inputs.values(), *(f.id for f in files.values())]):
        raise ValueError("bad id")
    if not isinstance(doc["config"], dict) or not isinstance(doc["meta"], dict):
        raise ValueError("config/meta")
    return Manifest(id=oid, kind=str(doc["kind"]), schema=int(doc["schema"]),
                    morfic_version=str(doc["morfic_version"]), created=str(doc["created"]),
                    config=doc["config"], inputs=inputs, files=files, meta=doc["meta"])


class ManifestIndex:
    """``manifests/<id>``: one empty marker file per manifest object."""

    def __init__(self, root: Path) -> None:
        self.dir = root / "manifests"

    def add(self, oid: str) -> None:
        """Record ``oid`` as a manifest. Creating an empty file is atomic; re-adding is a no-op."""
        self.dir.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(self.dir / oid, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o444)
        except FileExistsError:
            return
        os.close(fd)

    def has(self, oid: str) -> bool:
        """Whether ``oid`` is indexed as a manifest."""
        return is_object_id(oid) and (self.dir / oid).is_file()

    def ids(self) -> Iterator[str]:
        """Every indexed manifest id, sorted."""
        if not self.dir.is_dir():
            return iter(())
        return iter(sorted(e for e in os.listdir(self.dir) if is_object_id(e)))

    def stray(self) -> list[str]:
        """Names in ``manifests/`` that are not ids."""
        if not self.dir.is_dir():
            return []
        return sorted(e for e in os.listdir(self.dir) if not is_object_id(e))

    def remove(self, oid: str) -> None:
        """Drop ``oid`` from the index (gc only)."""
        try:
            os.unlink(self.dir / oid)
        except FileNotFoundError:
            pass
