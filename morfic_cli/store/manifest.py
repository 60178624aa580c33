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
from collections.abc import Iterable, Iterator
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

#: Longest accepted file name in a manifest (the whole relative name, and each '/'-separated part).
MAX_FILE_NAME = 255

#: Most '/'-separated parts of a manifest file name (``figures/ev.png`` has 2).
MAX_FILE_DEPTH = 4

#: Largest accepted manifest object (bytes); real manifests are a few KiB.
MAX_MANIFEST_BYTES = 16 << 20

#: Longest accepted ``morfic_version`` and input role.
MAX_LABEL = 100

_FILE_PART = re.compile(r"[^\x00-\x1f\x7f/\\:]+")
_LABEL = re.compile(r"[A-Za-z0-9._+-]+")
_ROLE = re.compile(r"[A-Za-z0-9._+-]+(/[A-Za-z0-9._+-]+)*")
_CREATED = re.compile(r"\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d{1,6})?Z")


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
            raise ArtifactNotFoundError(
                f"{self.kind} manifest {self.id[:12]} has no file '{name}'; its files are: {have}."
            )
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
        raise StoreError(
            f"cannot store this manifest as canonical JSON: {exc} (config and meta must "
            "hold only dicts with str keys, lists, str, int, finite float, bool, None)."
        ) from exc
    return text.encode("ascii")


def check_kind(kind: str) -> str:
    """Return ``kind`` if it is one of :data:`MANIFEST_KINDS`.

    Raises:
        StoreError: Unknown kind; the message lists the valid ones.
    """
    if kind not in MANIFEST_KINDS:
        raise StoreError(f"unknown manifest kind '{kind}'; valid kinds are: {', '.join(MANIFEST_KINDS)}.")
    return kind


def file_name_problem(name: object) -> str | None:
    """Why ``name`` is not a safe manifest file name, or ``None`` if it is.

    A safe name is relative and stays inside any folder it is joined to: 1 to
    :data:`MAX_FILE_DEPTH` parts separated by ``/``, each non-empty, not ``.`` or ``..``, without
    control characters, NUL, backslash or colon, at most :data:`MAX_FILE_NAME` characters in all.
    """
    if not isinstance(name, str):
        return f"is a {type(name).__name__}, not a string"
    if not name or len(name) > MAX_FILE_NAME:
        return f"must have 1 to {MAX_FILE_NAME} characters"
    if name.startswith("/"):
        return "is absolute"
    parts = name.split("/")
    if len(parts) > MAX_FILE_DEPTH:
        return f"has more than {MAX_FILE_DEPTH} '/'-separated parts"
    for part in parts:
        if part in ("", ".", ".."):
            return "has an empty, '.' or '..' part"
        if not _FILE_PART.fullmatch(part):
            return "holds a control character, NUL, '\\' or ':'"
    return None


#: Endings of the files Python runs or imports by itself from a folder on its path (``sitecustomize.py``, a
#: ``.pth`` file, an extension module): no artifact holds one (docs/concepts.md, "File names").
CODE_SUFFIXES = (".py", ".pyc", ".pyo", ".pyw", ".pyz", ".pth", ".so", ".pyd", ".dll", ".dylib", ".egg", ".whl")

_PLAIN_PART = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._+-]*")


def plain_name_problem(name: object) -> str | None:
    """Why ``name`` is not a file name morfic writes, stores or imports, or ``None`` if it is.

    :func:`file_name_problem`'s rule, plus: every part starts with an ASCII letter, digit or ``_`` (no hidden
    ``.config`` part, no leading ``-``) and holds only ASCII letters, digits, ``.``, ``_``, ``+`` and ``-``; and the
    name does not end in one of :data:`CODE_SUFFIXES` (any case). Every file morfic writes (``model.pt``,
    ``figures/ev.png``, ``eval.csv``) passes, so a name that does not came from a hand-made bundle: ``store
    import`` refuses it, and ``store get`` and every other write-out never write it (docs/concepts.md).
    """
    problem = file_name_problem(name)
    if problem is not None:
        return problem
    assert isinstance(name, str)
    bad = next((part for part in name.split("/") if not _PLAIN_PART.fullmatch(part)), None)
    if bad is not None and bad.startswith("."):
        return f"has the hidden part {ascii(bad[:40])} (starts with '.')"
    if bad is not None:
        return (
            f"has the part {ascii(bad[:40])}, which starts with or holds another character than ASCII letters, "
            "digits and '_' (then also '.', '+', '-')"
        )
    if name.lower().endswith(CODE_SUFFIXES):
        return (
            f"ends in {name[name.rfind('.') :]!r}, a file Python runs or imports from a folder on its path; no "
            "artifact holds code"
        )
    return None


def clashing_names(names: Iterable[str]) -> tuple[str, str] | None:
    """Two of ``names`` that cannot both be files of one folder, or None.

    They clash when they are equal, or equal but for case (one file on a case-insensitive file system), or when one
    is a folder part of the other (``figures`` and ``figures/ev.png``).
    Example: ``["A.csv", "a.csv"]`` -> ``("A.csv", "a.csv")``.
    """
    claims: dict[str, tuple[int, str, bool]] = {}  # case-folded path -> (which name, the name, is a file)
    for n, name in enumerate(names):
        parts = name.casefold().split("/")
        for i in range(1, len(parts) + 1):
            key, is_file = "/".join(parts[:i]), i == len(parts)
            other_n, other, other_file = claims.setdefault(key, (n, name, is_file))
            if other_n != n and (is_file or other_file):
                return other, name
    return None


def check_file_name(name: str) -> str:
    """Return ``name`` if it is a plain relative file name for a manifest (``a.csv``, ``figures/x.png``).

    Every manifest morfic writes (:func:`build_manifest`) and every file written out of the store
    (:func:`safe_join`) goes through here.

    Raises:
        StoreError: See :func:`plain_name_problem`.
    """
    problem = plain_name_problem(name)
    if problem is not None:
        raise StoreError(
            f"invalid manifest file name {ascii(str(name)[:80])}: it {problem}; use a relative name "
            "like 'curves.csv' or 'figures/ev.png' (ASCII letters, digits, '.', '_', '+', '-'; no "
            "leading '/' or '.', no '.' or '..' parts)."
        )
    return name


def safe_join(folder: Path, name: str) -> Path:
    """``folder / name`` for a manifest file name, refusing any name that would leave ``folder`` or is not plain.

    Every command that writes a manifest's files out goes through here (a manifest may come from an
    imported, untrusted bundle).

    Raises:
        StoreError: An unsafe name, or one that resolves outside ``folder`` (e.g. through a symlink).
    """
    check_file_name(name)
    base = Path(folder).resolve()
    path = base.joinpath(*name.split("/"))
    try:
        path.resolve().relative_to(base)
    except ValueError:
        raise StoreError(
            f"manifest file name {name!r} leads outside {folder} (through a symlink?); "
            "remove the link or write to an empty folder."
        ) from None
    return path


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
    clash = clashing_names(files or {})
    if clash is not None:
        raise StoreError(
            f"manifest files {clash[0]!r} and {clash[1]!r} cannot both be files of one folder (equal but "
            "for case, or one a folder of the other); rename one."
        )
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
    """Parse the bytes of object ``oid`` as a manifest, checking it against the schema.

    Raises:
        StoreError: The object is not a manifest (not canonical JSON of the schema), or a manifest
            whose content breaks the schema (the message names the field).
    """
    not_manifest = StoreError(
        f"object {oid} is not a manifest (a {len(data)}-byte blob); give the id "
        "or ref of a manifest, see `morfic store ls`."
    )
    if not data.startswith(MANIFEST_MAGIC):
        raise not_manifest
    if len(data) > MAX_MANIFEST_BYTES:
        raise StoreError(
            f"manifest {oid} is {len(data)} bytes, more than the {MAX_MANIFEST_BYTES} a manifest "
            "may have; it was not written by morfic."
        )
    try:
        doc = json.loads(data, parse_constant=_refuse_constant)
    except (ValueError, RecursionError):
        raise not_manifest from None
    if not isinstance(doc, dict) or set(doc) != MANIFEST_KEYS:
        raise not_manifest
    if doc["schema"] != SCHEMA_VERSION or isinstance(doc["schema"], bool):
        raise StoreError(
            f"manifest {oid} has schema {str(doc['schema'])[:40]!r}; this morfic reads schema "
            f"{SCHEMA_VERSION}. Upgrade morfic to read it."
        )
    problem = manifest_problem(doc)
    if problem is None and canonical_json(doc) != bytes(data):
        problem = "its bytes are not the canonical JSON of its content"
    if problem is not None:
        raise StoreError(
            f"manifest {oid} is invalid: {problem}. It was not written by morfic; drop it (or the bundle it came from)."
        )
    return _from_doc(oid, doc)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def manifest_problem(doc: dict[str, Any]) -> str | None:
    """What in a manifest document (already keyed by :data:`MANIFEST_KEYS`) breaks the schema, or ``None``.

    Checked: the kind, ``morfic_version`` (a short label), ``created`` (UTC ISO-8601 ending in ``Z``),
    ``config`` and ``meta`` (JSON objects), ``inputs`` (role -> full id), ``files`` (safe name ->
    ``{"id": full id, "size": int >= 0}``). NaN/Inf and non-canonical bytes are refused by the caller.
    """
    if doc["kind"] not in MANIFEST_KINDS:
        return f"unknown kind {str(doc['kind'])[:40]!r} (valid: {', '.join(MANIFEST_KINDS)})"
    version = doc["morfic_version"]
    if not (isinstance(version, str) and len(version) <= MAX_LABEL and _LABEL.fullmatch(version)):
        return "morfic_version is not a version label"
    if not _is_timestamp(doc["created"]):
        return "created is not a UTC time like 2025-01-02T03:04:05.123456Z"
    for what in ("config", "meta"):
        if not isinstance(doc[what], dict):
            return f"{what} is not a JSON object"
    inputs = doc["inputs"]
    if not isinstance(inputs, dict):
        return "inputs is not a JSON object"
    for role, oid in inputs.items():
        if not (len(role) <= 2 * MAX_LABEL and _ROLE.fullmatch(role)):
            return f"input role {role[:40]!r} is not a label like 'checkpoint' or 'rollout/go2/vx2'"
        if not (isinstance(oid, str) and is_object_id(oid)):
            return f"input '{role}' is not a full object id"
    files = doc["files"]
    if not isinstance(files, dict):
        return "files is not a JSON object"
    for name, entry in files.items():
        problem = file_name_problem(name)
        if problem is not None:
            return f"file name {name[:80]!r} {problem}"
        if not (isinstance(entry, dict) and set(entry) == {"id", "size"}):
            return f'file \'{name}\' is not {{"id": ..., "size": ...}}'
        if not (isinstance(entry["id"], str) and is_object_id(entry["id"])):
            return f"file '{name}' id is not a full object id"
        size = entry["size"]
        if isinstance(size, bool) or not isinstance(size, int) or size < 0:
            return f"file '{name}' size {str(size)[:40]} is not a byte count"
    return None


def _is_timestamp(text: Any) -> bool:
    if not (isinstance(text, str) and _CREATED.fullmatch(text)):
        return False
    try:
        datetime.strptime(text[:19], "%Y-%m-%dT%H:%M:%S")
    except ValueError:
        return False
    return True


def _from_doc(oid: str, doc: dict[str, Any]) -> Manifest:
    files = {n: FileEntry(id=f["id"], size=f["size"]) for n, f in doc["files"].items()}
    return Manifest(
        id=oid,
        kind=doc["kind"],
        schema=doc["schema"],
        morfic_version=doc["morfic_version"],
        created=doc["created"],
        config=doc["config"],
        inputs=dict(doc["inputs"]),
        files=files,
        meta=doc["meta"],
    )


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
