"""`morfic report --markdown --figures` on a store with an eval but no diagnosis (the README's path)."""

from __future__ import annotations

import json

import pytest
from smoke_runs import LEGACY_BUNDLE

from morfic_cli.report.tables import protocol_text

BUNDLE = LEGACY_BUNDLE

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_protocol_text_names_a_reduced_budget():
    assert protocol_text([{"num_envs": 64, "steps": 500}]) == "the paper protocol: 64 envs x 500 steps"
    assert protocol_text([{"num_envs": 16, "steps": 250}, {"num_envs": 64, "steps": 500}]) == (
        "a reduced protocol: 16 envs x 250 steps, 64 envs x 500 steps; the paper's is 64 x 500"
    )
    assert protocol_text([{}]) == "envs and steps not recorded"


def test_report_with_an_eval_and_no_diagnosis_builds_with_figures(run_cli, tmp_path):
    assert run_cli("store", "import", str(BUNDLE))[0] == 0
    code, _, err = run_cli("eval", "runs/film-cpu", "--robots", "go2", "--envs", "2", "--steps", "20", "-q")
    assert code == 0, err
    out = tmp_path / "report"
    code, stdout, err = run_cli("report", "--markdown", "--figures", "--out", str(out), "-f", "json")
    assert code == 0, err
    assert "Traceback" not in err and "ValueError" not in err
    assert json.loads(stdout)["out"] == str(out)
    text = (out / "report.md").read_text()
    assert "a reduced protocol: 2 envs x 20 steps; the paper's is 64 x 500" in text
    assert "(the paper protocol)" not in text
    assert any(p.suffix == ".png" for p in out.rglob("*"))


def test_report_preset_keeps_that_presets_runs_and_names_the_presets_there(run_cli, tmp_path):
    assert run_cli("store", "import", str(BUNDLE))[0] == 0  # runs/film-cpu, preset cpu
    code, stdout, err = run_cli("report", "--preset", "paper", "-f", "json")
    assert code == 1 and stdout == ""
    assert "Error: no run has preset paper; the runs here have: cpu (1 run)" in err
    code, stdout, err = run_cli("report", "--preset", "cpu", "-f", "json")
    assert code == 0, err
    assert json.loads(stdout)["ref"].startswith("reports/latest@")
