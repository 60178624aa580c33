"""Manifests: canonical JSON written out by hand, schema checks, inputs, files and the index."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import pytest

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import MANIFEST_KINDS, FileEntry, Manifest, Store
from morfic_cli.store.manifest import build_manifest, canonical_json

CSV_ID = "9c6536d38fa37da58fac066342747e6d20fdace12ab5b287cf04506f2afe95b0"  # sha256(b"x,y\n")
CREATED = "2025-01-02T03:04:05.000000Z"
EXPECTED = (
    b'{"config":{"a":[1.5,null],"b":1},"created":"2025-01-02T03:04:05.000000Z",'
    b'"files":{"t.csv":{"id":"9c6536d38fa37da58fac066342747e6d20fdace12ab5b287cf04506f2afe95b0","size":4}},'
    b'"inputs":{},"kind":"table","meta":{"note":"caf\\u00e9"},"morfic_version":"0.1.0","schema":1}'
)


@pytest.fixture
def store(tmp_path):
    return Store(tmp_path / "store")


def test_canonical_json_bytes_by_hand():
    doc = build_manifest(
        "table",
        created=CREATED,
        morfic_version="0.1.0",
        config={"b": 1, "a": [1.5, None]},
        files={"t.csv": FileEntry(id=CSV_ID, size=4)},
        meta={"note": "café"},
    )
    assert canonical_json(doc) == EXPECTED


def test_put_manifest_id_is_sha256_of_canonical_json(store, monkeypatch):
    monkeypatch.setattr("morfic_cli.store.utc_now", lambda: CREATED)
    monkeypatch.setattr("morfic_cli.store.__version__", "0.1.0")
    mid = store.put_manifest(
        "table", config={"b": 1, "a": [1.5, None]}, files={"t.csv": b"x,y\n"}, meta={"note": "café"}
    )
    assert mid == hashlib.sha256(EXPECTED).hexdigest()
    assert store.get_bytes(mid) == EXPECTED
    assert store.get_bytes(CSV_ID) == b"x,y\n"
    assert (store.root / "manifests" / mid).is_file()


def test_read_manifest_fields(store, tmp_path):
    path = tmp_path / "model.pt"
    path.write_bytes(b"weights")
    ckpt = store.put_manifest("checkpoint", files={"model.pt": path})
    run = store.put_manifest(
        "run",
        config={"variant": "film"},
        inputs={"checkpoint": ckpt},
        files={"curves.csv": b"it,r\n0,1.0\n"},
        meta={"seed": 0},
    )
    m = store.read_manifest(run)
    assert isinstance(m, Manifest)
    assert (m.id, m.kind, m.schema) == (run, "run", 1)
    assert m.config == {"variant": "film"} and m.meta == {"seed": 0}
    assert m.inputs == {"checkpoint": ckpt}
    assert m.files == {"curves.csv": FileEntry(id=hashlib.sha256(b"it,r\n0,1.0\n").hexdigest(), size=11)}
    assert m.created.endswith("Z") and m.created[:4].isdigit()
    assert store.read_file(run, "curves.csv") == b"it,r\n0,1.0\n"
    assert store.read_file(ckpt, "model.pt") == b"weights"
    assert store.file_path(ckpt, "model.pt").read_bytes() == b"weights"
    with pytest.raises(ArtifactNotFoundError, match="curves.csv"):
        store.read_file(run, "nope.csv")


def test_manifest_kinds(store):
    assert MANIFEST_KINDS == ("run", "checkpoint", "eval", "diagnosis", "rollout", "table", "report", "export", "media")
    with pytest.raises(StoreError, match="unknown manifest kind 'model'.*checkpoint"):
        store.put_manifest("model")
    assert not store.root.exists() or store.ls() == []


def test_inputs_must_exist(store):
    with pytest.raises(StoreError, match="input 'checkpoint'"):
        store.put_manifest("run", inputs={"checkpoint": "ab" * 32})


def test_inputs_are_resolved_to_full_ids(store):
    ckpt = store.put_manifest("checkpoint", files={"a": b"1"})
    store.set_ref("ckpts/a", ckpt)
    run = store.put_manifest("run", inputs={"ckpt": "ckpts/a", "again": ckpt[:10]})
    assert store.read_manifest(run).inputs == {"again": ckpt, "ckpt": ckpt}


@pytest.mark.parametrize("name", ["", "/abs", "a/../b", "./x", "a//b", "back\\slash"])
def test_bad_file_names(store, name):
    with pytest.raises(StoreError, match="invalid manifest file name"):
        store.put_manifest("table", files={name: b"x"})


def test_nan_in_config_is_refused(store):
    with pytest.raises(StoreError, match="canonical JSON"):
        store.put_manifest("run", config={"lr": math.nan})


def test_file_value_type(store):
    with pytest.raises(TypeError, match="bytes or a pathlib.Path"):
        store.put_manifest("table", files={"t.csv": "a,b"})  # type: ignore[dict-item]


def test_read_manifest_of_a_blob(store):
    oid = store.put_bytes(b"not a manifest")
    with pytest.raises(StoreError, match="not a manifest"):
        store.read_manifest(oid)


def test_file_paths_are_path_like(store, tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"123")
    mid = store.put_manifest("export", files={"x.bin": Path(p)})
    assert store.read_manifest(mid).files["x.bin"].size == 3
