"""Import treats a bundle as untrusted: every hostile bundle is refused whole, with the store unchanged.

Each row of ``HOSTILE`` is one bundle the store accepted (exit 0) before issue 20; every one must now
raise StoreError, create no ref and leave every file of the store as it was.
"""

from __future__ import annotations

import io
import math
import tarfile

import pytest
from crafted_bundles import (
    GOOD_TIME,
    history_bytes,
    listing,
    manifest_bytes,
    oid_of,
    report_bundle,
    write_bundle,
)

from morfic_cli.errors import StoreError
from morfic_cli.store import Store

DATA = b"a,b\n1,2\n"


def _one_file(size=len(DATA), **fields) -> dict:
    return dict(files={"t.csv": {"id": oid_of(DATA), "size": size}}, **fields)


def _bundle(tmp_path, manifest: bytes, *, blobs=(DATA,), times=None):
    return write_bundle(
        tmp_path / "b.tar",
        blobs=list(blobs),
        manifests=[manifest],
        refs={"runs/x": history_bytes([oid_of(manifest)], times)},
    )


def _nan_meta() -> bytes:
    import json

    doc = json.loads(manifest_bytes(**_one_file()))
    doc["meta"] = {"score": math.nan}
    return json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()


HOSTILE = {
    "declared size too big": lambda t: _bundle(t, manifest_bytes(**_one_file(size=999999))),
    "negative size": lambda t: _bundle(t, manifest_bytes(**_one_file(size=-5))),
    "unknown kind": lambda t: _bundle(t, manifest_bytes(kind="model", **_one_file())),
    "input points at a blob": lambda t: _bundle(t, manifest_bytes(inputs={"checkpoint": oid_of(DATA)})),
    "schema true": lambda t: _bundle(t, manifest_bytes(schema=True)),
    "NaN in meta": lambda t: _bundle(t, _nan_meta()),
    "garbage timestamp": lambda t: _bundle(t, manifest_bytes(created="yesterday-ish")),
    "5 MiB ref time": lambda t: _bundle(t, manifest_bytes(), times=["2" * (5 << 20)]),
    "traversal file name": lambda t: report_bundle(t / "b.tar", {"../../x": b"pwned"})[0],
    "absolute file name": lambda t: report_bundle(t / "b.tar", {str(t / "abs.txt"): b"pwned"})[0],
    "NUL in file name": lambda t: report_bundle(t / "b.tar", {"a\x00b": b"x"})[0],
    "backslash file name": lambda t: report_bundle(t / "b.tar", {"..\\x": b"x"})[0],
    "overlong file name": lambda t: report_bundle(t / "b.tar", {"a" * 300: b"x"})[0],
    "file size field is a string": lambda t: _bundle(t, manifest_bytes(**_one_file(size="8"))),
    "missing file object": lambda t: _bundle(t, manifest_bytes(**_one_file()), blobs=()),
    "ref at a blob": lambda t: write_bundle(t / "b.tar", blobs=[DATA], refs={"runs/x": history_bytes([oid_of(DATA)])}),
    "object bytes do not hash to the name": lambda t: write_bundle(
        t / "b.tar",
        extra={f"objects/{'ab' * 1}/{'cd' * 31}": b"not that"},
        header={"format": 1, "morfic_version": "0.1.0", "objects": 1, "refs": []},
    ),
    "header lies about refs": lambda t: write_bundle(
        t / "b.tar", header={"format": 1, "morfic_version": "0.1.0", "objects": 0, "refs": ["runs/ghost"]}
    ),
    "header is not JSON": lambda t: write_bundle(t / "b.tar", extra={"morfic-export.json": b"{nope"}),
    "symlink member": lambda t: _with_symlink(t / "b.tar"),
}


def _with_symlink(path):
    with tarfile.open(path, "w") as tar:
        data = b'{"format": 1, "morfic_version": "0.1.0", "objects": 0, "refs": []}'
        info = tarfile.TarInfo("morfic-export.json")
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
        link = tarfile.TarInfo("objects/ab/" + "c" * 62)
        link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
        tar.addfile(link)
    return path


@pytest.fixture
def local(tmp_path):
    store = Store(tmp_path / "store")
    store.set_ref("runs/keep", store.put_manifest("run", files={"k.csv": b"keep"}))
    return store


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_bundle_is_refused_whole(local, tmp_path, case):
    bundle = HOSTILE[case](tmp_path)
    before = listing(local.root)
    with pytest.raises(StoreError):
        local.import_tar(bundle)
    assert listing(local.root) == before  # no object, no index marker, no ref, no temp file
    assert local.list_refs() == ["runs/keep"]
    assert not (tmp_path / "abs.txt").exists() and not (tmp_path.parent / "x").exists()


@pytest.mark.parametrize("case", ["declared size too big", "traversal file name", "5 MiB ref time"])
def test_hostile_bundle_into_a_missing_store_creates_nothing(tmp_path, case):
    bundle = HOSTILE[case](tmp_path)
    store = Store(tmp_path / "fresh")
    with pytest.raises(StoreError):
        store.import_tar(bundle)
    assert not store.root.exists()


def test_truncated_tar_is_an_error_not_a_traceback(local, tmp_path):
    src = Store(tmp_path / "src")
    src.set_ref("runs/big", src.put_manifest("run", files={"w.bin": bytes(range(256)) * 4096}))
    full = src.export_tar(["runs/big"], tmp_path / "full.tar").path
    data = full.read_bytes()
    with tarfile.open(full) as tar:  # cut inside every member's data, and inside the first header block
        cuts = [m.offset_data + m.size // 2 for m in tar.getmembers() if m.size > 1] + [300]
    before = listing(local.root)
    for cut in cuts:
        cut_path = tmp_path / f"cut{cut}.tar"
        cut_path.write_bytes(data[:cut])
        with pytest.raises(StoreError, match="damaged or truncated|not a readable tar|not a morfic export"):
            local.import_tar(cut_path)
        assert listing(local.root) == before


def test_one_bad_ref_imports_no_ref_at_all(local, tmp_path):
    good = manifest_bytes(**_one_file())
    bad = manifest_bytes(kind="nosuch")
    path = write_bundle(
        tmp_path / "b.tar",
        blobs=[DATA],
        manifests=[good, bad],
        refs={"runs/a": history_bytes([oid_of(good)]), "runs/z": history_bytes([oid_of(bad)])},
    )
    with pytest.raises(StoreError, match="unknown kind"):
        local.import_tar(path)
    assert local.list_refs() == ["runs/keep"]


def test_a_diverged_ref_imports_nothing(local, tmp_path):
    other = manifest_bytes(**_one_file())
    local_copy = Store(tmp_path / "src")
    path = write_bundle(
        tmp_path / "b.tar",
        blobs=[DATA],
        manifests=[other],
        refs={"runs/keep": history_bytes([oid_of(other)]), "runs/new": history_bytes([oid_of(other)])},
    )
    before = listing(local.root)
    with pytest.raises(StoreError, match="diverged"):
        local.import_tar(path)
    assert listing(local.root) == before
    assert not local_copy.root.exists()


def test_a_well_formed_crafted_bundle_imports(local, tmp_path):
    """The crafted-bundle helper itself makes importable bundles (so the refusals above are for their flaw)."""
    manifest = manifest_bytes(**_one_file())
    local.import_tar(_bundle(tmp_path, manifest))
    assert local.read_file("runs/x", "t.csv") == DATA
    assert local.verify().ok


def test_importing_a_good_export_repairs_a_corrupt_local_copy(tmp_path):
    src = Store(tmp_path / "src")
    src.set_ref("runs/a", src.put_manifest("run", files={"w.bin": b"weights" * 100}))
    tar = src.export_tar(["runs/a"], tmp_path / "a.tar").path
    dst = Store(tmp_path / "dst")
    dst.import_tar(tar)
    oid = dst.read_manifest("runs/a").files["w.bin"].id
    path = dst.object_path(oid)
    path.chmod(0o644)
    path.write_bytes(b"Weights" + b"weights" * 99)  # same size, one byte off
    assert not dst.verify().ok
    report = dst.import_tar(tar)
    assert report.objects_repaired == 1
    assert dst.verify().ok
    assert dst.read_file("runs/a", "w.bin") == b"weights" * 100


def test_put_of_bytes_over_a_corrupt_same_size_object_rewrites_it(tmp_path):
    store = Store(tmp_path / "s")
    oid = store.put_bytes(b"0123456789")
    path = store.object_path(oid)
    path.chmod(0o644)
    path.write_bytes(b"x123456789")
    assert store.put_bytes(b"0123456789") == oid
    assert store.get_bytes(oid) == b"0123456789"
    path.chmod(0o644)
    path.write_bytes(b"y123456789")
    src = tmp_path / "f.bin"
    src.write_bytes(b"0123456789")
    assert store.put_file(src) == oid
    assert store.verify().ok


def test_manifest_files_good_names_still_import(tmp_path):
    """Names the pipeline really writes (report figures in a subfolder) are fine."""
    path, mid = report_bundle(tmp_path / "r.tar", {"report.md": b"# r\n", "figures/ev.png": b"png"})
    store = Store(tmp_path / "s")
    store.import_tar(path)
    assert sorted(store.read_manifest(mid).files) == ["figures/ev.png", "report.md"]
    assert GOOD_TIME == store.read_manifest(mid).created
