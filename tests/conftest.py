"""Shared fixtures (every test gets its own store directory and never touches ./artifacts) and the settings of the
pytest-xdist workers that run the suite (pyproject.toml's addopts)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from gl_probe import PROBE, probe_env

#: Most workers pyproject.toml's `-n auto` starts: the suite is sized for 2 cores. PYTEST_XDIST_AUTO_NUM_WORKERS
#: (xdist's own variable) or an explicit `-n N` chooses another count; `-n 0` runs serially.
MAX_AUTO_WORKERS = 2

# Reports write report.tex without compiling report.pdf (5-10 s each on 2 cores): the one LaTeX test compiles.
os.environ.setdefault("MORFIC_NO_PDF", "1")

WORKER = os.environ.get("PYTEST_XDIST_WORKER")  # "gw0", "gw1", ... in a pytest-xdist worker, else None
if WORKER and "OMP_NUM_THREADS" not in os.environ:
    # One OpenMP (torch) thread per worker, set before torch is imported: 2 workers x 2 threads would contend for
    # 2 cores. Subprocesses inherit it. A test that wants more threads sets them itself.
    os.environ["OMP_NUM_THREADS"] = "1"


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config):
    """`-n auto`: one worker per core, at most ``MAX_AUTO_WORKERS`` (None: xdist reads its variable)."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return max(1, min(MAX_AUTO_WORKERS, cores))


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
    per session for each distinct list of ``train_smoke_runs`` calls (tests/smoke_runs.py).

    Under pytest-xdist the workers share the templates: they live beside the workers' own temporary folders (the
    session's folder, ``popen-gw0``'s parent), and the first worker that asks for one trains it under a lock.
    """
    from smoke_runs import SmokeRuns

    if WORKER:
        root = tmp_path_factory.getbasetemp().parent / "smoke-templates"
        root.mkdir(exist_ok=True)
        return SmokeRuns(root)
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


@pytest.fixture
def wide_tables(monkeypatch):
    """The CLI's tables printed 250 columns wide, whenever its console was made.

    rich reads COLUMNS as a console is made, and ``_render.out_console`` is made when the CLI is first imported:
    by another test of the same process (an xdist worker runs many files), not always by this one.
    """
    from rich.console import Console

    from morfic_cli.cli import _render

    monkeypatch.setenv("COLUMNS", "250")
    monkeypatch.setattr(_render, "out_console", Console(emoji=False, width=250))


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
