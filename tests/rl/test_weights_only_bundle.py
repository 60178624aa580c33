"""A smoke run shipped weights-only (`store export --without-trainer-state`): evaluates, exports, won't resume."""

from __future__ import annotations

import json
import tarfile

import pytest
from crafted_bundles import listing

from morfic_cli.rl.resume import load_resume_point
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")

RUN = "runs/film-s0"


@pytest.fixture(scope="module")
def bundles(smoke_runs, tmp_path_factory):
    """The smoke-trained source store, and its run exported --latest in full and weights-only."""
    base = tmp_path_factory.mktemp("weights-only")
    src = smoke_runs.store(base / "src")
    full = src.export_tar([RUN], base / "full.tar", latest=True)
    shallow = src.export_tar([RUN], base / "shallow.tar", latest=True, without_trainer_state=True)
    return src, full, shallow


def _objects(path) -> list[str]:
    with tarfile.open(path) as tar:
        return sorted(n[8:10] + n[11:] for n in tar.getnames() if n.startswith("objects/"))


def _imported(tmp_path, report, name: str = "dst") -> Store:
    store = Store(tmp_path / name)
    store.import_tar(report.path)
    return store


def test_the_weights_only_bundle_is_the_run_without_its_trainer_state(bundles, tmp_path):
    src, full, shallow = bundles
    ckpt = src.read_manifest(RUN)
    state = src.read_manifest(ckpt.inputs["trainer_state"])
    assert sorted(ckpt.files) == ["curve.csv", "curve.png", "model.pt"]
    assert sorted(state.files) == ["trainer-tensors.pt", "trainer.json"]
    weights = sorted([ckpt.id, *(f.id for f in ckpt.files.values())])
    assert _objects(shallow.path) == weights and shallow.omitted == {state.id: "trainer_state"}
    assert _objects(full.path) == sorted([*weights, state.id, *(f.id for f in state.files.values())])
    assert shallow.bytes == src.objects.size(ckpt.id) + sum(f.size for f in ckpt.files.values())
    assert full.bytes - shallow.bytes == src.objects.size(state.id) + sum(f.size for f in state.files.values())
    size_full, size_shallow = full.path.stat().st_size, shallow.path.stat().st_size
    assert size_shallow < size_full / 2  # the trainer state is about twice the weights
    assert size_shallow - shallow.bytes < 64 * 1024 and size_full - full.bytes < 64 * 1024  # tar framing only
    # imported into an empty store: the same ref, the same checkpoint id, the same manifest bytes
    dst = _imported(tmp_path, shallow)
    assert dst.list_refs() == [RUN] and dst.resolve(RUN) == ckpt.id
    assert dst.get_bytes(ckpt.id) == src.get_bytes(ckpt.id)
    assert [e.id for e in dst.ref_history(RUN)] == [ckpt.id]
    assert list(dst.omitted.ids()) == [state.id] and dst.omitted_inputs(dst.read_manifest(RUN)) == {
        "trainer_state": state.id
    }
    assert dst.read_file(RUN, "model.pt") == src.read_file(RUN, "model.pt")


def test_a_weights_only_run_evaluates_diagnoses_and_exports(run_cli, bundles, tmp_path):
    _, _, shallow = bundles
    dst = _imported(tmp_path, shallow)
    root = str(dst.root)
    code, out, err = run_cli(
        "eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "4", "--store", root, "-f", "json", "-q"
    )
    assert code == 0, err
    assert [(r["robot"], r["mode"]) for r in json.loads(out)] == [("go2", "descriptor")]
    assert dst.read_manifest("evals/film-s0").inputs["checkpoint"] == dst.resolve(RUN)
    code, out, err = run_cli(
        "diagnose",
        RUN,
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "30",
        "--trunc-eps",
        "0.8",
        "--store",
        root,
        "-f",
        "json",
        "-q",
    )
    assert code == 0, err
    assert [r["robot"] for r in json.loads(out)] == ["go2"]
    # rsl-rl's layout needs an optimiser state: a fresh one, said so
    rsl = tmp_path / "rsl"
    code, out, err = run_cli("export", RUN, "--to", "rsl-rl", "--out", str(rsl), "--store", root, "-f", "json")
    assert code == 0, err
    assert json.loads(out)["optimizer"] == "fresh" and "optimizer state: fresh" in err
    assert sorted(p.name for p in rsl.iterdir()) == ["agent.json", "model_2.pt", "train.json"]
    # everything written since names the checkpoint, so gc still keeps it all and the gap is still declared
    assert dst.gc(dry_run=False).removed == [] and dst.verify().ok
    assert dst.export_tar([RUN], tmp_path / "again.tar", latest=True).omitted == shallow.omitted


def test_a_weights_only_run_exports_to_onnx(run_cli, bundles, tmp_path):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    src, _, shallow = bundles
    dst = _imported(tmp_path, shallow)
    out = tmp_path / "deploy"
    code, stdout, err = run_cli(
        "export", RUN, "--robot", "go2", "--out", str(out), "--store", str(dst.root), "-f", "json"
    )
    assert code == 0, err
    assert json.loads(stdout)["verification"]["ok"]
    manifest = dst.read_manifest("exports/film-s0/go2-onnx")
    assert manifest.inputs == {"checkpoint": src.resolve(RUN)} and sorted(p.name for p in out.iterdir()) == [
        "policy.json",
        "policy.onnx",
    ]


def test_resume_of_a_weights_only_run_is_an_error_and_changes_nothing(run_cli, bundles, tmp_path):
    _, _, shallow = bundles
    dst = _imported(tmp_path, shallow)
    before = listing(dst.root)
    code, out, err = run_cli("train", "--resume", RUN, "--store", str(dst.root), "-q")
    assert code == 1 and out == ""
    assert err.startswith(
        f"Error: {RUN} was imported without its trainer state (a weights-only bundle); it "
        "evaluates and exports, but cannot be resumed. Import the full bundle"
    )
    assert listing(dst.root) == before


def test_gc_re_export_and_filling_the_gap(bundles, tmp_path):
    src, full, shallow = bundles
    dst = _imported(tmp_path, shallow)
    before = listing(dst.root)
    report = dst.gc(dry_run=False)
    assert report.removed == [] and report.reachable == 4 and report.omitted == 1
    assert listing(dst.root) == before
    # a re-export of the shallow store is the same weights-only tar, and imports again
    again = dst.export_tar([RUN], tmp_path / "again.tar", latest=True)
    assert again.path.read_bytes() == shallow.path.read_bytes()
    third = _imported(tmp_path, again, "third")
    assert third.resolve(RUN) == src.resolve(RUN) and list(third.omitted.ids()) == list(dst.omitted.ids())
    # the full bundle on top: the trainer state arrives, the run resumes
    filled = dst.import_tar(full.path)
    state_id = src.read_manifest(RUN).inputs["trainer_state"]
    assert filled.refs == {RUN: "unchanged"} and filled.filled == [state_id] and filled.objects_added == 3
    assert list(dst.omitted.ids()) == [] and dst.verify().omitted == 0
    point = load_resume_point(dst, RUN)
    assert point.trainer["iteration"] == 2 and point.manifest.id == src.resolve(RUN)
