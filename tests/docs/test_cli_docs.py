"""docs/cli.md reads as plain Markdown, covers every command, and is what scripts/gen_cli_docs.py makes of the help."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import typer

from morfic_cli.cli import app

ROOT = Path(__file__).resolve().parents[2]
CLI_MD = ROOT / "docs" / "cli.md"


def _gen():
    spec = importlib.util.spec_from_file_location("gen_cli_docs", ROOT / "scripts" / "gen_cli_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _command_names() -> list[str]:
    names: list[str] = []

    def walk(cmd, name: str) -> None:
        names.append(name)
        for sub_name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, f"{name} {sub_name}")

    walk(typer.main.get_command(app), "morfic")
    return names


def test_cli_md_has_no_markup_escapes_or_html_entities():
    text = CLI_MD.read_text(encoding="utf-8")
    assert "\\[" not in text and "\\]" not in text
    assert not re.search(r"&(#x?[0-9a-fA-F]+|[a-z]+);", text)
    assert "pip install 'morfic[gpu]'" in text and "pip install 'morfic[wandb]'" in text
    assert "Train a policy with one critic-conditioning variant; checkpoints go to ref runs/NAME." in text  # not cut


def test_cli_md_has_a_section_for_every_command():
    text = CLI_MD.read_text(encoding="utf-8")
    headings = re.findall(r"^(#+) `(morfic[^`]*)`$", text, flags=re.M)
    names = _command_names()
    assert {"morfic train", "morfic store export", "morfic robots show"} <= set(names)
    assert [name for _, name in headings] == names
    assert all(len(hashes) == name.count(" ") + 2 for hashes, name in headings)  # `morfic` is ##, under the title


def test_clean_unescapes_and_shifts_headings():
    gen = _gen()
    raw = (
        "# `morfic`\n\n**Commands**:\n\n* `train`: Train a policy with one...\n* `--help`: Show this.\n\n"
        "## `morfic train`\n\n* `--logger <x>`: wandb (pip install &#x27;morfic\\\\\\[wandb]&#x27;) "
        "\\[default: 500].  [default: tensorboard]\n\nExample: a\nExample: b\n\n```console\n$ morfic train\n```\n"
    )
    assert gen.clean(raw, {"morfic train": "Train a policy with one variant."}) == (
        "## `morfic`\n\n**Commands**:\n\n* `train`: Train a policy with one variant.\n* `--help`: Show this.\n\n"
        "### `morfic train`\n\n* `--logger <x>`: wandb (pip install 'morfic[wandb]') [default: 500].  "
        "[default: tensorboard]\n\nExample: a\n\nExample: b\n\n```console\n$ morfic train\n```\n"
    )


def test_cli_md_is_current():
    """About a second (typer's docs in a subprocess); after a help text change: python scripts/gen_cli_docs.py."""
    current = CLI_MD.read_text(encoding="utf-8")
    assert _gen().render(current) == current, "docs/cli.md is out of date: run `python scripts/gen_cli_docs.py`"
