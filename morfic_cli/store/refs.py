"""Refs: human names for manifests (``runs/film-cpu-s0``) with an append-only history.

Each ref is one file ``refs/<name>`` holding its whole history as JSON lines, oldest first::

    {"id":"<64 hex>","time":"2025-01-02T03:04:05.123456Z","version":1}
    {"id":"<64 hex>","prev":"<sha256 of line 1>","time":"2025-01-02T04:00:00.000000Z","version":2}

The current value is the last line. An update appends a line by writing the full new history to a
temp file and renaming it over the old one, under the exclusive ``locks/refs.lock``, so
concurrent writers never lose an update and a crash leaves either the old or the new history.

Tamper evidence: every entry after the first carries ``prev``, the sha256 of the previous line's
bytes (a hash chain), so an edited, reordered or dropped line breaks the chain. After each update the
head -- version and sha256 of the last line -- is written to ``heads/<name>``; a history shorter than
its head was truncated. Both are checked by ``morfic store verify``. Histories written before the
chain existed (no ``prev``) still read; the chain starts at their first new entry.

Version syntax (see :func:`split_spec`): ``name`` is the current version, ``name@N`` (N >= 1)
is version N counted from the first, ``name@-K`` (K >= 1) is K updates before the current one
(``name@-1`` is the previous version).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store.lock import file_lock
from morfic_cli.store.objects import is_object_id, store_os_error, unlink_quiet, write_atomic

_SEGMENT = re.compile(r"[A-Za-z0-9._-]+")
_TIME = re.compile(r"\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d{1,6})?Z")
_ENTRY_KEYS = (frozenset({"id", "time", "version"}), frozenset({"id", "prev", "time", "version"}))

#: Longest accepted ref name.
MAX_REF_LENGTH = 200


@dataclass(frozen=True)
class RefEntry:
    """One version of a ref.

    Attributes:
        version: 1-based version number.
        id: Manifest id the ref pointed to at this version.
        time: UTC ISO-8601 time of the update.
        prev: sha256 of the previous history line (``None`` for version 1 and for entries written
            before the hash chain existed).
    """

    version: int
    id: str
    time: str
    prev: str | None = None


def is_ref_name(name: str) -> bool:
    """Whether ``name`` is a valid ref name (see :func:`check_ref_name`)."""
    if not name or len(name) > MAX_REF_LENGTH or ".." in name:
        return False
    return all(_SEGMENT.fullmatch(s) and s != "." for s in name.split("/"))


def check_ref_name(name: str) -> str:
    """Return ``name`` if valid: ``[A-Za-z0-9._-]`` segments joined by ``/``, no ``..``, no ``@``.

    Raises:
        StoreError: Invalid name; the message says what a valid one looks like.
    """
    if not is_ref_name(name):
        raise StoreError(
            f"invalid ref name '{name}': use segments of letters, digits, '.', '_' and '-' "
            "separated by '/', e.g. 'runs/film-cpu-s0' (no '..', no '@', at most "
            f"{MAX_REF_LENGTH} characters)."
        )
    return name


def split_spec(spec: str) -> tuple[str, int | None]:
    """Split ``name@N`` into ``(name, N)``; a spec without ``@`` gives ``(spec, None)``.

    Raises:
        StoreError: The part after ``@`` is not a non-zero integer.
    """
    if "@" not in spec:
        return spec, None
    name, _, version = spec.rpartition("@")
    try:
        number = int(version)
    except ValueError:
        number = 0
    if number == 0 or not version.lstrip("-").isdigit():
        raise StoreError(
            f"invalid ref version in '{spec}': use name@N for version N (1 is the first) or "
            "name@-K for K updates before the current one (name@-1 is the previous)."
        )
    return name, number


def pick_version(name: str, history: list[RefEntry], number: int) -> RefEntry:
    """The entry of ``history`` selected by ``@number`` (positive: absolute; negative: back from current).

    Raises:
        ArtifactNotFoundError: No such version; the message gives the valid range.
    """
    count = len(history)
    index = number - 1 if number > 0 else count - 1 + number
    if not 0 <= index < count:
        raise ArtifactNotFoundError(
            f"ref '{name}' has no version @{number}: it has versions 1..{count} (@{count} is current; "
            f"@-1 .. @-{count - 1} count back from it). See `morfic store show {name} --history`."
        )
    return history[index]


def encode_entry(entry: RefEntry) -> bytes:
    """One history line (canonical JSON, no newline)."""
    doc = {"id": entry.id, "time": entry.time, "version": entry.version}
    if entry.prev is not None:
        doc["prev"] = entry.prev
    return json.dumps(doc, sort_keys=True, separators=(",", ":")).encode("ascii")


def entry_hash(entry: RefEntry) -> str:
    """sha256 hex of an entry's line: what the next entry's ``prev`` holds."""
    return hashlib.sha256(encode_entry(entry)).hexdigest()


def next_entry(history: list[RefEntry], oid: str, time: str) -> RefEntry:
    """The entry that appends ``oid`` to ``history`` (chained to its last line)."""
    prev = entry_hash(history[-1]) if history else None
    return RefEntry(version=len(history) + 1, id=oid, time=time, prev=prev)


def encode_history(entries: list[RefEntry]) -> bytes:
    """The bytes of a ref history file (one canonical JSON object per line)."""
    return b"".join(encode_entry(e) + b"\n" for e in entries)


def decode_history(name: str, data: bytes) -> list[RefEntry]:
    """Parse a ref history file and check its hash chain.

    Raises:
        StoreError: A line that is not a valid entry, versions that are not 1, 2, 3, ..., a time that is
            not a UTC timestamp, a broken chain (an edited, dropped or reordered line), or a missing last
            newline (a truncated file).
    """

    def damaged(number: int, why: str) -> StoreError:
        return StoreError(
            f"ref '{name}' is damaged (line {number}: {why}); run `morfic store verify`, and "
            "re-import the ref from an export if it was tampered with."
        )

    entries: list[RefEntry] = []
    if data and not data.endswith(b"\n"):
        raise damaged(data.count(b"\n") + 1, "cut short, no newline at its end")
    for number, line in enumerate(data.split(b"\n")[:-1], start=1):
        try:
            raw = json.loads(line)
        except (ValueError, RecursionError):  # RecursionError: nested too deep
            raise damaged(number, "not JSON") from None
        if not isinstance(raw, dict) or frozenset(raw) not in _ENTRY_KEYS:
            raise damaged(number, "not a history entry")
        version, oid, time, prev = raw["version"], raw["id"], raw["time"], raw.get("prev")
        if isinstance(version, bool) or version != number:
            raise damaged(number, f"version {str(version)[:20]}, expected {number}")
        if not (isinstance(oid, str) and is_object_id(oid)):
            raise damaged(number, "id is not a full object id")
        if not (isinstance(time, str) and _TIME.fullmatch(time)):
            raise damaged(number, "time is not a UTC timestamp")
        if prev is not None or (entries and entries[-1].prev is not None):
            expected = entry_hash(entries[-1]) if entries else None
            if prev != expected:
                raise damaged(number, "its hash chain is broken: a line before it was edited, dropped or reordered")
        entry = RefEntry(version=version, id=oid, time=time, prev=prev)
        if encode_entry(entry) != line:
            raise damaged(number, "not in canonical form")
        entries.append(entry)
    return entries


def merge_status(name: str, local: list[RefEntry], incoming: list[RefEntry]) -> str:
    """How an imported history combines with the local one.

    Returns:
        ``"created"`` (no local history), ``"unchanged"`` (identical, or the local one already extends
        the incoming one), or ``"extended"`` (the local history is a strict prefix of the incoming one).

    Raises:
        StoreError: The histories diverged (neither is a prefix of the other).
    """
    if not local:
        return "created"
    common = min(len(local), len(incoming))
    for a, b in zip(local[:common], incoming[:common], strict=True):
        if a != b:
            raise StoreError(
                f"ref '{name}' has diverged: version {a.version} is {a.id[:12]} here but {b.id[:12]} in the "
                "import. Nothing was imported; rename the local ref, import into another store, or, for a ref "
                "that logs the results of several runs (diagnoses/calibration, say), `morfic store import "
                "--append` adds the import's versions after this store's."
            )
    return "extended" if len(incoming) > len(local) else "unchanged"


class RefMovedError(StoreError):
    """A compare-and-set ref update found the ref somewhere else than the writer expected (another writer moved it).

    Attributes:
        name: The ref.
        expected: The id the writer expected as the current version (``None``: no ref yet).
        current: The ref's current entry (``None``: no ref).
    """

    def __init__(self, name: str, expected: str | None, current: RefEntry | None) -> None:
        self.name, self.expected, self.current = name, expected, current
        now = f"is at version {current.version} ({current.id[:12]})" if current is not None else "does not exist"
        was = f"at {expected[:12]}" if expected is not None else "not to exist yet"
        super().__init__(
            f"ref '{name}' {now}, but this writer expected it {was}: another process updated it; nothing was written."
        )


#: ``expect`` of :meth:`RefDB.append` that checks nothing (a plain append).
ANY = object()


class RefDB:
    """The ``refs/`` directory: read, list and update ref histories."""

    def __init__(self, root: Path, lock_timeout: float | None = None) -> None:
        self.root = root
        self.dir = root / "refs"
        self.heads_dir = root / "heads"
        self.tmp_dir = root / "tmp"
        self.lock_path = root / "locks" / "refs.lock"
        self.lock_timeout = lock_timeout

    def path(self, name: str) -> Path:
        """The history file of ref ``name`` (validated)."""
        return self.dir.joinpath(*check_ref_name(name).split("/"))

    def exists(self, name: str) -> bool:
        """Whether ref ``name`` exists (``False`` for invalid names)."""
        return is_ref_name(name) and self.path(name).is_file()

    def history(self, name: str) -> list[RefEntry]:
        """Every version of ``name``, oldest first; ``[]`` if the ref does not exist."""
        path = self.path(name)
        try:
            data = path.read_bytes()
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
            return []
        return decode_history(name, data)

    def names(self) -> list[str]:
        """Every ref name, sorted."""
        if not self.dir.is_dir():
            return []
        found = []
        for folder, _, files in os.walk(self.dir):
            rel = Path(folder).relative_to(self.dir).as_posix()
            for file in files:
                name = file if rel == "." else f"{rel}/{file}"
                if is_ref_name(name):
                    found.append(name)
        return sorted(found)

    @contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the exclusive ref lock (for read-modify-write of histories)."""
        with file_lock(self.lock_path, exclusive=True, timeout=self.lock_timeout):
            yield

    def append(self, name: str, oid: str, time: str, *, expect: str | None | object = ANY) -> int:
        """Point ``name`` at ``oid``, appending a version; return the new version number.

        Setting a ref to the id it already points at appends nothing and returns the current version.

        Args:
            name: The ref.
            oid: The manifest id of the new version.
            time: UTC time of the update.
            expect: Compare-and-set: the id the ref must point at now (``None``: the ref must not exist yet);
                checked under the ref lock. The default appends whatever the ref holds.

        Raises:
            RefMovedError: ``expect`` was given and the ref is elsewhere; nothing was written.
        """
        self.path(name)
        with self.locked():
            history = self.history(name)
            current = history[-1].id if history else None
            if expect is not ANY and current != expect:
                raise RefMovedError(name, expect, history[-1] if history else None)  # type: ignore[arg-type]
            if history and history[-1].id == oid:
                return history[-1].version
            entry = next_entry(history, oid, time)
            self.write(name, [*history, entry])
        return entry.version

    def write(self, name: str, entries: list[RefEntry]) -> None:
        """Replace the history of ``name`` atomically (caller holds :meth:`locked`)."""
        path = self.path(name)
        self._check_no_conflict(name, path)
        try:
            write_atomic(self.tmp_dir, path, [encode_history(entries)])
            head = self.head_path(name)
            if entries:
                doc = {"entry": entry_hash(entries[-1]), "version": entries[-1].version}
                write_atomic(self.tmp_dir, head, [json.dumps(doc, sort_keys=True).encode() + b"\n"])
            else:
                unlink_quiet(head)
        except OSError as exc:
            raise store_os_error(exc, f"updating ref '{name}'", self.root) from exc

    def remove(self, name: str) -> None:
        """Delete ref ``name`` and its head (only to undo a failed import; caller holds :meth:`locked`)."""
        unlink_quiet(self.path(name))
        unlink_quiet(self.head_path(name))

    def head_path(self, name: str) -> Path:
        """``heads/<name>``: version and line hash of the last entry written to ref ``name``."""
        return self.heads_dir.joinpath(*check_ref_name(name).split("/"))

    def head_problem(self, name: str, history: list[RefEntry]) -> str | None:
        """Why ``history`` does not match the head recorded for it (truncated, rewritten), or ``None``.

        No head (a ref written before heads existed) is not a problem. A head one version behind the
        history is the trace of an update interrupted between its two writes, also not a problem.
        """
        try:
            raw = json.loads(self.head_path(name).read_bytes())
            version, digest = int(raw["version"]), str(raw["entry"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError):
            return f"ref '{name}' has an unreadable head file heads/{name}"
        if version < 1:
            return f"ref '{name}' has an unreadable head file heads/{name}"
        if version > len(history):
            return (
                f"ref '{name}' was truncated: its head is version {version} but the history has "
                f"{len(history)} version(s)"
            )
        if version < len(history) - 1 or entry_hash(history[version - 1]) != digest:
            return f"ref '{name}' was rewritten: version {version} does not match the head recorded for it"
        return None

    def _check_no_conflict(self, name: str, path: Path) -> None:
        """Refuse ``a/b`` when ref ``a`` exists, and ``a`` when refs ``a/...`` exist (like git)."""
        if path.is_dir():
            raise StoreError(
                f"cannot create ref '{name}': refs named '{name}/...' exist, and a name "
                "cannot be both a ref and a folder of refs; choose another name."
            )
        for parent in path.parents:
            if parent == self.dir:
                break
            if parent.is_file():
                other = parent.relative_to(self.dir).as_posix()
                raise StoreError(
                    f"cannot create ref '{name}': ref '{other}' exists, and a name cannot "
                    "be both a ref and a folder of refs; choose another name."
                )
