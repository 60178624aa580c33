"""Aggregation over seeds, bold marks, and the LaTeX / Markdown renderers, against hand-computed numbers."""

from __future__ import annotations

import math
import statistics

import pytest

from morfic_cli.report import paper
from morfic_cli.report.compare import add_paper_columns, compute_rows, pooled_std, transfer_rows
from morfic_cli.report.gather import RunInfo, StoreData
from morfic_cli.report.latex import cell_latex, document_latex, escape, table_latex
from morfic_cli.report.markdown import table_markdown
from morfic_cli.report.model import Part, Row, Table, bold_best, number_text
from morfic_cli.report.tables import fixed_rollout_table, paper_table, transfer_table


def _run(variant: str, seed: int, wall: float = 36.0, steps: int = 1000, iters: int = 10) -> RunInfo:
    return RunInfo(
        spec=f"runs/{variant}-s{seed}",
        name=f"{variant}-s{seed}",
        checkpoint=f"{variant}{seed}" * 8,
        variant=variant,
        seed=seed,
        preset="cpu",
        iteration=iters,
        max_iterations=iters,
        env_steps=steps,
        wall_time_s=wall,
        device="cpu",
        finished=True,
        created="",
    )


def _eval(
    run: RunInfo, robot: str, vx: float, std: float, s: float, n_alive: int = 100, command_vx: float = 2.0
) -> dict:
    return {
        "run": run.name,
        "variant": run.variant,
        "seed": run.seed,
        "preset": run.preset,
        "checkpoint": run.checkpoint,
        "robot": robot,
        "mode": "descriptor",
        "command_vx": command_vx,
        "d": 0.3,
        "vx_mean": vx,
        "vx_std": std,
        "vx_env_std": 0.01,
        "vx_step_mean": vx,
        "n_alive": n_alive,
        "vx_peak_1s_mean": vx + 0.1,
        "vx_peak_1s_std": std,
        "survival": s,
        "tracking_ratio": vx / 2,
        "valid_fraction": s,
        "num_envs": 64,
        "steps": 500,
    }


def test_mean_and_std_over_seeds_by_hand():
    a, b = _run("film", 0), _run("film", 1)
    data = StoreData(runs=[a, b], evals=[_eval(a, "aliengo", 1.0, 0.3, 0.5), _eval(b, "aliengo", 2.0, 0.4, 1.0)])
    (row,) = transfer_rows(data)
    assert row["n_seeds"] == 2 and row["runs"] == "film-s0;film-s1"
    assert row["vx"] == pytest.approx(1.5)
    assert row["vx_seed_std"] == pytest.approx(statistics.stdev([1.0, 2.0]))  # 0.7071
    # pooled over the alive steps of both seeds (100 each): sqrt(mean(0.09, 0.16) + var_pop(1, 2)) = sqrt(0.375)
    assert row["vx_std"] == pytest.approx(math.sqrt(0.375))
    assert row["vx_peak_1s"] == pytest.approx(1.6)
    assert row["survival"] == pytest.approx(0.75)
    assert row["cell"] == "1.50 ± 0.61 / 0.750"
    one = transfer_rows(StoreData(runs=[a], evals=[_eval(a, "go1", 1.234, 0.2, 0.5)]))[0]
    assert one["vx_seed_std"] is None and one["vx_std"] == pytest.approx(0.2)  # one seed: the run's own σ
    assert pooled_std([None], [None]) is None
    # unequal sample counts: seed 0 has 300 alive steps at mean 1 (σ 0), seed 1 has 100 at mean 2 (σ 0):
    # μ = (300 + 200) / 400 = 1.25, σ² = (300 * 0.0625 + 100 * 0.5625) / 400 = 0.1875
    assert pooled_std([1.0, 2.0], [0.0, 0.0], [300, 100]) == pytest.approx(math.sqrt(0.1875))
    # an evaluation stored before σ was over steps (no vx_env_std) has another σ: the cell's σ stays empty
    old = {
        k: v for k, v in _eval(a, "go1", 1.0, 0.3, 0.5).items() if k not in ("vx_env_std", "vx_step_mean", "n_alive")
    }
    (r_old,) = transfer_rows(StoreData(runs=[a], evals=[old]))
    assert r_old["vx_std"] is None and r_old["cell"] == "1.00 ± - / 0.500"


def test_paper_columns_and_compute_normalisation():
    a = _run("film", 0, wall=7200.0, steps=100_000_000, iters=4000)
    (c,) = compute_rows(StoreData(runs=[a]))
    assert c["device_hours"] == pytest.approx(2.0) and c["s_per_iteration"] == pytest.approx(1.8)
    assert c["device_hours_400m"] == pytest.approx(8.0)
    (cp,) = add_paper_columns([c])
    assert cp["paper_s_per_iteration"] == "1.98-2.70" and cp["paper_table"] == "tab:training_compute"
    (t,) = add_paper_columns(transfer_rows(StoreData(runs=[a], evals=[_eval(a, "b1", 0.2, 0.1, 1.0)])))
    assert t["paper_vx"] == 0.22 and t["paper_survival"] == 1.0 and t["paper_quantity"] == "v_x"
    # at 2.5 m/s the paper's v_x^max (its speed under the higher command) sits beside our v_x of that command
    (f,) = add_paper_columns(
        transfer_rows(StoreData(runs=[a], evals=[_eval(a, "aliengo", 0.9, 0.5, 1.0, command_vx=2.5)]))
    )
    assert f["paper_quantity"] == "v_x^max" and f["paper_table"] == "tab:cross_embodiment_baselines_25"
    assert f["paper_vx"] == 0.832 and f["paper_vx_std"] == 0.542 and f["paper_survival"] == 1.0
    assert f["vx"] == pytest.approx(0.9)


def test_bold_best_ties_and_missing():
    assert bold_best([0.2, None, 0.5, 0.5], True) == [False, False, True, True]
    assert bold_best([0.2, float("nan"), 0.1], False) == [False, False, True]
    assert bold_best([None, None], True) == [False, False]
    assert bold_best([0.7, None], True) == [False, False]  # one value: nothing to be best against


def test_a_one_method_table_is_not_bold_and_tables_are_placed_and_never_enlarged():
    a = _run("film", 0)
    rows = transfer_rows(StoreData(runs=[a], evals=[_eval(a, "go1", 1.9, 0.3, 0.9), _eval(a, "b1", 0.1, 0.1, 0.0)]))
    table = transfer_table(rows, key="k", title="t", command_vx=2.0, mode="descriptor")
    assert not any(p.bold for row in table.rows for cell in row.cells for p in cell)
    tex = table_latex(table)
    assert r"\begin{table}[H]" in tex and r"\mathbf" not in tex
    wide = table_latex(paper_table(paper.CROSS_EMBODIMENT_BASELINES))
    assert r"\resizebox{\ifdim\width>\linewidth\linewidth\else\width\fi}{!}" in wide


def test_transfer_table_bolds_best_speed_and_survival_per_robot_independently():
    a, b = _run("ppo", 0), _run("film", 0)
    rows = transfer_rows(StoreData(runs=[a, b], evals=[_eval(a, "go1", 1.9, 0.3, 0.9), _eval(b, "go1", 2.1, 0.5, 0.5)]))
    table = transfer_table(rows, key="k", title="t", command_vx=2.0, mode="descriptor")
    assert table.columns == ("PPO", "MorFiC-F")
    (row,) = table.rows
    assert [[p.bold for p in cell] for cell in row.cells] == [[False, True], [True, False]]
    assert cell_latex(row.cells[0], True) == r"$1.90{\pm}0.30/\mathbf{0.900}$"
    assert cell_latex(row.cells[1], True) == r"$\mathbf{2.10{\pm}0.50}/0.500$"
    assert transfer_table(rows, key="k", title="t", command_vx=2.5, mode="descriptor") is None


def test_fixed_rollout_table_never_bolds_the_mc_reference():
    rows = [
        {"preset": "cpu", "variant": v, "robot": "aliengo", "flip": f, "cos_grad": c, "actors": "film-s0"}
        for v, f, c in (("mc", 0.0, 1.0), ("film", 0.25, 0.4), ("ppo", 0.3, -0.1))
    ]
    table = fixed_rollout_table(rows)
    assert [r.label for r in table.rows] == ["MC", "PPO", "MorFiC-F"]
    assert table.groups == (("AlienGo", 2),)
    bold = {r.label: [c[0].bold for c in r.cells] for r in table.rows}
    assert bold == {"MC": [False, False], "PPO": [False, False], "MorFiC-F": [True, True]}


def test_fixed_rollout_critics_on_different_actors_rollouts_are_never_averaged():
    from morfic_cli.report.compare import fixed_rollout_rows

    film, ppo = _run("film", 0), _run("ppo", 0)

    def fixed(critic, actor, flip, cos):
        return {
            "run": critic.name,
            "variant": critic.variant,
            "robot": "aliengo",
            "mode": "descriptor",
            "actor": f"runs/{actor.name}",
            "actor_checkpoint": actor.checkpoint,
            "actor_variant": actor.variant,
            "flip": flip,
            "cos_grad": cos,
            "asa": 0.5,
            "ev": 0.1,
        }

    # the film critic: Flip 0.2 on film's rollout, 0.6 on ppo's (averaged, it would read 0.4); ppo's critic 0.3, 0.5
    data = StoreData(
        runs=[film, ppo],
        fixed=[
            fixed(film, film, 0.2, 0.4),
            fixed(film, ppo, 0.6, 0.1),
            fixed(ppo, film, 0.3, 0.2),
            fixed(ppo, ppo, 0.5, 0.3),
        ],
    )
    rows = fixed_rollout_rows(data)
    assert [(r["actor_variant"], r["variant"], r["flip"]) for r in rows] == [
        ("film", "ppo", 0.3),
        ("film", "film", 0.2),
        ("ppo", "ppo", 0.5),
        ("ppo", "film", 0.6),
    ]  # film's actor first
    table = fixed_rollout_table(rows)
    assert [r.label for r in table.rows] == [
        "PPO (MorFiC-F's rollout)",
        "MorFiC-F (MorFiC-F's rollout)",
        "PPO (PPO's rollout)",
        "MorFiC-F (PPO's rollout)",
    ]
    # bold within each actor's block: film's critic on film's rollout (0.2 < 0.3, 0.4 > 0.2); ppo's on ppo's (0.5 <
    # 0.6, 0.3 > 0.1)
    assert [[c[0].bold for c in r.cells] for r in table.rows] == [
        [False, False],
        [True, True],
        [True, True],
        [False, False],
    ]
    one = fixed_rollout_table([r for r in rows if r["actor_variant"] == "film"])
    assert [r.label for r in one.rows] == ["PPO", "MorFiC-F"]  # one actor: the paper's labels


def test_renderers_on_a_paper_table_keep_its_bold_marks_and_missing_entries():
    t = paper_table(paper.CROSS_EMBODIMENT_BASELINES)
    md = table_markdown(t)
    assert "| AlienGo | - / - | 0.30 ± 0.28 / 0.234 |" in md
    assert "**1.98 ± 0.51** / **1.000**" in md
    tex = table_latex(t)
    assert r"\label{tab:paper-cross_embodiment_baselines}" in tex and r"\resizebox" in tex
    assert r"$\mathbf{2.86{\pm}0.11}/0.969$" in tex
    support = table_latex(paper_table(paper.MORPHOLOGY_SUPPORT))
    assert r"\textbf{4.300}$\uparrow$" in support and r"\textbf{-0.720}$\uparrow$" in support
    fixed = table_latex(paper_table(paper.CAUSAL_ADV_ALL))
    assert r"\cmidrule(lr){2-3}" in fixed and r"\multicolumn{2}{c}{\textbf{AlienGo}}" in fixed


def test_latex_escaping_and_document():
    assert escape("mini_cheetah 50% & #1 ± σ") == r"mini\_cheetah 50\% \& \#1 $\pm$ $\sigma$"
    assert escape("run `morfic store ls`") == r"run \texttt{morfic store ls}"
    assert number_text(-0.0001, 2) == "0.00" and number_text(None, 2) == "-"
    t = Table("k", "T", "c", "Target", ("A",), (Row("x_y", ((Part(1.0, None, 1, True),),)), Row("section")), math=False)
    doc = document_latex("Title", [("S", table_latex(t))])
    assert r"\usepackage{booktabs}" in doc and r"x\_y & \textbf{1.0} \\" in doc
    assert r"\multicolumn{2}{l}{\textit{section}}" in doc


def test_several_presets_are_labelled_apart():
    import dataclasses

    a = _run("film", 0)
    b = dataclasses.replace(_run("film", 0), preset="smoke", checkpoint="s" * 64, name="film-smoke-s0")
    rows = transfer_rows(StoreData(runs=[a, b], evals=[_eval(a, "go2", 2.0, 0.3, 1.0), _eval(b, "go2", 0.1, 0.1, 0.0)]))
    assert [(r["preset"], r["n_seeds"]) for r in rows] == [("cpu", 1), ("smoke", 1)]  # never averaged together
    table = transfer_table(rows, key="k", title="t", command_vx=2.0, mode="descriptor")
    assert table.columns == ("MorFiC-F (cpu)", "MorFiC-F (smoke)")


def test_where_a_run_executed_is_not_part_of_its_identity():
    from morfic_cli.pipeline import experiment_config
    from morfic_cli.rl.config import apply_overrides, preset_cfg, train_cfg_to_dict

    base = preset_cfg("smoke", "film")
    moved = apply_overrides(base, ["env.sim.num_threads=16", "env.sim.device=cuda:0"])
    other = apply_overrides(base, ["ppo.gamma=0.98"])
    assert experiment_config(train_cfg_to_dict(moved)) == experiment_config(train_cfg_to_dict(base))
    assert experiment_config(train_cfg_to_dict(other)) != experiment_config(train_cfg_to_dict(base))


def test_ablation_columns_follow_the_papers_order():
    from morfic_cli.report.tables import ABLATION_VARIANTS

    runs = [_run(v, 0) for v in ("adaln", "hyper", "film-scaled", "film", "ppo")]
    rows = transfer_rows(StoreData(runs=runs, evals=[_eval(r, "go2", 1.0, 0.1, 1.0) for r in runs]))
    table = transfer_table(rows, key="k", title="t", command_vx=2.0, mode="descriptor", variants=ABLATION_VARIANTS)
    assert table.columns == ("MorFiC-F", "MorFiC-F(Scaled)", "MorFiC-H", "MorFiC-A")


def test_the_report_adds_an_every_variant_table_when_runs_leave_the_main_tables_four():
    from morfic_cli.report.build import _sections

    def keys(variants):
        runs = [_run(v, 0) for v in variants]
        data = StoreData(runs=runs, evals=[_eval(r, "go2", 1.0 + i / 10, 0.1, 1.0) for i, r in enumerate(runs)])
        (sec,) = [
            s
            for s in _sections(data, {"transfer": transfer_rows(data)}, [], False)
            if s.heading == "Zero-shot transfer"
        ]
        return {t.key: t for t in sec.tables}

    assert list(keys(["ppo", "film"])) == ["zero_shot_transfer"]  # the paper's main table holds them all
    tables = keys(["adaln", "ppo", "film", "hyper"])
    assert list(tables) == ["zero_shot_transfer", "zero_shot_transfer_every"]
    assert tables["zero_shot_transfer"].columns == ("PPO", "MorFiC-F")
    every = tables["zero_shot_transfer_every"]
    assert every.columns == ("PPO", "MorFiC-F", "MorFiC-H", "MorFiC-A")  # every variant, in our order
    # go2 speeds by hand: adaln 1.0, ppo 1.1, film 1.2, hyper 1.3 (the evals' order above); film's the best of PPO/F
    (row,) = every.rows
    assert [c[0].value for c in row.cells] == pytest.approx([1.1, 1.2, 1.3, 1.0])
    assert [c[0].bold for c in row.cells] == [False, False, True, False]
    assert list(keys(["hyper"])) == []  # one variant, outside the main four: no table of one column


def test_longtable_is_pandas_styler_with_escaped_cells_and_the_header_on_every_page():
    from morfic_cli.report.latex import longtable_latex

    tex = longtable_latex(("kind", "ref"), [("eval", "evals/film_cpu"), ("table", "`x` & y")], "lp{0.5\\linewidth}")
    assert tex.startswith("{\\scriptsize\n\\begin{longtable}{lp{0.5\\linewidth}}") and tex.endswith("\\end{longtable}}")
    assert tex.count("\\textbf{kind} & \\textbf{ref} \\\\") == 2  # first page and every later page
    assert "\\endfirsthead" in tex and "\\endhead" in tex and "\\bottomrule" in tex
    assert "eval & evals/film\\_cpu \\\\" in tex and "table & \\texttt{x} \\& y \\\\" in tex
    assert "- & - \\\\" in longtable_latex(("kind", "ref"), [], "ll")  # an empty list still has a row


def test_a_runs_diagnoses_at_two_commands_are_never_pooled_as_seeds(tmp_path):
    """Every run is diagnosed at 2.0 and 1.0 m/s: hyper-cpu-s1 on AlienGo read 2 seeds, EV -0.256 (the mean of -0.535
    at 2.0 and 0.023 at 1.0), and the newer fixed-rollout analysis at 1.0 hid the one at 2.0."""
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.report.build import _sections
    from morfic_cli.report.claims import at_command
    from morfic_cli.report.compare import compare_tables
    from morfic_cli.report.gather import gather, resolve_runs
    from morfic_cli.store import Store

    store = Store(tmp_path / "store")
    keys = {"variant": "film", "seed": 0, "preset": "cpu"}
    ckpt = store.put_manifest("checkpoint", config=keys, meta=keys, files={"model.pt": b"weights"})
    store.set_ref("runs/film-cpu-s0", ckpt)

    def csv(rows):
        return rows_to_csv(rows, list(dict.fromkeys(k for r in rows for k in r)))

    def diagnose(command_vx, ev, flip):  # one calibration and one fixed-rollout diagnosis at the command
        base = {
            "robot": "aliengo",
            "mode": "descriptor",
            "command_vx": command_vx,
            "num_envs": 64,
            "steps": 500,
            "actor": "runs/film-cpu-s0",
            "actor_variant": "film",
            "asa": 0.6,
            "ev": ev,
        }
        calib = {**base, "checkpoint": ckpt, "abs_nvb": 0.1, "nve": 0.5, "flip": flip, "cos_grad": 0.3, "d": 0.4}
        store.put_manifest("diagnosis", inputs={"checkpoint": ckpt}, files={"calibration.csv": csv([calib])})
        fixed = [
            {**base, "critic": "mc", "variant": "mc", "checkpoint": None, "flip": 0.0, "cos_grad": 1.0},
            {
                **base,
                "critic": "runs/film-cpu-s0",
                "variant": "film",
                "checkpoint": ckpt,
                "flip": flip,
                "cos_grad": 0.4,
            },
        ]
        store.put_manifest("diagnosis", inputs={"actor": ckpt}, files={"fixed_rollout.csv": csv(fixed)})

    diagnose(2.0, -0.535, 0.31)
    diagnose(1.0, 0.023, 0.12)  # newer: it used to hide the fixed-rollout analysis at 2.0
    data = gather(store, resolve_runs(store, None), curves=False)
    tables = compare_tables(data, with_paper=True)
    calib = {r["command_vx"]: r for r in tables["calibration"]}
    assert sorted(calib) == [1.0, 2.0]
    assert [(calib[c]["n_seeds"], calib[c]["runs"]) for c in (2.0, 1.0)] == [(1, "film-cpu-s0")] * 2
    assert calib[2.0]["ev"] == pytest.approx(-0.535) and calib[1.0]["ev"] == pytest.approx(0.023)  # not -0.256
    # the paper's numbers are at 2.0 m/s (AlienGo, MorFiC-F: |NVB| 0.048); it reports none at 1.0
    assert calib[2.0]["paper_abs_nvb"] == 0.048 and calib[2.0]["paper_table"] == "tab:critic_metrics_variants"
    assert calib[1.0]["paper_abs_nvb"] is None and calib[1.0]["paper_table"] is None
    film = {r["command_vx"]: r for r in tables["fixed_rollout"] if r["variant"] == "film"}
    assert {c: (r["n_seeds"], r["flip"]) for c, r in film.items()} == {2.0: (1, 0.31), 1.0: (1, 0.12)}
    # the claims' comparisons as a table of their own: (a)-(e) at 2.0 m/s, one seed of film alone: no test anywhere
    verdicts = tables["verdicts"]
    assert {r["claim"] for r in verdicts} == set("abcd") and {r["verdict"] for r in verdicts} == {"cannot tell"}
    assert len([r for r in verdicts if r["claim"] == "b"]) == 9 and all(r["table"] == "verdicts" for r in verdicts)
    a = next(r for r in verdicts if r["claim"] == "a" and r["unit"] == "aliengo")
    assert (a["outcome"], a["p_holm"], a["seeds_needed"], a["cell"]) == ("not significant", None, None, "-")
    assert film[2.0]["paper_flip"] == 0.255 and film[1.0]["paper_flip"] is None

    def section(sections, heading):
        (sec,) = [s for s in sections if s.heading == heading]
        return {t.key: t for t in sec.tables if t.source == "store"}, [(t.key, t.source) for t in sec.tables]

    sections = _sections(data, tables, [], True)
    crit, order = section(sections, "Critic diagnostics")
    assert [k for k, src in order if src == "store"] == [
        "critic_ev",
        "critic_metrics_variants",
        "critic_ev_1_0",
        "critic_metrics_variants_1_0",
    ]
    assert order.index(("critic_ev_1_0", "store")) > max(i for i, (_, src) in enumerate(order) if src == "paper")
    assert crit["critic_ev"].title == "Explained variance of the critics"  # the paper's command: as before
    assert crit["critic_ev_1_0"].title == "Explained variance of the critics at 1.0 m/s"
    assert crit["critic_ev"].rows[0].cells[0][0].value == pytest.approx(-0.535)
    assert crit["critic_ev_1_0"].rows[0].cells[0][0].value == pytest.approx(0.023)
    assert (
        crit["critic_ev"].notes
        == crit["critic_ev_1_0"].notes
        == ("Mean over 1 seed per cell; numbers from the artifacts listed under Provenance.",)
    )
    fx, order = section(sections, "Fixed-rollout diagnostic")
    assert [k for k, src in order] == ["causal_adv_all", "causal_adv_all", "causal_adv_all_1_0"]  # ours, paper's, ours
    assert fx["causal_adv_all"].title == "Fixed-rollout critic diagnostic"
    film_flip = {k: next(r for r in t.rows if r.label == "MorFiC-F").cells[0][0].value for k, t in fx.items()}
    assert film_flip == {"causal_adv_all": 0.31, "causal_adv_all_1_0": 0.12}
    # a store with diagnoses at 2.0 m/s only renders as it always did: no table at another command
    only = StoreData(runs=data.runs, calibration=at_command(data.calibration, 2.0), fixed=at_command(data.fixed, 2.0))
    tables_2 = compare_tables(only)
    assert [
        section(_sections(only, tables_2, [], False), h)[1] for h in ("Critic diagnostics", "Fixed-rollout diagnostic")
    ] == [[("critic_ev", "store"), ("critic_metrics_variants", "store")], [("causal_adv_all", "store")]]
