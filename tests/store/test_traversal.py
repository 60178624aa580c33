"""No path traversal from a manifest: names are checked at put, at read (so at import) and at every write-out."""

from __future__ import annotations

import os

import pytest
from crafted_bundles import history_bytes, listing, manifest_bytes, oid_of

from morfic_cli.errors import StoreError
from morfic_cli.report.build import write_out
from morfic_cli.store import Store
from morfic_cli.store.manifest import check_file_name, safe_join

BAD = [
    "../../x",
    "/tmp/abs",
    "a/../../x",
    "..",
    ".",
    "",
    "a//b",
    "a\\b",
    "a\x00b",
    "c:x",
    "a" * 256,
    "a/b/c/d/e",
    "x\n",
    # not plain (issue 53): hidden parts, code Python runs from a folder on its path, odd characters
    ".config/morfic/trusted-variants",
    "a/.hidden/b",
    ".trust-key",
    "sitecustomize.py",
    "x.PTH",
    "m.cpython-312.so",
    "x y.csv",
    "-rf",
    "+x",
    "caf\u00e9.csv",
    "a\u202eb",
    "a\x9bb",
]


@pytest.mark.parametrize("name", BAD)
def test_unsafe_names_are_refused_at_put(tmp_path, name):
    store = Store(tmp_path / "s")
    with pytest.raises(StoreError, match="invalid manifest file name"):
        store.put_manifest("report", files={name: b"x"})
    with pytest.raises(StoreError):
        check_file_name(name)
    assert not store.root.exists() or store.ls() == []


@pytest.mark.parametrize("name", ["report.md", "figures/ev.png", "a.b-c_d+e", "_x.csv", "model_100.pt", "x.py.csv"])
def test_safe_names(tmp_path, name):
    assert safe_join(tmp_path, name) == tmp_path.resolve().joinpath(*name.split("/"))


def _plant(store: Store, files: dict[str, bytes]) -> str:
    """A traversal manifest written straight into the store's files, bypassing every API check."""
    store.set_ref("runs/keep", store.put_manifest("run", files={"k": b"k"}))
    entries = {n: {"id": store.put_bytes(d), "size": len(d)} for n, d in files.items()}
    data = manifest_bytes(files=entries)
    mid = oid_of(data)
    path = store.root / "objects" / mid[:2] / mid[2:]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    (store.root / "manifests" / mid).write_bytes(b"")
    (store.root / "refs" / "reports").mkdir()
    (store.root / "refs" / "reports" / "evil").write_bytes(history_bytes([mid]))
    return mid


def test_a_planted_traversal_manifest_is_reported_by_verify_and_never_written_out(tmp_path):
    store = Store(tmp_path / "s")
    mid = _plant(store, {"../../escaped.txt": b"pwned", "ok.md": b"fine"})
    problems = store.verify().problems
    assert any(mid in p and "'../../escaped.txt'" in p for p in problems), problems
    out = tmp_path / "deep" / "er" / "out"
    with pytest.raises(StoreError):
        write_out(store, mid, out)
    assert not (tmp_path / "deep" / "escaped.txt").exists() and listing(tmp_path / "deep" / "er" / "out") == {}
    with pytest.raises(StoreError, match="refusing"):
        store.gc(dry_run=False)


def test_write_out_refuses_a_symlink_that_leaves_the_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    os.symlink(tmp_path / "elsewhere", out / "figures")
    with pytest.raises(StoreError, match="leads outside"):
        safe_join(out, "figures/ev.png")
