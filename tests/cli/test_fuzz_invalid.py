"""CLI fuzz: a table of invalid invocations, each refused before any work.

For every row: exit status 1, ``Error: `` on stderr, no traceback, and no file created, changed or removed
anywhere under the test's folder (the store, the files and folders the row points at). The rows are what an
adversarial probe of the CLI tried (issue 20), plus their neighbours; they run in-process through ``main``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from crafted_bundles import report_bundle

from morfic_cli.store import Store

BIG = "99999999999999999999"

#: One invalid invocation per row. {FILE} is an existing file, {DIR} an existing empty folder, {T} the
#: test folder; {TRUNC}, {EVIL} and {TAR} are a truncated export, a traversal bundle and a good export.
ROWS: list[tuple[str, ...]] = [
    # train: config values (--set) and arguments
    ("train", "--set", "ppo.learning_rate=NaN"),
    ("train", "--set", "ppo.learning_rate=Infinity"),
    ("train", "--set", "ppo.learning_rate=-1"),
    ("train", "--set", "ppo.learning_rate=0"),
    ("train", "--set", "env.decimation=0"),
    ("train", "--set", "ppo.num_mini_batches=0"),
    ("train", "--set", "ppo.num_mini_batches=100000"),
    ("train", "--set", "model.actor_hidden_dims=[]"),
    ("train", "--set", "model.actor_hidden_dims=[0]"),
    ("train", "--set", "model.actor_hidden_dims=[-5,3]"),
    ("train", "--set", "model.critic_hidden_dims=[]"),
    ("train", "--set", "model.actor_hidden_dims=[1.5]"),
    ("train", "--seed", BIG),
    ("train", "--seed", "-1"),
    ("train", "--set", "seed=-3"),
    ("train", "--set", "ppo.gamma=2"),
    ("train", "--set", "ppo.gamma=0"),
    ("train", "--set", "ppo.lam=1.5"),
    ("train", "--set", "ppo.schedule=nosuch"),
    ("train", "--set", "ppo.clip_param=0"),
    ("train", "--set", "ppo.desired_kl=-0.1"),
    ("train", "--set", "ppo.num_learning_epochs=0"),
    ("train", "--set", "ppo.entropy_coef=NaN"),
    ("train", "--set", "ppo.max_grad_norm=0"),
    ("train", "--set", "ppo.adaptation_learning_rate=-1"),
    ("train", "--set", "model.init_std=0"),
    ("train", "--set", "max_iterations=0"),
    ("train", "--set", "num_steps_per_env=0"),
    ("train", "--set", "save_interval=0"),
    ("train", "--set", "env.num_envs=0"),
    ("train", "--set", "env.num_envs=100000000"),
    ("train", "--set", "env.sim.physics_dt=0"),
    ("train", "--set", "env.sim.physics_dt=NaN"),
    ("train", "--set", "env.sim.backend=nosuch"),
    ("train", "--set", "env.sim.num_threads=0"),
    ("train", "--set", "env.episode_length_s=-1"),
    ("train", "--set", "env.rewards.w_lin=NaN"),
    ("train", "--set", "env.rewards.w_lin=-Infinity"),
    ("train", "--set", "env.commands.vx_init=[2,1]"),
    ("train", "--set", "env.commands.vx_init=[1]"),
    ("train", "--set", "env.rand.friction=[-1,1]"),
    ("train", "--set", "env.gait.duty=1.5"),
    ("train", "--set", "env.obs.history_len=0"),
    ("train", "--set", "nosuch.key=1"),
    ("train", "--set", "ppo.gamma"),
    ("train", "--set", "=3"),
    ("train", "--set", "ppo.gamma=abc"),
    ("train", "--set", "ppo=1"),
    ("train", "--name", "a b"),
    ("train", "--name", "../../evil"),
    ("train", "--name", "x@1"),
    ("train", "--name", ""),
    ("train", "--name", "runs/../x"),
    ("train", "--name", "film-s0"),  # exists: refused, not overwritten
    ("train", "--variant", "nosuch"),
    ("train", "--preset", "nosuch"),
    ("train", "--device", "tpu"),
    ("train", "--resume", "runs/nothing"),
    ("train", "--resume", ""),
    ("train", "--resume", "runs/film-s0@0"),
    ("train", "--resume", "runs/film-s0@99"),
    ("train", "--resume", "tables/nothing"),
    ("train", "--store", "{FILE}"),
    ("train", "--store", "{FILE}/sub"),
    ("train", "--seed", "abc"),
    # eval
    ("eval", "runs/film-s0", "--command-vx", "nan"),
    ("eval", "runs/film-s0", "--command-vx", "inf"),
    ("eval", "runs/film-s0", "--command-vx", ""),
    ("eval", "runs/film-s0", "--command-vx", "2.0,,"),
    ("eval", "runs/film-s0", "--command-vx", "100"),
    ("eval", "runs/film-s0", "--out", "{FILE}"),
    ("eval", "runs/film-s0", "--out", "{FILE}/x"),
    ("eval", "runs/film-s0", "--envs", "0"),
    ("eval", "runs/film-s0", "--envs", "-3"),
    ("eval", "runs/film-s0", "--envs", "100000000"),
    ("eval", "runs/film-s0", "--envs", "abc"),
    ("eval", "runs/film-s0", "--steps", "0"),
    ("eval", "runs/film-s0", "--seed", BIG),
    ("eval", "runs/film-s0", "--robots", ""),
    ("eval", "runs/film-s0", "--robots", "nosuch"),
    ("eval", "runs/film-s0", "--mode", "nosuch"),
    ("eval", "runs/nothing"),
    ("eval", ""),
    ("eval",),
    ("eval", "runs/film-s0", "--store", "{FILE}"),
    # distance
    ("distance", "--reference", ""),
    ("distance", "--reference", "go1,a1"),
    ("distance", "--reference", "nosuch"),
    ("distance", "--robots", ""),
    ("distance", "--robots", "go1,nosuch"),
    ("distance", "--normalize", "nosuch"),
    ("distance", "--store", "{FILE}"),
    # store
    ("store", "ls", "--store", "{FILE}"),
    ("store", "ls", "--kind", "nosuch"),
    ("store", "ls", "--format", "nosuch"),
    ("store", "show", "runs/nothing"),
    ("store", "show", "runs/film-s0@0"),
    ("store", "show", "runs/film-s0@abc"),
    ("store", "show", ""),
    ("store", "show", "ab"),
    ("store", "show", "runs/nothing", "--history"),
    ("store", "verify", "--store", "{FILE}"),
    ("store", "gc", "--store", "{FILE}"),
    ("store", "export"),
    ("store", "export", "runs/nothing", "--out", "{T}/bundles"),
    ("store", "export", "runs/film-s0", "--out", "{FILE}"),
    ("store", "export", "runs/film-s0", "--out", "{FILE}/x"),
    ("store", "export", "bad name", "--out", "{T}/bundles"),
    ("store", "export", "runs/film-s0", "--out", "{T}", "--name", "good"),
    ("store", "export", "runs/film-s0", "--out", "{T}", "--name", "../x"),
    ("store", "export", "runs/film-s0", "--out", "{T}", "--name", ""),
    ("store", "export", "runs/film-s0", "--out", "{T}/bundles", "--results-only"),  # a run without results
    ("store", "export", "runs/nothing", "--out", "{T}/bundles", "--results-only"),
    ("store", "import", "{T}/missing.tar"),
    ("store", "import", "{DIR}"),
    ("store", "import", "{FILE}"),
    ("store", "import", "{TRUNC}"),
    ("store", "import", "{EVIL}"),
    ("store", "import", "{TAR}", "--store", "{FILE}"),
    ("store", "nosuch"),
    # bench
    ("bench", "env", "--envs", "100000000"),
    ("bench", "env", "--envs", "0"),
    ("bench", "env", "--envs", "abc"),
    ("bench", "env", "--envs", "256,-1"),
    ("bench", "env", "--steps", "0"),
    ("bench", "env", "--seed", "-1"),
    ("bench", "nosuch"),
    ("bench", "env", "--backend", "nosuch"),
    ("bench", "train", "--iterations", "0"),
    ("bench", "train", "--preset", "nosuch"),
    ("bench", "train", "--set", "nosuch=1"),
    ("bench", "env", "--set", "ppo.gamma=0.9"),
    # reproduce
    ("reproduce", "--variants", ""),
    ("reproduce", "--variants", " , "),
    ("reproduce", "--variants", "nosuch"),
    ("reproduce", "--out", "{FILE}"),
    ("reproduce", "--set", "ppo.gamma=2"),
    ("reproduce", "--preset", "nosuch"),
    # report
    ("report", "--out", "{FILE}"),
    ("report", "--name", "a b"),
    ("report", "--name", "../x"),
    ("report", "runs/nothing"),
    # export
    ("export", "runs/film-s0", "--out", "{FILE}"),
    ("export", "runs/nothing"),
    ("export", "runs/film-s0", "--to", "nosuch"),
    ("export", "runs/film-s0", "--format", "nosuch"),
    ("export", "runs/film-s0", "--robot", "nosuch"),
    ("export", "runs/film-s0", "--store", "{FILE}"),
    # diagnose, compare-baselines, robots, the root
    ("diagnose", "runs/film-s0", "--command-vx", "nan"),
    ("diagnose", "runs/film-s0", "--envs", "0"),
    ("diagnose", "runs/film-s0", "--out", "{FILE}"),
    ("diagnose", "runs/film-s0", "--seed", BIG),
    ("diagnose",),
    ("diagnose", "runs/nothing"),
    ("compare-baselines", "runs/nothing"),
    ("robots", "show", "nosuch"),
    ("robots", "nosuch"),
    ("nosuch",),
    ("--nosuch",),
]


@pytest.fixture(scope="module")
def workspace(smoke_runs, tmp_path_factory):
    """A store with one smoke run (runs/film-s0), a file, an empty folder and three tars, shared by every row."""
    root = tmp_path_factory.mktemp("fuzz")
    store = smoke_runs.store(root / "store")
    (root / "a-file.txt").write_text("not a store\n")
    (root / "a-dir").mkdir()
    tar = store.export_tar(["runs/film-s0"], root / "good.tar").path
    data = tar.read_bytes()
    (root / "trunc.tar").write_bytes(data[: len(data) // 2])
    report_bundle(root / "evil.tar", {"../../x": b"pwned", "/tmp/morfic-fuzz-abs": b"pwned"})
    return root


def _snapshot(root: Path) -> dict[str, tuple[int, int, int]]:
    out = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            st = path.lstat()
            out[path.relative_to(root).as_posix()] = (st.st_size, st.st_mtime_ns, st.st_mode)
    return out


def test_the_table_is_big_enough():
    assert len(ROWS) >= 100 and len(set(ROWS)) == len(ROWS)


@pytest.mark.parametrize("row", ROWS, ids=[" ".join(r) or "-" for r in ROWS])
def test_invalid_invocation_is_refused_before_any_work(workspace, run_cli, monkeypatch, row):
    monkeypatch.setenv("MORFIC_STORE", str(workspace / "store"))
    subs = {
        "{FILE}": workspace / "a-file.txt",
        "{DIR}": workspace / "a-dir",
        "{T}": workspace,
        "{TRUNC}": workspace / "trunc.tar",
        "{EVIL}": workspace / "evil.tar",
        "{TAR}": workspace / "good.tar",
    }
    argv = []
    for arg in row:
        for key, value in subs.items():
            arg = arg.replace(key, str(value))
        argv.append(arg)
    before = _snapshot(workspace)
    code, _, err = run_cli(*argv)
    assert code == 1, f"exit {code}: {err[-500:]}"
    assert err.startswith("Error: ") or "\nError: " in err, err[-500:]
    assert "Traceback" not in err, err[-2000:]
    assert _snapshot(workspace) == before, "files changed"
    assert not Path("/tmp/morfic-fuzz-abs").exists()
    assert Store(workspace / "store").list_refs() == ["runs/film-s0"]
