"""scripts/results_tables.py: run CSVs -> docs/results.md's tables, with the paper's columns beside them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "results_tables.py"
spec = importlib.util.spec_from_file_location("results_tables", SCRIPT)
rt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(rt)

EVAL_HEAD = "robot,mode,command_vx,d,vx_mean,vx_std,survival,verdict\n"


def _runs(tmp_path: Path) -> Path:
    (tmp_path / "film-cpu-s0-eval.csv").write_text(EVAL_HEAD + "aliengo,descriptor,2.0,0.324,1.6449,0.6351,0.0,falls\n")
    (tmp_path / "ppo-cpu-s0-eval.csv").write_text(EVAL_HEAD + "aliengo,descriptor,2.0,0.324,1.2,0.48,0.421875,falls\n")
    (tmp_path / "film-cpu-s0-calibration.csv").write_text(
        "robot,ev,abs_nvb,nve,asa\ngo2,0.37296,0.33255,0.85886,0.53106\n")
    return tmp_path


def test_transfer_table_orders_runs_as_the_paper_and_adds_its_columns(tmp_path):
    lines = rt.transfer_table(rt.load(_runs(tmp_path), "eval"), "descriptor", 2.0)
    assert lines[0] == "| robot | d | `ppo-cpu-s0` | `film-cpu-s0` | paper ppo | paper film |"
    # ours rounded to 2/2/3 places with the verdict; the paper's AlienGo cells (zero-shot table)
    assert lines[2] == ("| aliengo | 0.324 | 1.20 ± 0.48 / 0.422 (falls) | 1.64 ± 0.64 / 0.000 (falls) | "
                        "0.27 ± 0.07 / 0.000 | 1.98 ± 0.51 / 1.000 |")


def test_calibration_table_and_the_marked_block(tmp_path):
    block = rt.render(_runs(tmp_path))
    assert "| go2 | 0.373 | 0.333/0.859/0.531 | 1.768/1.943/0.771 |" in block  # paper film on Go2
    doc = tmp_path / "results.md"
    doc.write_text(f"intro\n{rt.BEGIN}\nold\n{rt.END}\noutro\n")
    rt.write_between_markers(doc, block)
    text = doc.read_text()
    assert text.startswith(f"intro\n{rt.BEGIN}\n### Descriptor") and text.endswith(f"{rt.END}\noutro\n")
    assert "old" not in text
    doc.write_text("no markers\n")
    with pytest.raises(SystemExit, match="no <!-- results-tables:begin -->"):
        rt.write_between_markers(doc, block)
