"""gc never deletes what a ref reaches (even through a missing or corrupt manifest); tamper-evident ref history."""

from __future__ import annotations

import json
import os

import pytest
from crafted_bundles import history_bytes, listing

from morfic_cli.errors import StoreError
from morfic_cli.store import Store


@pytest.fixture
def store(tmp_path):
    store = Store(tmp_path / "store")
    weights = store.put_manifest("checkpoint", files={"model.pt": b"w" * 1000, "curve.csv": b"it\n1\n"})
    store.set_ref("runs/a", store.put_manifest("run", inputs={"checkpoint": weights}, files={"c.csv": b"1"}))
    store.set_ref("runs/b", store.put_manifest("run", files={"c.csv": b"2"}))
    store.put_bytes(b"garbage")
    return store


def _damage(store: Store, oid: str, how: str) -> None:
    path = store.object_path(oid)
    if how == "missing":
        os.unlink(path)
    else:
        path.chmod(0o644)
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0x20
        path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["missing", "corrupt"])
@pytest.mark.parametrize("which", ["ref target", "input"])
def test_gc_refuses_when_a_reachable_manifest_cannot_be_read(store, which, how):
    run = store.read_manifest("runs/a")
    oid = run.id if which == "ref target" else run.inputs["checkpoint"]
    _damage(store, oid, how)
    before = listing(store.root)
    with pytest.raises(StoreError, match=rf"{oid} \(.*refusing.*store verify"):
        store.gc(dry_run=False)
    assert listing(store.root) == before  # model.pt, curve.csv and even the garbage blob are still there


def test_gc_on_a_healthy_store_still_collects(store):
    report = store.gc(dry_run=False)
    assert [item.kind for item in report.removed] == ["blob"]
    assert store.verify().ok


def _history_file(store: Store, name: str):
    return store.root / "refs" / name


def _three_versions(store: Store) -> list[str]:
    ids = [store.put_manifest("run", meta={"i": i}) for i in range(3)]
    for oid in ids:
        store.set_ref("runs/h", oid)
    return ids


def test_history_is_a_hash_chain(store):
    import hashlib

    _three_versions(store)
    lines = _history_file(store, "runs/h").read_bytes().split(b"\n")[:-1]
    assert "prev" not in json.loads(lines[0])
    for before, line in zip(lines, lines[1:], strict=False):
        assert json.loads(line)["prev"] == hashlib.sha256(before).hexdigest()
    head = json.loads((store.root / "heads" / "runs" / "h").read_bytes())
    assert head == {"entry": hashlib.sha256(lines[-1]).hexdigest(), "version": 3}


def _rewrite(store: Store, mutate) -> None:
    path = _history_file(store, "runs/h")
    lines = path.read_bytes().split(b"\n")[:-1]
    path.write_bytes(b"".join(line + b"\n" for line in mutate(lines)))


def _swap_id(lines, ids):
    doc = json.loads(lines[1])
    doc["id"] = ids[0]
    lines[1] = json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()
    return lines


TAMPER = {
    "an old version pointed elsewhere": lambda lines, ids: _swap_id(lines, ids),
    "last version dropped": lambda lines, ids: lines[:-1],
    "middle version dropped": lambda lines, ids: [lines[0], lines[2]],
}


@pytest.mark.parametrize("case", sorted(TAMPER))
def test_verify_detects_a_rewritten_or_truncated_history(store, case):
    ids = _three_versions(store)
    assert store.verify().ok
    _rewrite(store, lambda lines: TAMPER[case](lines, ids))
    report = store.verify()
    assert not report.ok
    assert any(
        "runs/h" in p and ("chain" in p or "truncated" in p or "rewritten" in p or "version" in p)
        for p in report.problems
    ), report.problems


def test_verify_detects_a_line_cut_short(store):
    _three_versions(store)
    path = _history_file(store, "runs/h")
    path.write_bytes(path.read_bytes()[:-10])
    assert any("cut short" in p for p in store.verify().problems)


def test_a_history_from_before_the_chain_still_reads_and_extends(store):
    a, b, c = (store.put_manifest("run", meta={"legacy": i}) for i in range(3))
    path = _history_file(store, "runs/old")
    path.write_bytes(history_bytes([a, b]))  # the format every earlier morfic wrote
    assert [e.id for e in store.ref_history("runs/old")] == [a, b]
    assert store.verify().ok
    assert store.set_ref("runs/old", c) == 3
    history = store.ref_history("runs/old")
    assert [e.prev is None for e in history] == [True, True, False]
    assert store.resolve("runs/old@1") == a and store.verify().ok
    lines = path.read_bytes().split(b"\n")
    path.write_bytes(b"\n".join([lines[1], lines[0], *lines[2:]]))  # reorder the legacy part
    assert not store.verify().ok


def test_an_interrupted_update_between_history_and_head_is_not_a_problem(store):
    ids = _three_versions(store)
    head = store.root / "heads" / "runs" / "h"
    saved = head.read_bytes()
    store.set_ref("runs/h", ids[0])  # version 4; then pretend the head write never happened
    head.write_bytes(saved)
    assert store.verify().ok
