"""`morfic store ...`: CliRunner for output, `main` (run_cli fixture) for `Error:` and exit codes."""

from __future__ import annotations

import errno
import json
import os
import tarfile

import pytest
from typer.testing import CliRunner

from morfic_cli.cli import app
from morfic_cli.store import Store

runner = CliRunner()
COMMANDS = ["ls", "show", "get", "verify", "gc", "export", "import"]


@pytest.fixture
def store():
    """The store the CLI uses by default in tests (conftest points MORFIC_STORE at tmp_path)."""
    return Store(os.environ["MORFIC_STORE"])


@pytest.fixture
def filled(store):
    ckpt = store.put_manifest("checkpoint", files={"model.pt": b"w"})
    old = store.put_manifest("run", inputs={"checkpoint": ckpt}, files={"c.csv": b"1"})
    new = store.put_manifest("run", inputs={"checkpoint": ckpt}, files={"c.csv": b"2"})
    store.set_ref("runs/film-s0", old)
    store.set_ref("runs/film-s0", new)
    return {"ckpt": ckpt, "old": old, "new": new}


def _invoke(*args: str):
    result = runner.invoke(app, ["store", *args])
    assert result.exit_code == 0, (result.output, result.exception)
    return result


def test_help_lists_subcommands_and_examples():
    out = _invoke("--help").stdout
    for name in COMMANDS:
        assert name in out
    for name in COMMANDS:
        assert "Example:" in _invoke(name, "--help").stdout, name


def test_ls_json_on_empty_store():
    result = _invoke("ls", "--format", "json")
    assert json.loads(result.stdout) == []
    assert "no artifacts" in result.stderr


def test_ls_json_rows(filled):
    result = _invoke("ls", "--format", "json")
    rows = json.loads(result.stdout)
    by_id = {r["id"]: r for r in rows}
    assert set(by_id) == {filled["new"]}  # the unnamed checkpoint and runs/film-s0@1 only with --all
    assert by_id[filled["new"]]["ref"] == "runs/film-s0"
    assert by_id[filled["new"]]["kind"] == "run" and by_id[filled["new"]]["created"].endswith("Z")
    assert "1 unnamed artifact(s) not listed (1 B held here;" in result.stderr and "--all lists them" in result.stderr
    result = _invoke("ls", "--all", "--format", "json")
    assert {r["id"]: r["ref"] for r in json.loads(result.stdout)} == {
        filled["ckpt"]: None,
        filled["old"]: "runs/film-s0@1",
        filled["new"]: "runs/film-s0",
    }
    assert "unnamed" not in result.stderr
    runs = _invoke("ls", "--kind", "checkpoint", "--format", "json")
    assert json.loads(runs.stdout) == [] and "1 unnamed artifact(s)" in runs.stderr
    assert "no artifacts" not in runs.stderr
    runs = json.loads(_invoke("ls", "--kind", "checkpoint", "--all", "--format", "json").stdout)
    assert [r["id"] for r in runs] == [filled["ckpt"]]


def test_ls_csv_and_table(filled):
    csv = _invoke("ls", "--format", "csv").stdout.splitlines()
    assert csv[0] == "ref,id,kind,created,files,size" and len(csv) == 2  # runs/film-s0
    table = _invoke("ls").stdout
    assert "runs/film-s0" in table and filled["new"][:12] in table


def test_ls_empty_csv_has_header():
    assert _invoke("ls", "--format", "csv").stdout == "ref,id,kind,created,files,size\n"


def test_store_option_beats_env(filled, tmp_path):
    result = runner.invoke(app, ["store", "ls", "--format", "json", "--store", str(tmp_path / "other")])
    assert result.exit_code == 0 and json.loads(result.stdout) == []


def test_show_manifest_and_versions(filled):
    shown = json.loads(_invoke("show", "runs/film-s0", "--format", "json").stdout)
    assert shown["id"] == filled["new"] and shown["kind"] == "run" and shown["refs"] == ["runs/film-s0"]
    assert shown["inputs"] == {"checkpoint": filled["ckpt"]}
    assert set(shown) >= {"schema", "morfic_version", "created", "config", "files", "meta"}
    assert json.loads(_invoke("show", "runs/film-s0@1", "-f", "json").stdout)["id"] == filled["old"]
    assert json.loads(_invoke("show", filled["ckpt"][:8], "-f", "json").stdout)["kind"] == "checkpoint"
    history = json.loads(_invoke("show", "runs/film-s0", "--history", "-f", "json").stdout)
    assert [(h["version"], h["id"], h["current"]) for h in history] == [
        (1, filled["old"], False),
        (2, filled["new"], True),
    ]


def test_verify_and_gc(filled, store):
    assert "OK" in _invoke("verify").stderr
    loose = store.put_bytes(b"loose")
    dry = json.loads(_invoke("gc", "--format", "json").stdout)
    assert [r["id"] for r in dry] == [loose]
    assert store.has(loose)
    assert "dry run" in _invoke("gc").stderr
    assert [r["id"] for r in json.loads(_invoke("gc", "--yes", "-f", "json").stdout)] == [loose]
    assert not store.has(loose)
    assert store.read_manifest("runs/film-s0@1").id == filled["old"]


def test_export_import_round_trip(filled, tmp_path):
    out = tmp_path / "bundles"  # created
    result = _invoke("export", "runs/film-s0", "--out", str(out), "-f", "json")
    assert "exported 1 ref" in result.stderr
    tar = out / "film-s0.tar"
    with tarfile.open(tar) as t:
        objects = [m for m in t.getmembers() if m.name.startswith("objects/")]
    # 3 manifests (checkpoint, both run versions) and 3 files (model.pt, c.csv twice)
    assert (
        json.loads(result.stdout)
        == {
            "path": str(tar),
            "refs": ["runs/film-s0"],
            "objects": 6,
            "bytes": sum(m.size for m in objects),
            "omitted": [],
            "omitted_files": [],
        }
        and len(objects) == 6
    )
    dst = tmp_path / "dst"
    rows = json.loads(_invoke("import", str(tar), "--store", str(dst), "-f", "json").stdout)
    assert rows == [{"bundle": "film-s0.tar", "ref": "runs/film-s0", "status": "created"}]
    rows = json.loads(_invoke("import", str(tar), "--store", str(dst), "-f", "json").stdout)
    assert rows == [{"bundle": "film-s0.tar", "ref": "runs/film-s0", "status": "unchanged"}]
    assert Store(dst).resolve("runs/film-s0@1") == filled["old"]


def test_export_names_the_tar_after_the_refs_and_prints_its_path(filled, store, tmp_path):
    for name in ("runs/film-s1", "diagnoses/calibration", "tables/distance"):
        store.set_ref(name, filled["ckpt"])
    out = tmp_path / "b"
    table = _invoke("export", "runs/film-s0", "runs/film-s1", "--out", str(out)).stdout
    assert table == f"{out / 'film-s0+film-s1.tar'}\n"  # --format table: the path alone
    assert (out / "film-s0+film-s1.tar").is_file()
    many = json.loads(
        _invoke(
            "export",
            "runs/film-s0",
            "runs/film-s1",
            "tables/distance",
            "diagnoses/calibration",
            "--out",
            str(out),
            "-f",
            "json",
        ).stdout
    )
    assert many["path"] == str(out / "calibration+3-more.tar")  # sorted: diagnoses/ first
    assert many["refs"] == ["diagnoses/calibration", "runs/film-s0", "runs/film-s1", "tables/distance"]
    named = json.loads(_invoke("export", "runs/film-s0", "--out", str(out), "--name", "film.tar", "-f", "json").stdout)
    assert named["path"] == str(out / "film.tar")
    assert sorted(p.name for p in out.iterdir()) == ["calibration+3-more.tar", "film-s0+film-s1.tar", "film.tar"]


def test_export_keeps_an_existing_tar_unless_force(run_cli, filled, store, tmp_path):
    tar = tmp_path / "film-s0.tar"
    tar.write_bytes(b"old")
    code, out, err = run_cli("store", "export", "runs/film-s0", "--out", str(tmp_path))
    assert code == 1 and out == "" and err.startswith(f"Error: {tar} exists; pass --force")
    assert tar.read_bytes() == b"old"
    code, out, err = run_cli("store", "export", "runs/film-s0", "--out", str(tmp_path), "--force", "-f", "json")
    assert code == 0, err
    assert json.loads(out)["path"] == str(tar) and tar.read_bytes()[:3] != b"old"
    dst = Store(tmp_path / "dst")
    dst.import_tar(tar)
    assert dst.resolve("runs/film-s0") == filled["new"]


# -- `Error:` on stderr and exit 1, through the real entry point ---------------------------------


def test_missing_id_is_error_exit_1(run_cli, filled):
    code, out, err = run_cli("store", "show", "deadbeef")
    assert code == 1 and out == ""
    assert err.startswith("Error: no artifact 'deadbeef'") and "morfic store ls" in err


def test_unknown_ref_suggests_close_name(run_cli, filled):
    code, _, err = run_cli("store", "show", "runs/film-s1")
    assert code == 1 and "Error:" in err and "runs/film-s0" in err


def test_ambiguous_version_is_error(run_cli, filled):
    code, _, err = run_cli("store", "show", "runs/film-s0@7")
    assert code == 1 and "Error: ref 'runs/film-s0' has no version @7" in err


def test_verify_corrupt_store_is_error_with_each_problem(run_cli, filled, store):
    weights = store.read_manifest(filled["ckpt"]).files["model.pt"].id
    path = store.object_path(weights)
    os.chmod(path, 0o644)
    data = bytearray(path.read_bytes())
    data[0] ^= 0x01
    path.write_bytes(bytes(data))
    code, _, err = run_cli("store", "verify")
    assert code == 1
    assert f"  object {weights} is corrupt: its bytes hash to " in err
    assert "Error: 1 problem(s) found" in err


def test_bad_kind_is_error(run_cli):
    code, _, err = run_cli("store", "ls", "--kind", "model")
    assert code == 1 and "Error: unknown manifest kind 'model'" in err and "checkpoint" in err


def test_disk_full_during_import_is_error_and_store_consistent(run_cli, filled, tmp_path, monkeypatch):
    assert run_cli("store", "export", "runs/film-s0", "--out", str(tmp_path))[0] == 0
    out = tmp_path / "film-s0.tar"
    dst = tmp_path / "dst"

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    code, _, err = run_cli("store", "import", str(out), "--store", str(dst))
    monkeypatch.undo()
    assert code == 1 and err.startswith("Error: disk full")
    assert Store(dst).list_refs() == [] and Store(dst).verify().ok
    assert run_cli("store", "import", str(out), "--store", str(dst))[0] == 0
    assert Store(dst).resolve("runs/film-s0") == filled["new"]


def test_import_of_several_tars_imports_each_and_names_the_bad_one(run_cli, filled, store, tmp_path):
    out = tmp_path / "tars"
    for ref in ("runs/film-s0", "runs/film-s1"):
        if ref == "runs/film-s1":
            store.set_ref(ref, filled["ckpt"])
        assert run_cli("store", "export", ref, "--out", str(out))[0] == 0
    bad = out / "bad.tar"
    bad.write_bytes((out / "film-s1.tar").read_bytes()[:700])  # truncated
    dst = tmp_path / "dst"
    code, stdout, err = run_cli(
        "store",
        "import",
        str(out / "film-s0.tar"),
        str(bad),
        str(out / "film-s1.tar"),
        "--store",
        str(dst),
        "-f",
        "json",
    )
    assert code == 1
    assert json.loads(stdout) == [
        {"bundle": "film-s0.tar", "ref": "runs/film-s0", "status": "created"},
        {"bundle": "film-s1.tar", "ref": "runs/film-s1", "status": "created"},
    ]
    lines = err.splitlines()
    assert lines[0].startswith("film-s0.tar: imported ") and "1 ref(s)" in lines[0]
    assert lines[1].startswith("Error: ") and "bad.tar" in lines[1] and "nothing was imported" in lines[1]
    assert lines[2].startswith("film-s1.tar: imported ")
    assert lines[3].startswith("Error: 1 of 3 tar(s) not imported (bad.tar; why above); the other 2 were imported")
    dst_store = Store(dst)
    assert dst_store.resolve("runs/film-s0") == filled["new"] and dst_store.resolve("runs/film-s1") == filled["ckpt"]
    assert sorted(dst_store.list_refs()) == ["runs/film-s0", "runs/film-s1"] and dst_store.verify().ok
    code, stdout, err = run_cli(
        "store", "import", str(out / "film-s0.tar"), str(out / "film-s1.tar"), "--store", str(dst), "-f", "json"
    )  # again: nothing new, exit 0
    assert code == 0 and [r["status"] for r in json.loads(stdout)] == ["unchanged", "unchanged"]


def test_bundles_of_two_stores_with_a_shared_ref_import_together_with_append(run_cli, tmp_path):
    """Two stores each log version 1 of diagnoses/calibration: without --append the second tar is refused with a
    pointer to --append and nothing of it lands; with it, its version goes after the first (README's import of the
    shipped results bundles, which come from several stores)."""
    ids, tars = [], []
    for i in (1, 2):
        src = Store(tmp_path / f"src{i}")
        ids.append(src.put_manifest("diagnosis", files={"calibration.csv": f"run {i}".encode()}))
        src.set_ref("diagnoses/calibration", ids[-1])
        src.set_ref(f"runs/film-s{i}", src.put_manifest("checkpoint", files={"model.pt": f"w{i}".encode()}))
        tars.append(tmp_path / f"b{i}.tar")
        src.export_tar(["diagnoses/calibration", f"runs/film-s{i}"], tars[-1])
    dst = tmp_path / "dst"
    code, _, err = run_cli("store", "import", *map(str, tars), "--store", str(dst))
    assert code == 1 and "ref 'diagnoses/calibration' has diverged" in err and "--append" in err
    assert sorted(Store(dst).list_refs()) == ["diagnoses/calibration", "runs/film-s1"]  # b2.tar: nothing
    code, stdout, err = run_cli("store", "import", "--append", *map(str, tars), "--store", str(dst), "-f", "json")
    assert code == 0, err
    assert {(r["bundle"], r["ref"]): r["status"] for r in json.loads(stdout)} == {
        ("b1.tar", "diagnoses/calibration"): "unchanged",
        ("b1.tar", "runs/film-s1"): "unchanged",
        ("b2.tar", "diagnoses/calibration"): "extended",
        ("b2.tar", "runs/film-s2"): "created",
    }
    dst_store = Store(dst)
    assert [(e.version, e.id) for e in dst_store.ref_history("diagnoses/calibration")] == [(1, ids[0]), (2, ids[1])]
    assert dst_store.verify().ok
    # a run of the same name from another store is another run: refused even with --append, nothing of it lands
    other = Store(tmp_path / "other")
    other.set_ref("runs/film-s1", other.put_manifest("checkpoint", files={"model.pt": b"someone else's"}))
    other.export_tar(["runs/film-s1"], tmp_path / "other.tar")
    code, _, err = run_cli("store", "import", "--append", str(tmp_path / "other.tar"), "--store", str(dst))
    assert code == 1 and "ref 'runs/film-s1' has diverged" in err
    assert [e.id for e in dst_store.ref_history("runs/film-s1")] == [Store(tmp_path / "src1").resolve("runs/film-s1")]


def test_import_of_a_non_export_is_error(run_cli, tmp_path):
    bogus = tmp_path / "x.tar"
    bogus.write_text("hello")
    code, _, err = run_cli("store", "import", str(bogus))
    assert code == 1 and "Error:" in err and "not a readable tar" in err


def test_get_writes_each_file_byte_identical_to_its_object(run_cli, filled, store, tmp_path):
    out = tmp_path / "got"
    code, stdout, err = run_cli("store", "get", "runs/film-s0@1", "--out", str(out), "-f", "json")
    assert code == 0, err
    (row,) = json.loads(stdout)
    assert row["file"] == "c.csv" and row["path"] == str(out / "c.csv") and row["size"] == 1
    manifest = store.read_manifest("runs/film-s0@1")
    assert (out / "c.csv").read_bytes() == store.object_path(manifest.files["c.csv"].id).read_bytes() == b"1"
    code, _, err = run_cli("store", "get", filled["ckpt"][:12], "--file", "model.pt", "--out", str(out))
    assert code == 0, err
    assert (out / "model.pt").read_bytes() == b"w"


def test_get_names_a_rollout_after_what_it_recorded(run_cli, store, tmp_path):
    mid = store.put_manifest(
        "rollout",
        files={"rollout.mcap": b"mcap bytes"},
        meta={"robot": "go1", "mode": "descriptor", "command": [2, 0.0, 0.0]},
    )
    code, _, err = run_cli("store", "get", mid, "--out", str(tmp_path / "r"))
    assert code == 0, err
    assert (tmp_path / "r" / "go1-descriptor-vx2.0.mcap").read_bytes() == b"mcap bytes"


def test_get_bad_input_is_an_error_and_writes_nothing(run_cli, filled, tmp_path):
    (tmp_path / "afile").write_text("x")
    code, _, err = run_cli("store", "get", "runs/film-s0", "--out", str(tmp_path / "afile"))
    assert code == 1 and err.startswith("Error: ") and "is a file" in err
    code, _, err = run_cli("store", "get", "runs/film-s0", "--file", "nope.pt", "--out", str(tmp_path / "o"))
    assert code == 1 and "its files are: c.csv" in err and not (tmp_path / "o").exists()


def test_get_prints_each_whole_path_in_the_table(filled, store, tmp_path):
    out = tmp_path / "a-rather-long-folder-name" / "so-that-the-path-is-wider-than-its-column"
    table = _invoke("get", "runs/film-s0", "--out", str(out)).stdout  # 80 columns: the path cell folds
    cells = [line.split("│")[2].strip() for line in table.splitlines() if line.count("│") == 5]
    assert "…" not in table and "".join(cells) == str(out / "c.csv")
    assert (
        (out / "c.csv").read_bytes()
        == store.object_path(store.read_manifest("runs/film-s0").files["c.csv"].id).read_bytes()
        == b"2"
    )
