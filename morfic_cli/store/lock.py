"""File locks for the artifact store (``fcntl.flock`` on lock files under ``<root>/locks/``).

Two locks exist:

* ``locks/store.lock`` is a reader/writer lock. Everything that writes objects, manifests or refs
  holds it *shared* (many writers at once are fine, they never overwrite each other's files);
  ``gc`` holds it *exclusive*, so it can never delete an object that a writer has put but not yet
  named by a ref.
* ``locks/refs.lock`` is exclusive and held only for the read-modify-write of a ref history, so two
  processes appending to the same ref at once lose nothing.

``flock`` locks belong to an open file description and are released by the kernel when the process
dies, so a crashed or killed writer never leaves a stale lock behind.
"""

from __future__ import annotations

import errno
import fcntl
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from morfic_cli.errors import StoreError

#: Seconds to wait for a lock before giving up with a :class:`LockTimeoutError` (env ``MORFIC_LOCK_TIMEOUT``).
DEFAULT_TIMEOUT_S = 60.0

#: Environment variable that overrides :data:`DEFAULT_TIMEOUT_S` for every store a process opens.
TIMEOUT_ENV = "MORFIC_LOCK_TIMEOUT"


class LockTimeoutError(StoreError):
    """A store lock stayed busy (held by another process) longer than the timeout."""


def default_timeout() -> float:
    """Seconds a store waits for a lock: ``MORFIC_LOCK_TIMEOUT`` if set, else :data:`DEFAULT_TIMEOUT_S`.

    Raises:
        StoreError: ``MORFIC_LOCK_TIMEOUT`` is not a positive number of seconds.
    """
    raw = os.environ.get(TIMEOUT_ENV, "").strip()
    if not raw:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = -1.0
    if not 0 < value < float("inf"):
        raise StoreError(
            f"{TIMEOUT_ENV}={raw[:40]!r} is not a number of seconds; set it to how long to wait for a "
            f"busy store lock (e.g. {TIMEOUT_ENV}=600), or unset it for {DEFAULT_TIMEOUT_S:.0f} s."
        )
    return value


def _open_lock_file(path: Path) -> int:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise StoreError(
            f"cannot open the lock file {path}: {exc.strerror or exc}; check that the store directory is writable."
        ) from exc


def _acquire(fd: int, path: Path, *, exclusive: bool, timeout: float) -> None:
    """Take ``flock`` on ``fd``, polling with back-off until ``timeout`` seconds have passed."""
    op = (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB
    deadline = time.monotonic() + timeout
    delay = 0.001
    while True:
        try:
            fcntl.flock(fd, op)
            return
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                raise StoreError(f"cannot lock {path}: {exc.strerror or exc}.") from exc
        if time.monotonic() >= deadline:
            kind = "exclusive" if exclusive else "shared"
            holder = (
                ("a writer: a training's checkpoint, an import, ..." if exclusive else "`morfic store gc`")
                if path.name == "store.lock"
                else "another writer"
            )
            raise LockTimeoutError(
                f"timed out after {timeout:g} s waiting for the {kind} lock {path}: another morfic "
                f"process is using the store ({holder}). Wait for it to finish and retry (or wait longer: "
                f"{TIMEOUT_ENV}=SECONDS)."
            )
        time.sleep(delay)
        delay = min(delay * 2, 0.05)


@contextmanager
def file_lock(path: Path, *, exclusive: bool = True, timeout: float | None = None) -> Iterator[None]:
    """Hold ``flock`` on ``path`` (created if missing) for the body of a ``with`` block.

    Args:
        path: The lock file. Its content is never used.
        exclusive: ``LOCK_EX`` if true, else ``LOCK_SH``.
        timeout: Seconds to wait before raising :class:`LockTimeoutError` (default :func:`default_timeout`).
    """
    timeout = default_timeout() if timeout is None else timeout
    fd = _open_lock_file(path)
    try:
        _acquire(fd, path, exclusive=exclusive, timeout=timeout)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the flock


class StoreLock:
    """The store-wide reader/writer lock of one :class:`~morfic_cli.store.Store` instance.

    Re-entrant within the instance: nested :meth:`shared` blocks (``store.writing()`` around
    ``put_bytes``, which takes the lock itself) share one descriptor, and a :meth:`shared` block
    inside :meth:`exclusive` is already covered. Asking for :meth:`exclusive` while this instance
    holds the lock shared is refused (it would wait for itself).
    """

    def __init__(self, path: Path, timeout: float | None = None) -> None:
        self.path = path
        self.timeout = default_timeout() if timeout is None else timeout
        self._mutex = threading.RLock()
        self._fd: int | None = None
        self._mode: str | None = None
        self._depth = 0

    @contextmanager
    def shared(self) -> Iterator[None]:
        """Hold the lock shared (writers). Re-entrant."""
        with self._mutex:
            if self._depth == 0:
                self._take(exclusive=False)
            self._depth += 1
        try:
            yield
        finally:
            self._leave()

    @contextmanager
    def exclusive(self) -> Iterator[None]:
        """Hold the lock exclusively (gc). Refused inside a shared block of the same instance."""
        with self._mutex:
            if self._mode == "shared":
                raise StoreError(
                    "cannot run gc inside `store.writing()`: the write holds the store "
                    "lock shared; run gc after the write has finished."
                )
            if self._depth == 0:
                self._take(exclusive=True)
            self._depth += 1
        try:
            yield
        finally:
            self._leave()

    def _take(self, *, exclusive: bool) -> None:
        fd = _open_lock_file(self.path)
        try:
            _acquire(fd, self.path, exclusive=exclusive, timeout=self.timeout)
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        self._mode = "exclusive" if exclusive else "shared"

    def _leave(self) -> None:
        with self._mutex:
            self._depth -= 1
            if self._depth == 0 and self._fd is not None:
                os.close(self._fd)
                self._fd = None
                self._mode = None
