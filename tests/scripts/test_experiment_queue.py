"""scripts/experiment_queue.sh refuses a run imported results-only before it touches anything, evaluates one
run at a time across queues (a lock), and ships every seed results-only beside its weights.

Such a run is finished in the store but has no weights: the queue used to skip its training and then fail in its
first eval, after the shell had already truncated ``docs/results/<run>-walk.json``. The script runs here from a
copy under a temporary directory (it works relative to its own folder), on a hand-made store.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import time
from pathlib import Path

from morfic_cli.store import Store

ROOT = Path(__file__).resolve().parents[2]


def _repo_with_queue(tmp_path: Path) -> Path:
    """A copy of scripts/experiment_queue.sh under tmp_path/repo (the script works relative to its own folder)."""
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "experiment_queue.sh", repo / "scripts")
    return repo


def _queue(repo: Path, env: dict[str, str], *items: str) -> subprocess.CompletedProcess:
    """``scripts/experiment_queue.sh ITEMS`` of ``repo`` run with ``env``, its output captured."""
    return subprocess.run(
        ["bash", str(repo / "scripts" / "experiment_queue.sh"), *items],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def _finished_run(store: Store, name: str) -> None:
    """runs/<name>: a finished checkpoint with weights and a curve, and evals/<name> of it."""
    ckpt = store.put_manifest(
        "checkpoint",
        config={"variant": "film"},
        meta={"finished": True},
        files={"model.pt": name.encode() * 1000, "curve.csv": f"it,{name}".encode()},
    )
    store.set_ref(f"runs/{name}", ckpt)
    store.set_ref(
        f"evals/{name}",
        store.put_manifest(
            "eval", config={"run": name}, inputs={"checkpoint": ckpt}, files={"eval.csv": f"robot\ngo2,{name}".encode()}
        ),
    )


def test_a_results_only_run_stops_the_queue_before_anything_is_written(tmp_path):
    src = Store(tmp_path / "src")
    _finished_run(src, "film-cpu-s1")
    _finished_run(src, "ppo-cpu-s2")
    dst = Store(tmp_path / "dst")
    dst.import_tar(src.export_tar(["runs/film-cpu-s1"], tmp_path / "r.tar", results_only=True).path)
    dst.import_tar(src.export_tar(["runs/ppo-cpu-s2"], tmp_path / "w.tar", latest=True).path, append=True)
    assert "model.pt" in dst.omitted_files(dst.read_manifest("runs/film-cpu-s1"))
    assert not dst.omitted_files(dst.read_manifest("runs/ppo-cpu-s2"))

    repo = _repo_with_queue(tmp_path)
    walk = repo / "docs" / "results" / "film-cpu-s1-walk.json"
    walk.parent.mkdir(parents=True)
    walk.write_text('{"kept": true}')
    env = {**os.environ, "MORFIC_STORE": str(dst.root)}
    # the run with weights first: every item is checked before the first is trained or evaluated
    got = _queue(repo, env, "ppo:2", "film:1")
    assert got.returncode == 1, got.stdout + got.stderr
    assert got.stderr.startswith("Error: runs/film-cpu-s1 ") and "results-only bundle" in got.stderr
    assert "artifacts/bundles/results/film-cpu-s1.tar" in got.stderr
    assert "evaluate" not in got.stdout and "train" not in got.stdout
    assert walk.read_text() == '{"kept": true}'
    assert sorted(p.name for p in walk.parent.iterdir()) == ["film-cpu-s1-walk.json"]


def test_a_second_queue_waits_for_the_evaluation_lock_before_it_evaluates(tmp_path):
    """Two queues side by side: one evaluates (holds the lock), the other waits, then goes on when it is released."""
    store = Store(tmp_path / "store")
    _finished_run(store, "ppo-cpu-s2")  # finished: the queue goes straight to its evaluation
    repo = _repo_with_queue(tmp_path)
    lock = tmp_path / "queue.lock"
    env = {**os.environ, "MORFIC_STORE": str(store.root), "MORFIC_QUEUE_LOCK": str(lock)}
    with lock.open("a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)  # the other queue's evaluation
        queue = subprocess.Popen(
            ["bash", str(repo / "scripts" / "experiment_queue.sh"), "ppo:2"],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        first = queue.stdout.readline()
        assert "ppo-cpu-s2 waits for another queue's evaluation" in first and str(lock) in first
        time.sleep(1.0)
        assert queue.poll() is None and not (repo / "docs" / "results" / "ppo-cpu-s2-walk.json.tmp").exists()
        fcntl.flock(held, fcntl.LOCK_UN)
        out, err = queue.communicate(timeout=120)
    # released: it evaluates (and fails there, on this hand-made checkpoint), leaving no temporary file
    assert "evaluate and diagnose ppo-cpu-s2" in out, out + err
    assert queue.returncode == 1 and not (repo / "docs" / "results" / "ppo-cpu-s2-walk.json.tmp").exists()


FAKE_MORFIC = r"""#!/usr/bin/env bash
# a stand-in for morfic: every call logged; a finished run with weights; exports write an empty tar
echo "$*" >> "$MORFIC_CALLS"
case "$1 $2" in
  "store show") echo '{"meta": {"finished": true}}' ;;
  "store export")
    out=""; prev=""
    for a in "$@"; do [ "$prev" = --out ] && out=$a; prev=$a; done
    mkdir -p "$out" && touch "$out/${3#runs/}.tar" ;;
  eval*) echo '{}' ;;
esac
"""


def _stubbed_morfic(tmp_path: Path, script: str) -> tuple[dict[str, str], Path]:
    """The queue's environment with ``script`` as ``morfic`` first on PATH; (env, the file its calls are logged to)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "morfic").write_text(script)
    (bin_dir / "morfic").chmod(0o755)
    calls = tmp_path / "calls.txt"
    env = {
        **os.environ,
        "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
        "MORFIC_CALLS": str(calls),
        "MORFIC_STORE": str(tmp_path / "store"),
        "MORFIC_QUEUE_LOCK": str(tmp_path / "queue.lock"),
    }
    return env, calls


def test_every_seed_ships_results_only_and_its_weights_where_they_belong(tmp_path):
    """Seed 0's weights go where `reproduce --preset shipped` imports them (artifacts/bundles/), other seeds' under
    weights/; every seed's results-only bundle under results/ (the queue's shipping step, morfic stubbed out)."""
    repo = _repo_with_queue(tmp_path)
    for stub in ("experiment_tables.py", "results_tables.py"):  # the tables' steps are not this test's
        (repo / "scripts" / stub).write_text("")
    env, calls = _stubbed_morfic(tmp_path, FAKE_MORFIC)
    got = _queue(repo, env, "film:0", "ppo:1")
    assert got.returncode == 0, got.stdout + got.stderr
    exports = [line for line in calls.read_text().splitlines() if line.startswith("store export")]
    assert exports == [
        "store export runs/film-cpu-s0 --results-only --out artifacts/bundles/results --force",
        "store export runs/film-cpu-s0 --latest --without-trainer-state --out artifacts/bundles --force",
        "store export runs/ppo-cpu-s1 --results-only --out artifacts/bundles/results --force",
        "store export runs/ppo-cpu-s1 --latest --without-trainer-state --out artifacts/bundles/weights --force",
    ]
    bundles = repo / "artifacts" / "bundles"
    assert sorted(str(p.relative_to(bundles)) for p in bundles.rglob("*.tar")) == [
        "film-cpu-s0.tar",
        "results/film-cpu-s0.tar",
        "results/ppo-cpu-s1.tar",
        "weights/ppo-cpu-s1.tar",
    ]
    assert (
        "done film-cpu-s0" in got.stdout
        and "artifacts/bundles/results/film-cpu-s0.tar and artifacts/bundles/film-cpu-s0.tar" in got.stdout
    )


def test_a_training_stopped_from_outside_is_exported_partial_and_not_evaluated(tmp_path):
    """Ctrl-C to the training (not the queue's --stop-at) checkpoints and exits 0: the run is still unfinished, so
    the queue exports it as a partial bundle and stops instead of evaluating and shipping it as a finished run."""
    repo = _repo_with_queue(tmp_path)
    unfinished = FAKE_MORFIC.replace('"finished": true', '"finished": false')  # train returns, the run stays unfinished
    env, calls = _stubbed_morfic(tmp_path, unfinished)
    env["MORFIC_QUEUE_POLL_S"] = "0.1"
    got = _queue(repo, env, "film-act:0", "ppo:1")
    assert got.returncode == 0, got.stdout + got.stderr
    lines = calls.read_text().splitlines()
    assert "train --resume runs/film-act-cpu-s0 -q" in lines
    assert [line for line in lines if line.startswith(("store export", "eval"))] == [
        "store export runs/film-act-cpu-s0 --latest --out artifacts/bundles/partial --force"
    ]
    assert "film-act-cpu-s0 stopped before its last iteration" in got.stdout and "ppo-cpu-s1" not in got.stdout
