"""Shared fixtures: every test gets its own store directory and never touches ./artifacts."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _isolated_store(tmp_path, monkeypatch):
    monkeypatch.setenv("MORFIC_STORE", str(tmp_path / "store"))
    monkeypatch.delenv("MORFIC_DEBUG", raising=False)


@pytest.fixture
def run_cli(capsys):
    """Run ``morfic`` in-process through ``main`` (the real error handling) -> (exit code, stdout, stderr)."""
    from morfic_cli.cli import main

    def _run(*args: str) -> tuple[int, str, str]:
        code = 0
        try:
            main(list(args))
        except SystemExit as exc:  # main exits non-zero through sys.exit
            code = exc.code if isinstance(exc.code, int) else 1
        out, err = capsys.readouterr()
        return code, out, err

    return _run
