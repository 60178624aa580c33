r"""Regenerate docs/cli.md, the command reference, from the code's help text.

    python scripts/gen_cli_docs.py          # rewrite docs/cli.md
    python scripts/gen_cli_docs.py --check  # exit 1 if docs/cli.md is not what the code's help gives

The hand-written header of docs/cli.md (everything before the line starting ``## `morfic```) is kept. The
reference after it is typer's own ``typer morfic_cli.cli utils docs --name morfic``, cleaned:

- HTML entities unescaped (typer exports rich text through HTML: ``&#x27;`` -> ``'``, ``&lt;`` -> ``<``);
- rich's markup escapes removed (``morfic\\\[gpu]`` -> ``morfic[gpu]``, ``\[default: 500]`` -> ``[default: 500]``);
- every heading one level down (``# `morfic``` -> ``## `morfic```: the page has its own title);
- a line break inside the help's prose (``Example:`` lines) becomes a paragraph break (Markdown would join them);
- each command list names a command by the first paragraph of its help, whole (typer cuts it at 45 characters:
  ``Train a policy with one...``), as ``morfic --help`` does.

Takes about a second (it imports the CLI, not torch). tests/docs/test_cli_docs.py checks the result.
"""

from __future__ import annotations

import argparse
import html
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI_MD = ROOT / "docs" / "cli.md"
#: The first line of the generated part; the header is everything before it.
START = "## `morfic`"

_ESCAPE = re.compile(r"\\+(?=\[)")  # rich escapes a markup-looking '[' with backslashes (doubled by the export)
_HEADING = re.compile(r"^(#+) (`morfic[^`]*`)$")
_COMMAND_ITEM = re.compile(r"^\* `([^`]+)`: .*$")


def typer_docs() -> str:
    """The raw Markdown of ``typer morfic_cli.cli utils docs --name morfic`` (run in a subprocess)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cli.md"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "typer",
                "morfic_cli.cli",
                "utils",
                "docs",
                "--name",
                "morfic",
                "--output",
                str(out),
            ],
            check=True,
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
        )
        return out.read_text(encoding="utf-8")


def summaries() -> dict[str, str]:
    """Full command name (``morfic store get``) -> the first paragraph of its help, on one line, unescaped."""
    import typer

    from morfic_cli.cli import app

    found: dict[str, str] = {}

    def walk(cmd, name: str) -> None:  # noqa: ANN001
        first = (cmd.help or "").split("\n\n")[0]
        found[name] = _ESCAPE.sub("", " ".join(first.split()))
        for sub_name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, f"{name} {sub_name}")

    walk(typer.main.get_command(app), "morfic")
    return found


def clean(raw: str, short: dict[str, str]) -> str:
    """Typer's Markdown made readable (see the module docstring); ``short``: :func:`summaries`."""
    lines = []
    group = ""  # the command whose section we are in
    fenced = False
    for line in html.unescape(raw).splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced:
            line = _ESCAPE.sub("", line)
            heading = _HEADING.match(line)
            if heading:
                group = heading.group(2).strip("`")
                line = "#" + line
            item = _COMMAND_ITEM.match(line)
            if item and f"{group} {item.group(1)}" in short:
                line = f"* `{item.group(1)}`: {short[f'{group} {item.group(1)}']}"
            if (
                line
                and lines
                and lines[-1]
                and not line.startswith(("* ", "```"))
                and not lines[-1].startswith(("* ", "```"))
            ):
                lines.append("")  # a line break of the help (Example: lines) is a paragraph in Markdown
        lines.append(line)
    return "\n".join(lines).strip() + "\n"


def render(current: str) -> str:
    """docs/cli.md as it should be: the header of ``current`` followed by the cleaned reference."""
    header, found, _ = current.partition("\n" + START + "\n")
    if not found:
        raise SystemExit(f"{CLI_MD} has no line '{START}': the generated part must start there.")
    return header + "\n" + clean(typer_docs(), summaries())


def main(argv: list[str] | None = None) -> int:
    """Rewrite docs/cli.md, or with ``--check`` only compare (exit status 1 if it is out of date)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check that docs/cli.md is current")
    args = parser.parse_args(argv)
    current = CLI_MD.read_text(encoding="utf-8")
    wanted = render(current)
    if args.check:
        if wanted != current:
            print(f"{CLI_MD} is out of date; run `python scripts/gen_cli_docs.py`.", file=sys.stderr)
            return 1
        return 0
    CLI_MD.write_text(wanted, encoding="utf-8")
    print(f"wrote {CLI_MD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
