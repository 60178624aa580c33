"""Issue 58's goal (morfic_cli/report/goal.py): the bars at their edges, the goal table, the report's section."""

from __future__ import annotations

import pytest
from fake_runs import fake_run

from morfic_cli.report import build
from morfic_cli.report import goal as G
from morfic_cli.report.gather import RunInfo, StoreData


def _row(vx: float, s: float, command: float = 1.0, mode: str = "full", verdict: str = "ok", **kw) -> dict:
    return {"robot": "go2", "mode": mode, "command_vx": command, "vx_mean": vx, "survival": s, "verdict": verdict, **kw}


@pytest.mark.parametrize(
    ("row", "met"),
    [
        (_row(0.9, 0.95), True),  # 1.0 m/s: both bars exactly
        (_row(0.8999, 0.95), False),
        (_row(0.9, 0.9499), False),
        (_row(0.9, 0.95, verdict="drags feet"), False),  # a gait that is not valid
        (_row(0.9, 0.95, mode="descriptor"), False),  # the goal is full mode
        (_row(1.5, 0.9, 2.0), True),  # 2.0 m/s: its own bars exactly
        (_row(1.4999, 0.9, 2.0), False),
        (_row(1.5, 0.8999, 2.0), False),
        (_row(0.9, 0.95, 2.0), False),  # 1.0 m/s's bars do not clear 2.0 m/s's
        (_row(2.5, 1.0, 2.5), False),  # no bar at 2.5 m/s
        ({"mode": "full", "command_vx": 2.0, "vx": 1.5, "survival": 0.9, "verdict": "ok"}, True),  # a comparison row
    ],
)
def test_meets_goal_at_the_edges_of_the_bars(row, met):
    assert G.meets_goal(row) is met


def test_the_bar_is_read_in_other_modes_but_the_goal_only_in_full_mode():
    row = _row(1.0, 1.0, mode="actuation-matched")
    assert G.passes_bar(row) and not G.meets_goal(row)


def _seeds() -> list[dict]:
    """film: two seeds on Go2 at 2.0 m/s (one clears the bar); film-act: one seed that clears it on Go2 and A1."""
    return [
        _row(1.0, 1.0, 2.0, variant="film", seed=0, verdict="drags feet"),
        _row(2.0, 0.9, 2.0, variant="film", seed=1),
        _row(1.6, 0.95, 2.0, variant="film-act", seed=0),
        {**_row(1.5, 0.9, 2.0, variant="film-act", seed=0), "robot": "a1"},
    ]


def _variant(r):
    return str(r["variant"])


def test_goal_table_gives_seed_means_with_t_intervals_and_the_marks():
    table = G.goal_table(_seeds(), "full", 2.0, [("film", "film"), ("film-act", "film-act")], _variant)
    assert table is not None and table.key == "goal_full_2_0"
    go2 = [[p.text for p in cell] for cell in table.rows[0].cells]
    # film's v_x 1.0, 2.0: mean 1.5, s = 0.7071, t(0.975, 1) = 12.706: half 12.706 x 0.7071 / sqrt(2) = 6.353
    # S 1.0, 0.9: mean 0.95, half 12.706 x 0.07071 / sqrt(2) = 0.635: [0.315, 1.585], clipped to [0, 1] (a share)
    assert go2[0] == ["1.50 [-4.85, 7.85]", "0.950 [0.315, 1.000]", "drags feet 1/2, ok 1/2", "meets in 1 of 2 seeds"]
    assert go2[1] == ["1.60", "0.950", "ok", "meets"]
    assert table.rows[0].cells[1][3].bold and not table.rows[0].cells[0][3].bold
    a1 = [[p.text for p in cell] for cell in table.rows[2].cells]
    assert a1[0] == [None] * 4 and a1[1][3] == "meets"  # film has no A1 row: missing, never a zero
    assert table.rows[-1].label == "clears the bar"
    assert [c[0].text for c in table.rows[-1].cells] == ["0 of 7", "2 of 7"]
    assert G.goal_table(_seeds(), "full", 2.5, [("film", "film")], _variant) is None  # no bar at 2.5 m/s


def test_robots_meeting_needs_every_command_of_the_goal():
    rows = _seeds()
    assert G.robots_meeting(rows, "film-act", _variant) == ([], [1.0])  # no 1.0 m/s rows: nothing met
    rows += [_row(0.95, 1.0, 1.0, variant="film-act", seed=0)]
    assert G.robots_meeting(rows, "film-act", _variant) == (["go2"], [])


def test_reference_effects_one_seed_has_no_test():
    effects = G.reference_effects(_seeds(), "film-act", _variant)
    vx = next(e for e in effects if e.robot == "go2" and e.metric == "vx")
    assert vx.effect.estimate == pytest.approx(1.6 - 1.5) and not vx.effect.has_test and not vx.below
    assert "Go2 at 2.0 m/s v_x +0.10 (n 1 vs 2: no test)" in G.reference_text(effects)


def _run(variant: str, seed: int = 0) -> RunInfo:
    return fake_run(variant, seed)


def test_report_section_only_with_an_actuation_run():
    rows = [{**r, "preset": "cpu"} for r in _seeds()]
    assert build.goal_section(StoreData(runs=[_run("film"), _run("film", 1)], evals=rows[:2])) is None
    section = build.goal_section(StoreData(runs=[_run("film"), _run("film", 1), _run("film-act")], evals=rows))
    assert section is not None and section.heading == build.GOAL_HEADING
    assert [t.key for t in section.tables] == ["goal_full_2_0"]
    assert section.tables[0].columns == ("MorFiC-F, 2 seeds", "MorFiC-F(act), 1 seed")
    assert "MorFiC-F(act), 1 seed: robots meeting the goal (both commands, every seed): 0 of 7" in section.text
    assert "no full-mode rows at 1.0 m/s" in section.text


def test_report_section_shows_what_ended_the_failed_episodes_only_where_counts_exist():
    rows = [{**r, "preset": "cpu"} for r in _seeds()]
    runs = [_run("film"), _run("film", 1), _run("film-act")]
    ended = [
        {**r, "preset": "cpu"}
        for r in _ended("film-act", 0, "go2", (4, 1, 0, 0)) + _ended("ppo", 0, "go2", (1, 0, 0, 0))
    ]
    section = build.goal_section(StoreData(runs=runs, evals=rows, terminations=ended))
    assert section is not None and [t.key for t in section.tables] == ["goal_full_2_0", "ended_by_full_2_0"]
    table = section.tables[1]
    assert table.columns == ("MorFiC-F(act), 1 seed",)  # ppo is no column of the goal section; film has no counts
    assert [c[0].text for c in table.rows[0].cells] == ["illegal_contact 4, excessive_tilt 1"]


TERMS = ("illegal_contact", "excessive_tilt", "base_too_low", "nonfinite")


def _ended(variant: str, seed: int, robot: str, counts: tuple[int, ...], command: float = 2.0) -> list[dict]:
    """One eval row's termination lines (terminations.csv's columns, every term) with its run's keys."""
    return [
        {"robot": robot, "mode": "full", "command_vx": command, "term": t, "envs": n, "variant": variant, "seed": seed}
        for t, n in zip(TERMS, counts, strict=True)
    ]


def test_ended_by_counts_sum_over_seeds_and_name_the_terms_most_first():
    lines = _ended("film", 0, "go2", (3, 5, 0, 0)) + _ended("film", 1, "go2", (9, 0, 1, 0))
    # illegal_contact 3 + 9 = 12, excessive_tilt 5 + 0 = 5, base_too_low 0 + 1 = 1, over 2 seeds
    counts = G.ended_by_counts(lines, "full", 2.0, _variant)
    assert counts == {
        ("film", "go2"): ({"illegal_contact": 12, "excessive_tilt": 5, "base_too_low": 1, "nonfinite": 0}, 2)
    }
    assert G.ended_by_text(counts[("film", "go2")][0]) == "illegal_contact 12, excessive_tilt 5, base_too_low 1"
    assert G.ended_by_text({"illegal_contact": 2, "excessive_tilt": 3}) == "excessive_tilt 3, illegal_contact 2"
    assert G.ended_by_text({"illegal_contact": 2, "excessive_tilt": 2}) == "illegal_contact 2, excessive_tilt 2"
    assert G.ended_by_text(dict.fromkeys(TERMS, 0)) == "none"  # recorded, nothing failed
    assert G.ended_by_counts(lines, "full", 1.0, _variant) == {}
    assert G.ended_by_counts(lines, "descriptor", 2.0, _variant) == {}


def test_ended_by_table_marks_seeds_without_counts_and_leaves_unrecorded_cells_missing():
    # film has eval rows of 2 seeds on Go2 at 2.0 m/s (_seeds), counts of seed 0 only; film-act none on Go2, A1 a tie
    lines = _ended("film", 0, "go2", (3, 5, 0, 0)) + _ended("film-act", 0, "a1", (2, 2, 0, 0))
    lines += _ended("film-act", 0, "go2", (0, 0, 0, 0))
    cols = [("film", "film"), ("film-act", "film-act")]
    table = G.ended_by_table(lines, _seeds(), "full", 2.0, cols, _variant)
    assert table is not None and table.key == "ended_by_full_2_0" and table.columns == ("film", "film-act")
    cells = {row.label: [cell[0].text for cell in row.cells] for row in table.rows}
    assert cells["Go2"] == ["excessive_tilt 5, illegal_contact 3 (1 of 2 seeds)", "none"]
    assert cells["A1"] == [None, "illegal_contact 2, excessive_tilt 2"]  # film: no counts there, "-"
    assert cells["B1"] == [None, None] and len(table.rows) == len(G.ROBOTS)
    assert G.ended_by_table(lines, _seeds(), "full", 1.0, cols, _variant) is None  # no counts at 1.0 m/s
    only_act = G.ended_by_table(_ended("film-act", 0, "a1", (1, 0, 0, 0)), _seeds(), "full", 2.0, cols, _variant)
    assert only_act is not None and only_act.columns == ("film-act",)  # a column without counts is left out


def test_gather_reads_the_counts_of_the_eval_each_kept_row_came_from(tmp_path):
    from morfic_cli.evaluation.terminations import TERMINATION_COLUMNS, TERMINATIONS_CSV, termination_lines
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.report.gather import gather, resolve_runs
    from morfic_cli.store import Store

    store = Store(tmp_path / "store")
    meta = {"variant": "mine", "seed": 0, "preset": "cpu"}
    store.set_ref("runs/x", ckpt := store.put_manifest("checkpoint", meta=meta, files={"model.pt": b"w"}))
    head = b"robot,mode,command_vx,vx_mean,survival,verdict,num_envs,steps\n"

    def put_eval(rows: bytes, counts: dict[str, dict[str, int]] | None) -> str:
        files = {"eval.csv": head + rows}
        if counts is not None:
            lines = termination_lines(
                [{"robot": r, "mode": "full", "command_vx": 2.0, "terminations": c} for r, c in counts.items()]
            )
            files[TERMINATIONS_CSV] = rows_to_csv(lines, TERMINATION_COLUMNS)
        return store.put_manifest("eval", inputs={"checkpoint": ckpt}, files=files)

    protocol = put_eval(
        b"go2,full,2.0,1.5,0.75,falls,64,500\ngo1,full,2.0,1.9,1.0,ok,64,500\n",
        {"go2": {"illegal_contact": 16, "excessive_tilt": 3}, "go1": {"illegal_contact": 0, "excessive_tilt": 0}},
    )
    put_eval(b"go2,full,2.0,0.1,0.0,falls,2,10\n", {"go2": {"illegal_contact": 2, "excessive_tilt": 0}})  # quick
    put_eval(b"a1,full,2.0,1.0,0.5,falls,64,500\n", None)  # made before the counts were recorded
    data = gather(store, resolve_runs(store, None), curves=False)
    got = {(r["robot"], r["term"]): (r["envs"], r["artifact"], r["variant"]) for r in data.terminations}
    # the protocol's 64 x 500 rows are kept (not the quick eval's), and their counts with them; A1: none recorded
    assert got == {
        ("go2", "illegal_contact"): (16, protocol, "mine"),
        ("go2", "excessive_tilt"): (3, protocol, "mine"),
        ("go1", "illegal_contact"): (0, protocol, "mine"),
        ("go1", "excessive_tilt"): (0, protocol, "mine"),
    }
    assert {r["robot"] for r in data.evals} == {"go2", "go1", "a1"}


def test_only_the_references_runs_need_an_extra_eval_and_only_where_their_own_lack_the_goals_mode():
    # film: descriptor and full at 2.0 m/s, descriptor alone at 1.0 m/s (eval_modes) -> full mode at 1.0 m/s
    assert G.goal_evals("film") == (1.0,)
    assert G.goal_evals("film-act") == () and G.goal_evals("ppo") == ()  # not the reference
    assert G.goal_evals("genloco", G.Goal(reference="genloco")) == ()  # full mode at 1.0 m/s already (issue 57)
    assert G.goal_evals("film", G.Goal(mode="actuation-matched")) == (1.0, 2.0)  # in none of film's evals
    at_1_5 = G.Goal(bars=(G.GoalBar(1.5, 1.2, 0.9), G.GoalBar(2.0, 1.5, 0.9)))
    assert G.goal_evals("film", at_1_5) == (1.5,)  # no eval of film at 1.5 m/s at all; 2.0 m/s has full mode


def test_the_extra_evals_name_is_its_command_and_mode():
    assert G.goal_eval_name(1.0) == "eval-1.0-full"
    assert G.goal_eval_name(1.0, "terminations") == "terminations-1.0-full"
    assert G.goal_eval_name(2.0, goal=G.Goal(mode="actuation-matched")) == "eval-actuation-matched"
