"""The CLI skeleton: subcommands, central error handling, and a light start-up."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

SUBCOMMANDS = [
    "train",
    "eval",
    "play",
    "diagnose",
    "compare-baselines",
    "distance",
    "export",
    "report",
    "reproduce",
    "store",
    "robots",
    "bench",
]


def test_help_lists_all_eleven_subcommands(run_cli):
    code, out, _ = run_cli("--help")
    assert code == 0
    for name in SUBCOMMANDS:
        assert name in out, name


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_every_subcommand_has_help_with_an_example(run_cli, name):
    code, out, _ = run_cli(name, "--help")
    assert code == 0
    assert "Example" in out or name in ("store", "robots")


@pytest.mark.parametrize(
    "argv",
    [
        ["compare-baselines", "runs/film-s0"],
        ["report"],
        ["reproduce", "--variants", "nope"],
    ],
)
def test_report_commands_on_an_empty_store_are_error_lines(run_cli, argv):
    code, out, err = run_cli(*argv)
    assert code == 1
    assert err.startswith("Error: ")
    assert "not implemented" not in err
    assert out == ""
    assert "Traceback" not in err


def test_usage_errors_are_error_lines_with_exit_1(run_cli):
    code, out, err = run_cli("distance", "--no-such-option")
    assert code == 1
    assert err.startswith("Error: ")
    assert "--help" in err


def test_debug_env_reraises_with_traceback(monkeypatch):
    from morfic_cli.cli import main
    from morfic_cli.errors import MorficError

    monkeypatch.setenv("MORFIC_DEBUG", "1")
    with pytest.raises(MorficError, match="no training runs"):
        main(["report"])


def test_version(run_cli):
    from morfic_cli import __version__

    code, out, _ = run_cli("--version")
    assert code == 0 and out.strip() == f"morfic {__version__}"


def test_help_does_not_import_torch_or_mujoco():
    code = (
        "import sys\n"
        "from morfic_cli.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = sorted(m for m in ('torch', 'mujoco', 'pandas', 'matplotlib') if m in sys.modules)\n"
        "print('HEAVY=' + ','.join(heavy))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    heavy = proc.stdout.strip().splitlines()[-1].removeprefix("HEAVY=")
    assert heavy == ""


def test_console_script_entry_point_runs():
    proc = subprocess.run(
        [sys.executable, "-m", "morfic_cli", "robots", "ls", "--format", "json"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    from morfic_cli.morphology.robots import list_robots

    assert [r["robot"] for r in json.loads(proc.stdout)] == list_robots()


def test_docs_cli_md_documents_every_registered_command():
    from pathlib import Path

    from morfic_cli.cli import app

    registered = [c.name for c in app.registered_commands] + [g.name for g in app.registered_groups]
    assert set(SUBCOMMANDS) <= set(registered)
    text = (Path(__file__).resolve().parents[2] / "docs" / "cli.md").read_text()
    for name in registered:  # a new command needs its section in docs/cli.md
        assert f"## `morfic {name}" in text, name
