"""`morfic reproduce`, `morfic compare-baselines` and `morfic report` on a store made by a tiny reproduce."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil

import pytest

from morfic_cli.store import Store

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
        main(["reproduce", "--preset", "smoke", "--variants", VARIANTS, "--store", str(root), "--format", "json",
              "--quiet"])
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
    for ref in ("runs/film-smoke-s0", "runs/ppo-smoke-s0", "evals/film-smoke-s0", "evals/ppo-smoke-s0",
                "diagnoses/calibration", "diagnoses/fixed-rollout/aliengo", "diagnoses/fixed-rollout/mini_cheetah",
                "diagnoses/critic-study",
                "tables/compare-baselines", "tables/morphology-support", "reports/smoke"):
        assert store.has_ref(ref), ref
    report = store.read_manifest("reports/smoke")
    assert report.kind == "report"
    assert {"report.md", "report.tex", "report.json", "provenance.csv", "figures/ev.png", "figures/distance.png",
            "figures/compute.png", "figures/curves.png"} <= set(report.files)
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
    cfg = ReproduceCfg(preset="smoke", variants=("film",), robots=("go2",), command_vx=(2.0,), modes=("descriptor",),
                       eval_envs=2, eval_steps=5, diagnose_envs=2, diagnose_steps=80, trunc_eps=0.5,
                       fixed_rollout_robots=("go2",), torch_threads=1)

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


def test_compare_baselines_with_paper_csv_has_the_papers_aliengo_film_value(run_cli, store):
    code, out, err = run_cli("compare-baselines", "--with-paper", "--format", "csv")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    # with --with-paper and no external baseline trained: the external table holds the paper's group only
    assert {r["table"] for r in rows} == {"transfer", "external", "calibration", "fixed_rollout", "compute",
                                          "verdicts"}
    assert {r["group"] for r in rows if r["table"] == "external"} == {"paper"}
    cell = next(r for r in rows if r["table"] == "transfer" and r["variant"] == "film" and r["robot"] == "aliengo"
                and r["mode"] == "descriptor" and float(r["command_vx"]) == 2.0)
    assert float(cell["paper_vx"]) == 1.98 and cell["paper_table"] == "tab:zero_shot_transfer"
    assert "1.98" in out
    assert float(cell["n_seeds"]) == 1 and cell["vx"] != ""
    # full-mode rows get no paper numbers; a number the paper does not print stays empty, never 0
    full = next(r for r in rows if r["table"] == "transfer" and r["mode"] == "full")
    assert full["paper_vx"] == ""
    fast = next(r for r in rows if r["table"] == "transfer" and r["variant"] == "ppo" and r["command_vx"] == "2.5"
                and r["mode"] == "descriptor")
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
    assert "| AlienGo | 0.27 ± 0.07 / 0.000 | 0.64 ± 0.26 / **1.000** | 0.40 ± 0.18 / 0.156 | " \
           "**1.98 ± 0.51** / **1.000** |" in md
    # the external baselines' table: the paper's rows (URMA's "-/-" on AlienGo stays missing), ours not trained yet
    assert "| URMA (paper) | 1.84 ± 0.26 / **1.000** | 1.93 ± 0.28 / **1.000** | 1.79 ± 0.25 / **1.000** | - / - |" \
        in md
    assert "| *Ours: not trained yet* |" in md
    ours = md[md.index("**Zero-shot cross-morphology transfer.**"):md.index("(paper).**")]
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
    assert "_" not in re.sub(r"\$[^$]*\$|\\_|\\label\{[^}]*\}|\\includegraphics[^}]*\}|\\begin\{longtable\}\{[^}]*\}",
                             "", tex)  # every underscore outside math is escaped
    for line in tex.splitlines():
        if line.count("&") and line.rstrip().endswith("\\\\"):
            assert "$" not in line or line.count("$") % 2 == 0, line


def test_smoke_report_tex_compiles_with_pdflatex(run_cli, store, tmp_path):
    from morfic_cli.report.latex import compile_pdf, pdflatex

    if pdflatex() is None:
        pytest.skip("pdflatex is not installed (apt-get install texlive-latex-base texlive-latex-recommended)")
    code, out, err = run_cli("report", "--latex", "--figures", "--with-paper", "--out", str(tmp_path / "tex"),
                             "--format", "json")
    assert code == 0, err
    assert (tmp_path / "tex" / "report.pdf").read_bytes().startswith(b"%PDF")
    tex = (tmp_path / "tex" / "report.tex").read_text()
    figures = {f"figures/{p.name}": p.read_bytes() for p in (tmp_path / "tex" / "figures").iterdir()}
    assert compile_pdf(tex, figures).startswith(b"%PDF")
