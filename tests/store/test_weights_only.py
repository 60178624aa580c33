"""Weights-only exports: trainer states left out and declared, recorded at import, known-absent afterwards."""

from __future__ import annotations

import json
import tarfile

import pytest
from crafted_bundles import history_bytes, listing, manifest_bytes, oid_of, write_bundle

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import Store
from morfic_cli.store.gc import walk

STATE = "trainer_state"


def _checkpoint(store: Store, weights: bytes, tensors: bytes, curve: bytes) -> tuple[str, str]:
    """A training checkpoint as the runner writes one: weights + curve, input trainer_state -> (ckpt, state)."""
    state = store.put_manifest(
        "checkpoint",
        config={"role": "trainer-state"},
        files={"trainer.json": b'{"iteration": 1}', "trainer-tensors.pt": tensors},
    )
    ckpt = store.put_manifest(
        "checkpoint", config={"variant": "film"}, inputs={STATE: state}, files={"model.pt": weights, "curve.csv": curve}
    )
    return ckpt, state


@pytest.fixture
def src(tmp_path):
    """A store whose runs/a has two checkpoints, each with its trainer state."""
    store = Store(tmp_path / "src")
    for weights, tensors, curve in ((b"W" * 100, b"T" * 1000, b"c1"), (b"V" * 100, b"U" * 1000, b"c2")):
        store.set_ref("runs/a", _checkpoint(store, weights, tensors, curve)[0])
    return store


@pytest.fixture
def ids(src):
    """ckpt1, state1 (runs/a@1 and its trainer state), ckpt2, state2 (runs/a@2 = runs/a)."""
    out = {}
    for n in (1, 2):
        out[f"ckpt{n}"] = src.resolve(f"runs/a@{n}")
        out[f"state{n}"] = src.read_manifest(out[f"ckpt{n}"]).inputs[STATE]
    return out


def _members(path) -> tuple[dict, list[str], list[str]]:
    """(header, object ids, index marker ids) of an export tar."""
    with tarfile.open(path) as tar:
        header = json.loads(tar.extractfile("morfic-export.json").read())
        names = tar.getnames()
    objects = sorted(n[8:10] + n[11:] for n in names if n.startswith("objects/"))
    markers = sorted(n[10:] for n in names if n.startswith("manifests/"))
    return header, objects, markers


def _blob(store: Store, manifest: str, name: str) -> str:
    return store.read_manifest(manifest).files[name].id


def _history(store: Store, name: str) -> list[tuple[int, str, str]]:
    return [(e.version, e.id, e.time) for e in store.ref_history(name)]


def test_weights_only_export_leaves_out_the_trainer_state_and_lists_it(src, ids, tmp_path):
    full = src.export_tar(["runs/a"], tmp_path / "full.tar", latest=True)
    shallow = src.export_tar(["runs/a"], tmp_path / "shallow.tar", latest=True, without_trainer_state=True)
    assert full.omitted == {} and shallow.omitted == {ids["state2"]: STATE}
    header, objects, markers = _members(tmp_path / "shallow.tar")
    weights = [ids["ckpt2"], _blob(src, ids["ckpt2"], "model.pt"), _blob(src, ids["ckpt2"], "curve.csv")]
    assert objects == sorted(weights) and markers == [ids["ckpt2"]]
    assert header == {
        "format": 1,
        "morfic_version": header["morfic_version"],
        "objects": 3,
        "refs": ["runs/a"],
        "omitted": {ids["state2"]: STATE},
    }
    # the full export: the same plus the trainer state manifest and its two files; no "omitted" in its header
    full_header, full_objects, full_markers = _members(tmp_path / "full.tar")
    state_files = [_blob(src, ids["state2"], "trainer.json"), _blob(src, ids["state2"], "trainer-tensors.pt")]
    assert full_objects == sorted([*weights, ids["state2"], *state_files])
    assert full_markers == sorted([ids["ckpt2"], ids["state2"]]) and "omitted" not in full_header
    assert full.bytes - shallow.bytes == src.objects.size(ids["state2"]) + 1000 + len(b'{"iteration": 1}')
    # the exported checkpoint manifest is the store's, byte for byte
    with tarfile.open(tmp_path / "shallow.tar") as tar:
        data = tar.extractfile(f"objects/{ids['ckpt2'][:2]}/{ids['ckpt2'][2:]}").read()
    assert data == src.get_bytes(ids["ckpt2"])


def test_every_version_of_a_weights_only_export_leaves_out_every_trainer_state(src, ids, tmp_path):
    report = src.export_tar(["runs/a"], tmp_path / "a.tar", without_trainer_state=True)
    assert report.omitted == dict(sorted({ids["state1"]: STATE, ids["state2"]: STATE}.items()))
    _, objects, markers = _members(tmp_path / "a.tar")
    assert len(objects) == 6 and markers == sorted([ids["ckpt1"], ids["ckpt2"]])


def test_import_records_the_gap_and_every_walk_knows_it(src, ids, tmp_path):
    src.export_tar(["runs/a"], tmp_path / "s.tar", latest=True, without_trainer_state=True)
    dst = Store(tmp_path / "dst")
    report = dst.import_tar(tmp_path / "s.tar")
    assert report.refs == {"runs/a": "created"} and report.omitted == [ids["state2"]] and report.filled == []
    assert report.objects_added == 3 and report.manifests == 1
    assert dst.resolve("runs/a") == ids["ckpt2"] and dst.read_manifest("runs/a") == src.read_manifest(ids["ckpt2"])
    assert sorted(p.name for p in (dst.root / "shallow").iterdir()) == [ids["state2"]]
    assert dst.is_omitted(ids["state2"]) and not src.is_omitted(ids["state2"])
    # verify and gc: healthy, nothing to delete, the marker stays
    check = dst.verify()
    assert check.ok and check.omitted == 1 and check.manifests == 1
    for dry_run in (True, False):
        gc = dst.gc(dry_run=dry_run)
        assert gc.removed == [] and gc.reachable == 3 and gc.omitted == 1
    assert list(dst.omitted.ids()) == [ids["state2"]]
    assert walk(dst, [ids["ckpt2"]]).absent == {ids["state2"]: STATE}
    # show names the gap; the trainer state itself is a clear not-found
    assert dst.describe("runs/a")["omitted"] == {STATE: ids["state2"]}
    assert "omitted" not in src.describe("runs/a")
    with pytest.raises(ArtifactNotFoundError, match="weights-only bundle left it out"):
        dst.resolve(ids["state2"])
    assert [r["id"] for r in dst.ls()] == [ids["ckpt2"]]
    assert dst.read_file("runs/a", "model.pt") == b"V" * 100


def test_re_export_of_a_shallow_store_stays_shallow_and_is_the_same_tar(src, ids, tmp_path):
    src.export_tar(["runs/a"], tmp_path / "s.tar", latest=True, without_trainer_state=True)
    dst = Store(tmp_path / "dst")
    dst.import_tar(tmp_path / "s.tar")
    again = dst.export_tar(["runs/a"], tmp_path / "again.tar", latest=True)  # no flag: the gap is declared anyway
    assert again.omitted == {ids["state2"]: STATE}
    assert (tmp_path / "again.tar").read_bytes() == (tmp_path / "s.tar").read_bytes()
    third = Store(tmp_path / "third")
    assert third.import_tar(tmp_path / "again.tar").omitted == [ids["state2"]]
    assert _history(third, "runs/a") == _history(dst, "runs/a")


def test_full_import_on_top_fills_the_gap(src, ids, tmp_path):
    src.export_tar(["runs/a"], tmp_path / "s.tar", latest=True, without_trainer_state=True)
    src.export_tar(["runs/a"], tmp_path / "full.tar", latest=True)
    dst = Store(tmp_path / "dst")
    dst.import_tar(tmp_path / "s.tar")
    report = dst.import_tar(tmp_path / "full.tar")
    assert report.refs == {"runs/a": "unchanged"} and report.filled == [ids["state2"]] and report.omitted == []
    assert report.objects_added == 3 and report.objects_present == 3
    assert list(dst.omitted.ids()) == [] and not dst.is_omitted(ids["state2"])
    assert dst.read_file(ids["state2"], "trainer-tensors.pt") == b"U" * 1000
    assert dst.verify().omitted == 0 and "omitted" not in dst.describe("runs/a")
    assert dst.export_tar(["runs/a"], tmp_path / "back.tar", latest=True).omitted == {}
    assert (tmp_path / "back.tar").read_bytes() == (tmp_path / "full.tar").read_bytes()
    # and a weights-only bundle into a store that has it all records nothing
    whole = Store(tmp_path / "whole")
    whole.import_tar(tmp_path / "full.tar")
    assert whole.import_tar(tmp_path / "s.tar").omitted == [] and list(whole.omitted.ids()) == []
    assert whole.verify().omitted == 0


def test_a_trainer_state_something_else_reaches_is_exported(src, ids, tmp_path):
    """A ref naming the trainer state itself keeps it in a weights-only export (only the input is skipped)."""
    src.set_ref("resume/a", ids["state2"])
    report = src.export_tar(["runs/a", "resume/a"], tmp_path / "x.tar", latest=True, without_trainer_state=True)
    assert report.omitted == {}
    _, objects, markers = _members(tmp_path / "x.tar")
    assert len(objects) == 6 and markers == sorted([ids["ckpt2"], ids["state2"]])


def test_gc_still_refuses_on_real_damage_in_a_shallow_store(src, ids, tmp_path):
    src.export_tar(["runs/a"], tmp_path / "s.tar", latest=True, without_trainer_state=True)
    dst = Store(tmp_path / "dst")
    dst.import_tar(tmp_path / "s.tar")
    dst.omitted.remove(ids["state2"])  # without the record, the absent trainer state is damage again
    with pytest.raises(StoreError, match=f"{ids['state2']} \\(missing\\)"):
        dst.gc(dry_run=False)
    assert any(f"input '{STATE}' {ids['state2']} is missing" in p for p in dst.verify().problems)
    assert dst.has(ids["ckpt2"])


def test_a_marker_only_excuses_a_trainer_state_input(tmp_path):
    store = Store(tmp_path / "s")
    gone = store.put_manifest("checkpoint", files={"model.pt": b"w"})
    run = store.put_manifest("run", inputs={"checkpoint": gone})
    store.set_ref("runs/r", run)
    store.objects.remove(gone)
    store.omitted.add(gone)
    with pytest.raises(StoreError, match="missing"):
        store.gc(dry_run=True)
    assert any(f"input 'checkpoint' {gone} is missing" in p for p in store.verify().problems)


def test_gc_drops_markers_that_no_longer_say_anything(src, ids, tmp_path):
    src.export_tar(["runs/a"], tmp_path / "s.tar", latest=True, without_trainer_state=True)
    dst = Store(tmp_path / "dst")
    dst.import_tar(tmp_path / "s.tar")
    stray = "ab" * 32  # reached by nothing
    dst.omitted.add(stray)
    assert dst.gc(dry_run=True).removed == [] and sorted(dst.omitted.ids()) == sorted([stray, ids["state2"]])
    dst.gc(dry_run=False)
    assert list(dst.omitted.ids()) == [ids["state2"]]
    (dst.root / "shallow" / "junk").write_text("x")
    assert dst.verify().problems == ["unexpected file in shallow/: junk"]


# -- hand-made bundles: only a trainer_state input may be left out, and only when the header says so ---------

_W = b"weights"
_STATE_ID = oid_of(b"a trainer state that is not in the bundle")


def _ckpt_bundle(path, role: str, omitted: object, *, hold_state: bool = False):
    """runs/evil -> a checkpoint naming ``_STATE_ID`` (or a held state manifest) under ``role``.

    ``omitted``: the header's "omitted" (a key None stands for the state's id), or None for no such key.
    """
    state = manifest_bytes(kind="checkpoint", config={"role": "trainer-state"})
    state_id = oid_of(state) if hold_state else _STATE_ID
    ckpt = manifest_bytes(
        kind="checkpoint", inputs={role: state_id}, files={"model.pt": {"id": oid_of(_W), "size": len(_W)}}
    )
    manifests = [ckpt, state] if hold_state else [ckpt]
    header = {"format": 1, "morfic_version": "0.1.0", "objects": 1 + len(manifests), "refs": ["runs/evil"]}
    if isinstance(omitted, dict):
        header["omitted"] = {state_id if k is None else k: v for k, v in omitted.items()}
    elif omitted is not None:
        header["omitted"] = omitted
    return write_bundle(
        path, blobs=[_W], manifests=manifests, refs={"runs/evil": history_bytes([oid_of(ckpt)])}, header=header
    ), oid_of(ckpt)


REFUSED = {
    "omitted-as-a-checkpoint": (
        dict(role="checkpoint", omitted={None: "checkpoint"}),
        "may only leave out trainer_state inputs",
    ),
    "declared-trainer-state-used-as-checkpoint": (
        dict(role="checkpoint", omitted={None: STATE}),
        "names the left-out input",
    ),
    "undeclared-gap": (dict(role=STATE, omitted=None), "the export is incomplete"),
    "declared-but-named-by-nothing": (
        dict(role=STATE, omitted={None: STATE, "cd" * 32: STATE}),
        "no manifest in it names that input",
    ),
    "declared-yet-held": (dict(role=STATE, omitted={None: STATE}, hold_state=True), "yet it holds it"),
    "omitted-not-a-map": (dict(role=STATE, omitted=[_STATE_ID]), "invalid morfic-export.json"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_bundle_that_leaves_out_more_than_trainer_states_imports_nothing(tmp_path, case):
    kwargs, needle = REFUSED[case]
    path, _ = _ckpt_bundle(tmp_path / "evil.tar", **kwargs)
    local = Store(tmp_path / "local")
    local.set_ref("runs/mine", local.put_manifest("run", files={"c.csv": b"1"}))
    for store in (local, Store(tmp_path / "missing")):
        before = listing(store.root)
        with pytest.raises(StoreError, match=needle):
            store.import_tar(path)
        assert listing(store.root) == before


def test_a_well_formed_weights_only_bundle_imports(tmp_path):
    path, ckpt = _ckpt_bundle(tmp_path / "ok.tar", role=STATE, omitted={None: STATE})
    store = Store(tmp_path / "s")
    report = store.import_tar(path)
    assert report.omitted == [_STATE_ID] and store.resolve("runs/evil") == ckpt
    assert store.verify().ok and store.gc(dry_run=False).removed == []


def test_cli_weights_only_round_trip(run_cli, src, ids, tmp_path):
    out = tmp_path / "s.tar"
    code, _, err = run_cli(
        "store", "export", "runs/a", "--latest", "--without-trainer-state", "--out", str(out), "--store", str(src.root)
    )
    assert code == 0, err
    assert "3 objects" in err and "1 trainer state(s) left out" in err
    if out.is_dir():  # `--out` as the folder the tar goes into (issue 18b): DIR/a.tar
        out = out / "a.tar"
    assert _members(out)[0]["omitted"] == {ids["state2"]: STATE}
    dst = tmp_path / "dst"
    code, _, err = run_cli("store", "import", str(out), "--store", str(dst))
    assert code == 0 and "1 trainer state(s) left out" in err
    code, _, err = run_cli("store", "verify", "--store", str(dst))
    assert code == 0 and "1 trainer state(s) left out by a weights-only import" in err
    code, out_json, _ = run_cli("store", "show", "runs/a", "--store", str(dst), "-f", "json")
    assert code == 0 and json.loads(out_json)["omitted"] == {STATE: ids["state2"]}
    code, _, err = run_cli("store", "show", ids["state2"], "--store", str(dst))
    assert code == 1 and "Error:" in err and "weights-only bundle left it out" in err
