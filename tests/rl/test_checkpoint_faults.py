"""Faults around checkpoints, with real processes (issue 36, item 4).

- ``kill -9`` of ``morfic train`` at chosen moments (default run) and at 24 moments drawn with a seeded RNG (``slow``):
  ``morfic train --resume`` always works, or, killed before the first checkpoint, is a clean ``Error:`` that says to
  start afresh and a fresh start works; ``store verify`` passes, no lock stays held (the kernel drops a dead process's
  ``flock``; what a lock file holds is never read), every ref version written before the kill is kept, and the resumed
  run finishes (``slow``: with the weights of an uninterrupted run, bit for bit).
- Two trainings into one run at once: the second to checkpoint stops with ``Error:``, the ref's history is the
  winner's alone (a linear chain of checkpoints), the store verifies.
- ``store gc`` during an import and during a training: nothing reachable is lost; a gc that cannot get the store lock
  in time, or a checkpoint that waits for a gc too long, fails with ``Error: timed out ...`` (``MORFIC_LOCK_TIMEOUT``).
- An import killed mid-way leaves only its staging folder in ``tmp/``, which ``gc --yes`` removes.

Every trainer runs in its own process (``python -m morfic_cli``) on a store under ``tmp_path``.
"""

from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import subprocess
import sys
import tarfile
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from morfic_cli.store import Store

BUNDLES = Path(__file__).resolve().parents[2] / "artifacts" / "bundles"
NAME = "k"
REF = f"runs/{NAME}"


# ------------------------------------------------------------------------------------------------ process helpers
def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MORFIC_DEBUG", "MORFIC_LOCK_TIMEOUT")}
    env.update(
        MORFIC_STORE=str(tmp_path / "store"),
        MORFIC_LOG_DIR=str(tmp_path / "logs"),
        OMP_NUM_THREADS="1",
        PYTHONUNBUFFERED="1",
        **extra,
    )
    return env


def _morfic(tmp_path: Path, *args: str, timeout: float = 300, **extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "morfic_cli", *args],
        env=_env(tmp_path, **extra),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def _spawn(tmp_path: Path, tag: str, *args: str, **extra: str) -> subprocess.Popen:
    """``morfic ARGS`` in the background, stdout and stderr to files (read by :func:`_finish`)."""
    out = open(tmp_path / f"{tag}.out", "w")  # noqa: SIM115 -- closed by _finish
    err = open(tmp_path / f"{tag}.err", "w")  # noqa: SIM115
    proc = subprocess.Popen(
        [sys.executable, "-m", "morfic_cli", *args], env=_env(tmp_path, **extra), stdout=out, stderr=err, text=True
    )
    proc.files = (out, err)  # type: ignore[attr-defined]
    proc.tag = tag  # type: ignore[attr-defined]
    return proc


def _finish(tmp_path: Path, proc: subprocess.Popen, timeout: float = 300) -> subprocess.CompletedProcess:
    proc.wait(timeout=timeout)
    for fh in proc.files:  # type: ignore[attr-defined]
        fh.close()
    tag = proc.tag  # type: ignore[attr-defined]
    return subprocess.CompletedProcess(
        proc.args, proc.returncode, (tmp_path / f"{tag}.out").read_text(), (tmp_path / f"{tag}.err").read_text()
    )


def _train_args(iterations: int, name: str = NAME) -> list[str]:
    return [
        "train",
        "--preset",
        "smoke",
        "--name",
        name,
        "--set",
        f"max_iterations={iterations}",
        "--set",
        "save_interval=1",
        "-q",
        "-f",
        "json",
    ]  # a checkpoint every iteration: kills land between them


def _ok(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr


def _clean_error(proc: subprocess.CompletedProcess, *needles: str) -> None:
    """Exit 1 with one ``Error: ...`` message on stderr, no traceback, and every needle in it."""
    assert proc.returncode == 1, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("Error: ") or "\nError: " in proc.stderr, proc.stderr
    message = " ".join(proc.stderr.split())  # the error printer wraps long lines
    for needle in needles:
        assert needle in message, (needle, proc.stderr)


def _verified(tmp_path: Path) -> None:
    """``morfic store verify`` passes (exit 0, no problem line)."""
    _ok(_morfic(tmp_path, "store", "verify", MORFIC_LOCK_TIMEOUT="30"))


def _count(folder: Path) -> int:
    try:
        return len(os.listdir(folder))
    except FileNotFoundError:
        return 0


def _locks_free(root: Path) -> bool:
    """Whether both store locks can be taken exclusively at once: no live process holds either."""
    for name in ("store.lock", "refs.lock"):
        path = root / "locks" / name
        if not path.exists():
            continue
        fd = os.open(path, os.O_RDWR)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        finally:
            os.close(fd)  # releases it
    return True


def _scribble_on_locks(root: Path) -> None:
    """Fill the lock files with stale-looking content: a lock is the kernel's flock, never what the file holds."""
    for name in ("store.lock", "refs.lock"):
        path = root / "locks" / name
        if path.exists():
            path.write_bytes(b"pid 99999 holds this lock since 1970\n" * 10)


def _history(root: Path) -> list[tuple[int, str]]:
    store = Store(root)
    return [(e.version, e.id) for e in store.ref_history(REF)] if store.has_ref(REF) else []


def _assert_linear(root: Path, iterations: int, name: str = NAME) -> list:
    """The run's history: checkpoints of iterations 1..N of one training, each the parent of the next."""
    store = Store(root)
    history = store.ref_history(f"runs/{name}")
    metas = [store.read_manifest(e.id).meta for e in history]
    assert [m["iteration"] for m in metas] == list(range(1, iterations + 1)), [m["iteration"] for m in metas]
    assert metas[0]["parent"] is None
    assert [m["parent"] for m in metas[1:]] == [e.id for e in history[:-1]]
    assert {m["run"] for m in metas} == {name} and metas[-1]["finished"]
    return history


# ------------------------------------------------------------------------------------------------ kill -9 trials
@dataclass
class Tally:
    """What the kill trials found (printed by the slow test, asserted by every test)."""

    trials: int = 0
    killed: int = 0
    finished_first: int = 0
    before_first_checkpoint: int = 0
    mid_checkpoint: int = 0
    between_checkpoints: int = 0
    resumed: int = 0
    restarted: int = 0
    gc_runs: int = 0
    verify_failures: int = 0
    stale_locks: int = 0
    versions_lost: int = 0
    bit_exact: int = 0
    notes: list[str] = field(default_factory=list)


def _wait_and_kill(tmp_path: Path, proc: subprocess.Popen, trigger: tuple[str, float]) -> bool:
    """SIGKILL ``proc`` at ``trigger``; return whether it was still running then.

    ``("after", s)``: s seconds after the start. ``("logdir", 0)``: as soon as its TensorBoard folder exists (the
    training loop has begun; the first checkpoint comes one iteration later). ``("manifests", m)``: as soon as the store
    indexes at least m manifests (a checkpoint is two: trainer state, then weights; odd m = inside checkpoint
    (m + 1) / 2). ``("tmp", s)``: the first moment after s seconds that ``tmp/`` holds a file (a write in flight).
    """
    kind, value = trigger
    root = tmp_path / "store"
    start = time.monotonic()
    while proc.poll() is None:
        now = time.monotonic() - start
        if kind == "after":
            hit = now >= value
        elif kind == "logdir":
            hit = (tmp_path / "logs" / NAME).is_dir()
        elif kind == "manifests":
            hit = _count(root / "manifests") >= value
        else:
            hit = now >= value and _count(root / "tmp") > 0
        if hit:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.0005 if kind in ("tmp", "manifests") else 0.002)
    proc.wait(timeout=120)
    return proc.returncode == -signal.SIGKILL


def _kill_trial(
    tmp_path: Path,
    iterations: int,
    trigger: tuple[str, float],
    tally: Tally,
    *,
    gc: bool,
    reference: bytes | None = None,
) -> None:
    """One trial: train, kill -9 at ``trigger``, check the store, resume (or restart), check again."""
    import shutil

    for path in (tmp_path / "store", tmp_path / "logs"):
        shutil.rmtree(path, ignore_errors=True)
    root = tmp_path / "store"
    tally.trials += 1
    proc = _spawn(tmp_path, "victim", *_train_args(iterations))
    killed = _wait_and_kill(tmp_path, proc, trigger)
    done = _finish(tmp_path, proc)
    if not killed:  # it finished before the moment came: a plain run
        _ok(done)
        tally.finished_first += 1
    else:
        tally.killed += 1
    kept = _history(root)
    store = Store(root)
    named = {e for _, e in kept}
    unnamed = [oid for oid in store.index.ids() if oid not in named]
    trainer_states = {store.read_manifest(oid).inputs.get("trainer_state") for oid in named}
    if killed:
        if not kept:
            tally.before_first_checkpoint += 1
        elif set(unnamed) - trainer_states or _count(root / "tmp"):
            tally.mid_checkpoint += 1  # a checkpoint's manifests or a temp file without the ref update
        else:
            tally.between_checkpoints += 1
    if not _locks_free(root):
        tally.stale_locks += 1
    assert _locks_free(root), "a killed process left a lock held"
    _scribble_on_locks(root)
    verify = _morfic(tmp_path, "store", "verify", MORFIC_LOCK_TIMEOUT="30")
    tally.verify_failures += verify.returncode != 0
    _ok(verify)
    if gc:  # a gc between the kill and the resume keeps everything the ref reaches
        _ok(_morfic(tmp_path, "store", "gc", "--yes", MORFIC_LOCK_TIMEOUT="30"))
        tally.gc_runs += 1
        assert _count(root / "tmp") == 0
    resume = _morfic(tmp_path, "train", "--resume", REF, "-q", "-f", "json", MORFIC_LOCK_TIMEOUT="30")
    if kept:
        _ok(resume)
        if Store(root).read_manifest(kept[-1][1]).meta["finished"]:  # killed after its last checkpoint
            assert "nothing to do" in resume.stderr, resume.stderr
        else:
            assert json.loads(resume.stdout)["iteration"] == iterations
        tally.resumed += 1
    else:
        _clean_error(
            resume,
            f"no artifact '{REF}'",
            "killed before its first checkpoint",
            f"start it afresh with `morfic train --name {NAME}`",
        )
        _ok(_morfic(tmp_path, *_train_args(iterations), MORFIC_LOCK_TIMEOUT="30"))
        tally.restarted += 1
    after = _history(root)
    lost = [entry for entry in kept if entry not in after]
    tally.versions_lost += len(lost)
    assert after[: len(kept)] == kept, "a version written before the kill is gone"
    _assert_linear(root, iterations)
    if reference is not None:
        same = Store(root).read_file(REF, "model.pt") == reference
        tally.bit_exact += same
        if not same:
            tally.notes.append(f"{trigger}: weights differ from the uninterrupted run")
    _verified(tmp_path)


def test_kill_9_at_fixed_moments_then_resume_or_restart(tmp_path):
    """Before the first checkpoint, and inside the second (its trainer state written, its weights not yet)."""
    tally = Tally()
    for n, trigger in enumerate([("logdir", 0), ("manifests", 3)]):
        _kill_trial(tmp_path, 3, trigger, tally, gc=n == 1)
    assert tally.killed == 2 and tally.before_first_checkpoint == 1, tally
    assert tally.resumed == 1 and tally.restarted == 1, tally
    assert (tally.verify_failures, tally.stale_locks, tally.versions_lost) == (0, 0, 0)


@pytest.mark.slow
def test_kill_9_at_24_random_moments(tmp_path):
    """24 kills over a 6-iteration run: uniform in time, at a drawn manifest count, or at a write in flight.

    The times are drawn (seed 36) over the measured duration of an uninterrupted run of the same config, whose final
    weights every resumed run must match bit for bit (CPU resume is exact).
    """
    iterations = 6
    start = time.monotonic()
    _ok(_morfic(tmp_path, *_train_args(iterations)))
    duration = time.monotonic() - start
    reference = Store(tmp_path / "store").read_file(REF, "model.pt")
    rng = random.Random(36)
    tally = Tally()
    for trial in range(24):
        kind = ("after", "manifests", "tmp")[trial % 3]
        if kind == "manifests":
            trigger = ("manifests", float(rng.randint(1, 2 * iterations - 1)))
        else:
            trigger = (kind, rng.uniform(0.0, duration))
        _kill_trial(tmp_path, iterations, trigger, tally, gc=trial % 2 == 1, reference=reference)
    total = time.monotonic() - start
    print(f"\nkill -9 trials over a {duration:.1f} s run: {tally} in {total:.0f} s")
    assert tally.trials == 24 and tally.killed >= 1
    assert tally.resumed + tally.restarted == tally.trials
    assert (tally.verify_failures, tally.stale_locks, tally.versions_lost) == (0, 0, 0)
    assert tally.bit_exact == tally.trials, tally.notes


# ------------------------------------------------------------------------------------------------ concurrent trainings
def test_two_trainings_into_one_run_at_once(tmp_path):
    """Both start before either has a checkpoint: the second to checkpoint stops; the history is the winner's."""
    a = _spawn(tmp_path, "a", *_train_args(3))
    b = _spawn(tmp_path, "b", *_train_args(3))
    results = [_finish(tmp_path, a), _finish(tmp_path, b)]
    assert sorted(r.returncode for r in results) == [0, 1], [r.stderr for r in results]
    winner = next(r for r in results if r.returncode == 0)
    loser = next(r for r in results if r.returncode == 1)
    _ok(winner)
    if "already exists" not in loser.stderr:  # it got past the start check: it lost at its first checkpoint
        _clean_error(
            loser,
            f"run '{REF}' was created by another process",
            "two trainings cannot write one run",
            "without recording its checkpoint at iteration 1",
            "Give each training its own --name",
        )
    else:
        _clean_error(loser, f"run '{REF}' already exists")
    history = _assert_linear(tmp_path / "store", 3)
    assert json.loads(winner.stdout)["id"] == history[-1].id
    _verified(tmp_path)
    gc = _morfic(tmp_path, "store", "gc", "--yes", "-f", "json")  # the loser's unnamed checkpoint goes
    _ok(gc)
    assert _history(tmp_path / "store") == [(e.version, e.id) for e in history]
    _verified(tmp_path)


@pytest.mark.slow
def test_a_resume_while_the_run_still_trains(tmp_path):
    """`--resume runs/NAME` while its training goes on: one of the two stops; the history stays one chain."""
    a = _spawn(tmp_path, "a", *_train_args(10))
    while _count(tmp_path / "store" / "manifests") < 4 and a.poll() is None:
        time.sleep(0.005)
    b = _spawn(tmp_path, "b", "train", "--resume", REF, "-q", "-f", "json")
    results = [_finish(tmp_path, a), _finish(tmp_path, b)]
    losers = [r for r in results if r.returncode != 0]
    assert len(losers) <= 1, [r.stderr for r in results]
    for loser in losers:
        _clean_error(loser, f"run '{REF}' was advanced by another process", "two trainings cannot write one run")
    if losers:
        _ok(next(r for r in results if r.returncode == 0))
    else:  # the resume found the run finished (nothing to do) or started after its end
        assert "nothing to do" in results[1].stderr or json.loads(results[1].stdout)["iteration"] == 10
    _assert_linear(tmp_path / "store", 10)
    _verified(tmp_path)


# ------------------------------------------------------------------------------------------------ gc vs writers
_HOLD = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from morfic_cli.store import Store
    from morfic_cli.store.lock import file_lock

    root, mode, ready, go = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3]), Path(sys.argv[4])

    def wait():
        ready.touch()
        deadline = time.monotonic() + 120
        while not go.exists() and time.monotonic() < deadline:
            time.sleep(0.01)

    store = Store(root)
    if mode == "gc":  # what gc holds while it runs: the store lock, exclusive
        store.put_bytes(b"layout")
        with file_lock(root / "locks" / "store.lock", exclusive=True):
            wait()
    else:  # a writer between "put the manifest" and "set the ref"
        with store.writing():
            mid = store.put_manifest("table", files={"t.csv": b"a,b\\n1,2\\n"})
            wait()
            store.set_ref("tables/held", mid)
    """
)


def _hold(tmp_path: Path, mode: str) -> tuple[subprocess.Popen, Path]:
    ready, go = tmp_path / f"{mode}.ready", tmp_path / f"{mode}.go"
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(tmp_path / "store"), mode, str(ready), str(go)],
        env=_env(tmp_path),
        stderr=subprocess.PIPE,
        text=True,
    )
    while not ready.exists():
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.01)
    return proc, go


def test_gc_waits_for_a_writer_and_times_out_cleanly(tmp_path):
    """A writer holds the store lock shared mid-write: gc fails with the timeout error, deleting nothing; then runs."""
    writer, go = _hold(tmp_path, "writer")
    store = Store(tmp_path / "store")
    [pending] = list(store.index.ids())  # put, not yet named by a ref: what gc would delete
    gc = _morfic(tmp_path, "store", "gc", "--yes", MORFIC_LOCK_TIMEOUT="1")
    _clean_error(
        gc,
        "timed out after 1 s waiting for the exclusive lock",
        "locks/store.lock",
        "another morfic process is using the store (a writer",
        "MORFIC_LOCK_TIMEOUT=SECONDS",
    )
    assert store.has(pending) and store.read_manifest(pending).kind == "table"
    waiting = _spawn(tmp_path, "gc", "store", "gc", "--yes", MORFIC_LOCK_TIMEOUT="120")
    time.sleep(0.5)  # (gc is most likely waiting now; either order must keep the write)
    go.touch()
    assert writer.wait(timeout=60) == 0, writer.stderr.read() if writer.stderr else ""
    _ok(_finish(tmp_path, waiting))
    assert store.resolve("tables/held") == pending
    assert store.read_file("tables/held", "t.csv") == b"a,b\n1,2\n"
    _verified(tmp_path)


def test_a_bad_lock_timeout_is_an_error(tmp_path):
    _clean_error(
        _morfic(tmp_path, "store", "verify", MORFIC_LOCK_TIMEOUT="soon"),
        "MORFIC_LOCK_TIMEOUT='soon' is not a number of seconds",
    )


def test_a_checkpoint_that_waits_for_gc_too_long_stops_the_training_cleanly(tmp_path):
    """gc holds the store lock when the first checkpoint is due: the training stops with the timeout error, says to
    start afresh (it had no checkpoint), and a fresh start works once gc is done."""
    holder, go = _hold(tmp_path, "gc")
    train = _morfic(tmp_path, *_train_args(2), MORFIC_LOCK_TIMEOUT="2")
    _clean_error(
        train,
        "timed out after 2 s waiting for the shared lock",
        "locks/store.lock",
        "`morfic store gc`",
        "This training stopped at iteration 1 without writing that checkpoint",
        f"it has no checkpoint yet: start it again with `morfic train --name {NAME}`",
    )
    assert _history(tmp_path / "store") == []
    go.touch()
    assert holder.wait(timeout=60) == 0
    _clean_error(_morfic(tmp_path, "train", "--resume", REF), "killed before its first checkpoint")
    _ok(_morfic(tmp_path, *_train_args(2)))
    _assert_linear(tmp_path / "store", 2)
    _verified(tmp_path)


def test_gc_in_a_loop_during_a_training_loses_nothing(tmp_path):
    """gc --yes over and over while a training checkpoints: every version stays whole and resumable."""
    from morfic_cli.rl.resume import load_resume_point

    train = _spawn(tmp_path, "train", *_train_args(3))
    gcs = []
    while train.poll() is None:
        if (tmp_path / "store" / "locks").is_dir():
            gcs.append(_morfic(tmp_path, "store", "gc", "--yes"))
        else:
            time.sleep(0.01)
    _ok(_finish(tmp_path, train))
    for gc in gcs:
        _ok(gc)
    history = _assert_linear(tmp_path / "store", 3)
    store = Store(tmp_path / "store")
    for entry in history:  # each version: weights, curve and trainer state are there and load
        point = load_resume_point(store, f"{REF}@{entry.version}")
        assert point.trainer["iteration"] == store.read_manifest(entry.id).meta["iteration"]
    _verified(tmp_path)
    print(f"\n{len(gcs)} gc run(s) during the training")


def _tar_contents(tar_path: Path) -> tuple[set[str], dict[str, bytes]]:
    """The object ids and the ref histories (name -> bytes) a bundle holds."""
    objects, refs = set(), {}
    with tarfile.open(tar_path) as tar:
        for member in tar.getmembers():
            if member.name.startswith("objects/"):
                objects.add(member.name.replace("objects/", "").replace("/", ""))
            elif member.name.startswith("refs/"):
                refs[member.name.removeprefix("refs/")] = tar.extractfile(member).read()  # type: ignore[union-attr]
    return objects, refs


def test_gc_in_a_loop_during_an_import_loses_nothing(tmp_path):
    """gc --yes over and over while three shipped bundles are imported: all of each bundle is there, refs whole."""
    tars = [BUNDLES / f"{v}-cpu-s0.tar" for v in ("film", "ppo", "hyper")]
    importer = _spawn(tmp_path, "import", "store", "import", *map(str, tars))
    gcs, during = [], 0
    while importer.poll() is None:
        staging = (
            [n for n in os.listdir(tmp_path / "store" / "tmp") if n.startswith("import-")]
            if (tmp_path / "store" / "tmp").is_dir()
            else []
        )
        if (tmp_path / "store" / "locks").is_dir():
            during += bool(staging)
            gcs.append(_morfic(tmp_path, "store", "gc", "--yes"))
        else:
            time.sleep(0.005)
    _ok(_finish(tmp_path, importer))
    for gc in gcs:
        _ok(gc)
    store = Store(tmp_path / "store")
    for tar in tars:
        objects, refs = _tar_contents(tar)
        assert all(store.has(oid) for oid in objects), tar
        for name, data in refs.items():
            assert (store.root / "refs" / name).read_bytes() == data
    _verified(tmp_path)
    removed = _morfic(tmp_path, "store", "gc", "--yes", "-f", "json")
    _ok(removed)
    assert json.loads(removed.stdout) == []  # everything imported is reachable
    print(f"\n{len(gcs)} gc run(s) during the import, {during} started while a bundle was being staged")


def test_an_import_killed_mid_way_leaves_only_a_staging_folder_that_gc_removes(tmp_path):
    tars = [BUNDLES / f"{v}-cpu-s0.tar" for v in ("film", "ppo")]
    importer = _spawn(tmp_path, "import", "store", "import", *map(str, tars))
    tmp = tmp_path / "store" / "tmp"
    while importer.poll() is None:
        if tmp.is_dir() and any(n.startswith("import-") and os.listdir(tmp / n) for n in os.listdir(tmp)):
            importer.send_signal(signal.SIGKILL)
            break
        time.sleep(0.0005)
    done = _finish(tmp_path, importer)
    _verified(tmp_path)
    assert _locks_free(tmp_path / "store")
    if done.returncode == -signal.SIGKILL:
        assert any(n.startswith("import-") for n in os.listdir(tmp))
    _ok(_morfic(tmp_path, "store", "gc", "--yes"))
    assert os.listdir(tmp) == []  # the staging folder and the files staged in it
    _ok(_morfic(tmp_path, "store", "import", *map(str, tars)))
    store = Store(tmp_path / "store")
    assert store.has_ref("runs/film-cpu-s0") and store.has_ref("runs/ppo-cpu-s0")
    _verified(tmp_path)
