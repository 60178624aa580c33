"""`morfic train` end to end: smoke runs of every variant, exact resume, Ctrl-C, bad input."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import signal
import subprocess
import sys
import time
import types

import pytest
import torch
from smoke_runs import LEGACY_BUNDLE

from morfic_cli.recording.curves import read_curve_csv
from morfic_cli.rl.build import dummy_observations
from morfic_cli.rl.config import smoke_preset
from morfic_cli.rl.load import load_trained
from morfic_cli.rl.runner import new_run, resume_run
from morfic_cli.rl.variants import ACTUATION_ABLATIONS, STOCK, VARIANTS
from morfic_cli.store import Store

TIMING = {"wall_time_s", "steps_per_s", "collect_s", "learn_s"}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _store() -> Store:
    return Store(os.environ["MORFIC_STORE"])


def _weights(store: Store, spec: str) -> dict:
    return torch.load(io.BytesIO(store.read_file(spec, "model.pt")), weights_only=True)


# film-act's ablations are its networks and env code with one env key changed (tests/rl/test_variants.py)
@pytest.mark.parametrize("variant", [v for v in VARIANTS if v not in ACTUATION_ABLATIONS])
def test_smoke_training_of_every_variant_through_the_cli(run_cli, variant):
    code, out, err = run_cli("train", "--variant", variant, "--preset", "smoke", "--format", "json", "--quiet")
    assert code == 0, err
    result = json.loads(out)
    assert result["ref"] == f"runs/{variant}-smoke-s0@1"  # save_interval 10: one checkpoint, at the end
    assert result["iteration"] == 2 and result["env_steps"] == 2 * 8 * 8
    store = _store()
    manifest = store.read_manifest(f"runs/{variant}-smoke-s0")
    assert manifest.kind == "checkpoint"
    assert manifest.meta["variant"] == variant and manifest.meta["iteration"] == 2 and manifest.meta["finished"]
    assert manifest.config["variant"] == variant and manifest.config["preset"] == "smoke"
    assert [e.id for e in store.ref_history(f"runs/{variant}-smoke-s0")][-1] == manifest.id
    assert len(store.ref_history(f"runs/{variant}-smoke-s0")) == 1
    rows = read_curve_csv(store.read_file(manifest.id, "curve.csv"))
    assert [r["iteration"] for r in rows] == [1, 2]
    adapts = not STOCK[variant].own_models  # the external baselines adapt nothing: NaN, a blank cell
    assert {"explained_variance", "value_loss", "kl", "clip_fraction", *(["adaptation_error"] * adapts)} <= set(rows[0])
    assert store.read_file(manifest.id, "curve.png")[:8] == b"\x89PNG\r\n\x1a\n"
    trained = load_trained(store, f"runs/{variant}-smoke-s0")
    with torch.no_grad():
        assert trained.actor(dummy_observations(trained.cfg, 3)).shape == (3, 12)
        assert trained.critic(dummy_observations(trained.cfg, 3)).shape == (3, 1)


def test_resume_after_interruption_equals_an_uninterrupted_run():
    store = _store()
    cfg = smoke_preset("film", seed=3)
    cfg = type(cfg)(**{**cfg.__dict__, "max_iterations": 3})
    straight = new_run(store, cfg, "straight")
    straight.train()

    stopped = new_run(store, cfg, "stopped")
    stopped.progress = lambda row: setattr(stopped, "stop_requested", True)  # "Ctrl-C" during iteration 1
    last = stopped.train()
    assert last.iteration == 1
    assert store.read_manifest("runs/stopped").meta["interrupted"] is True
    assert store.verify().ok

    resumed = resume_run(store, "runs/stopped")
    assert resumed.iteration == 1
    resumed.train()
    a, b = _weights(store, "runs/straight"), _weights(store, "runs/stopped")
    for part in ("actor", "critic"):
        assert a[part].keys() == b[part].keys()
        for key in a[part]:
            assert torch.equal(a[part][key], b[part][key]), f"{part}.{key} differs after resume"
    rows_a = read_curve_csv(store.read_file("runs/straight", "curve.csv"))
    rows_b = read_curve_csv(store.read_file("runs/stopped", "curve.csv"))
    assert [{k: v for k, v in r.items() if k not in TIMING} for r in rows_a] == [
        {k: v for k, v in r.items() if k not in TIMING} for r in rows_b
    ]


def test_the_training_clock_counts_what_the_user_waits_for(monkeypatch):
    """wall_time_s = the wall time of the learn call, checkpoints and the per-iteration hook included, over resumes.

    The clock is a fake that only the per-iteration hook advances (10 s an iteration, outside rsl-rl's collection
    and learning, as checkpoints are): a clock of collection + learning alone would read 0 here, ours reads 10 s an
    iteration exactly.
    """
    import morfic_cli.rl.curve_logger as curve_logger

    now = [1000.0]
    monkeypatch.setattr(curve_logger, "time", types.SimpleNamespace(perf_counter=lambda: now[0]))

    def hook(row):
        now[0] += 10.0

    store = _store()
    cfg = dataclasses.replace(smoke_preset("film"), max_iterations=3, save_interval=1)
    run = new_run(store, cfg, "clocked")
    run.progress = hook
    run.train()
    assert run.wall_time_s == 30.0  # what `morfic train` prints
    # the stored time is read as the last checkpoint is written: after the last hook, before its own write
    stored = store.read_manifest("runs/clocked").meta["wall_time_s"]
    rows = read_curve_csv(store.read_file("runs/clocked", "curve.csv"))
    assert [r["wall_time_s"] for r in rows] == [0.0, 10.0, 20.0]  # each row is read before its iteration's hook
    assert stored == 30.0

    resumed = resume_run(store, "runs/clocked", ["max_iterations=5"])
    resumed.progress = hook
    resumed.train()
    assert resumed.wall_time_s == 50.0  # accumulated across the resume
    rows = read_curve_csv(store.read_file("runs/clocked", "curve.csv"))
    assert [r["wall_time_s"] for r in rows] == [0.0, 10.0, 20.0, 30.0, 40.0]
    # curve.png only in the last checkpoint of each training (drawn off the loop); curve.csv in every one
    files = [set(store.read_manifest(e.id).files) for e in store.ref_history("runs/clocked")]
    assert [("curve.png" in f, "curve.csv" in f) for f in files] == [
        (False, True),
        (False, True),
        (True, True),
        (False, True),
        (True, True),
    ]


def test_resume_extends_a_finished_run_with_set(run_cli):
    assert run_cli("train", "--preset", "smoke", "--set", "max_iterations=1", "-q")[0] == 0
    code, out, err = run_cli("train", "--resume", "runs/film-smoke-s0", "--set", "max_iterations=2", "-f", "json", "-q")
    assert code == 0, err
    assert json.loads(out)["iteration"] == 2
    history = _store().ref_history("runs/film-smoke-s0")
    assert _store().read_manifest("runs/film-smoke-s0").meta["parent"] == history[0].id


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--set", "ppo.learnin_rate=1e-3"], "unknown config key 'ppo.learnin_rate'"),
        (["--set", "env.num_envs=many"], "takes an integer"),
        (["--set", "novalue"], "key=value"),
        (["--variant", "filmm"], "unknown variant 'filmm'; valid variants are: actor-only, adaln, "),
        (["--resume", "runs/nothing"], "no artifact 'runs/nothing'"),
    ],
)
def test_bad_input_is_an_error_and_writes_nothing(run_cli, argv, needle):
    code, out, err = run_cli("train", *(argv if "--resume" in argv else ["--preset", "smoke", *argv]))
    assert code == 1
    assert err.startswith("Error: ") and needle in err, err
    assert out == ""
    assert _store().list_refs() == []


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
def test_device_cuda_without_cuda_is_an_error(run_cli):
    code, _, err = run_cli("train", "--preset", "smoke", "--device", "cuda")
    assert code == 1 and "no CUDA device" in err


def test_an_existing_run_name_is_not_overwritten(run_cli):
    assert run_cli("train", "--preset", "smoke", "--set", "max_iterations=1", "-q")[0] == 0
    before = _store().ref_history("runs/film-smoke-s0")
    code, _, err = run_cli("train", "--preset", "smoke", "-q")
    assert code == 1 and "already exists" in err and "--resume runs/film-smoke-s0" in err
    assert _store().ref_history("runs/film-smoke-s0") == before


def test_a_policy_bundle_without_trainer_state_cannot_be_resumed(run_cli, tmp_path):
    """The shipped bundle predates trainer states in bundles: weights only, so it evaluates but cannot resume."""
    bundle = LEGACY_BUNDLE
    other = tmp_path / "other"
    assert run_cli("store", "import", str(bundle), "--store", str(other))[0] == 0
    code, _, err = run_cli("train", "--resume", "runs/film-cpu", "--store", str(other))
    assert code == 1 and "no trainer state" in err
    assert load_trained(Store(other), "runs/film-cpu").meta["iteration"] == 1000  # but it evaluates


def test_sigint_writes_a_checkpoint_and_exits_cleanly(tmp_path):
    store_dir = tmp_path / "sig"
    env = dict(os.environ, MORFIC_STORE=str(store_dir))
    proc = subprocess.Popen(
        [sys.executable, "-m", "morfic_cli", "train", "--preset", "smoke", "--set", "max_iterations=500", "-f", "json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    deadline = time.time() + 120
    while time.time() < deadline and not (store_dir / "refs").exists():  # the first checkpoint is written
        time.sleep(0.2)
    time.sleep(3.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    result = json.loads(out)
    assert result["interrupted"] is True and 1 <= result["iteration"] < 500
    store = Store(store_dir)
    assert store.verify().ok
    assert store.read_manifest("runs/film-smoke-s0").meta["interrupted"] is True
    assert "--resume runs/film-smoke-s0" in err
