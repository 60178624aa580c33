"""A smoke experiment shipped results-only (`store export runs/NAME --results-only`): reports, won't run.

The source store is made the way scripts/experiment_queue.sh makes the experiment's: `reproduce --seeds 1`, then
`reproduce --seeds 2` (a reduced protocol: 2 robots, one command), so ``diagnoses/calibration`` and
``diagnoses/fixed-rollout/aliengo`` are shared by both seeds' runs.
"""

from __future__ import annotations

import shutil
import tarfile

import pytest
from crafted_bundles import listing

from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")

RUN = "runs/film-smoke-s1"
HEAVY = ("model.pt", "rollout.mcap", "obs.npz")


def _pipeline(store: Store, seeds: int):
    from morfic_cli.pipeline import Pipeline, ReproduceCfg

    cfg = ReproduceCfg(
        preset="smoke",
        variants=("film",),
        seeds=seeds,
        robots=("go2", "aliengo"),
        command_vx=(2.0,),
        modes=("descriptor",),
        eval_envs=2,
        eval_steps=5,
        diagnose_envs=2,
        diagnose_steps=80,
        trunc_eps=0.5,
        fixed_rollout_robots=("aliengo",),
        torch_threads=1,
    )
    return Pipeline(store, cfg)


def _reproduce(store: Store, seeds: int) -> None:
    assert not _pipeline(store, seeds).run().interrupted


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    """The source store; the run's results-only, weights-only and full (--latest) bundles."""
    base = tmp_path_factory.mktemp("results-only")
    src = Store(base / "src")
    _reproduce(src, 1)
    _reproduce(src, 2)
    results = src.export_tar([RUN], base / "results.tar", results_only=True)
    weights = src.export_tar([RUN], base / "weights.tar", latest=True, without_trainer_state=True)
    full = src.export_tar([RUN], base / "full.tar", latest=True)
    return src, results, weights, full


def _imported(tmp_path, *reports, name: str = "dst") -> Store:
    store = Store(tmp_path / name)
    for report in reports:
        store.import_tar(report.path)
    return store


def _tar_objects(path) -> set[str]:
    with tarfile.open(path) as tar:
        return {n[8:10] + n[11:] for n in tar.getnames() if n.startswith("objects/")}


def test_the_bundle_holds_the_results_and_none_of_the_weights_or_logs(bundles):
    src, results, weights, full = bundles
    assert results.refs == ["diagnoses/calibration", "diagnoses/fixed-rollout/aliengo", "evals/film-smoke-s1", RUN]
    # every weight, trainer state and rollout log in the source store, every rendered figure of a result (the eval
    # rollouts' speed.png/pdf, the calibrations' ev.png/pdf) and every curve.png, and seed 0's curve table
    heavy, states, figures = set(), set(), {}
    seed0 = src.read_manifest("runs/film-smoke-s0")
    for oid in src.index.ids():
        manifest = src.read_manifest(oid)
        heavy |= {e.id for n, e in manifest.files.items() if n in HEAVY}
        figures |= {
            e.id: n
            for n, e in manifest.files.items()
            if n.endswith((".png", ".pdf")) and manifest.kind in ("rollout", "diagnosis", "checkpoint")
        }
        if manifest.config.get("role") == "trainer-state":
            states |= {oid, *(e.id for e in manifest.files.values())}
    curves0 = {seed0.files["curve.csv"].id}
    in_tar = _tar_objects(results.path)
    assert in_tar and not in_tar & (heavy | states | curves0 | set(figures))
    # the figures of the run's results are left out and listed as such, under their own names
    results_of_run = [src.read_manifest(r) for r in ("evals/film-smoke-s1", "diagnoses/calibration")]
    run_figures = {
        e.id: n
        for m in [*results_of_run, *(src.read_manifest(i) for r in results_of_run for i in r.inputs.values())]
        for n, e in m.files.items()
        if n.endswith((".png", ".pdf"))
    }
    assert {"speed.png", "speed.pdf", "ev.png", "ev.pdf"} <= set(run_figures.values())
    assert {oid: results.omitted_files[oid] for oid in run_figures} == run_figures
    # seed 0's checkpoint comes along (the frozen actor, the first calibration's critic), without its curve
    assert seed0.id in in_tar and curves0 <= set(results.omitted_files)
    assert set(results.omitted_files) <= heavy | curves0 | set(figures) and set(results.omitted) <= states
    assert {
        results.omitted_files[e.id] for e in src.read_manifest(RUN).files.values() if e.id in results.omitted_files
    } == {"model.pt", "curve.png"}
    # the results are in: the eval table, both calibration tables, the fixed-rollout table, the run's curve
    for ref, file in (
        ("evals/film-smoke-s1", "eval.csv"),
        ("diagnoses/calibration", "calibration.csv"),
        ("diagnoses/calibration@1", "calibration.csv"),
        ("diagnoses/fixed-rollout/aliengo", "fixed_rollout.csv"),
        (RUN, "curve.csv"),
    ):
        assert src.read_manifest(ref).files[file].id in in_tar, ref
    # sizes: the whole results bundle is smaller than the run's weights file alone
    model = src.read_manifest(RUN).files["model.pt"]
    assert results.path.stat().st_size < model.size < weights.path.stat().st_size < full.path.stat().st_size
    assert results.bytes == sum(src.objects.size(oid) for oid in in_tar)


def test_import_gives_the_same_refs_and_ids(bundles, tmp_path):
    src, results, _, _ = bundles
    dst = _imported(tmp_path, results)
    assert dst.list_refs() == results.refs
    for name in results.refs[:-1]:
        assert [(e.version, e.id, e.time) for e in dst.ref_history(name)] == [
            (e.version, e.id, e.time) for e in src.ref_history(name)
        ], name
    last = src.ref_history(RUN)[-1]
    assert [(e.version, e.id, e.time) for e in dst.ref_history(RUN)] == [(1, last.id, last.time)]
    assert dst.get_bytes(last.id) == src.get_bytes(last.id)
    assert sorted(dst.objects.iter_ids()) == sorted(_tar_objects(results.path))
    check = dst.verify()
    assert check.ok and check.omitted_files == len(results.omitted_files) and check.omitted == len(results.omitted)
    assert dst.gc(dry_run=False).removed == []


def _report_md(run_cli, store: Store, out) -> str:
    code, _, err = run_cli(
        "report", RUN, "--markdown", "--figures", "--out", str(out), "--store", str(store.root), "-q"
    )
    assert code == 0, err
    return (out / "report.md").read_text()


def test_report_over_the_imported_results_is_the_sources(run_cli, bundles, tmp_path):
    from morfic_cli.report.compare import compare_tables
    from morfic_cli.report.gather import gather, resolve_runs

    src, results, _, _ = bundles
    dst = _imported(tmp_path, results)
    theirs, ours = (gather(s, resolve_runs(s, [RUN])) for s in (src, dst))
    assert len(ours.evals) == 2 and len(ours.calibration) == 2 and len(ours.fixed) == 2  # go2, aliengo; MC + s1
    for field in ("evals", "calibration", "fixed", "curves"):
        assert getattr(ours, field) == getattr(theirs, field), field
    assert compare_tables(ours, with_paper=True) == compare_tables(theirs, with_paper=True)
    # the report itself: the same text up to its provenance (whose support-table id is per store), the same figures
    copy = Store(tmp_path / "copy")
    shutil.copytree(src.root, copy.root)
    mine, source = _report_md(run_cli, dst, tmp_path / "mine"), _report_md(run_cli, copy, tmp_path / "source")
    assert "| Go2 |" in mine and "| AlienGo |" in mine and "Frozen actor(s): film-smoke-s0." in mine
    assert mine.split("## Provenance")[0] == source.split("## Provenance")[0]
    figures = sorted(p.name for p in (tmp_path / "mine" / "figures").iterdir())
    assert "speed-film-smoke-s1-aliengo.png" in figures and "curves.png" in figures
    assert figures == sorted(p.name for p in (tmp_path / "source" / "figures").iterdir())
    # the bundle left the speed figures out: the report drew them from the eval table, the source copied its own
    from morfic_cli.evaluation.figures import table_figure

    row = next(r for r in ours.evals if r["robot"] == "aliengo" and r["run"] == "film-smoke-s1")
    drawn = table_figure(row, "film-smoke-s1 on aliengo, descriptor mode, command 2 m/s")
    rollout = src.read_manifest(row["artifact"]).inputs["rollout/aliengo/descriptor/vx2"]
    for suffix, data in zip((".png", ".pdf"), drawn, strict=True):
        assert (tmp_path / "mine" / "figures" / f"speed-film-smoke-s1-aliengo{suffix}").read_bytes() == data
        assert (
            (tmp_path / "source" / "figures" / f"speed-film-smoke-s1-aliengo{suffix}").read_bytes()
            == src.read_file(rollout, f"speed{suffix}")
            != data
        )


COMMANDS = {
    "eval": ("eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "4", "-q"),
    "diagnose": ("diagnose", RUN, "--robots", "go2", "--envs", "2", "--steps", "30", "--trunc-eps", "0.8", "-q"),
    "fixed-rollout": (
        "diagnose",
        "--fixed-rollout",
        "aliengo",
        "--actor",
        RUN,
        "--critics",
        RUN,
        "--envs",
        "2",
        "--steps",
        "30",
        "--trunc-eps",
        "0.8",
        "-q",
    ),
    "resume": ("train", "--resume", RUN, "-q"),
    "play": ("play", RUN, "--robot", "go2", "--steps", "1", "-q"),
    "export-rsl-rl": ("export", RUN, "--to", "rsl-rl", "--out", "OUT"),
    "export-onnx": ("export", RUN, "--robot", "go2", "--out", "OUT"),
}


@pytest.mark.parametrize("what", sorted(COMMANDS))
def test_what_needs_the_weights_is_an_error_and_changes_nothing(run_cli, bundles, tmp_path, what):
    _, results, _, _ = bundles
    dst = _imported(tmp_path, results)
    before = listing(dst.root)
    args = [str(tmp_path / "out") if a == "OUT" else a for a in COMMANDS[what]]
    code, out, err = run_cli(*args, "--store", str(dst.root))
    assert code == 1 and out == ""
    assert err.startswith(
        f"Error: {RUN} was imported from a results-only bundle: its weights (model.pt) and trainer state were left out"
    ), err
    assert (
        "Import a bundle with its weights first: its weights-only bundle (made by `morfic store export "
        f"{RUN} --latest --without-trainer-state`" in " ".join(err.split())
    )
    assert listing(dst.root) == before and not (tmp_path / "out").exists()


def test_the_weights_only_bundle_on_top_makes_it_evaluate(run_cli, bundles, tmp_path):
    _, results, weights, _ = bundles
    dst = _imported(tmp_path, results, weights)
    assert dst.ref_history(RUN)[-1].version == 1 and dst.verify().ok
    code, _, err = run_cli(
        "eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "4", "-q", "--store", str(dst.root)
    )
    assert code == 0, err
    code, _, err = run_cli("train", "--resume", RUN, "-q", "--store", str(dst.root))
    assert code == 1 and "was imported without its trainer state (a weights-only bundle)" in err


def test_a_fixed_rollout_whose_log_was_left_out_is_collected_again(run_cli, bundles, tmp_path):
    """The frozen actor's rollout rides along without its log: a new critic's fixed rollout collects it again."""
    from morfic_cli.diagnostics.samples import find_rollout

    src, results, _, _ = bundles
    actor = src.export_tar(["runs/film-smoke-s0"], tmp_path / "actor.tar", latest=True, without_trainer_state=True)
    dst = _imported(tmp_path, results, actor)
    fixed = src.read_manifest("diagnoses/fixed-rollout/aliengo")
    samples = src.read_manifest(fixed.inputs["rollout"])
    checkpoint = samples.inputs["checkpoint"]
    assert find_rollout(src, checkpoint, samples.config) == samples.id
    # the manifest came along, its log did not: it does not count as a stored rollout
    assert dst.has(samples.id) and "rollout.mcap" in dst.omitted_files(samples)
    assert find_rollout(dst, checkpoint, samples.config) is None
    settings = ("--envs", "2", "--steps", "80", "--trunc-eps", "0.5", "--command-vx", "2.0", "-q")
    code, _, err = run_cli(
        "diagnose",
        "--fixed-rollout",
        "aliengo",
        "--actor",
        "runs/film-smoke-s0",
        "--critics",
        "runs/film-smoke-s0",
        *settings,
        "--store",
        str(dst.root),
    )
    assert code == 0, err
    again = dst.read_manifest("diagnoses/fixed-rollout/aliengo").inputs["rollout"]
    assert again != samples.id and find_rollout(dst, checkpoint, samples.config) == again
    assert not dst.omitted_files(dst.read_manifest(again))


def test_reuse_false_scores_the_critics_again_as_a_new_analysis(bundles, tmp_path):
    from morfic_cli.pipeline import Pipeline, ReproduceCfg

    src = bundles[0]
    shutil.copytree(src.root, tmp_path / "copy")
    store = Store(tmp_path / "copy")
    cfg = ReproduceCfg(
        preset="smoke",
        variants=("film",),
        seeds=1,
        robots=("go2", "aliengo"),
        command_vx=(2.0,),
        modes=("descriptor",),
        eval_envs=2,
        eval_steps=5,
        diagnose_envs=2,
        diagnose_steps=80,
        trunc_eps=0.5,
        fixed_rollout_robots=("aliengo",),
        torch_threads=1,
    )
    pipe = Pipeline(store, cfg)
    skipped = pipe.fixed_rollout("aliengo")
    assert skipped.status == "skipped"
    before = store.ref_history("diagnoses/fixed-rollout/aliengo")[-1].version
    again = pipe.fixed_rollout("aliengo", reuse=False)
    assert again.status == "done" and again.id != skipped.id
    assert store.ref_history("diagnoses/fixed-rollout/aliengo")[-1].version == before + 1
    # the same critic on the same stored rollout: the same scores
    rows = [store.read_file(i, "fixed_rollout.csv").decode().splitlines() for i in (skipped.id, again.id)]
    first = [r.split(",")[:6] for r in rows[0][1:]]
    assert [r.split(",")[:6] for r in rows[1][1:]] == first


def test_the_1_0_diagnosis_needs_the_weights_and_is_found_once_made(bundles, tmp_path, capsys):
    """scripts/experiment_tables.py's 1.0 m/s diagnosis: none from a results-only import, made once the weights are
    in, then found in the store (the same artifact) instead of made again."""
    import csv
    import importlib.util
    import io
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "experiment_tables.py"
    spec = importlib.util.spec_from_file_location("experiment_tables", path)
    et = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(et)
    _, results, weights, _ = bundles
    store = _imported(tmp_path, results)
    pipe = _pipeline(store, 2)
    ids: dict[str, str] = {}
    et.write_trained_regime_diagnosis(store, pipe, RUN, "film-smoke-s1", tmp_path, ids, run_missing=True)
    assert ids == {} and not (tmp_path / "film-smoke-s1-calibration-1.0.csv").exists()
    assert "no 1.0 m/s diagnosis of runs/film-smoke-s1" in capsys.readouterr().err
    store.import_tar(weights.path)
    assert et.trained_regime_diagnosis(store, pipe, RUN, run_missing=False) is None  # not made without --run-missing
    et.write_trained_regime_diagnosis(store, pipe, RUN, "film-smoke-s1", tmp_path, ids, run_missing=True)
    made = ids["diagnosis-1.0"]
    assert et.trained_regime_diagnosis(store, pipe, RUN, run_missing=True) == made
    rows = list(csv.DictReader(io.StringIO((tmp_path / "film-smoke-s1-calibration-1.0.csv").read_text())))
    assert [(r["run"], r["robot"], float(r["command_vx"])) for r in rows] == [
        ("film-smoke-s1", "go2", 1.0),
        ("film-smoke-s1", "aliengo", 1.0),
    ]
