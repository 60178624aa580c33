"""One meaning per flag, over every command (CliRunner): --out is a directory, --format table prints no JSON."""

from __future__ import annotations

import json
import os

import pytest
import typer
from typer.testing import CliRunner

from morfic_cli.cli import app
from morfic_cli.cli._options import OutputFormat
from morfic_cli.store import Store

runner = CliRunner()


def _commands() -> dict:
    """Every leaf command of the app by its full name ("eval", "store get", ...)."""
    out: dict = {}

    def walk(cmd, prefix: str) -> None:
        if hasattr(cmd, "commands"):  # a group
            for name, sub in cmd.commands.items():
                walk(sub, f"{prefix} {name}".strip())
        else:
            out[prefix] = cmd

    walk(typer.main.get_command(app), "")
    return out


def _option(cmd, flag: str):
    return next((p for p in cmd.params if flag in getattr(p, "opts", ())), None)


def test_every_out_is_a_directory_and_every_format_the_stdout_format():
    commands = _commands()
    with_out = {name for name, cmd in commands.items() if _option(cmd, "--out")}
    assert with_out >= {"eval", "diagnose", "export", "report", "reproduce", "store get", "store export"}
    for name in sorted(with_out):
        text = (_option(commands[name], "--out").help or "").lower()
        assert "director" in text or "folder" in text, name
    for name, cmd in sorted(commands.items()):
        fmt = _option(cmd, "--format")
        if fmt is None:
            continue
        assert fmt.type_descriptor.annotation is OutputFormat, name  # never a model format (export: --to)
    assert [f.value for f in OutputFormat] == ["table", "json", "csv"]


def test_out_given_a_file_is_an_error_for_every_directory_out(run_cli, tmp_path):
    afile = tmp_path / "a-file"
    afile.write_text("x")
    store = Store(os.environ["MORFIC_STORE"])
    store.set_ref("runs/x", store.put_manifest("checkpoint", files={"model.pt": b"w"}))
    argv = {
        "eval": ["eval", "runs/x"],
        "diagnose": ["diagnose", "runs/x"],
        "export": ["export", "runs/x"],
        "report": ["report"],
        "reproduce": ["reproduce"],
        "store get": ["store", "get", "runs/x"],
        "store export": ["store", "export", "runs/x"],
        "critic-study": ["critic-study", "--actor", "runs/x"],
    }
    assert set(argv) == {n for n, c in _commands().items() if _option(c, "--out")}
    for name, args in argv.items():
        code, _, err = run_cli(*args, "--out", str(afile))
        assert code == 1 and err.startswith("Error: ") and "a-file" in err, (name, err)
    assert afile.read_text() == "x"


def _is_json(text: str) -> bool:
    try:
        json.loads(text)
    except ValueError:
        return False
    return True


@pytest.mark.parametrize(
    "argv",
    [
        ["robots", "ls"],
        ["robots", "show", "go2"],
        ["distance", "--robots", "go1"],
        ["store", "ls"],
        ["store", "show", "runs/x"],
        ["store", "show", "runs/x", "--history"],
        ["store", "gc"],
    ],
)
def test_format_table_prints_no_json(argv):
    store = Store(os.environ["MORFIC_STORE"])
    store.set_ref("runs/x", store.put_manifest("checkpoint", config={"a": {"b": 1}}, files={"model.pt": b"w"}))
    result = runner.invoke(app, [*argv, "--format", "table"])
    assert result.exit_code == 0, result.output
    out = result.stdout.strip()
    assert not _is_json(out) and not out.startswith(("{", "[")), out[:200]
    result = runner.invoke(app, [*argv, "--format", "json"])
    assert result.exit_code == 0 and _is_json(result.stdout), argv


def test_an_object_as_a_table_is_a_key_value_table(capsys):
    from morfic_cli.cli._render import emit_object

    emit_object(
        {
            "ref": "runs/x@1",
            "files": {"model.pt": 3},
            "inputs": ["history", "morphology"],
            "hint": "pip install 'morfic[gpu]'",
        },
        OutputFormat.table,
    )
    out = capsys.readouterr().out
    assert not _is_json(out.strip()) and "files.model.pt" in out and "history, morphology" in out
    assert "morfic[gpu]" in out  # rich markup does not eat the brackets


def test_help_reads_well(monkeypatch):
    monkeypatch.setenv("COLUMNS", "250")  # wide: every line break left is one the help text itself makes
    out = runner.invoke(app, ["train", "--help"]).stdout
    assert "pip install 'morfic[gpu]'" in out and "pip install 'morfic[wandb]'" in out  # markup keeps [..]
    assert "Ctrl-C finishes the current iteration, writes a checkpoint" in out  # not hard-wrapped mid-sentence
    quiet = next(line for line in out.splitlines() if "--quiet" in line)
    assert "<bool>" not in quiet and "No progress" in quiet  # a flag looks like a flag
    out = runner.invoke(app, ["eval", "--help"]).stdout
    assert "[default: 500]" in out


def test_a_flag_at_the_start_of_a_source_line_continues_the_sentence(monkeypatch):
    from morfic_cli.cli import unwrap_help

    assert (
        unwrap_help("Intro.\n\n  Runs are grouped;\n  --with-paper adds [x].\n  - an item\n  Example: morfic a\n")
        == "Intro.\n\nRuns are grouped; --with-paper adds \\[x].\n- an item\nExample: morfic a"
    )
    monkeypatch.setenv("COLUMNS", "250")
    out = runner.invoke(app, ["compare-baselines", "--help"]).stdout
    assert "aggregated over seeds, plus training compute. --with-paper adds" in out
    out = runner.invoke(app, ["bench", "--help"]).stdout
    assert "or the GPU; bench train --device cuda trains as" in out
    assert "Example: morfic bench train --preset cpu --iterations 5" in [line.strip() for line in out.splitlines()]
