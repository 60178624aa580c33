"""``morfic robots ls|show``: listing, facts, generated XML, and errors on stderr with exit 1."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import mujoco
import pytest

from morfic_cli.cli import main
from morfic_cli.morphology.descriptor import DESCRIPTOR_NAMES

ROBOTS_DIR = Path(__file__).resolve().parents[2] / "robots"


def _ok(capsys, *argv: str) -> str:
    main(list(argv))
    out, err = capsys.readouterr()
    assert "Error" not in err
    return out


def _fails(capsys, *argv: str) -> tuple[str, str]:
    with pytest.raises(SystemExit) as info:
        main(list(argv))
    assert info.value.code == 1
    out, err = capsys.readouterr()
    assert err.startswith("Error: ")
    assert "Traceback" not in err
    return out, err


def test_ls_json_lists_the_library(capsys):
    from morfic_cli.morphology.robots import list_robots

    rows = json.loads(_ok(capsys, "robots", "ls", "--format", "json"))
    assert [r["robot"] for r in rows][0] == "go2"
    assert [r["robot"] for r in rows] == list_robots()
    by_name = {r["robot"]: r for r in rows}
    assert [n for n, r in by_name.items() if r["template"]] == ["go2"]
    assert by_name["go2"]["total_mass_kg"] == pytest.approx(16.085)
    assert by_name["go2"]["base_mass_kg"] == pytest.approx(6.921)
    assert by_name["b1"]["n_outside_support"] == 8  # the paper marks 8 of B1's 11 dims
    assert by_name["go2"]["n_outside_support"] == 1
    assert 0.2 < by_name["go2"]["nominal_height_m"] < 0.4


def test_ls_table_and_csv(capsys):
    assert "Robot library" in _ok(capsys, "robots", "ls")
    rows = list(csv.DictReader(io.StringIO(_ok(capsys, "robots", "ls", "--format", "csv"))))
    assert len(rows) == len(json.loads(_ok(capsys, "robots", "ls", "--format", "json"))) and rows[0]["robot"] == "go2"


def test_show_json_has_facts_descriptor_marks_and_conflicts(capsys):
    obj = json.loads(_ok(capsys, "robots", "show", "aliengo", "--format", "json"))
    assert obj["robot"] == "aliengo"
    assert [d["name"] for d in obj["descriptor"]] == list(DESCRIPTOR_NAMES)
    hip = next(d for d in obj["descriptor"] if d["name"] == "hip_mass")
    assert hip["value"] == 1.0 and hip["mark"] == "↑"
    assert any(f["field"] == "links.hip.mass" and f["unit"] == "kg" for f in obj["facts"])
    facts = {f["field"]: f["value"] for f in obj["facts"]}
    assert isinstance(facts["base.mass"], float) and len(facts["base.size"]) == 3  # numbers, not text
    assert all(isinstance(v, float) for v in facts["base.size"])
    assert any("hip_mass" in c["field"] for c in obj["conflicts"])


def test_show_table_and_csv(capsys):
    out = _ok(capsys, "robots", "show", "go2")
    assert "11-D descriptor" in out and "Facts" in out
    rows = list(csv.DictReader(io.StringIO(_ok(capsys, "robots", "show", "go2", "--format", "csv"))))
    assert {r["section"] for r in rows} == {"summary", "fact", "descriptor"}


def test_show_xml_compiles(capsys):
    xml = _ok(capsys, "robots", "show", "go1", "--xml")
    model = mujoco.MjModel.from_xml_string(xml)
    assert model.nu == 12
    assert model.key("home").id == 0


def test_unknown_robot_is_an_error_listing_the_valid_ones(capsys):
    out, err = _fails(capsys, "robots", "show", "go3")
    assert "unknown robot 'go3'" in err and "go2" in err
    assert out == ""


def test_bad_toml_in_the_library_is_an_error(capsys, tmp_path, monkeypatch):
    text = (ROBOTS_DIR / "go2.toml").read_text().replace("mass = { value = 0.678", "mass = { value = -0.678")
    (tmp_path / "go2.toml").write_text(text)
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path))
    _, err = _fails(capsys, "robots", "show", "go2")
    assert "links.hip.mass" in err and "go2.toml" in err
    _, err = _fails(capsys, "robots", "ls")
    assert "links.hip.mass" in err


def test_toml_syntax_error_is_an_error(capsys, tmp_path, monkeypatch):
    (tmp_path / "go2.toml").write_text((ROBOTS_DIR / "go2.toml").read_text().replace("[leg]", "[leg"))
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path))
    _, err = _fails(capsys, "robots", "show", "go2", "--xml")
    assert "TOML syntax error" in err


def test_robots_dir_that_does_not_exist(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path / "nowhere"))
    _, err = _fails(capsys, "robots", "ls")
    assert "MORFIC_ROBOTS_DIR" in err


def test_help_has_an_example(capsys):
    for argv in (["robots", "--help"], ["robots", "ls", "--help"], ["robots", "show", "--help"]):
        try:
            main(argv)
        except SystemExit as exc:  # help may exit 0 through sys.exit
            assert exc.code in (0, None)
        assert "Example" in capsys.readouterr().out
