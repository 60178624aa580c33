"""scripts/ship_critic_study.py: the store's critic study -> its results-only bundle, rows and record."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "ship_critic_study.py"
spec = importlib.util.spec_from_file_location("ship_critic_study", SCRIPT)
ship = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ship)


def _doc(inputs: dict[str, str], meta: dict) -> dict:
    return {"id": "ab" * 32, "inputs": inputs, "meta": meta, "config": {"seeds": 1, "layout": 2}}


def test_a_layout2_record_names_every_actor_with_its_checkpoint():
    doc = _doc(
        {
            "actor/film-cpu-s0": "7cc932adfd3a" + "0" * 52,
            "actor/concat-cpu-s0": "6f6f096cb0c5" + "1" * 52,
            "rollout/film-cpu-s0/1/go2": "ff" * 32,
        },
        {"actor": "film-cpu-s0, concat-cpu-s0", "seconds": {"fits": 10.0, "rollouts": 2.0, "scoring": 1.0}},
    )
    record = ship.study_record(doc, 1234.5, "a CPU", "idle")
    assert record["id"] == "abababababab" and record["full_id"] == "ab" * 32
    assert record["actor"] == "film-cpu-s0, concat-cpu-s0"
    assert record["actor_checkpoints"] == {"film-cpu-s0": "7cc932adfd3a", "concat-cpu-s0": "6f6f096cb0c5"}
    assert record["seconds"] == {"fits": 10.0, "rollouts": 2.0, "scoring": 1.0}
    assert record["wall_seconds"] == 1234.5 and record["machine"] == "a CPU" and record["note"] == "idle"
    assert record["config"] == {"seeds": 1, "layout": 2}


def test_a_layout1_record_takes_its_one_actor_from_meta_and_leaves_out_an_unmeasured_wall_time():
    record = ship.study_record(_doc({"actor": "7cc932adfd3a"}, {"actor": "film-cpu-s0", "seconds": {}}), None, "m", "")
    assert record["actor"] == "film-cpu-s0" and record["actor_checkpoints"] == {}
    assert "wall_seconds" not in record


def test_a_store_without_a_study_is_an_error_and_writes_nothing(tmp_path, capsys, monkeypatch):
    from morfic_cli.store import Store

    Store(tmp_path / "store")  # an empty store
    out, bundles = tmp_path / "results", tmp_path / "bundles"
    rc = ship.main(["--store", str(tmp_path / "store"), "--out", str(out), "--bundles", str(bundles)])
    assert rc == 1
    assert capsys.readouterr().err.startswith("Error: ")
    assert not out.exists() and not bundles.exists()


def test_the_shipped_record_is_what_results_tables_reads():
    """docs/results/critic-study.json carries the keys scripts/results_tables.py's study block reads."""
    record = json.loads((Path(__file__).resolve().parents[2] / "docs/results/critic-study.json").read_text())
    assert {"id", "actor", "seconds"} <= set(record)
