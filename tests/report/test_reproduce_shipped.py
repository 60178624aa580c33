"""`morfic reproduce --preset shipped`: import the shipped runs' bundles, evaluate, diagnose and report them.

The bundles here are smoke-trained runs exported under the shipped runs' names (``film-cpu-s0.tar``): the preset
takes a bundle's run as shipped, so what it is trained with does not matter to the pipeline.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from morfic_cli.pipeline import SHIPPED_PROTOCOL, Pipeline, reproduce_cfg, shipped_variants
from morfic_cli.store import Store
from morfic_cli.store.transfer import export_tar

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _bundle(folder: Path, variant: str, name: str) -> Path:
    """A smoke run of ``variant`` named ``name``, exported (latest version) as ``folder/<name>.tar``."""
    from morfic_cli.rl.config import smoke_preset
    from morfic_cli.rl.runner import new_run

    store = Store(folder / f"store-{name}-{variant}")
    run = new_run(store, smoke_preset(variant, seed=0), name)
    run.train()
    run.env.close()
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{name}.tar"
    export_tar(store, [f"runs/{name}"], out, latest=True)
    return out


@pytest.fixture(scope="module")
def bundles(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("bundles") / "bundles"
    _bundle(folder, "film", "film-cpu-s0")
    return folder


def _tiny(cfg):
    """The shipped pipeline at test size (2 robots, 2 envs, short rollouts)."""
    return dataclasses.replace(cfg, robots=("go2", "aliengo"), eval_envs=2, eval_steps=20, diagnose_envs=2,
                               diagnose_steps=80, trunc_eps=0.5, fixed_rollout_robots=("aliengo",))


def _state(store: Store) -> tuple[int, dict[str, int]]:
    return len(store.ls()), {name: len(store.ref_history(name)) for name in store.list_refs()}


def test_shipped_cfg_is_the_cpu_runs_with_the_quick_protocol(bundles):
    cfg = reproduce_cfg("shipped", bundles=bundles)
    assert shipped_variants(bundles) == ("film",) and cfg.variants == ("film",)
    assert (cfg.preset, cfg.seeds, cfg.report_name) == ("cpu", 1, "shipped")
    assert (cfg.modes, cfg.command_vx, cfg.eval_envs, cfg.eval_steps) == (("descriptor",), (2.0,), 16, 500)
    assert SHIPPED_PROTOCOL["diagnose_steps"] == cfg.diagnose_steps == 800
    full = reproduce_cfg("shipped", bundles=bundles, full_protocol=True)
    assert (full.modes, full.command_vx, full.eval_envs, full.diagnose_envs) == (("descriptor", "full"), (2.0, 2.5),
                                                                               64, 64)


def test_shipped_imports_evaluates_reports_and_a_rerun_does_nothing(bundles, tmp_path):
    store = Store(tmp_path / "store")
    cfg = _tiny(reproduce_cfg("shipped", bundles=bundles))
    pipe = Pipeline(store, cfg, out=tmp_path / "out")
    assert [kind for kind, _, _ in pipe.plan()] == ["import", "eval", "diagnose", "fixed-rollout", "compare",
                                                    "report"]
    result = pipe.run()
    assert [(s.kind, s.status) for s in result.steps] == [
        ("import", "done"), ("eval", "done"), ("diagnose", "done"), ("fixed-rollout", "done"), ("compare", "done"),
        ("report", "done")]
    # the imported run is the bundle's, with the bundle's ids
    shipped = Store(bundles / "store-film-cpu-s0-film")
    assert store.resolve("runs/film-cpu-s0") == shipped.resolve("runs/film-cpu-s0")
    evals = store.read_manifest("evals/film-cpu-s0")
    assert evals.config["modes"] == ["descriptor"] and evals.config["command_vx"] == [2.0]
    assert evals.inputs["checkpoint"] == shipped.resolve("runs/film-cpu-s0")
    # the quick protocol steps the robots as one batch, and every artifact says so
    assert evals.config["batch_robots"] is True
    for robot in ("go2", "aliengo"):
        rollout = store.read_manifest(evals.inputs[f"rollout/{robot}/descriptor/vx2"])
        assert rollout.config["batch"] == ["go2", "aliengo"] and rollout.config["num_envs"] == 2
    diagnosis = store.read_manifest("diagnoses/calibration")
    assert diagnosis.config["batch"] == ["go2", "aliengo"]
    diag_rollout = store.read_manifest(diagnosis.inputs["rollout/runs/film-cpu-s0/aliengo"])
    assert diag_rollout.config["batch"] == ["go2", "aliengo"] and diag_rollout.config["actions"] == "sample"
    # the fixed-rollout analysis (film actor) reuses the diagnosis's rollout of film on aliengo
    fixed = store.read_manifest("diagnoses/fixed-rollout/aliengo")
    assert fixed.inputs["rollout"] == diag_rollout.id
    assert store.has_ref("reports/shipped") and (tmp_path / "out" / "report.md").is_file()
    md = (tmp_path / "out" / "report.md").read_text()
    assert "shipped preset" in md and "2 envs x 20 steps" in md  # the report names its reduced protocol
    # the claims open the report: film alone can be compared with nothing, so (a)-(d) cannot tell
    claims = md[md.index("## The paper's claims"):md.index("## Zero-shot transfer")]
    assert [claims.count(f"**({k})") for k in "abcde"] == [1] * 5
    assert claims.count("Verdict: **cannot tell**") >= 4
    tex = (tmp_path / "out" / "report.tex").read_text()
    assert tex.count("\\item \\textbf{(") == 5 and "\\begin{itemize}" in tex

    before = _state(store)
    again = Pipeline(store, cfg, out=tmp_path / "out").run()
    assert [s.status for s in again.steps] == ["skipped"] * 6
    assert _state(store) == before


def test_a_bundle_that_is_not_the_named_variant_is_refused(tmp_path):
    folder = tmp_path / "bundles"
    _bundle(folder, "ppo", "film-cpu-s0")  # a ppo run under film's name
    store = Store(tmp_path / "store")
    cfg = _tiny(reproduce_cfg("shipped", bundles=folder, variants=("film",)))
    from morfic_cli.errors import MorficError

    with pytest.raises(MorficError, match="not a finished film run"):
        Pipeline(store, cfg).run()


@pytest.mark.parametrize("args, message", [
    (["--variants", "ppo"], "no shipped bundle .*ppo-cpu-s0.tar; the shipped variants are film"),
    (["--seeds", "2"], "one seed per variant"),
    (["--set", "max_iterations=1"], "trains nothing"),
    (["--executor", "ray"], "without --executor ray"),
])
def test_shipped_bad_input(run_cli, bundles, tmp_path, args, message):
    import re

    root = tmp_path / "store"
    code, _, err = run_cli("reproduce", "--preset", "shipped", "--bundles", str(bundles), *args, "--store",
                           str(root))
    assert code == 1 and err.startswith("Error: ") and re.search(message, err), err
    assert not (root / "refs").exists() or not any((root / "refs").rglob("*"))  # nothing written


def test_shipped_flags_need_the_shipped_preset_and_bundles(run_cli, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run_cli("reproduce", "--preset", "shipped", "--bundles", str(empty))
    assert code == 1 and "no shipped bundles (<variant>-cpu-s0.tar)" in err, err
    code, _, err = run_cli("reproduce", "--preset", "shipped", "--bundles", str(tmp_path / "missing"))
    assert code == 1 and "no bundle folder" in err, err
    code, _, err = run_cli("reproduce", "--preset", "smoke", "--full-protocol")
    assert code == 1 and "--full-protocol is for --preset shipped" in err, err


def test_shipped_imports_the_shipped_critic_study_once(bundles, tmp_path):
    import shutil

    folder = tmp_path / "bundles"
    shutil.copytree(bundles, folder, ignore=shutil.ignore_patterns("store-*"))
    shipped_study = Path(__file__).resolve().parents[2] / "artifacts" / "bundles" / "results" / "critic-study.tar"
    (folder / "results").mkdir()
    shutil.copy(shipped_study, folder / "results" / "critic-study.tar")
    store = Store(tmp_path / "store")
    pipe = Pipeline(store, _tiny(reproduce_cfg("shipped", bundles=folder)))
    assert [kind for kind, _, _ in pipe.plan()][-3:] == ["critic-study", "compare", "report"]
    first = pipe.critic_study()
    assert (first.status, first.ref) == ("done", "diagnoses/critic-study")
    assert first.id == store.resolve("diagnoses/critic-study")
    assert "critic_study.csv" in store.read_manifest(first.id).files
    again = Pipeline(store, _tiny(reproduce_cfg("shipped", bundles=folder))).critic_study()
    assert (again.status, again.id) == ("skipped", first.id)  # importing the same tar again changes nothing
