"""The pipeline-wide tests, in one module: `morfic reproduce` (smoke and shipped presets), `morfic compare-baselines`
and `morfic report`.

The smoke tests share one `reproduce --preset smoke --variants film,ppo` (the ``reproduced`` fixture, copied per
test where a test writes). The shipped preset's bundles are smoke-trained runs exported under the shipped runs'
names (``film-cpu-s0.tar``): the preset takes a bundle's run as shipped, so what it is trained with does not matter
to the pipeline.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import re
import shutil
from pathlib import Path

import pytest

from morfic_cli.pipeline import SHIPPED_PROTOCOL, Pipeline, reproduce_cfg, shipped_variants
from morfic_cli.store import Store
from morfic_cli.store.transfer import export_tar

VARIANTS = "film,ppo"


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def reproduced(tmp_path_factory):
    """`morfic reproduce --preset smoke --variants film,ppo` once, through the CLI; (store root, stdout json)."""
    import contextlib

    from morfic_cli.cli import main

    root = tmp_path_factory.mktemp("reproduce") / "store"
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main(
            [
                "reproduce",
                "--preset",
                "smoke",
                "--variants",
                VARIANTS,
                "--store",
                str(root),
                "--format",
                "json",
                "--quiet",
            ]
        )
    return root, json.loads(out.getvalue())


@pytest.fixture
def store(reproduced, tmp_path, monkeypatch):
    root = tmp_path / "store"
    shutil.copytree(reproduced[0], root)
    monkeypatch.setenv("MORFIC_STORE", str(root))
    return Store(root)


def _state(store: Store) -> tuple[int, dict[str, int]]:
    return len(store.ls()), {name: len(store.ref_history(name)) for name in store.list_refs()}


def test_reproduce_writes_every_stage_and_the_report(reproduced):
    root, summary = reproduced
    store = Store(root)
    # train, eval, diagnose x 2 variants, fixed rollout x 2 robots, the critic study, compare, report
    assert summary["work_done"] == summary["steps"] == 2 + 2 + 2 + 2 + 1 + 1 + 1
    for ref in (
        "runs/film-smoke-s0",
        "runs/ppo-smoke-s0",
        "evals/film-smoke-s0",
        "evals/ppo-smoke-s0",
        "diagnoses/calibration",
        "diagnoses/fixed-rollout/aliengo",
        "diagnoses/fixed-rollout/mini_cheetah",
        "diagnoses/critic-study",
        "tables/compare-baselines",
        "tables/morphology-support",
        "reports/smoke",
    ):
        assert store.has_ref(ref), ref
    report = store.read_manifest("reports/smoke")
    assert report.kind == "report"
    assert {
        "report.md",
        "report.tex",
        "report.json",
        "provenance.csv",
        "figures/ev.png",
        "figures/distance.png",
        "figures/compute.png",
        "figures/curves.png",
    } <= set(report.files)
    # every input of the report is in its provenance section, by full id
    md = store.read_file("reports/smoke", "report.md").decode()
    for oid in report.inputs.values():
        assert oid in md
    assert "## Critic study: the conditioning alone, the actor fixed" in md  # the smoke preset's tiny study
    assert summary["out"].endswith("reports/smoke") and any(f.endswith("report.md") for f in summary["files"])
    evals = store.read_manifest("evals/film-smoke-s0")
    assert evals.config["command_vx"] == [2.0, 2.5] and evals.config["modes"] == ["descriptor", "full"]


def test_rerun_does_no_work(run_cli, store):
    before = _state(store)
    code, out, err = run_cli("reproduce", "--preset", "smoke", "--variants", VARIANTS, "--format", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["work_done"] == 0 and summary["skipped"] == summary["steps"] == 11
    assert _state(store) == before  # not one new manifest, not one new ref version
    assert err.count("skipped (in the store)") == 11
    assert "report:" in err and "reports/smoke" in err


def test_a_report_of_another_layout_is_built_anew_not_reused(run_cli, store, monkeypatch):
    from morfic_cli.report import build

    first = store.resolve("reports/smoke")
    assert store.read_manifest(first).config["layout"] == build.REPORT_LAYOUT
    monkeypatch.setattr(build, "REPORT_LAYOUT", build.REPORT_LAYOUT + 1)  # a morfic that lays reports out anew
    code, out, err = run_cli("reproduce", "--preset", "smoke", "--variants", VARIANTS, "--format", "json")
    assert code == 0, err
    assert json.loads(out)["work_done"] == 1  # only the report: the runs, evals and diagnoses are reused
    again = store.read_manifest("reports/smoke")
    assert again.id != first and again.config["layout"] == build.REPORT_LAYOUT


def test_reproduce_continues_after_ctrl_c(tmp_path):
    """A Ctrl-C during training checkpoints and stops; the next run resumes that run instead of restarting it."""
    from morfic_cli.pipeline import Pipeline, ReproduceCfg

    store = Store(tmp_path / "store")
    cfg = ReproduceCfg(
        preset="smoke",
        variants=("film",),
        robots=("go2",),
        command_vx=(2.0,),
        modes=("descriptor",),
        eval_envs=2,
        eval_steps=5,
        diagnose_envs=2,
        diagnose_steps=80,
        trunc_eps=0.5,
        fixed_rollout_robots=("go2",),
        torch_threads=1,
    )

    class CtrlC:
        pipeline = None

        def step_start(self, *a):
            pass

        def step_advance(self, completed=None, advance=0, detail=""):
            if completed == 1:
                assert self.pipeline.interrupt()

        def step_end(self, result):
            pass

    progress = CtrlC()
    first = Pipeline(store, cfg, progress=progress)
    progress.pipeline = first
    result = first.run()
    assert result.interrupted and [s.kind for s in result.steps] == ["train"]
    ckpt = store.read_manifest("runs/film-smoke-s0")
    assert ckpt.meta["iteration"] == 1 and ckpt.meta["interrupted"] and not ckpt.meta["finished"]

    second = Pipeline(store, cfg).run()
    assert not second.interrupted
    assert second.steps[0].status == "resumed" and "1->2" in second.steps[0].detail
    assert store.read_manifest("runs/film-smoke-s0").meta["finished"]
    assert [s.kind for s in second.steps] == ["train", "eval", "diagnose", "fixed-rollout", "compare", "report"]
    third = Pipeline(store, cfg).run()
    assert third.work_done == 0


def test_a_run_of_the_same_name_with_another_config_is_refused(tmp_path):
    from morfic_cli.errors import MorficError
    from morfic_cli.pipeline import Pipeline, ReproduceCfg
    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.runner import new_run

    store = Store(tmp_path / "store")
    run = new_run(store, apply_overrides(preset_cfg("smoke", "film"), ["max_iterations=1"]), "film-smoke-s0")
    run.train()
    run.env.close()
    with pytest.raises(MorficError, match="another config"):
        Pipeline(store, ReproduceCfg(variants=("film",))).run()


def test_the_fixed_rollout_leaves_out_the_critics_that_read_other_inputs(tmp_path):
    """The frozen film actor's rollouts record the 11-D z_m: a critic of the extended descriptor cannot be scored."""
    from morfic_cli.rl.variants import REPRODUCE_VARIANTS

    store = Store(tmp_path / "store")
    pipe = Pipeline(store, reproduce_cfg("cpu", variants=("film", "film-act", "film-act-11d", "ppo-act", "urma")))
    actor, critics = pipe.fixed_rollout_models()
    assert actor == "runs/film-cpu-s0"
    assert critics == ["runs/film-cpu-s0", "runs/film-act-11d-cpu-s0", "runs/urma-cpu-s0"]
    assert pipe.fixed_rollout_left_out()["runs/film-act-cpu-s0"] == (
        "runs/film-act-cpu-s0's critic is left out of the fixed-rollout analysis: trained with other env.obs than "
        "the frozen actor's run, its values read other inputs or predict other returns than that actor's rollouts "
        "record"
    )
    assert list(pipe.fixed_rollout_left_out()) == ["runs/film-act-cpu-s0", "runs/ppo-act-cpu-s0"]
    paper = Pipeline(store, reproduce_cfg("cpu"))  # every variant reproduce trains is scored, as before
    assert paper.fixed_rollout_models()[1] == [f"runs/{v}-cpu-s0" for v in REPRODUCE_VARIANTS]
    alone = Pipeline(store, reproduce_cfg("cpu", variants=("film", "ppo-act")))
    assert alone.fixed_rollout_models()[1] == ["runs/film-cpu-s0"]
    nothing = Pipeline(store, reproduce_cfg("cpu", variants=("ppo-act",)))
    assert nothing.fixed_rollout_models()[1] == []
    assert nothing.fixed_rollout_unavailable() == (
        "every critic is left out: " + nothing.fixed_rollout_left_out()["runs/ppo-act-cpu-s0"]
    )


def test_compare_baselines_with_paper_csv_has_the_papers_aliengo_film_value(run_cli, store):
    code, out, err = run_cli("compare-baselines", "--with-paper", "--format", "csv")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    # with --with-paper and no external baseline trained: the external table holds the paper's group only
    assert {r["table"] for r in rows} == {"transfer", "external", "calibration", "fixed_rollout", "compute", "verdicts"}
    assert {r["group"] for r in rows if r["table"] == "external"} == {"paper"}
    cell = next(
        r
        for r in rows
        if r["table"] == "transfer"
        and r["variant"] == "film"
        and r["robot"] == "aliengo"
        and r["mode"] == "descriptor"
        and float(r["command_vx"]) == 2.0
    )
    assert float(cell["paper_vx"]) == 1.98 and cell["paper_table"] == "tab:zero_shot_transfer"
    assert "1.98" in out
    assert float(cell["n_seeds"]) == 1 and cell["vx"] != ""
    # full-mode rows get no paper numbers; a number the paper does not print stays empty, never 0
    full = next(r for r in rows if r["table"] == "transfer" and r["mode"] == "full")
    assert full["paper_vx"] == ""
    fast = next(
        r
        for r in rows
        if r["table"] == "transfer" and r["variant"] == "ppo" and r["command_vx"] == "2.5" and r["mode"] == "descriptor"
    )
    assert fast["paper_vx"] == "" and fast["paper_survival"] == "" and fast["paper_quantity"] == ""
    mc = [r for r in rows if r["table"] == "fixed_rollout" and r["variant"] == "mc"]
    assert {r["robot"] for r in mc} == {"aliengo", "mini_cheetah"}
    assert all(float(r["flip"]) == 0.0 and float(r["paper_cos_grad"]) == 1.0 for r in mc)


def test_compare_baselines_table_and_json(run_cli, store):
    code, out, err = run_cli("compare-baselines", "runs/film-smoke-s0", "--format", "json")
    assert code == 0, err
    rows = json.loads(out)
    assert {r["variant"] for r in rows if r["table"] == "transfer"} == {"film"}
    assert not any(k.startswith("paper_") for k in rows[0])
    code, out, err = run_cli("compare-baselines", "--with-paper")
    assert code == 0, err
    assert "zero-shot transfer" in out and "paper" in out and "1.98" in out


def test_compare_baselines_bad_input(run_cli, store, tmp_path):
    code, out, err = run_cli("compare-baselines", "runs/nope")
    assert code == 1 and err.startswith("Error: no artifact 'runs/nope'") and out == ""
    code, out, err = run_cli("compare-baselines", "evals/film-smoke-s0")
    assert code == 1 and "not a training run" in err
    code, out, err = run_cli("compare-baselines", "--store", str(tmp_path / "empty"))
    assert code == 1 and "no training runs" in err


def test_report_latex_out_writes_a_tex(run_cli, store, tmp_path):
    out_dir = tmp_path / "rep"
    code, out, err = run_cli("report", "--latex", "--out", str(out_dir), "--format", "json")
    assert code == 0, err
    result = json.loads(out)
    tex = (out_dir / "report.tex").read_text()
    assert "report.tex" in result["files"] and result["out"] == str(out_dir)
    _check_latex_structure(tex)
    assert r"\section*{Provenance}" in tex
    for oid in store.read_manifest(result["id"]).inputs.values():
        assert oid in tex
    assert not (out_dir / "report.md").exists()  # --latex alone: no markdown
    # the same store and options find the stored report again
    code, out, err = run_cli("report", "--latex", "--format", "json")
    assert code == 0 and json.loads(out)["id"] == result["id"] and json.loads(out)["reused"]


def test_report_markdown_default_with_paper_tables(run_cli, store, tmp_path):
    code, out, err = run_cli("report", "--with-paper", "--out", str(tmp_path / "md"), "--format", "json")
    assert code == 0, err
    md = (tmp_path / "md" / "report.md").read_text()
    assert "## Zero-shot transfer" in md and "## Provenance" in md
    assert "**Zero-shot cross-morphology transfer (paper).**" in md
    assert (
        "| AlienGo | 0.27 ± 0.07 / 0.000 | 0.64 ± 0.26 / **1.000** | 0.40 ± 0.18 / 0.156 | "
        "**1.98 ± 0.51** / **1.000** |" in md
    )
    # the external baselines' table: the paper's rows (URMA's "-/-" on AlienGo stays missing), ours not trained yet
    assert (
        "| URMA (paper) | 1.84 ± 0.26 / **1.000** | 1.93 ± 0.28 / **1.000** | 1.79 ± 0.25 / **1.000** | - / - |" in md
    )
    assert "| *Ours: not trained yet* |" in md
    ours = md[md.index("**Zero-shot cross-morphology transfer.**") : md.index("(paper).**")]
    assert "| Target | PPO | MorFiC-F |" in ours and "**" in ours.split("|---|")[1]


def test_report_bad_input(run_cli, tmp_path):
    code, out, err = run_cli("report", "--store", str(tmp_path / "empty"))
    assert code == 1 and "no training runs" in err and out == ""


def _check_latex_structure(tex: str) -> None:
    """A standalone booktabs document whose environments and braces balance."""
    assert tex.startswith(r"\documentclass") and tex.rstrip().endswith(r"\end{document}")
    assert tex.isascii()  # no character pdflatex's default input encoding might not know
    assert r"\usepackage{booktabs}" in tex and r"\toprule" in tex and r"\bottomrule" in tex
    begins = re.findall(r"\\begin\{(\w+\*?)\}", tex)
    ends = re.findall(r"\\end\{(\w+\*?)\}", tex)
    assert sorted(begins) == sorted(ends)
    stripped = re.sub(r"\\[{}]", "", tex)
    assert stripped.count("{") == stripped.count("}")
    assert "_" not in re.sub(
        r"\$[^$]*\$|\\_|\\label\{[^}]*\}|\\includegraphics[^}]*\}|\\begin\{longtable\}\{[^}]*\}", "", tex
    )  # every underscore outside math is escaped
    for line in tex.splitlines():
        if line.count("&") and line.rstrip().endswith("\\\\"):
            assert "$" not in line or line.count("$") % 2 == 0, line


def test_smoke_report_tex_compiles_with_pdflatex(run_cli, store, tmp_path, monkeypatch):
    from morfic_cli.report.latex import NO_PDF_ENV, compile_pdf, pdflatex

    monkeypatch.delenv(NO_PDF_ENV, raising=False)  # the one test that compiles (tests/conftest.py sets it)
    if pdflatex() is None:
        pytest.skip("pdflatex is not installed (apt-get install texlive-latex-base texlive-latex-recommended)")
    code, out, err = run_cli(
        "report", "--latex", "--figures", "--with-paper", "--out", str(tmp_path / "tex"), "--format", "json"
    )
    assert code == 0, err
    assert (tmp_path / "tex" / "report.pdf").read_bytes().startswith(b"%PDF")
    tex = (tmp_path / "tex" / "report.tex").read_text()
    figures = {f"figures/{p.name}": p.read_bytes() for p in (tmp_path / "tex" / "figures").iterdir()}
    assert compile_pdf(tex, figures).startswith(b"%PDF")


# `morfic reproduce --preset shipped`: import the shipped runs' bundles, evaluate, diagnose and report them


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
    return dataclasses.replace(
        cfg,
        robots=("go2", "aliengo"),
        eval_envs=2,
        eval_steps=20,
        diagnose_envs=2,
        diagnose_steps=80,
        trunc_eps=0.5,
        fixed_rollout_robots=("aliengo",),
    )


def test_shipped_cfg_is_the_cpu_runs_with_the_quick_protocol(bundles, tmp_path):
    cfg = reproduce_cfg("shipped", bundles=bundles)
    assert shipped_variants(bundles) == ("film",) and cfg.variants == ("film",)
    assert (cfg.preset, cfg.seeds, cfg.report_name) == ("cpu", 1, "shipped")
    assert (cfg.modes, cfg.command_vx, cfg.eval_envs, cfg.eval_steps) == (("descriptor",), (2.0,), 16, 500)
    assert SHIPPED_PROTOCOL["diagnose_steps"] == cfg.diagnose_steps == 800
    full = reproduce_cfg("shipped", bundles=bundles, full_protocol=True)
    assert (full.modes, full.command_vx, full.eval_envs, full.diagnose_envs) == (None, (2.0, 2.5), 64, 64)
    # the paper's protocol evaluates each run in its variant's modes (the paper's variants: descriptor and full)
    assert Pipeline(Store(tmp_path / "store"), full).eval_cfg("runs/film-cpu-s0").modes == ("descriptor", "full")


def test_shipped_imports_evaluates_reports_and_a_rerun_does_nothing(bundles, tmp_path):
    store = Store(tmp_path / "store")
    cfg = _tiny(reproduce_cfg("shipped", bundles=bundles))
    pipe = Pipeline(store, cfg, out=tmp_path / "out")
    assert [kind for kind, _, _ in pipe.plan()] == ["import", "eval", "diagnose", "fixed-rollout", "compare", "report"]
    result = pipe.run()
    assert [(s.kind, s.status) for s in result.steps] == [
        ("import", "done"),
        ("eval", "done"),
        ("diagnose", "done"),
        ("fixed-rollout", "done"),
        ("compare", "done"),
        ("report", "done"),
    ]
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
    claims = md[md.index("## The paper's claims") : md.index("## Zero-shot transfer")]
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


@pytest.mark.parametrize(
    "args, message",
    [
        (["--variants", "ppo"], "no shipped bundle .*ppo-cpu-s0.tar; the shipped variants are film"),
        (["--seeds", "2"], "one seed per variant"),
        (["--set", "max_iterations=1"], "trains nothing"),
        (["--executor", "ray"], "without --executor ray"),
        (["--jobs", "0"], "--jobs must be 1 or more, got 0"),
        (["--jobs", "2", "--executor", "ray"], "--jobs is for --executor local"),
    ],
)
def test_shipped_bad_input(run_cli, bundles, tmp_path, args, message):
    import re

    root = tmp_path / "store"
    code, _, err = run_cli("reproduce", "--preset", "shipped", "--bundles", str(bundles), *args, "--store", str(root))
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


def test_shipped_side_by_side_stores_what_one_process_stores(bundles, tmp_path):
    """``--jobs 2``: the evals and diagnoses in two worker processes leave the store one process leaves, ref
    versions in the same order; a job's user error fails the command after the others, naming the job."""
    from morfic_cli.cluster.pool import JobPool
    from morfic_cli.errors import MorficError
    from tests.cluster.store_contents import comparable, differences

    folder = tmp_path / "bundles"
    folder.mkdir()
    shutil.copy(bundles / "film-cpu-s0.tar", folder)
    _bundle(folder, "concat", "concat-cpu-s0")
    cfg = _tiny(reproduce_cfg("shipped", bundles=folder))
    assert cfg.variants == ("concat", "film")
    one = Pipeline(Store(tmp_path / "one"), cfg)  # the steps the pool takes over, one after another, here
    for kind, _label, fn in one.plan():
        if kind in ("import", "eval", "diagnose"):
            fn()
    pipe = Pipeline(Store(tmp_path / "two"), cfg, out=tmp_path / "out-two")
    ended: list[str] = []
    pipe.progress.step_end = lambda step: ended.append(f"{step.kind} {step.label}")  # type: ignore[method-assign]
    two = pipe.run(JobPool(pipe, 2))
    assert ended == [f"{kind} {label}" for kind, label, _ in pipe.plan()]  # results arrive in plan order
    assert all(s.status == "done" for s in two.steps)
    assert all(s.seconds > 0 for s in two.steps if s.kind in ("eval", "diagnose"))
    mine, theirs = comparable(tmp_path / "one"), comparable(tmp_path / "two")
    assert set(mine) <= set(theirs) and differences(mine, {ref: theirs[ref] for ref in mine}) == []
    assert len(Store(tmp_path / "two").ref_history("diagnoses/calibration")) == 2

    bad = Pipeline(Store(tmp_path / "bad"), dataclasses.replace(cfg, robots=("go2", "nosuchbot")))
    for spec in ("runs/concat-cpu-s0", "runs/film-cpu-s0"):
        bad.import_run(spec.split("/")[1].split("-")[0], spec)
    with pytest.raises(
        MorficError, match=r"4 job\(s\) failed; the 0 that finished .* First: eval runs/concat-cpu-s0: "
    ):
        JobPool(bad, 2)(
            [
                ("eval", "runs/concat-cpu-s0"),
                ("eval", "runs/film-cpu-s0"),
                ("diagnose", "runs/concat-cpu-s0"),
                ("diagnose", "runs/film-cpu-s0"),
            ]
        )


def test_ctrl_c_stops_the_side_by_side_workers_at_once_and_leaves_no_job_folder(bundles, tmp_path, monkeypatch):
    import _thread
    import multiprocessing
    import signal
    import tempfile
    import threading

    from morfic_cli.cluster.pool import JobPool

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    pipe = Pipeline(Store(tmp_path / "store"), _tiny(reproduce_cfg("shipped", bundles=bundles)))
    pipe.import_run("film", "runs/film-cpu-s0")
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # an xdist worker ignores SIGINT
    try:
        threading.Timer(1.0, _thread.interrupt_main).start()  # a Ctrl-C while the workers start
        with pytest.raises(KeyboardInterrupt):
            JobPool(pipe, 2)([("eval", "runs/film-cpu-s0"), ("diagnose", "runs/film-cpu-s0")])
    finally:
        signal.signal(signal.SIGINT, previous)
    assert multiprocessing.active_children() == []
    assert list((tmp_path / "tmp").iterdir()) == []
    assert not pipe.store.has_ref("evals/film-cpu-s0") and not pipe.store.has_ref("diagnoses/calibration")


def test_the_actors_diagnosis_records_the_token_groups_a_urma_critic_reads(bundles, tmp_path):
    """Under the batched protocol film's diagnosis keeps urma's token groups, so the fixed-rollout analysis reuses
    its rollouts: its calibration is the one without them (same physics, same actor inputs)."""
    from morfic_cli.diagnostics.calibration import diagnose_runs
    from morfic_cli.diagnostics.fixed_rollout import recording_tokens
    from morfic_cli.rl.load import load_trained

    assert Pipeline(
        Store(tmp_path / "a"), reproduce_cfg("smoke", variants=("film", "urma"))
    ).fixed_rollout_reads_tokens()
    assert not Pipeline(
        Store(tmp_path / "b"), reproduce_cfg("smoke", variants=("film", "ppo"))
    ).fixed_rollout_reads_tokens()
    pipe = Pipeline(Store(tmp_path / "store"), _tiny(reproduce_cfg("shipped", bundles=bundles)))
    pipe.import_run("film", "runs/film-cpu-s0")
    cfg = pipe.diagnose_cfg(pipe.cfg.robots)
    film = load_trained(pipe.store, "runs/film-cpu-s0")
    plain = diagnose_runs(pipe.store, ["runs/film-cpu-s0"], cfg, trained=[film]).rows
    tokens = diagnose_runs(pipe.store, ["runs/film-cpu-s0"], cfg, trained=[recording_tokens(film)]).rows
    assert [r["rollout"] for r in plain] != [r["rollout"] for r in tokens]  # other rollouts: more groups kept
    assert [{**r, "rollout": ""} for r in plain] == [{**r, "rollout": ""} for r in tokens]
