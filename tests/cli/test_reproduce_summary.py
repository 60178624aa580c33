"""`morfic reproduce`'s closing output: the report's files as counts, the `report:` line last (80 columns)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from fake_runs import fake_run

from morfic_cli.cli._options import OutputFormat
from morfic_cli.cli.reproduce import _summary, files_summary


def _result(out: Path) -> SimpleNamespace:
    files = [
        out / "report.md",
        out / "report.pdf",
        *(out / "figures" / f"fig{i}.png" for i in range(150)),
        *(out / "figures" / f"fig{i}.pdf" for i in range(60)),
        *(out / f"table{i}.csv" for i in range(8)),
    ]
    report = SimpleNamespace(ref="reports/shipped", id="ab" * 32, out_files=files, pdf_error=None)
    return SimpleNamespace(report=report, work_done=3, steps=[None] * 10, seconds=12.34)


def test_files_summary_counts_by_type():
    assert (
        files_summary([Path("a.png"), Path("b.png"), Path("c.md"), Path("README")])
        == "4 files: 2 .png, 1 (no extension), 1 .md"
    )
    assert files_summary([]) == "0 files"


def test_the_table_counts_the_files_and_the_report_line_comes_last(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    out = tmp_path / "reports" / "shipped"
    _summary(_result(out), False, OutputFormat.table, out)
    stdout, stderr = capsys.readouterr()
    assert "fig1.png" not in stdout and "1 .md" in stdout  # 219 paths were 219+ wrapped lines
    assert len(stdout.splitlines()) < 25
    assert "220 files: 150 .png, 61 .pdf, 8 .csv, 1 .md" in " ".join(stdout.split())
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("report: ") and "report.pdf" in last


def test_json_keeps_every_path(capsys, tmp_path):
    out = tmp_path / "r"
    _summary(_result(out), True, OutputFormat.json, out)
    stdout, stderr = capsys.readouterr()
    assert len(json.loads(stdout)["files"]) == 220 and stderr == ""


def _runs(*pairs: tuple[str, int]):
    from morfic_cli.report.gather import StoreData

    return StoreData(runs=[fake_run(v, s, checkpoint="c") for v, s in pairs])


def test_a_one_seed_report_says_first_why_it_cannot_tell_and_how_to_get_the_answer():
    """`reproduce --preset shipped` reports one seed a variant: its first lines say so (the README reads 3 seeds)."""
    from morfic_cli.report.build import _intro, seeds_note

    intro = _intro(_runs(("film", 0), ("ppo", 0)), with_paper=True)
    first = intro.split("\n\n")[0]
    assert first.startswith("Read this first: this store has one training seed per variant")
    assert "`morfic store import --append artifacts/bundles/results/*.tar`, then `morfic report`" in first
    assert "docs/reproducing.md" in first and intro.split("\n\n")[1].startswith("Built by morfic")
    partly = seeds_note(_runs(("film", 0), ("film", 1), ("ppo", 0)))
    assert partly.startswith("Read this first: ppo has one training seed here")
    assert seeds_note(_runs(("film", 0), ("film", 1), ("ppo", 0), ("ppo", 2))) == ""
    assert _intro(_runs(("film", 0), ("film", 1)), with_paper=False).startswith("Built by morfic")
