"""The code and the docs stand alone: every file they mention exists in this repository.

Scans ``morfic_cli/``, ``docs/``, ``examples/`` and the README for mentions of Markdown files and of paths under
the repository's own top-level folders, and for citations of design notes that live outside it (a spec by
section number, an anchors file, a ``reference/`` folder).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOP = ("morfic_cli", "docs", "tests", "examples", "robots", "artifacts", "scripts", ".ci")
PATH = re.compile(
    r"(?<![\w./-])((?:\.\./)*(?:"
    + "|".join(re.escape(t) for t in TOP)
    + r")/[\w./-]*[\w-]|[\w./-]*[\w-]\.md)(?![\w/-])"
)
WRITTEN = {"report.md"}
"""Files morfic writes (the report's Markdown), mentioned by their name or under an output folder."""
OUTSIDE = re.compile(r"\bSPEC(?:\.md| section| §)|\banchors\.md\b|\breference/|\bARCHITECTURE\.md\b")


def _sources() -> list[Path]:
    files = [ROOT / "README.md"]
    for folder, pattern in (("morfic_cli", "*.py"), ("docs", "*.md"), ("examples", "*.py")):
        files += sorted((ROOT / folder).rglob(pattern))
    return files


def _exists(mention: str, source: Path) -> bool:
    mention = mention.rstrip(".").split("#")[0].split("::")[0]
    if any((base / mention).exists() for base in (ROOT, source.parent)):
        return True
    # a pattern (docs/*.md, robots/NAME.toml, reports/<preset>/...), an example path (/tmp/...), or a file morfic
    # writes (report.md)
    placeholder = any(ch in mention for ch in "*<") or re.search(r"\b[A-Z]{3,}\b", mention) is not None
    return placeholder or mention.startswith("/") or Path(mention).name in WRITTEN


@pytest.mark.parametrize("source", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_mentioned_file_exists(source):
    text = source.read_text(encoding="utf-8")
    missing = sorted({m for m in PATH.findall(text) if not _exists(m, source)})
    assert not missing, f"{source.relative_to(ROOT)} mentions files that are not in the repository: {missing}"


@pytest.mark.parametrize("source", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_citation_of_notes_outside_the_repository(source):
    lines = [
        f"{i}: {line.strip()}"
        for i, line in enumerate(source.read_text(encoding="utf-8").splitlines(), 1)
        if OUTSIDE.search(line)
    ]
    assert not lines, f"{source.relative_to(ROOT)} cites design notes that are not in this repository: {lines}"
