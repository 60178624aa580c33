"""Tables in a narrow terminal: what a user copies (refs, ids, robots, modes) is never cut; lesser columns are left
out (named in the caption) or wrapped; json and csv keep every column."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from rich.console import Console

from morfic_cli.cli import _render
from morfic_cli.cli._options import OutputFormat
from morfic_cli.cli._render import Column, emit_rows, fit_columns

BUNDLE = Path(__file__).resolve().parents[2] / "artifacts" / "bundles" / "film-cpu-s0.tar"


@pytest.fixture
def console(monkeypatch):
    """The table console, ``width`` characters wide; ``.text()`` is what it printed."""

    def make(width: int) -> Console:
        con = Console(width=width, file=io.StringIO(), color_system=None)
        con.text = con.file.getvalue  # type: ignore[attr-defined]
        monkeypatch.setattr(_render, "out_console", con)
        return con

    return make


LS_ROWS = [
    {
        "ref": "diagnoses/fixed-rollout/film-scaled-cpu-s0",
        "id": "7cc932adfd3a" + "0" * 52,
        "kind": "diagnosis",
        "created": "2026-12-01T21:26:01Z",
        "files": 3,
        "size": 8_200_000,
    },
    {
        "ref": "runs/film-scaled-cpu-s0",
        "id": "ba6f9f58eae2" + "1" * 52,
        "kind": "checkpoint",
        "created": "2026-12-03T17:53:15Z",
        "files": 1,
        "size": 1_100,
    },
]


def _ls_columns():
    from morfic_cli.cli.store import _LS_COLUMNS

    return _LS_COLUMNS


@pytest.mark.parametrize("width", [80, 100, 200])
def test_store_ls_rows_keep_refs_and_ids_whole(console, width):
    con = console(width)
    emit_rows(LS_ROWS, OutputFormat.table, _ls_columns(), title="artifacts")
    text = con.text()
    assert max(len(line) for line in text.splitlines()) <= width
    assert "…" not in text
    for row in LS_ROWS:
        assert row["ref"] in text and row["id"][:12] in text and row["kind"] in text
    if width == 80:  # 42 + 12 + 10 + padding leaves no room for size, created or files
        assert "2026-12-01" not in text and "7.8 MiB" not in text
        assert "left out at this terminal width: created (UTC), files, size" in " ".join(text.split())
    if width == 100:  # room for size (7), not for created (19)
        assert "2026-12-01" not in text and "7.8 MiB" in text
    if width == 200:
        assert "2026-12-01 21:26:01" in text and "left out" not in text


def test_json_and_csv_keep_every_column_whatever_the_width(console, capsys):
    console(40)
    emit_rows(LS_ROWS, OutputFormat.json, _ls_columns())
    assert [set(r) for r in json.loads(capsys.readouterr().out)] == [set(LS_ROWS[0])] * 2
    emit_rows(LS_ROWS, OutputFormat.csv, _ls_columns())
    assert capsys.readouterr().out.splitlines()[0] == "ref,id,kind,created,files,size"


def test_too_narrow_for_the_whole_columns_folds_them_and_cuts_nothing(console):
    con = console(50)
    emit_rows(LS_ROWS, OutputFormat.table, _ls_columns())
    text = con.text()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 50
    ref_cells = [line.split("│")[1].strip() for line in text.splitlines() if line.startswith("│")]
    assert "diagnoses/fixed-rollout/film-scaled-cpu-s0" in "".join(ref_cells)  # folded over lines, every character


def test_fit_columns_drops_highest_drop_first_and_shrinks_wrapping_columns_to_their_longest_word():
    cols = [Column("robot"), Column("a", drop=1), Column("b", drop=2), Column("note")]
    cells = [["mini_cheetah", "0.416", "1.38", "moving upright"]]
    # natural: 12 + 5 + 4 + 14 = 35 content + 3*4+1 = 48
    assert fit_columns(cols, cells, 48) == ([0, 1, 2, 3], None)
    keep, widths = fit_columns(cols, cells, 47)  # b (drop 2) goes first: 12 + 5 + 14 + 10 = 41
    assert keep == [0, 1, 3] and widths is None
    keep, widths = fit_columns(cols, cells, 33)  # a goes too: 12 + 14 + 7 = 33
    assert keep == [0, 3] and widths is None
    keep, widths = fit_columns(cols, cells, 30)  # note wraps, down to its longest word (7), robot stays whole
    assert keep == [0, 3] and widths is not None and (widths[0], widths[3]) == (12, 11)


def test_eval_table_at_80_columns_shows_robot_and_mode_whole(console, run_cli, tmp_path):
    """The shipped policy on two robots in both modes, as `morfic eval` prints it in an 80-column terminal."""
    store = str(tmp_path / "s")
    code, _, err = run_cli("store", "import", str(BUNDLE), "--store", store)
    assert code == 0, err
    con = console(80)
    code, _, err = run_cli(
        "eval",
        "runs/film-cpu-s0",
        "--robots",
        "aliengo,mini_cheetah",
        "--mode",
        "both",
        "--envs",
        "2",
        "--steps",
        "5",
        "--scene-envs",
        "0",
        "-q",
        "--store",
        store,
    )
    assert code == 0, err
    text = con.text()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 80
    rows = [[c.strip() for c in line.split("│")[1:-1]] for line in text.splitlines() if line.startswith("│")]
    assert [r[:2] for r in rows] == [
        ["aliengo", "descriptor"],
        ["aliengo", "full"],
        ["mini_cheetah", "descriptor"],
        ["mini_cheetah", "full"],
    ]
    note = " ".join(text.split()).split("left out at this terminal width: ")[1]
    assert note.endswith("peak, track, ended by (--format json or csv has every column)"), note  # d too if need be
    code, out, err = run_cli(
        "eval",
        "runs/film-cpu-s0",
        "--robots",
        "aliengo",
        "--envs",
        "2",
        "--steps",
        "5",
        "--scene-envs",
        "0",
        "-q",
        "--store",
        store,
        "--format",
        "json",
    )
    assert code == 0, err
    (row,) = json.loads(out)
    assert row["robot"] == "aliengo" and row["mode"] == "descriptor"
    assert isinstance(row["vx_peak_1s_mean"], float) and isinstance(row["tracking_ratio"], float)


def test_diagnose_table_keeps_the_metrics_whole_at_80_columns_with_a_long_run_name(console):
    """A user variant's run name (35 characters) folds; the metric columns keep their width; lesser ones leave."""
    from morfic_cli.cli.diagnose import CALIBRATION_TABLE

    run = "custom_variant.GatedCritic-smoke-s0"
    rows = [
        {
            "run": run,
            "variant": "custom_variant:GatedCritic",
            "robot": robot,
            "d": 0.25,
            "ev": -1.234,
            "cell": "0.412/1.038/0.611",
            "flip": 0.421,
            "cos_grad": -0.125,
            "n_samples": 12345,
        }
        for robot in ("go2", "mini_cheetah")
    ]
    con = console(80)
    emit_rows(rows, OutputFormat.table, CALIBRATION_TABLE, title="critic calibration")
    text = con.text()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 80
    for cell in ("-1.234", "0.412/1.038/0.611", "0.421", "-0.125", "mini_cheetah"):  # each on one line, whole
        assert text.count(cell) == 2 if cell != "mini_cheetah" else text.count(cell) == 1, (cell, text)
    assert "CosGrad" in text and "|NVB|/NVE/ASA" in text  # headers on one line too
    run_cells = "".join(line.split("│")[1].strip() for line in text.splitlines() if line.startswith("│"))
    assert run_cells == run * 2  # folded over lines, every character
    assert "left out at this terminal width: variant, d, |I_eps|" in " ".join(text.split())
    con = console(160)  # wide enough: every column, the name on one line
    emit_rows(rows, OutputFormat.table, CALIBRATION_TABLE)
    assert run in con.text() and "left out" not in con.text()


@pytest.mark.parametrize("command", ["train", "eval", "play", "export", "diagnose", "reproduce"])
def test_help_at_80_columns_cuts_no_option_help(run_cli, monkeypatch, command):
    """A word longer than the help column is cut with an ellipsis (`[default: 2.0; 1.0 with --training-condit…`)."""
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = run_cli(command, "--help")
    assert code == 0
    assert max(len(line) for line in out.splitlines()) <= 80  # the width was honoured
    assert "…" not in out, [line for line in out.splitlines() if "…" in line]
