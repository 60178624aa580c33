"""Results-only exports on a hand-made store: which refs go in, what stays out, and the store after import.

The store is what `morfic reproduce` leaves, in miniature: two runs (a, b) with a checkpoint each (weights,
curve, a trainer state), an eval per run (with a rollout: log + figure), and the shared refs
``diagnoses/calibration`` (v1: a's diagnosis, v2: b's) and ``diagnoses/fixed-rollout/x`` (v1: actor a, critics a
and b), and a later ``tables/compare-baselines`` naming both checkpoints.
"""

from __future__ import annotations

import json
import tarfile

import pytest
from crafted_bundles import history_bytes, listing, manifest_bytes, oid_of, write_bundle

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store import Store
from morfic_cli.store.gc import walk
from morfic_cli.store.results import results_histories
from morfic_cli.store.shallow import RESULTS_ONLY, WEIGHTS_ONLY, omittable_file

STATE = "trainer_state"


def _run(store: Store, name: str) -> dict[str, str]:
    """runs/<name> -> one checkpoint (its state, weights, curve), its rollout (log, obs, figure) and evals/<name>."""
    ids = {}
    ids["state"] = store.put_manifest(
        "checkpoint",
        config={"role": "trainer-state"},
        files={"trainer.json": b"{}", "trainer-tensors.pt": name.encode() * 3000},
    )
    ids["ckpt"] = store.put_manifest(
        "checkpoint",
        config={"variant": "film"},
        inputs={STATE: ids["state"]},
        files={
            "model.pt": name.encode() * 1000,
            "curve.csv": f"it,{name}".encode(),
            "curve.png": b"png" + name.encode(),
        },
    )
    store.set_ref(f"runs/{name}", ids["ckpt"])
    ids["rollout"] = store.put_manifest(
        "rollout",
        config={"run": name},
        inputs={"checkpoint": ids["ckpt"]},
        files={
            "rollout.mcap": name.encode() * 2000,
            "obs.npz": name.encode() * 500,
            "speed.png": b"speed" + name.encode(),
        },
    )
    ids["eval"] = store.put_manifest(
        "eval",
        config={"run": name},
        inputs={"checkpoint": ids["ckpt"], "rollout/go2/descriptor/vx2": ids["rollout"]},
        files={"eval.csv": f"robot\ngo2,{name}".encode()},
    )
    store.set_ref(f"evals/{name}", ids["eval"])
    return ids


def _diagnosis(store: Store, name: str, ckpt: str) -> tuple[str, str]:
    """A calibration diagnosis of one checkpoint with its diagnostic rollout -> (diagnosis, rollout)."""
    rollout = store.put_manifest(
        "rollout",
        config={"diag": name},
        inputs={"checkpoint": ckpt},
        files={"rollout.mcap": b"D" * 700 + name.encode(), "obs.npz": b"O" * 300 + name.encode()},
    )
    diag = store.put_manifest(
        "diagnosis",
        config={"specs": [name]},
        inputs={f"checkpoint/runs/{name}": ckpt, f"rollout/runs/{name}/go2": rollout},
        files={"calibration.csv": f"checkpoint\n{ckpt}".encode()},
    )
    return diag, rollout


@pytest.fixture
def src(tmp_path):
    store = Store(tmp_path / "src")
    a, b = _run(store, "a"), _run(store, "b")
    a["diag"], a["drollout"] = _diagnosis(store, "a", a["ckpt"])
    store.set_ref("diagnoses/calibration", a["diag"])
    b["diag"], b["drollout"] = _diagnosis(store, "b", b["ckpt"])
    store.set_ref("diagnoses/calibration", b["diag"])
    fixed = store.put_manifest(
        "diagnosis",
        config={"robot": "x"},
        inputs={"actor": a["ckpt"], "rollout": a["drollout"], "critic/runs/a": a["ckpt"], "critic/runs/b": b["ckpt"]},
        files={"fixed_rollout.csv": b"critic\nMC"},
    )
    store.set_ref("diagnoses/fixed-rollout/x", fixed)
    a["check"] = store.put_manifest(
        "table",
        config={"check": "training-conditions"},
        inputs={"checkpoint": a["ckpt"]},
        files={"training_check.csv": b"vx\n1"},
    )
    store.set_ref("checks/training-conditions/a", a["check"])
    store.set_ref(
        "tables/compare-baselines",
        store.put_manifest(  # made from the results: rebuilt by a report
            "table",
            inputs={"checkpoint/a": a["ckpt"], "checkpoint/b": b["ckpt"], "eval/a": a["eval"], "eval/b": b["eval"]},
            files={"t.csv": b"1"},
        ),
    )
    store.ids = {"a": a, "b": b, "fixed": fixed}
    return store


def _members(path) -> tuple[dict, list[str], list[str], list[str]]:
    """(header, object ids, index marker ids, ref names) of an export tar."""
    with tarfile.open(path) as tar:
        header = json.loads(tar.extractfile("morfic-export.json").read())
        names = tar.getnames()
    objects = sorted(n[8:10] + n[11:] for n in names if n.startswith("objects/"))
    return (
        header,
        objects,
        sorted(n[10:] for n in names if n.startswith("manifests/")),
        sorted(n[5:] for n in names if n.startswith("refs/")),
    )


def _files(store: Store, oid: str, *names: str) -> list[str]:
    manifest = store.read_manifest(oid)
    return [manifest.files[n].id for n in names]


def _history(store: Store, name: str) -> list[tuple[int, str, str]]:
    return [(e.version, e.id, e.time) for e in store.ref_history(name)]


def test_the_refs_of_a_runs_results_and_how_much_of_each_history(src):
    a, b = src.ids["a"], src.ids["b"]
    got = results_histories(src, ["runs/a"])
    # runs/a as --latest makes it; evals/a and its check whole; the shared refs up to a's last result:
    # calibration@1 only, the fixed rollout (it names a) whole; compare-baselines (a table made from the evals)
    # and b's run and evals stay out
    assert {name: [e.id for e in h] for name, h in got.items()} == {
        "runs/a": [a["ckpt"]],
        "evals/a": [a["eval"]],
        "diagnoses/calibration": [a["diag"]],
        "diagnoses/fixed-rollout/x": [src.ids["fixed"]],
        "checks/training-conditions/a": [a["check"]],
    }
    assert got["runs/a"][0].version == 1 and got["runs/a"][0].time == src.ref_history("runs/a")[-1].time
    assert got["diagnoses/calibration"] == src.ref_history("diagnoses/calibration")[:1]
    got = results_histories(src, ["runs/b"])
    assert [e.id for e in got["diagnoses/calibration"]] == [a["diag"], b["diag"]]  # b's is v2: the prefix holds a's
    assert sorted(got) == ["diagnoses/calibration", "diagnoses/fixed-rollout/x", "evals/b", "runs/b"]


def test_a_results_only_bundle_leaves_out_weights_states_and_logs(src, tmp_path):
    a, b = src.ids["a"], src.ids["b"]
    report = src.export_tar(["runs/b"], tmp_path / "b.tar", results_only=True)
    header, objects, markers, refs = _members(report.path)
    assert refs == report.refs == ["diagnoses/calibration", "diagnoses/fixed-rollout/x", "evals/b", "runs/b"]
    # what stays out: both trainer states (a's checkpoint comes with calibration@1 and the fixed rollout), both
    # weights, a's curve (b's table stays: b is the run exported; its figure curve.png does not), every rollout log
    # and observation file (b's and a's eval rollouts are not reached: evals/a is not in), every rendered figure
    assert report.omitted == dict(sorted({a["state"]: STATE, b["state"]: STATE}.items()))
    left_files = {
        **dict(
            zip(
                _files(src, a["ckpt"], "model.pt", "curve.csv", "curve.png"),
                ("model.pt", "curve.csv", "curve.png"),
                strict=True,
            )
        ),
        **dict(zip(_files(src, b["ckpt"], "model.pt", "curve.png"), ("model.pt", "curve.png"), strict=True)),
        **dict.fromkeys(_files(src, b["rollout"], "speed.png"), "speed.png"),
    }
    for rollout in (b["rollout"], a["drollout"], b["drollout"]):
        mcap, obs = _files(src, rollout, "rollout.mcap", "obs.npz")
        left_files |= {mcap: "rollout.mcap", obs: "obs.npz"}
    assert report.omitted_files == dict(sorted(left_files.items()))
    assert header == {
        "format": 1,
        "morfic_version": header["morfic_version"],
        "objects": len(objects),
        "refs": refs,
        "omitted": report.omitted,
        "omitted_files": report.omitted_files,
    }
    # what goes in: 9 manifests and their kept files, nothing else
    manifests = sorted(
        [
            a["ckpt"],
            b["ckpt"],
            b["rollout"],
            b["eval"],
            a["drollout"],
            b["drollout"],
            a["diag"],
            b["diag"],
            src.ids["fixed"],
        ]
    )
    kept = [
        *_files(src, b["ckpt"], "curve.csv"),
        *_files(src, b["eval"], "eval.csv"),
        *_files(src, a["diag"], "calibration.csv"),
        *_files(src, b["diag"], "calibration.csv"),
        *_files(src, src.ids["fixed"], "fixed_rollout.csv"),
    ]
    assert markers == manifests and objects == sorted([*manifests, *kept])
    assert not set(objects) & (set(left_files) | set(report.omitted))
    assert report.bytes == sum(src.objects.size(oid) for oid in objects)
    assert sum(src.objects.size(oid) for oid in left_files) == (
        2 * 1000 + 4 + 4 + 2000 + 500 + 2 * (701 + 301) + len(b"pngb") + len(b"speedb")
    )


def test_import_gives_the_same_refs_and_ids_and_every_walk_knows_the_gaps(src, tmp_path):
    b = src.ids["b"]
    report = src.export_tar(["runs/b"], tmp_path / "b.tar", results_only=True)
    dst = Store(tmp_path / "dst")
    imported = dst.import_tar(report.path)
    assert imported.refs == dict.fromkeys(report.refs, "created")
    assert imported.omitted == sorted(report.omitted) and imported.omitted_files == sorted(report.omitted_files)
    for name in ("diagnoses/calibration", "diagnoses/fixed-rollout/x", "evals/b"):
        assert _history(dst, name) == _history(src, name), name
    assert _history(dst, "runs/b") == [(1, b["ckpt"], src.ref_history("runs/b")[-1].time)]
    for oid in (b["ckpt"], b["eval"], b["diag"], src.ids["fixed"]):
        assert dst.get_bytes(oid) == src.get_bytes(oid)
    assert sorted(p.name for p in (dst.root / "shallow").iterdir()) == sorted([*report.omitted, *report.omitted_files])
    check = dst.verify()
    assert check.ok and check.omitted == 2 and check.omitted_files == len(report.omitted_files) == 12
    assert dst.gc(dry_run=False).removed == [] and dst.gc(dry_run=True).omitted == 14
    assert sorted(dst.omitted.ids()) == sorted([*report.omitted, *report.omitted_files])
    reached = walk(dst, [b["ckpt"]])
    model, curve_png = _files(src, b["ckpt"], "model.pt", "curve.png")
    assert reached.absent == {b["state"]: STATE} and reached.absent_files == {model: "model.pt", curve_png: "curve.png"}
    # what is there reads; what was left out says so
    assert dst.read_file("runs/b", "curve.csv") == b"it,b"
    assert dst.describe("runs/b")["omitted_files"] == {"curve.png": curve_png, "model.pt": model}
    assert dst.omitted_files(dst.read_manifest(b["rollout"])) == dict(
        zip(
            ("rollout.mcap", "obs.npz", "speed.png"),
            _files(src, b["rollout"], "rollout.mcap", "obs.npz", "speed.png"),
            strict=True,
        )
    )
    for reader in (dst.read_file, dst.file_path):
        with pytest.raises(ArtifactNotFoundError, match="a results-only bundle left it out"):
            reader("runs/b", "model.pt")
    for name in ("rollout.mcap", "speed.png"):
        with pytest.raises(ArtifactNotFoundError, match="a results-only bundle left it out"):
            dst.read_file(b["rollout"], name)
    a = src.ids["a"]  # a's checkpoint is here (the fixed rollout's actor), its curve is in a's own bundle
    names = ("curve.csv", "curve.png", "model.pt")
    assert dst.describe(a["ckpt"])["omitted_files"] == dict(zip(names, _files(src, a["ckpt"], *names), strict=True))
    with pytest.raises(ArtifactNotFoundError, match="a results-only bundle left it out"):
        dst.read_file(a["ckpt"], "curve.csv")
    # a re-export from the imported store is the same tar
    again = dst.export_tar(["runs/b"], tmp_path / "again.tar", results_only=True)
    assert again.path.read_bytes() == report.path.read_bytes()


def test_weights_omitted_is_true_only_for_a_checkpoint_whose_model_pt_was_left_out(src, tmp_path):
    dst = Store(tmp_path / "dst")
    dst.import_tar(src.export_tar(["runs/b"], tmp_path / "b.tar", results_only=True).path)
    assert dst.weights_omitted(dst.read_manifest("runs/b"))  # b's weights left out
    assert dst.weights_omitted(dst.read_manifest(src.ids["a"]["ckpt"]))  # a's checkpoint, the fixed rollout's actor
    assert not src.weights_omitted(src.read_manifest("runs/b"))  # the full store holds them
    assert not dst.weights_omitted(dst.read_manifest("evals/b"))  # no model.pt: not a checkpoint
    dst.import_tar(src.export_tar(["runs/b"], tmp_path / "w.tar", latest=True, without_trainer_state=True).path)
    assert not dst.weights_omitted(dst.read_manifest("runs/b"))  # a weights-only bundle on top fills them


def test_two_runs_bundles_import_in_either_order(src, tmp_path):
    paths = [src.export_tar([f"runs/{r}"], tmp_path / f"{r}.tar", results_only=True).path for r in "ab"]
    stores, statuses = [], []
    for order in (paths, paths[::-1]):
        dst = Store(tmp_path / f"dst-{order[0].stem}")
        statuses.append([dst.import_tar(p).refs["diagnoses/calibration"] for p in order])
        stores.append(dst)
        assert dst.list_refs() == [
            "checks/training-conditions/a",
            "diagnoses/calibration",
            "diagnoses/fixed-rollout/x",
            "evals/a",
            "evals/b",
            "runs/a",
            "runs/b",
        ]
        assert _history(dst, "diagnoses/calibration") == _history(src, "diagnoses/calibration")
        assert dst.verify().ok
    # a first: calibration@1, then b's bundle extends it; b first: a's bundle holds a prefix, unchanged
    assert statuses == [["created", "extended"], ["created", "unchanged"]]
    assert sorted(stores[0].objects.iter_ids()) == sorted(stores[1].objects.iter_ids())


def test_a_weights_only_bundle_on_top_fills_the_weights(src, tmp_path):
    b = src.ids["b"]
    results = src.export_tar(["runs/b"], tmp_path / "r.tar", results_only=True)
    weights = src.export_tar(["runs/b"], tmp_path / "w.tar", latest=True, without_trainer_state=True)
    dst = Store(tmp_path / "dst")
    dst.import_tar(results.path)
    filled = dst.import_tar(weights.path)
    model, curve_png = _files(src, b["ckpt"], "model.pt", "curve.png")
    assert filled.refs == {"runs/b": "unchanged"} and filled.filled == sorted([model, curve_png])
    assert filled.objects_added == 2
    assert dst.read_file("runs/b", "model.pt") == b"b" * 1000 and not dst.is_omitted(model)
    assert dst.is_omitted(b["state"]) and dst.verify().ok and dst.verify().omitted_files == 10


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ("rollouts/a", r"'rollouts/a' is neither \(it is a rollout artifact\): name the runs \(runs/NAME"),
        ("runs/nope", "no ref 'runs/nope'"),
    ],
)
def test_results_only_takes_runs_or_results(src, tmp_path, spec, needle):
    src.set_ref("rollouts/a", src.put_manifest("rollout", config={"x": 1}))
    before = listing(src.root)
    with pytest.raises((StoreError, ArtifactNotFoundError), match=needle):
        src.export_tar([spec], tmp_path / "x.tar", results_only=True)
    assert not (tmp_path / "x.tar").exists() and listing(src.root) == before


def test_a_run_without_results_is_an_error(src, tmp_path):
    src.set_ref("runs/c", src.put_manifest("checkpoint", files={"model.pt": b"c"}))
    src.set_ref("tables/c", src.put_manifest("table", inputs={"checkpoint": "runs/c", "eval": "evals/a"}))  # derived
    with pytest.raises(StoreError, match="runs/c has no eval, diagnosis or check in store"):
        src.export_tar(["runs/a", "runs/c"], tmp_path / "x.tar", results_only=True)
    assert not (tmp_path / "x.tar").exists()


def test_results_only_leaves_out_only_what_shallow_names():
    assert RESULTS_ONLY.roles == {STATE} and RESULTS_ONLY.files == {"model.pt", "rollout.mcap", "obs.npz", "curve.png"}
    assert RESULTS_ONLY.foreign_files == {"curve.csv"} and not RESULTS_ONLY.own and RESULTS_ONLY.figures
    kept = RESULTS_ONLY.keeping(frozenset({"k"}))
    cases = {
        ("k", "curve.csv", "checkpoint"): False,
        ("o", "curve.csv", "checkpoint"): True,
        ("k", "model.pt", "checkpoint"): True,
        ("o", "eval.csv", "eval"): False,
        ("k", "curve.png", "checkpoint"): True,
        ("r", "speed.png", "rollout"): True,
        ("r", "speed.pdf", "rollout"): True,
        ("d", "ev.PNG", "diagnosis"): True,
        ("d", "calibration.csv", "diagnosis"): False,
        ("m", "video.mp4", "media"): False,
        ("p", "figures/ev.pdf", "report"): True,
        ("c", "x.png", "checkpoint"): False,
    }
    assert {case: kept.leaves_out(*case) for case in cases} == cases
    assert not WEIGHTS_ONLY.leaves_out("r", "speed.png", "rollout")


def test_only_results_figures_and_the_named_files_may_be_missing():
    assert [
        omittable_file(k, n)
        for k, n in (
            ("rollout", "speed.png"),
            ("diagnosis", "critic_study.png"),
            ("eval", "x.gif"),
            ("report", "figures/ev.pdf"),
            ("checkpoint", "curve.png"),
            ("table", "model.pt"),
        )
    ] == [True] * 6
    assert [
        omittable_file(k, n)
        for k, n in (
            ("checkpoint", "x.png"),
            ("media", "video.mp4"),
            ("table", "t.png"),
            ("diagnosis", "calibration.csv"),
            ("rollout", "speed.png.csv"),
            ("eval", "eval.csv"),
        )
    ] == [False] * 6


# -- hand-made bundles: only the weight and log files may be left out, and only when the header says so ----------

_CURVE = b"curve"
_GONE = b"weights that are not in the bundle"


def _file_bundle(path, name: str, omitted_files: object, *, hold: bool = False):
    """runs/evil -> a checkpoint naming the object of ``_GONE`` as file ``name`` (held in the tar with ``hold``)."""
    ckpt = manifest_bytes(
        kind="checkpoint",
        files={
            name: {"id": oid_of(_GONE), "size": len(_GONE)},
            "curve.csv": {"id": oid_of(_CURVE), "size": len(_CURVE)},
        },
    )
    blobs = [_CURVE, _GONE] if hold else [_CURVE]
    header = {"format": 1, "morfic_version": "0.1.0", "objects": 1 + len(blobs), "refs": ["runs/evil"]}
    if omitted_files is not None:
        header["omitted_files"] = omitted_files
    return write_bundle(
        path, blobs=blobs, manifests=[ckpt], refs={"runs/evil": history_bytes([oid_of(ckpt)])}, header=header
    ), oid_of(ckpt)


REFUSED = {
    "a-file-name-that-may-not-be-left-out": (
        dict(name="eval.csv", omitted_files={oid_of(_GONE): "eval.csv"}),
        "may only leave out curve.csv, curve.png, model.pt, obs.npz, rollout.mcap "
        r"and rendered figures \(png/pdf/gif/mp4 of diagnosis, eval, report, "
        r"rollout artifacts\) files",
    ),
    "declared-as-another-file": (
        dict(name="eval.csv", omitted_files={oid_of(_GONE): "model.pt"}),
        "names the left-out file",
    ),
    "undeclared-gap": (dict(name="model.pt", omitted_files=None), "the export is incomplete"),
    "declared-but-named-by-nothing": (
        dict(name="model.pt", omitted_files={oid_of(_GONE): "model.pt", "cd" * 32: "obs.npz"}),
        "no manifest in it names that file",
    ),
    "declared-yet-held": (
        dict(name="model.pt", omitted_files={oid_of(_GONE): "model.pt"}, hold=True),
        "yet it holds it",
    ),
    "not-a-map": (dict(name="model.pt", omitted_files=[oid_of(_GONE)]), "invalid morfic-export.json"),
    # a figure may be left out of a result (rollout, eval, diagnosis, report), not of a checkpoint
    "a-checkpoints-figure": (
        dict(name="x.png", omitted_files={oid_of(_GONE): "x.png"}),
        r"names the left-out file \w+ as 'x.png' \(a checkpoint artifact\), but only",
    ),
    "a-figure-label-that-is-no-plain-name": (
        dict(name="model.pt", omitted_files={oid_of(_GONE): "../x.png"}),
        "as '../x.png', but a bundle may only leave out",
    ),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_bundle_that_leaves_out_other_files_imports_nothing(tmp_path, case):
    kwargs, needle = REFUSED[case]
    path, _ = _file_bundle(tmp_path / "evil.tar", **kwargs)
    for store in (Store(tmp_path / "local"), Store(tmp_path / "missing")):
        if store.root.name == "local":
            store.set_ref("runs/mine", store.put_manifest("run", files={"c.csv": b"1"}))
        before = listing(store.root)
        with pytest.raises(StoreError, match=needle):
            store.import_tar(path)
        assert listing(store.root) == before


def test_a_well_formed_results_only_bundle_imports(tmp_path):
    path, ckpt = _file_bundle(tmp_path / "ok.tar", "model.pt", {oid_of(_GONE): "model.pt"})
    store = Store(tmp_path / "s")
    report = store.import_tar(path)
    assert report.omitted_files == [oid_of(_GONE)] and store.resolve("runs/evil") == ckpt
    assert store.verify().ok and store.verify().omitted_files == 1 and store.gc(dry_run=False).removed == []


def test_a_results_figures_may_be_left_out_and_verify_counts_them(tmp_path):
    """A diagnosis whose ev.png the header lists as left out imports; verify counts the gap, gc keeps the rest."""
    table = b"robot,ev\ngo2,0.5\n"
    diag = manifest_bytes(
        kind="diagnosis",
        files={
            "ev.png": {"id": oid_of(_GONE), "size": len(_GONE)},
            "calibration.csv": {"id": oid_of(table), "size": len(table)},
        },
    )
    header = {
        "format": 1,
        "morfic_version": "0.1.0",
        "objects": 2,
        "refs": ["diagnoses/calibration"],
        "omitted_files": {oid_of(_GONE): "ev.png"},
    }
    path = write_bundle(
        tmp_path / "d.tar",
        blobs=[table],
        manifests=[diag],
        header=header,
        refs={"diagnoses/calibration": history_bytes([oid_of(diag)])},
    )
    store = Store(tmp_path / "s")
    assert store.import_tar(path).omitted_files == [oid_of(_GONE)]
    check = store.verify()
    assert check.ok and check.omitted_files == 1 and store.gc(dry_run=False).removed == []
    assert store.omitted_files(store.read_manifest(oid_of(diag))) == {"ev.png": oid_of(_GONE)}
    with pytest.raises(ArtifactNotFoundError, match="rendered figures"):
        store.read_file("diagnoses/calibration", "ev.png")
    assert store.read_file("diagnoses/calibration", "calibration.csv") == table


def test_cli_results_only_round_trip(run_cli, src, tmp_path):
    b = src.ids["b"]
    code, out, err = run_cli(
        "store", "export", "runs/b", "--results-only", "--out", str(tmp_path / "bundles"), "--store", str(src.root)
    )
    assert code == 0, err
    assert out == f"{tmp_path / 'bundles' / 'b.tar'}\n"
    left = "2 trainer state(s) and 12 weight, rollout-log, curve and figure file(s) left out"
    assert "exported 4 ref(s)" in err and left in err
    dst = str(tmp_path / "dst")
    code, _, err = run_cli("store", "import", str(tmp_path / "bundles" / "b.tar"), "--store", dst)
    assert code == 0 and left in err
    code, _, err = run_cli("store", "verify", "--store", dst)
    assert code == 0 and "12 weight, rollout-log, curve and figure file(s) left out by a results-only import" in err
    code, out, _ = run_cli("store", "show", "runs/b", "--store", dst, "-f", "json")
    assert code == 0 and json.loads(out)["omitted_files"] == dict(
        zip(("model.pt", "curve.png"), _files(src, b["ckpt"], "model.pt", "curve.png"), strict=True)
    )
    code, _, err = run_cli(
        "store", "get", "runs/b", "--file", "model.pt", "--out", str(tmp_path / "got"), "--store", dst
    )
    assert code == 1 and err.startswith("Error: file 'model.pt'") and "results-only bundle left it out" in err
    src.set_ref("rollouts/b", b["rollout"])  # neither a run nor a result
    code, out, err = run_cli(
        "store", "export", "rollouts/b", "--results-only", "--out", str(tmp_path / "x"), "--store", str(src.root)
    )
    assert code == 1 and out == ""
    assert err.startswith("Error: --results-only exports runs or results, and 'rollouts/b' is neither")
    assert not (tmp_path / "x").exists()
    # a result named by its ref goes in alone, at its current version, its checkpoint without weights or curve
    report = src.export_tar(["evals/b"], tmp_path / "e.tar", results_only=True)
    assert report.refs == ["evals/b"]
    assert {"model.pt", "curve.png", "rollout.mcap", "obs.npz"} <= set(report.omitted_files.values())
    assert report.omitted == {b["state"]: STATE}
