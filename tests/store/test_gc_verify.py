"""verify (clean vs one flipped byte) and gc (dry run vs --yes, reachability from every ref version)."""

from __future__ import annotations

import os

import pytest

from morfic_cli.errors import StoreError
from morfic_cli.store import Store


@pytest.fixture
def store(tmp_path):
    return Store(tmp_path / "store")


def _flip_one_byte(path, offset: int = 0) -> None:
    os.chmod(path, 0o644)  # objects are read-only
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x01
    path.write_bytes(bytes(data))


def _populated(store: Store) -> dict[str, str]:
    ckpt = store.put_manifest("checkpoint", files={"model.pt": b"weights-v1"})
    run1 = store.put_manifest("run", inputs={"checkpoint": ckpt}, files={"curves.csv": b"it\n0\n"})
    ckpt2 = store.put_manifest("checkpoint", files={"model.pt": b"weights-v2"})
    run2 = store.put_manifest("run", inputs={"checkpoint": ckpt2}, files={"curves.csv": b"it\n0\n1\n"})
    store.set_ref("runs/x", run1)
    store.set_ref("runs/x", run2)
    junk = store.put_manifest("table", files={"junk.csv": b"junk"})
    blob = store.put_bytes(b"loose blob")
    return {"ckpt": ckpt, "run1": run1, "ckpt2": ckpt2, "run2": run2, "junk": junk, "blob": blob}


def test_verify_clean(store):
    # 5 manifests + their 5 files + 1 loose blob
    _populated(store)
    report = store.verify()
    assert report.ok and report.problems == []
    assert report.objects == 11 and report.manifests == 5 and report.refs == 1


def test_verify_detects_one_flipped_byte_in_any_object(store):
    ids = _populated(store)
    for oid in store.objects.iter_ids():
        path = store.object_path(oid)
        _flip_one_byte(path, offset=len(path.read_bytes()) // 2)
        report = store.verify()
        assert not report.ok, oid
        assert any(f"object {oid} is corrupt" in p for p in report.problems)
        _flip_one_byte(path, offset=len(path.read_bytes()) // 2)  # restore
    assert store.verify().ok
    assert ids


def test_verify_detects_missing_objects_and_damaged_refs(store):
    ids = _populated(store)
    store.objects.remove(store.read_manifest(ids["ckpt"]).files["model.pt"].id)
    problems = store.verify().problems
    assert any("file 'model.pt'" in p and "missing" in p for p in problems)
    (store.root / "refs" / "runs" / "x").write_text("not json\n")
    assert any("ref 'runs/x' is damaged" in p for p in store.verify().problems)


def test_verify_detects_dangling_index_entry(store):
    (store.root / "manifests").mkdir(parents=True)
    (store.root / "manifests" / ("ab" * 32)).touch()
    assert any("has no object" in p for p in store.verify().problems)


def test_gc_dry_run_then_yes_keeps_everything_reachable_from_old_versions(store):
    ids = _populated(store)
    before = set(store.objects.iter_ids())
    dry = store.gc()
    assert dry.dry_run
    junk_file = store.read_manifest(ids["junk"]).files["junk.csv"].id
    assert {i.id for i in dry.removed} == {ids["junk"], junk_file, ids["blob"]}
    assert {i.kind for i in dry.removed} == {"table", "blob"}
    assert set(store.objects.iter_ids()) == before  # nothing deleted in a dry run

    real = store.gc(dry_run=False)
    assert [i.id for i in real.removed] == [i.id for i in dry.removed]
    assert real.removed_bytes == dry.removed_bytes > 0
    assert set(store.objects.iter_ids()) == before - {i.id for i in dry.removed}
    # runs/x@1, its checkpoint input and that checkpoint's file all survive
    assert store.read_file(store.read_manifest("runs/x@1").inputs["checkpoint"], "model.pt") == b"weights-v1"
    assert store.read_file("runs/x", "curves.csv") == b"it\n0\n1\n"
    assert not (store.root / "manifests" / ids["junk"]).exists()
    assert store.verify().ok
    assert store.gc(dry_run=False).removed == []


def test_gc_removes_temp_leftovers(store):
    _populated(store)
    (store.root / "tmp" / "obj-crashed.tmp").write_bytes(b"half")
    assert store.gc().temp_files == 1
    assert (store.root / "tmp" / "obj-crashed.tmp").exists()
    assert store.gc(dry_run=False).temp_files == 1
    assert os.listdir(store.root / "tmp") == []


def test_gc_refuses_when_reachability_is_uncertain(store):
    ids = _populated(store)
    _flip_one_byte(store.object_path(ids["run1"]), offset=5)
    with pytest.raises(StoreError, match="refusing"):
        store.gc(dry_run=False)
    (store.root / "refs" / "runs" / "y").write_text("garbage\n")
    with pytest.raises(StoreError, match="damaged"):
        store.gc(dry_run=False)


def test_gc_waits_for_writers(store):
    _populated(store)
    other = Store(store.root, lock_timeout=0.2)
    with store.writing():
        blob = store.put_bytes(b"written, not yet referenced")
        with pytest.raises(StoreError, match="timed out.*lock"):
            other.gc(dry_run=False)
        with pytest.raises(StoreError, match="inside `store.writing\\(\\)`"):
            store.gc(dry_run=False)
    assert store.has(blob)
    assert blob in {i.id for i in other.gc(dry_run=False).removed}
