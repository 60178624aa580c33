"""Objects: ids, idempotence, read-only files, and crash / full-disk / Ctrl-C safety of writes."""

from __future__ import annotations

import errno
import hashlib
import os
import stat
import subprocess
import sys
import textwrap

import pytest

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import Store

HELLO_ID = "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824"  # sha256(b"hello")


@pytest.fixture
def store(tmp_path):
    return Store(tmp_path / "store")


def _visible_objects(store: Store) -> list[str]:
    return list(store.objects.iter_ids())


def _tmp_files(store: Store) -> list[str]:
    tmp = store.root / "tmp"
    return sorted(os.listdir(tmp)) if tmp.is_dir() else []


def test_id_is_sha256_of_bytes(store):
    assert hashlib.sha256(b"hello").hexdigest() == HELLO_ID
    assert store.put_bytes(b"hello") == HELLO_ID
    assert store.object_path(HELLO_ID) == store.root / "objects" / "2c" / HELLO_ID[2:]
    assert store.get_bytes(HELLO_ID) == b"hello"
    assert store.has(HELLO_ID)


def test_put_is_idempotent(store):
    first = store.put_bytes(b"hello")
    mtime = store.object_path(first).stat().st_mtime_ns
    assert store.put_bytes(b"hello") == first
    assert store.object_path(first).stat().st_mtime_ns == mtime
    assert _visible_objects(store) == [first]
    assert _tmp_files(store) == []


def test_objects_are_read_only(store):
    oid = store.put_bytes(b"hello")
    mode = stat.S_IMODE(store.object_path(oid).stat().st_mode)
    assert mode == 0o444


def test_put_file_streams_to_same_id(store, tmp_path, monkeypatch):
    monkeypatch.setattr("morfic_cli.store.objects.CHUNK_SIZE", 7)  # force many chunks
    data = bytes(range(256)) * 5
    path = tmp_path / "blob.bin"
    path.write_bytes(data)
    assert store.put_file(path) == hashlib.sha256(data).hexdigest() == store.put_bytes(data)
    assert len(_visible_objects(store)) == 1


def test_put_file_missing_is_store_error(store, tmp_path):
    with pytest.raises(StoreError, match="cannot read"):
        store.put_file(tmp_path / "nope.bin")


def test_missing_store_reads_as_empty(tmp_path):
    store = Store(tmp_path / "never-created")
    assert store.ls() == []
    assert store.list_refs() == []
    assert not store.has(HELLO_ID)
    assert store.verify().ok
    assert store.gc(dry_run=False).removed == []
    assert not store.root.exists()


def test_missing_object_and_corruption_on_read(store):
    with pytest.raises(ArtifactNotFoundError):
        store.get_bytes(HELLO_ID)
    oid = store.put_bytes(b"hello")
    path = store.object_path(oid)
    os.chmod(path, 0o644)
    path.write_bytes(b"jello")
    with pytest.raises(StoreError, match="corrupt"):
        store.get_bytes(oid)


def test_rename_failure_leaves_no_object(store, monkeypatch):
    """A crash between temp write and rename: nothing visible, no temp left, store consistent."""

    def boom(src, dst):
        raise OSError(errno.EIO, "I/O error")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(StoreError, match="I/O error"):
        store.put_bytes(b"hello")
    monkeypatch.undo()
    assert not store.has(HELLO_ID)
    assert _visible_objects(store) == []
    assert _tmp_files(store) == []
    assert store.verify().ok
    assert store.put_bytes(b"hello") == HELLO_ID


def test_ctrl_c_during_write_leaves_store_consistent(store, monkeypatch):
    def interrupt(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupt)
    with pytest.raises(KeyboardInterrupt):
        store.put_manifest("table", files={"t.csv": b"a,b\n1,2\n"})
    monkeypatch.undo()
    assert _visible_objects(store) == []
    assert _tmp_files(store) == []
    assert store.ls() == []
    assert store.verify().ok


def test_disk_full_is_store_error_and_removes_temp(store, monkeypatch):
    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(StoreError, match="disk full"):
        store.put_bytes(b"hello")
    monkeypatch.undo()
    assert _visible_objects(store) == []
    assert _tmp_files(store) == []
    assert store.verify().ok


def test_disk_full_during_manifest_leaves_no_manifest(store, monkeypatch):
    calls = {"n": 0}
    real_fsync = os.fsync

    def full_on_second_object(fd):
        if not stat.S_ISDIR(os.fstat(fd).st_mode):
            calls["n"] += 1
            if calls["n"] == 2:
                raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", full_on_second_object)
    with pytest.raises(StoreError, match="disk full"):
        store.put_manifest("table", files={"t.csv": b"a,b\n"})
    monkeypatch.undo()
    assert store.ls() == []  # the file object exists, unreferenced; the manifest does not
    assert _tmp_files(store) == []
    assert store.verify().ok
    assert len(store.gc(dry_run=False).removed) == 1


def test_sigkill_between_write_and_rename(store):
    """A real process killed (SIGKILL) after fsync, before the rename: no object, a temp leftover that gc removes."""
    script = textwrap.dedent(
        """
        import os, signal, sys
        from morfic_cli.store import Store
        os.replace = lambda src, dst: os.kill(os.getpid(), signal.SIGKILL)
        Store(sys.argv[1]).put_bytes(b"hello")
        """
    )
    proc = subprocess.run([sys.executable, "-c", script, str(store.root)], capture_output=True, timeout=60)
    assert proc.returncode == -9
    assert not store.has(HELLO_ID)
    leftovers = _tmp_files(store)
    assert len(leftovers) == 1
    assert (store.root / "tmp" / leftovers[0]).read_bytes() == b"hello"
    report = store.verify()
    assert report.ok and report.temp_files == 1
    gc = store.gc(dry_run=False)
    assert gc.temp_files == 1 and _tmp_files(store) == []
    assert store.put_bytes(b"hello") == HELLO_ID


def test_store_root_that_is_a_file(tmp_path):
    path = tmp_path / "file"
    path.write_text("x")
    with pytest.raises(StoreError, match="not a directory"):
        Store(path).put_bytes(b"hello")


def test_importing_the_store_does_not_import_torch_or_mujoco():
    code = "import sys, morfic_cli.store; sys.exit(bool({'torch', 'mujoco'} & set(sys.modules)))"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0
