"""export / import: closure of refs in one tar, identical ids and histories, idempotent re-import, merges."""

from __future__ import annotations

import io
import os
import stat
import tarfile

import pytest

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import Store


@pytest.fixture
def src(tmp_path):
    store = Store(tmp_path / "src")
    ckpt = store.put_manifest("checkpoint", files={"model.pt": b"w1"})
    store.set_ref("runs/a", store.put_manifest("run", inputs={"checkpoint": ckpt}, files={"c.csv": b"1"}))
    store.set_ref("runs/a", store.put_manifest("run", files={"c.csv": b"2"}))
    store.set_ref("runs/b", store.put_manifest("run", files={"c.csv": b"3"}))
    store.put_manifest("table", files={"unrelated.csv": b"x"})  # not exported
    return store


def _history(store: Store, name: str) -> list[tuple[int, str, str]]:
    return [(e.version, e.id, e.time) for e in store.ref_history(name)]


def test_round_trip_into_fresh_store(src, tmp_path):
    out = tmp_path / "a.tar"
    report = src.export_tar(["runs/a"], out)
    assert report.refs == ["runs/a"] and report.objects == 6
    dst = Store(tmp_path / "dst")
    imported = dst.import_tar(out)
    assert imported.refs == {"runs/a": "created"}
    assert imported.objects_added == 6 and imported.objects_present == 0 and imported.manifests == 3
    assert _history(dst, "runs/a") == _history(src, "runs/a")
    assert dst.list_refs() == ["runs/a"]
    for spec in ("runs/a", "runs/a@1"):
        assert dst.resolve(spec) == src.resolve(spec)
        assert dst.read_manifest(spec) == src.read_manifest(spec)
    ckpt = dst.read_manifest("runs/a@1").inputs["checkpoint"]
    assert dst.read_file(ckpt, "model.pt") == b"w1"
    # everything exported is reachable in dst: gc removes nothing
    assert dst.gc(dry_run=False).removed == []
    assert dst.verify().ok


def test_closure_counts(src, tmp_path):
    """runs/a@1 reaches its run, c.csv, the checkpoint input and model.pt; @2 its run and c.csv: 6 objects."""
    out = tmp_path / "a.tar"
    src.export_tar(["runs/a"], out)
    with tarfile.open(out) as tar:
        names = tar.getnames()
    objects = [n for n in names if n.startswith("objects/")]
    manifests = [n for n in names if n.startswith("manifests/")]
    assert len(objects) == 6 and len(manifests) == 3
    assert sorted(n for n in names if n.startswith("refs/")) == ["refs/runs/a"]
    assert names[0] == "morfic-export.json"


def test_reimport_is_idempotent(src, tmp_path):
    out = tmp_path / "a.tar"
    src.export_tar(["runs/a", "runs/b"], out)
    dst = Store(tmp_path / "dst")
    dst.import_tar(out)
    before = sorted(dst.objects.iter_ids()), _history(dst, "runs/a"), _history(dst, "runs/b")
    again = dst.import_tar(out)
    assert again.objects_added == 0 and again.objects_present > 0
    assert again.refs == {"runs/a": "unchanged", "runs/b": "unchanged"}
    assert (sorted(dst.objects.iter_ids()), _history(dst, "runs/a"), _history(dst, "runs/b")) == before


def test_import_back_into_source_is_a_no_op(src, tmp_path):
    out = tmp_path / "a.tar"
    src.export_tar(["runs/a"], out)
    assert src.import_tar(out).refs == {"runs/a": "unchanged"}


def test_export_is_deterministic(src, tmp_path):
    src.export_tar(["runs/b", "runs/a"], tmp_path / "1.tar")
    src.export_tar(["runs/a", "runs/b"], tmp_path / "2.tar")
    assert (tmp_path / "1.tar").read_bytes() == (tmp_path / "2.tar").read_bytes()


def test_export_is_readable_as_the_umask_allows(src, tmp_path):
    """A bundle is made to be shared: 0644 under umask 022 and 0640 under 027, not mkstemp's 0600."""
    old = os.umask(0o022)
    try:
        src.export_tar(["runs/a"], tmp_path / "a.tar")
        os.umask(0o027)
        src.export_tar(["runs/a"], tmp_path / "b.tar")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.tar").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "b.tar").stat().st_mode) == 0o640


def test_import_extends_a_prefix_history(src, tmp_path):
    old = tmp_path / "old.tar"
    dst = Store(tmp_path / "dst")
    src.export_tar(["runs/b"], old)
    dst.import_tar(old)
    src.set_ref("runs/b", src.put_manifest("run", files={"c.csv": b"4"}))
    new = tmp_path / "new.tar"
    src.export_tar(["runs/b"], new)
    assert dst.import_tar(new).refs == {"runs/b": "extended"}
    assert _history(dst, "runs/b") == _history(src, "runs/b")
    assert len(_history(dst, "runs/b")) == 2
    # the older export does not roll it back
    assert dst.import_tar(old).refs == {"runs/b": "unchanged"}
    assert len(_history(dst, "runs/b")) == 2


def test_import_refuses_diverged_history(src, tmp_path):
    out = tmp_path / "b.tar"
    src.export_tar(["runs/b"], out)
    dst = Store(tmp_path / "dst")
    dst.set_ref("runs/b", dst.put_manifest("run", files={"c.csv": b"local"}))
    before = _history(dst, "runs/b")
    with pytest.raises(StoreError, match="diverged"):
        dst.import_tar(out)
    assert _history(dst, "runs/b") == before


def test_import_rejects_corrupt_object(src, tmp_path):
    out = tmp_path / "a.tar"
    src.export_tar(["runs/a"], out)
    bad = tmp_path / "bad.tar"
    with tarfile.open(out) as tin, tarfile.open(bad, "w") as tout:
        for member in tin.getmembers():
            data = tin.extractfile(member).read()
            if member.name.startswith("objects/") and len(data) == 1:
                data = b"Z"  # same size, wrong content
            tout.addfile(member, io.BytesIO(data))
    dst = Store(tmp_path / "dst")
    with pytest.raises(StoreError, match="corrupt"):
        dst.import_tar(bad)
    assert dst.list_refs() == []
    assert dst.verify().ok


def test_import_rejects_foreign_tar(tmp_path):
    foreign = tmp_path / "foreign.tar"
    with tarfile.open(foreign, "w") as tar:
        info = tarfile.TarInfo("etc/passwd")
        info.size = 1
        tar.addfile(info, io.BytesIO(b"x"))
    with pytest.raises(StoreError, match="not a morfic export"):
        Store(tmp_path / "dst").import_tar(foreign)
    (tmp_path / "text.tar").write_text("not a tar")
    with pytest.raises(StoreError, match="not a readable tar"):
        Store(tmp_path / "dst").import_tar(tmp_path / "text.tar")
    with pytest.raises(StoreError, match="no such file"):
        Store(tmp_path / "dst").import_tar(tmp_path / "missing.tar")


def test_export_unknown_ref(src, tmp_path):
    with pytest.raises(ArtifactNotFoundError, match="runs/zz"):
        src.export_tar(["runs/zz"], tmp_path / "x.tar")
    assert not (tmp_path / "x.tar").exists()


def test_import_rejects_incomplete_export(src, tmp_path):
    out = tmp_path / "a.tar"
    src.export_tar(["runs/a"], out)
    weights = src.read_manifest(src.read_manifest("runs/a@1").inputs["checkpoint"]).files["model.pt"].id
    cut = tmp_path / "cut.tar"
    with tarfile.open(out) as tin, tarfile.open(cut, "w") as tout:
        for member in tin.getmembers():
            if member.name != f"objects/{weights[:2]}/{weights[2:]}":
                tout.addfile(member, tin.extractfile(member))
    dst = Store(tmp_path / "dst")
    with pytest.raises(StoreError, match="incomplete"):
        dst.import_tar(cut)
    assert dst.list_refs() == []


def test_export_latest_is_a_one_version_snapshot(src, tmp_path):
    """runs/a@2 alone: its run manifest and c.csv = 2 objects (not @1's run, c.csv, checkpoint, model.pt)."""
    out = tmp_path / "latest.tar"
    report = src.export_tar(["runs/a"], out, latest=True)
    assert report.objects == 2
    dst = Store(tmp_path / "dst")
    assert dst.import_tar(out).refs == {"runs/a": "created"}
    head = src.ref_history("runs/a")[-1]
    assert _history(dst, "runs/a") == [(1, head.id, head.time)]
    assert dst.read_file("runs/a", "c.csv") == b"2"
    assert dst.verify().ok and dst.gc(dry_run=False).removed == []
    # the full history does not merge onto the snapshot (version 1 differs): refused, nothing changes
    full = tmp_path / "full.tar"
    src.export_tar(["runs/a"], full)
    with pytest.raises(StoreError, match="diverged"):
        dst.import_tar(full)
    assert _history(dst, "runs/a") == [(1, head.id, head.time)]


def test_bundle_name_follows_the_refs():
    from morfic_cli.store.transfer import bundle_name

    assert bundle_name(["runs/film-cpu-s0"]) == "film-cpu-s0.tar"
    assert bundle_name(["runs/film-s1", "runs/film-s0", "runs/film-s1"]) == "film-s0+film-s1.tar"  # sorted, once
    assert bundle_name(["runs/b", "runs/a", "tables/c"]) == "a+b+c.tar"
    assert bundle_name(["runs/d", "runs/b", "runs/a", "tables/c"]) == "a+3-more.tar"


def test_export_path_is_dir_slash_name_and_refuses_to_overwrite(tmp_path):
    from morfic_cli.store.transfer import export_path

    assert export_path(tmp_path / "new", ["runs/a"]) == tmp_path / "new" / "a.tar"
    assert not (tmp_path / "new").exists()  # nothing created before the export
    assert (
        export_path(tmp_path, ["runs/a"], "film")
        == export_path(tmp_path, ["runs/a"], "film.tar")
        == tmp_path / "film.tar"
    )
    (tmp_path / "a.tar").write_bytes(b"x")
    with pytest.raises(StoreError, match="exists; pass --force"):
        export_path(tmp_path, ["runs/a"])
    assert export_path(tmp_path, ["runs/a"], force=True) == tmp_path / "a.tar"
    (tmp_path / "d.tar").mkdir()
    with pytest.raises(StoreError, match="is a folder"):
        export_path(tmp_path, ["runs/d"], force=True)
    for bad in ("", ".tar", "../x", "a/b", "a b", ".hidden"):
        with pytest.raises(StoreError, match="is not a file name"):
            export_path(tmp_path, ["runs/a"], bad)
