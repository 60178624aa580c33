"""Refs and resolution: names, append-only history, @N / @-K, prefixes, and two concurrent writers."""

from __future__ import annotations

import hashlib
import itertools
import os
import subprocess
import sys
import textwrap
import time

import pytest

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import RefEntry, Store


@pytest.fixture
def store(tmp_path):
    return Store(tmp_path / "store")


def _manifests(store: Store, n: int) -> list[str]:
    return [store.put_manifest("run", meta={"i": i}) for i in range(n)]


@pytest.mark.parametrize("name", ["runs/film-s0", "a", "A.b_c-1/x/y", "evals/go2.v2"])
def test_valid_ref_names(store, name):
    (mid,) = _manifests(store, 1)
    assert store.set_ref(name, mid) == 1
    assert store.resolve(name) == mid
    assert name in store.list_refs()


@pytest.mark.parametrize(
    "name", ["", "/runs", "runs/", "runs//x", "runs/../x", "a..b", "runs/x@1", "sp ace", "runs/.", "é"]
)
def test_invalid_ref_names(store, name):
    (mid,) = _manifests(store, 1)
    with pytest.raises(StoreError, match="invalid ref name"):
        store.set_ref(name, mid)


def test_history_and_versions(store):
    a, b, c = _manifests(store, 3)
    assert [store.set_ref("runs/x", m) for m in (a, b, c)] == [1, 2, 3]
    history = store.ref_history("runs/x")
    assert [(e.version, e.id) for e in history] == [(1, a), (2, b), (3, c)]
    assert all(isinstance(e, RefEntry) and e.time.endswith("Z") for e in history)
    assert store.resolve("runs/x") == c
    assert store.resolve("runs/x@1") == a
    assert store.resolve("runs/x@3") == c
    assert store.resolve("runs/x@-1") == b  # one update before the current
    assert store.resolve("runs/x@-2") == a
    assert store.read_manifest("runs/x@2").id == b


def test_history_file_is_json_lines(store):
    a, b = _manifests(store, 2)
    store.set_ref("runs/x", a)
    store.set_ref("runs/x", b)
    lines = (store.root / "refs" / "runs" / "x").read_text().splitlines()
    assert lines[0].startswith('{"id":"' + a + '","time":"') and lines[0].endswith('","version":1}')
    assert lines[1].startswith('{"id":"' + b)


@pytest.mark.parametrize("spec", ["runs/x@4", "runs/x@-3", "runs/x@0", "runs/x@two", "runs/x@+1"])
def test_bad_versions(store, spec):
    for m in _manifests(store, 3):
        store.set_ref("runs/x", m)
    with pytest.raises(StoreError, match="version"):
        store.resolve(spec)


def test_setting_the_same_id_adds_no_version(store):
    a, b = _manifests(store, 2)
    assert store.set_ref("runs/x", a) == 1
    assert store.set_ref("runs/x", a) == 1
    assert store.set_ref("runs/x", b) == 2
    assert store.set_ref("runs/x", a) == 3
    assert len(store.ref_history("runs/x")) == 3


def test_ref_must_name_an_existing_manifest(store):
    blob = store.put_bytes(b"blob")
    with pytest.raises(StoreError, match="not one"):
        store.set_ref("runs/x", blob)
    with pytest.raises(ArtifactNotFoundError):
        store.set_ref("runs/x", "f" * 64)
    assert store.list_refs() == []


def test_ref_and_folder_clash(store):
    (mid,) = _manifests(store, 1)
    store.set_ref("runs/x", mid)
    with pytest.raises(StoreError, match="folder of refs"):
        store.set_ref("runs", mid)
    with pytest.raises(StoreError, match="folder of refs"):
        store.set_ref("runs/x/y", mid)


def test_full_id_and_prefix(store):
    (mid,) = _manifests(store, 1)
    assert store.resolve(mid) == mid
    assert store.resolve(mid[:4]) == mid
    assert store.resolve(mid[:10].upper()) == mid
    with pytest.raises(ArtifactNotFoundError, match="too short"):
        store.resolve(mid[:3])


def _colliding_blobs() -> tuple[bytes, bytes]:
    """Two small blobs whose ids share the first 4 hex characters (found by hashing)."""
    seen: dict[str, bytes] = {}
    for i in itertools.count():
        data = f"blob {i}".encode()
        prefix = hashlib.sha256(data).hexdigest()[:4]
        if prefix in seen:
            return seen[prefix], data
        seen[prefix] = data
    raise AssertionError  # pragma: no cover


def test_ambiguous_prefix_lists_candidates(store):
    x, y = _colliding_blobs()
    ix, iy = store.put_bytes(x), store.put_bytes(y)
    assert ix[:4] == iy[:4] and ix != iy
    with pytest.raises(ArtifactNotFoundError, match="ambiguous") as err:
        store.resolve(ix[:4])
    assert ix in str(err.value) and iy in str(err.value) and "blob" in str(err.value)
    longer = next(n for n in range(5, 64) if ix[:n] != iy[:n])
    assert store.resolve(ix[:longer]) == ix


def test_unknown_spec_says_what_to_do(store):
    (mid,) = _manifests(store, 1)
    store.set_ref("runs/film-s0", mid)
    with pytest.raises(ArtifactNotFoundError, match="runs/film-s1.*morfic store ls.*runs/film-s0"):
        store.resolve("runs/film-s1")
    with pytest.raises(ArtifactNotFoundError, match="morfic store ls"):
        store.resolve("deadbeef")
    with pytest.raises(ArtifactNotFoundError, match="morfic store ls"):
        store.ref_history("runs/nope")


def test_ls_labels(store):
    a, b, unnamed = _manifests(store, 3)
    store.set_ref("runs/x", a)
    store.set_ref("runs/x", b)
    rows = {r["id"]: r for r in store.ls()}
    assert rows[b]["ref"] == "runs/x"
    assert rows[a]["ref"] == "runs/x@1"
    assert rows[unnamed]["ref"] is None
    assert set(rows[a]) >= {"ref", "id", "kind", "created"}
    current = {r["id"] for r in store.ls(include_superseded=False)}
    assert current == {b, unnamed}
    assert store.ls(kind="eval") == []
    assert [r["id"] for r in store.ls()] == [a, b, unnamed]  # oldest first


WORKER = textwrap.dedent(
    """
    import os, sys, time
    from morfic_cli.store import Store
    root, tag, go = sys.argv[1], sys.argv[2], sys.argv[3]
    store = Store(root)
    while not os.path.exists(go):
        time.sleep(0.001)
    for i in range(50):
        with store.writing():
            mid = store.put_manifest("run", meta={"writer": tag, "i": i})
            store.set_ref("runs/shared", mid)
    """
)


def test_two_processes_appending_to_one_ref_lose_nothing(store, tmp_path):
    store.put_bytes(b"create the layout")
    go = tmp_path / "go"
    procs = [subprocess.Popen([sys.executable, "-c", WORKER, str(store.root), tag, str(go)]) for tag in ("a", "b")]
    time.sleep(0.3)  # both interpreters are up and waiting
    go.touch()
    assert [p.wait(timeout=120) for p in procs] == [0, 0]
    history = store.ref_history("runs/shared")
    assert [e.version for e in history] == list(range(1, 101))
    assert len({e.id for e in history}) == 100
    metas = [store.read_manifest(e.id).meta for e in history]
    for tag in "ab":  # each writer's 50 updates are all there, in its own order
        assert [m["i"] for m in metas if m["writer"] == tag] == list(range(50))
    assert store.verify().ok
    assert os.listdir(store.root / "tmp") == []


def test_interrupted_ref_update_keeps_old_history(store, monkeypatch):
    a, b = _manifests(store, 2)
    store.set_ref("runs/x", a)

    def interrupt(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupt)
    with pytest.raises(KeyboardInterrupt):
        store.set_ref("runs/x", b)
    monkeypatch.undo()
    assert [e.id for e in store.ref_history("runs/x")] == [a]
    assert os.listdir(store.root / "tmp") == []
    assert store.set_ref("runs/x", b) == 2


def test_compare_and_set_ref_update(store):
    """``expect``: the update happens only when the ref is where the writer last saw it (None: not there yet)."""
    from morfic_cli.store import RefMovedError

    a, b, c = _manifests(store, 3)
    assert store.set_ref("runs/cas", a, expect=None) == 1
    with pytest.raises(RefMovedError, match="ref 'runs/cas' is at version 1.*expected it not to exist yet"):
        store.set_ref("runs/cas", b, expect=None)
    assert store.set_ref("runs/cas", b, expect=a) == 2
    with pytest.raises(RefMovedError, match="expected it at") as err:
        store.set_ref("runs/cas", c, expect=a)  # a stale writer
    assert err.value.current is not None and err.value.current.id == b and err.value.expected == a
    with pytest.raises(RefMovedError, match="does not exist"):
        store.set_ref("runs/other", c, expect=a)
    assert [e.id for e in store.ref_history("runs/cas")] == [a, b]
    assert not store.has_ref("runs/other")
    assert store.verify().ok
