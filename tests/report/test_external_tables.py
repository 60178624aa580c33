"""The external baselines' tables: the paper's row group and ours, the "not trained yet" line, EV figure, compute.

One module store: a smoke run each of film, bot, urma and genloco (with each variant's env defaults), evaluated on
Go2 at 2.0 and 2.5 m/s (2 envs x 10 steps) and diagnosed on Go2 (2 envs x 80 steps).
"""

from __future__ import annotations

import contextlib
import io
import json

import pytest
from fake_runs import fake_run

from morfic_cli.report import compare as C
from morfic_cli.report import paper
from morfic_cli.report import tables as T
from morfic_cli.report.gather import RunInfo, StoreData, gather, resolve_runs
from morfic_cli.store import Store

VARIANTS = ("film", "bot", "urma", "genloco")

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _cli(*args: str) -> str:
    from morfic_cli.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main(list(args))
    return out.getvalue()


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Store:
    import torch

    from morfic_cli.rl.config import preset_cfg
    from morfic_cli.rl.runner import new_run

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("external") / "store"
    st = Store(root)
    for variant in VARIANTS:  # preset_cfg: urma's body tokens, genloco's procedural geometry
        run = new_run(st, preset_cfg("smoke", variant), f"{variant}-smoke-s0")
        run.train()
        run.env.close()
        _cli(
            "eval",
            f"runs/{variant}-smoke-s0",
            "--robots",
            "go2",
            "--command-vx",
            "2.0,2.5",
            "--mode",
            "descriptor",
            "--envs",
            "2",
            "--steps",
            "10",
            "--store",
            str(root),
            "-q",
            "-f",
            "json",
        )
    _cli(
        "diagnose",
        *(f"runs/{v}-smoke-s0" for v in VARIANTS),
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "80",
        "--trunc-eps",
        "0.5",
        "--store",
        str(root),
        "-q",
        "-f",
        "json",
    )
    torch.set_num_threads(threads)
    return st


@pytest.fixture(scope="module")
def data(store) -> StoreData:
    return gather(store, resolve_runs(store, None), curves=False)


def _run(variant: str) -> RunInfo:
    return fake_run(variant, checkpoint=variant * 8, created="2026-01-01T00:00:00Z")


# ---------------------------------------------------------------------------- the paper's group (no store)
def test_the_paper_group_is_the_papers_two_tables_as_printed():
    rows = C.paper_external_rows()
    assert len(rows) == 2 * 5 * 7  # two commands x (URMA, BodyTransformer, GenLoco, Embodiment Scaling, MorFiC) x 7
    assert {r["group"] for r in rows} == {"paper"} and {r["n_seeds"] for r in rows} == {None}
    by = {(r["command_vx"], r["variant"], r["robot"]): r for r in rows}
    # cells read off the paper's Table "External baselines vs. MorFiC" and its 2.5 m/s twin
    assert (by[2.0, "urma", "go2"]["vx"], by[2.0, "urma", "go2"]["vx_std"], by[2.0, "urma", "go2"]["survival"]) == (
        1.84,
        0.26,
        1.0,
    )
    assert by[2.0, "bot", "aliengo"]["label"] == "BodyTransformer"  # the paper's BodyTransformer is our bot
    assert (by[2.0, "bot", "aliengo"]["vx"], by[2.0, "bot", "aliengo"]["survival"]) == (0.30, 0.234)
    assert by[2.0, "urma", "aliengo"]["vx"] is None and by[2.0, "urma", "aliengo"]["cell"] == "- / -"  # "-/-"
    assert by[2.0, "genloco", "b1"]["cell"] == "0.00 / 0.000"  # printed without a ± term
    assert by[2.0, "embodiment-scaling", "b1"]["vx"] == 2.86 and by[2.0, "embodiment-scaling", "b1"]["note"]
    assert "1,500 GPU-hours" in by[2.0, "embodiment-scaling", "b1"]["note"]
    assert (by[2.5, "urma", "go1"]["vx"], by[2.5, "urma", "go1"]["vx_std"]) == (2.514, 0.430)
    assert by[2.5, "film", "mini_cheetah"]["quantity"] == "v_x^max" and by[2.0, "film", "go2"]["quantity"] == "v_x"
    assert by[2.5, "film", "mini_cheetah"]["vx"] == 1.128
    # every number equals paper.py's
    for r in rows:
        table = paper.CROSS_EMBODIMENT_BASELINES if r["command_vx"] == 2.0 else paper.CROSS_EMBODIMENT_BASELINES_25
        method = C.paper_method(r["variant"])
        speed = table.parts[0]
        assert (r["vx"], r["vx_std"], r["survival"]) == (
            table.value(r["robot"], method, speed),
            table.value(r["robot"], method, f"{speed}_std"),
            table.value(r["robot"], method, "survival"),
        )


def test_without_a_run_of_ours_the_table_says_not_trained_yet_in_one_line():
    data = StoreData(runs=[_run("film"), _run("ppo")])
    assert C.external_rows(data) == []  # nothing of ours and the paper's numbers not asked for
    rows = C.external_rows(data, with_paper=True)
    assert rows == C.paper_external_rows()
    table = T.external_table(rows, 2.0)
    labels = [r.label for r in table.rows]
    assert labels == [
        C.PAPER_GROUP,
        "URMA (paper)",
        "BodyTransformer (paper)",
        "GenLoco (paper)",
        "Embodiment Scaling (paper)",
        "MorFiC-F (paper)",
        "Ours: not trained yet",
    ]
    assert C.external_note(False) in table.notes and C.PAPER_ONLY["embodiment-scaling"] in table.notes
    assert C.external_note(True) == ""
    # the report's section: the paper's group at 2.0 and 2.5 m/s, the line, and the compute of the paper's methods
    from morfic_cli.report.build import _external_section

    section = _external_section({}, with_paper=False)
    keys = [t.key for t in section.tables]
    assert keys == ["external_baselines_2_0", "external_baselines_2_5", "external_compute"]
    assert all(t.rows[-1].label == "Ours: not trained yet" for t in section.tables[:2])


def test_the_paper_cells_keep_the_papers_numbers_and_bold():
    table = T.external_table([], 2.0)
    urma = next(r for r in table.rows if r.label == "URMA (paper)")
    go2, aliengo, anymal = urma.cells[0], urma.cells[3], urma.cells[6]
    assert (go2[0].value, go2[0].std, go2[0].bold, go2[1].value, go2[1].bold) == (1.84, 0.26, False, 1.0, True)
    assert aliengo[0].value is None and aliengo[1].value is None
    assert anymal[0].bold  # the paper bolds URMA's 1.80 on ANYmal-C


def test_the_claims_read_the_paper_variants_rows_only():
    rows = [{"variant": v} for v in ("film", "ppo", "bot", "genloco", "mc", "my_lab.critics:Gated")]
    data = StoreData(runs=[], evals=rows, calibration=rows, fixed=rows)
    evals, calibration, fixed = C.claim_rows(data)
    assert [r["variant"] for r in evals] == [r["variant"] for r in calibration] == ["film", "ppo", "mc"]
    assert [r["variant"] for r in C.without_external(rows)] == ["film", "ppo", "mc", "my_lab.critics:Gated"]


# ---------------------------------------------------------------------------- our group (the store)
def test_the_paper_variants_tables_and_claims_leave_the_external_baselines_out(data):
    tables = C.compare_tables(data)
    assert {r["variant"] for r in tables["transfer"]} == {"film"}
    evals, calibration, fixed = C.claim_rows(data)
    assert {r["variant"] for r in evals} == {"film"} and {r["variant"] for r in calibration} == {"film"}
    assert {r["variant"] for r in tables["external"] if r["group"] == "ours"} == set(VARIANTS)


def test_our_group_is_the_mean_over_seeds_of_each_evaluation(data):
    ours = [r for r in C.external_rows(data) if r["group"] == "ours"]
    assert len(ours) == 4 * 2  # 4 variants x 2 commands on go2
    for row in ours:
        (ev,) = [e for e in data.evals if e["variant"] == row["variant"] and e["command_vx"] == row["command_vx"]]
        # one seed: the mean over seeds is the run's own v_x, σ its own σ over env-steps, S its own
        assert (row["vx"], row["vx_std"], row["survival"], row["n_seeds"]) == (
            pytest.approx(ev["vx_mean"]),
            pytest.approx(ev["vx_std"]),
            pytest.approx(ev["survival"]),
            1,
        )
    table = T.external_table(C.external_rows(data), 2.5)
    labels = [r.label for r in table.rows]
    assert labels[6:] == [
        C.OURS_GROUP,
        "URMA (smoke, 1 seed)",
        "BodyTransformer (smoke, 1 seed)",
        "GenLoco (smoke, 1 seed)",
        "MorFiC-F (smoke, 1 seed)",
    ]
    bot = table.rows[labels.index("BodyTransformer (smoke, 1 seed)")]
    (ev,) = [e for e in data.evals if e["variant"] == "bot" and e["command_vx"] == 2.5]
    assert bot.cells[0][0].value == pytest.approx(ev["vx_mean"]) and bot.cells[1][0].value is None  # go2; no go1
    assert "Ours: not trained yet" not in labels and C.external_note(False) not in table.notes


def test_every_kept_eval_row_carries_its_evals_termination_counts(data):
    from morfic_cli.evaluation.terminations import termination_names

    assert len(data.terminations) == 4 * 2 * len(termination_names())  # 4 runs x 2 commands on go2, every term
    for ev in data.evals:
        mine = [r for r in data.terminations if (r["run"], r["command_vx"]) == (ev["run"], ev["command_vx"])]
        assert [r["term"] for r in mine] == list(termination_names())
        assert {r["artifact"] for r in mine} == {ev["artifact"]}
        fell = round((1 - ev["survival"]) * ev["num_envs"])  # each fallen env counts under one term at least
        assert sum(r["envs"] for r in mine) >= fell and (fell > 0) == (sum(r["envs"] for r in mine) > 0)


def test_the_compute_table_counts_each_models_parameters(store, data):
    from morfic_cli.rl.load import load_trained

    rows = {r["variant"]: r for r in C.compute_rows(data)}
    for variant in VARIANTS:
        models = load_trained(store, f"runs/{variant}-smoke-s0")
        assert rows[variant]["actor_params"] == sum(p.numel() for p in models.actor.parameters())
        assert rows[variant]["critic_params"] == sum(p.numel() for p in models.critic.parameters())
        assert rows[variant]["transitions"] == 8 * 8 * 2  # smoke: 8 envs x 8 steps x 2 iterations
        assert rows[variant]["wall_time_s"] == store.read_manifest(f"runs/{variant}-smoke-s0").meta["wall_time_s"]
    assert 250_000 < rows["bot"]["actor_params"] < 300_000  # BoT-Hard: about 0.27 M
    table = T.external_compute_table(list(rows.values()))
    bot = next(r for r in table.rows if r.label == "BodyTransformer (smoke, 1 seed)")
    assert bot.cells[0][0].text == f"{rows['bot']['actor_params']:,}" and bot.cells[4][0].text == "cpu"
    assert any(
        r.label == "Embod. Scaling, full Gendog pool (paper)" and r.cells[3][0].text == "1507 GPU-h" for r in table.rows
    )
    assert C.paper_hours("genloco") == "53.3 (200M); 213.5 (800M)" and C.paper_hours("film") == "2.2-3.0"


def test_the_ev_figure_of_the_external_baselines(data):
    from morfic_cli.report.build import ev_external_figure

    calibration = C.calibration_rows(data)
    figure = ev_external_figure(calibration)
    assert list(figure) == ["ev-external"] and figure["ev-external"][0].startswith(b"\x89PNG")
    assert ev_external_figure([r for r in calibration if r["variant"] == "film"]) == {}  # no baseline: no figure


def test_compare_baselines_prints_both_groups_and_the_line(store, run_cli, wide_tables):
    code, out, err = run_cli("compare-baselines", "--store", str(store.root), "-f", "json")
    assert code == 0, err
    rows = [r for r in json.loads(out) if r["table"] == "external"]
    assert {r["group"] for r in rows} == {"paper", "ours"}
    code, out, err = run_cli("compare-baselines", "runs/film-smoke-s0", "--with-paper", "--store", str(store.root))
    assert code == 0, err
    assert "external baselines at 2 m/s" in out and "Ours: not trained yet" in " ".join(err.split())


def test_reproduce_trains_the_external_baselines_by_default():
    from morfic_cli.pipeline import reproduce_cfg
    from morfic_cli.rl.variants import REPRODUCE_VARIANTS

    for preset in ("smoke", "cpu", "paper"):
        assert set(C.EXTERNAL_VARIANTS) | set(C.PAPER_VARIANTS) <= set(reproduce_cfg(preset).variants)
    assert reproduce_cfg("cpu").variants == REPRODUCE_VARIANTS
    assert C.PAPER_VARIANTS == ("ppo", "actor-only", "concat", "film", "film-scaled", "hyper", "adaln")
    assert C.EXTERNAL_VARIANTS == ("bot", "urma", "genloco") and C.EXTERNAL_TABLE_VARIANTS == (
        "urma",
        "bot",
        "genloco",
        "film",
    )
