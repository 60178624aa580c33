"""Shared fixtures: every test gets its own store directory and never touches ./artifacts."""

from __future__ import annotations

import subprocess
import sys

import pytest
from gl_probe import PROBE, probe_env


@pytest.fixture(scope="session", autouse=True)
def _isolated_config(tmp_path_factory):
    """The user's config folder (the allow-list of trusted variants, `morfic trust`) is a temporary one, for module
    fixtures too; each test then gets its own (below)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.mktemp("config")))
        yield


@pytest.fixture(autouse=True)
def _isolated_store(tmp_path, monkeypatch):
    monkeypatch.setenv("MORFIC_STORE", str(tmp_path / "store"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # the allow-list of trusted variants
    monkeypatch.setenv("MORFIC_LOG_DIR", str(tmp_path / "logs"))  # `morfic train`'s TensorBoard run folders
    monkeypatch.delenv("MORFIC_DEBUG", raising=False)
    from morfic_cli.rl.variants import consent_scope

    with consent_scope():  # consent to a user variant given in one test never reaches the next
        yield


@pytest.fixture(scope="session")
def smoke_runs(tmp_path_factory):
    """The session's smoke-trained stores: ``smoke_runs.store(root, *calls)`` copies one to ``root``, trained once
    per session for each distinct list of ``train_smoke_runs`` calls (tests/smoke_runs.py)."""
    from smoke_runs import SmokeRuns

    return SmokeRuns(tmp_path_factory.mktemp("smoke-templates"))


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


@pytest.fixture(scope="session")
def gl_backend():
    """The backend that renders here (probed in a subprocess: a GL failure can abort the process), else skip."""
    env = probe_env()
    proc = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300, check=False
    )
    if proc.returncode != 0:
        last = ((proc.stderr or proc.stdout).strip().splitlines() or ["(no output)"])[-1]
        pytest.skip(
            f"no working OpenGL backend for offscreen rendering (MUJOCO_GL={env.get('MUJOCO_GL', '')!r}): {last[:300]}"
        )
    backend = proc.stdout.strip().splitlines()[-1]
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MUJOCO_GL", backend)
        yield backend


@pytest.fixture
def one_torch_thread():
    """Torch on one thread for the test (tiny batches run faster than on threads contending for 2 cores)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
