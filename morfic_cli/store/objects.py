"""Content-addressed objects: ``objects/ab/cdef...`` named by the sha256 of their bytes.

Writing an object is crash-safe: the bytes go to a temp file under ``tmp/`` (same filesystem as
``objects/``), are flushed and ``fsync``-ed, made read-only (``0o444``) and only then
``os.replace``-d into place. A crash, a full disk or Ctrl-C before the rename leaves no visible
object, only (at worst) a temp file that ``gc`` removes. Putting bytes that are already stored
is a no-op when the stored copy is intact; a stored copy that no longer hashes to its id is rewritten
(so putting or importing good bytes repairs a corrupt object).
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from morfic_cli.errors import ArtifactNotFoundError, StoreError

#: Bytes read per chunk when streaming files in and out.
CHUNK_SIZE = 1 << 20

_HEX64 = re.compile(r"[0-9a-f]{64}")
_HEX62 = re.compile(r"[0-9a-f]{62}")
_HEX2 = re.compile(r"[0-9a-f]{2}")


def is_object_id(text: str) -> bool:
    """Whether ``text`` is a full object id (64 lower-case hex characters)."""
    return bool(_HEX64.fullmatch(text))


def object_relpath(oid: str) -> str:
    """Path of an object relative to the store root, ``objects/ab/cdef...``."""
    return f"objects/{oid[:2]}/{oid[2:]}"


def sha256_file(path: Path) -> str:
    """Stream ``path`` through sha256 and return the hex digest."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(CHUNK_SIZE), b""):
            digest.update(chunk)
    return digest.hexdigest()


def store_os_error(exc: OSError, action: str, root: Path) -> StoreError:
    """Turn an ``OSError`` raised while writing into a :class:`StoreError` that says what to do.

    Args:
        exc: The error from the operating system.
        action: What was being done, e.g. ``"writing an object"``.
        root: The store root, named in the message.
    """
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return StoreError(
            f"disk full while {action} in store {root}: free some space (or point --store "
            "at another disk) and retry; the store is unchanged and consistent."
        )
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return StoreError(
            f"permission denied while {action} in store {root}: {exc.strerror}; "
            "check that the store directory is writable."
        )
    return StoreError(f"error while {action} in store {root}: {exc.strerror or exc}.")


def fsync_dir(path: Path) -> None:
    """Best-effort ``fsync`` of a directory so a rename inside it is durable."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def unlink_quiet(path: str | Path) -> None:
    """Remove ``path`` if it exists, ignoring errors (used on cleanup paths)."""
    try:
        os.unlink(path)
    except OSError:
        pass


def write_atomic(tmp_dir: Path, dest: Path, chunks: Iterable[bytes], *, mode: int = 0o644) -> str:
    """Write ``chunks`` to ``dest`` via a fsynced temp file in ``tmp_dir`` and ``os.replace``.

    Args:
        tmp_dir: Directory for the temp file; must be on the same filesystem as ``dest``.
        dest: Final path. Its parent directory is created.
        chunks: The content.
        mode: Permission bits of the final file.

    Returns:
        The sha256 hex digest of what was written.

    Raises:
        OSError: From the filesystem; the temp file is removed first (also on ``KeyboardInterrupt``).
    """
    tmp_dir.mkdir(parents=True, exist_ok=True)
    fd, path = tempfile.mkstemp(dir=tmp_dir, prefix="w-", suffix=".tmp")
    tmp: str | None = path
    try:
        digest = _write_fd(fd, chunks)
        os.chmod(path, mode)
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, dest)
        tmp = None
        fsync_dir(dest.parent)
        return digest
    finally:
        if tmp is not None:
            unlink_quiet(tmp)


def _write_fd(fd: int, chunks: Iterable[bytes]) -> str:
    """Write every chunk to ``fd``, flush, fsync and close it; return the sha256 hex digest."""
    digest = hashlib.sha256()
    with os.fdopen(fd, "wb") as fh:
        for chunk in chunks:
            digest.update(chunk)
            fh.write(chunk)
        fh.flush()
        os.fsync(fh.fileno())
    return digest.hexdigest()


class ObjectDB:
    """The ``objects/`` directory of a store: put, get, list and remove immutable blobs.

    Callers that must keep ``gc`` away (the :class:`~morfic_cli.store.Store` facade) hold the
    store lock; this class only does the file work.
    """

    def __init__(self, root: Path) -> None:
        self.root = root
        self.dir = root / "objects"
        self.tmp_dir = root / "tmp"

    def path(self, oid: str) -> Path:
        """Where object ``oid`` lives (whether or not it exists).

        Raises:
            StoreError: ``oid`` is not a full 64-hex id.
        """
        if not is_object_id(oid):
            raise StoreError(
                f"'{oid}' is not a full object id (64 lower-case hex characters); "
                "use store.resolve() for refs and prefixes."
            )
        return self.dir / oid[:2] / oid[2:]

    def has(self, oid: str) -> bool:
        """Whether object ``oid`` is stored."""
        return is_object_id(oid) and self.path(oid).is_file()

    def size(self, oid: str) -> int:
        """Size in bytes of a stored object."""
        return self._existing(oid).stat().st_size

    def put_bytes(self, data: bytes) -> str:
        """Store ``data``; return its id. Idempotent."""
        oid = hashlib.sha256(data).hexdigest()
        if self.intact(oid, len(data)):
            return oid
        return self._write([data], expected=oid)

    def put_file(self, path: Path) -> str:
        """Stream the file at ``path`` into the store; return its id (same as ``put_bytes``)."""
        path = Path(path)
        try:
            fh = open(path, "rb")
        except OSError as exc:
            raise StoreError(f"cannot read {path}: {exc.strerror or exc}.") from exc
        with fh:
            return self._write(iter(lambda: fh.read(CHUNK_SIZE), b""))

    def put_stream(self, chunks: Iterable[bytes], expected: str) -> str:
        """Store streamed bytes that must hash to ``expected`` (used by import).

        Raises:
            StoreError: The bytes hash to something else; nothing is stored.
        """
        return self._write(chunks, expected=expected)

    def get_bytes(self, oid: str, *, verify: bool = True) -> bytes:
        """The bytes of object ``oid``, rehashed unless ``verify`` is false.

        Raises:
            ArtifactNotFoundError: No such object.
            StoreError: The bytes no longer hash to ``oid`` (corruption).
        """
        data = self._existing(oid).read_bytes()
        if verify and hashlib.sha256(data).hexdigest() != oid:
            raise StoreError(
                f"object {oid} is corrupt (its bytes no longer hash to its id); "
                "run `morfic store verify` and restore it from an export."
            )
        return data

    def read_head(self, oid: str, n: int) -> bytes:
        """The first ``n`` bytes of a stored object (for cheap sniffing)."""
        with open(self._existing(oid), "rb") as fh:
            return fh.read(n)

    def iter_ids(self) -> Iterator[str]:
        """Every stored object id, sorted."""
        for fan in sorted(self._fan_dirs()):
            for entry in sorted(os.listdir(self.dir / fan)):
                if _HEX62.fullmatch(entry):
                    yield fan + entry

    def stray_files(self) -> list[Path]:
        """Files under ``objects/`` whose names are not object ids."""
        if not self.dir.is_dir():
            return []
        stray = []
        for fan in sorted(os.listdir(self.dir)):
            sub = self.dir / fan
            if not (_HEX2.fullmatch(fan) and sub.is_dir()):
                stray.append(sub)
                continue
            stray.extend(sub / e for e in sorted(os.listdir(sub)) if not _HEX62.fullmatch(e))
        return stray

    def find_prefix(self, prefix: str) -> list[str]:
        """Every stored id that starts with ``prefix`` (at least 2 hex characters)."""
        sub = self.dir / prefix[:2]
        if not sub.is_dir():
            return []
        rest = prefix[2:]
        return sorted(prefix[:2] + e for e in os.listdir(sub) if _HEX62.fullmatch(e) and e.startswith(rest))

    def remove(self, oid: str) -> None:
        """Delete an object (gc only) and its fan-out directory once empty."""
        path = self.path(oid)
        unlink_quiet(path)
        try:
            path.parent.rmdir()
        except OSError:
            pass

    def _fan_dirs(self) -> list[str]:
        if not self.dir.is_dir():
            return []
        return [d for d in os.listdir(self.dir) if _HEX2.fullmatch(d) and (self.dir / d).is_dir()]

    def _existing(self, oid: str) -> Path:
        path = self.path(oid)
        if not path.is_file():
            raise ArtifactNotFoundError(f"object {oid} is not in store {self.root}; try `morfic store ls`.")
        return path

    def intact(self, oid: str, size: int | None = None) -> bool:
        """Whether ``oid`` is stored and its bytes hash to it (and, if ``size`` is given, has that size)."""
        try:
            st = self.path(oid).stat()
        except (FileNotFoundError, NotADirectoryError):
            return False
        if size is not None and st.st_size != size:
            return False
        try:
            return sha256_file(self.path(oid)) == oid
        except OSError:
            return False

    def stage(self, chunks: Iterable[bytes], staging: Path) -> tuple[Path, str, int]:
        """Write ``chunks`` to a fsynced read-only temp file in ``staging`` (not yet an object).

        Returns:
            ``(temp path, sha256 hex, size)``; :meth:`commit_staged` makes it the object.
        """
        staging.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=staging, prefix="obj-", suffix=".tmp")
        try:
            oid = _write_fd(fd, chunks)
            os.chmod(tmp, 0o444)
            return Path(tmp), oid, os.stat(tmp).st_size
        except BaseException:
            unlink_quiet(tmp)
            raise

    def commit_staged(self, tmp: Path, oid: str) -> bool:
        """Rename a staged file (from :meth:`stage`, hashing to ``oid``) into place unless an intact copy exists.

        Returns:
            Whether the object was written (new, or replacing a corrupt copy).
        """
        if self.intact(oid):
            unlink_quiet(tmp)
            return False
        dest = self.path(oid)
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp, dest)
        fsync_dir(dest.parent)
        return True

    def _write(self, chunks: Iterable[bytes], expected: str | None = None) -> str:
        """Write ``chunks`` to a temp file, then rename it to the object path of its hash."""
        try:
            self.tmp_dir.mkdir(parents=True, exist_ok=True)
            fd, path = tempfile.mkstemp(dir=self.tmp_dir, prefix="obj-", suffix=".tmp")
        except OSError as exc:
            raise store_os_error(exc, "writing an object", self.root) from exc
        tmp: str | None = path
        try:
            oid = _write_fd(fd, chunks)
            if expected is not None and oid != expected:
                raise StoreError(f"object {expected} is corrupt: its bytes hash to {oid}; nothing was stored.")
            size = os.stat(path).st_size
            if not self.intact(oid, size):
                os.chmod(path, 0o444)
                dest = self.path(oid)
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(path, dest)
                tmp = None
                fsync_dir(dest.parent)
            return oid
        except OSError as exc:
            raise store_os_error(exc, "writing an object", self.root) from exc
        finally:
            if tmp is not None:
                unlink_quiet(tmp)
