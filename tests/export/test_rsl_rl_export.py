"""`morfic export --to rsl-rl`: a checkpoint rsl-rl's own OnPolicyRunner.load reads, with the same actions."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest
import torch
from rsl_rl.runners import OnPolicyRunner
from smoke_runs import LEGACY_BUNDLE

from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.rl.config import train_cfg_from_dict
from morfic_cli.rl.load import load_trained
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")

BUNDLE = LEGACY_BUNDLE


@pytest.fixture(scope="module")
def smoke_store(smoke_runs, tmp_path_factory):
    return smoke_runs.store(tmp_path_factory.mktemp("rslrl") / "store")


def _rsl_rl_runner(out: Path) -> tuple[OnPolicyRunner, LocomotionEnv, dict]:
    """rsl-rl's runner on morfic's env, built from the exported configs, with the exported checkpoint loaded."""
    agent = json.loads((out / "agent.json").read_text())
    cfg = train_cfg_from_dict(json.loads((out / "train.json").read_text()))
    env = LocomotionEnv(cfg.env, mode="train", seed=123)
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(env, agent, log_dir=None, device="cpu")
    (model,) = out.glob("model_*.pt")
    infos = runner.load(str(model))  # rsl-rl's own load: every key of the default load_cfg
    return runner, env, infos


def _same_actions(runner: OnPolicyRunner, env: LocomotionEnv, store: Store, spec: str) -> None:
    policy = runner.get_inference_policy("cpu")
    obs = env.get_observations()
    obs["history"] = torch.randn(obs["history"].shape, generator=torch.Generator().manual_seed(1))
    obs["morphology"] = torch.rand(obs["morphology"].shape, generator=torch.Generator().manual_seed(2)) * 2 - 1
    ours = load_trained(store, spec).actor
    with torch.no_grad():
        a_rsl, a_ours = policy(obs), ours(obs)
    assert a_rsl.shape == (env.num_envs, 12)
    assert torch.equal(a_rsl, a_ours)
    assert a_rsl.abs().sum() > 0


def test_rsl_rl_loads_a_trained_checkpoint_with_its_optimizer(run_cli, smoke_store, tmp_path):
    out = tmp_path / "rsl"
    code, stdout, err = run_cli(
        "export", "runs/film-s0", "--to", "rsl-rl", "--out", str(out), "--store", str(smoke_store.root), "-f", "json"
    )
    assert code == 0, err
    result = json.loads(stdout)
    assert result["ref"] == "exports/film-s0/rsl-rl@1" and result["optimizer"] == "trained"
    assert sorted(p.name for p in out.iterdir()) == ["agent.json", "model_2.pt", "train.json"]
    assert sorted(torch.load(out / "model_2.pt", weights_only=False)) == [
        "actor_state_dict",
        "adaptation_optimizer_state_dict",
        "critic_state_dict",
        "infos",
        "iter",
        "optimizer_state_dict",
    ]  # with a trainer state: the adaptation module's optimiser too (docs/deploy.md)
    runner, env, infos = _rsl_rl_runner(out)
    assert runner.current_learning_iteration == 2
    assert infos["morfic_checkpoint"] == load_trained(smoke_store, "runs/film-s0").checkpoint_id
    # the optimiser moments are the run's: the Adam step count of the trained state is there
    state = runner.alg.optimizer.state_dict()["state"]
    assert state and all(int(s["step"]) == 4 for s in state.values())  # 2 iterations x 1 epoch x 2 mini-batches
    _same_actions(runner, env, smoke_store, "runs/film-s0")
    env.close()
    # the same export again: the store already holds it, no new version
    code, stdout, _ = run_cli(
        "export", "runs/film-s0", "--to", "rsl-rl", "--store", str(smoke_store.root), "-f", "json"
    )
    assert code == 0 and json.loads(stdout)["ref"] == "exports/film-s0/rsl-rl@1"


def test_rsl_rl_loads_the_shipped_weights_only_bundle(run_cli, tmp_path):
    other = tmp_path / "other"
    assert run_cli("store", "import", str(BUNDLE), "--store", str(other))[0] == 0
    out = tmp_path / "rsl"
    code, stdout, err = run_cli(
        "export", "runs/film-cpu", "--to", "rsl-rl", "--out", str(out), "--store", str(other), "-f", "json"
    )
    assert code == 0, err
    assert json.loads(stdout)["optimizer"] == "fresh" and "optimizer state: fresh" in err
    (model,) = out.glob("model_*.pt")
    assert sorted(torch.load(model, weights_only=False)) == [
        "actor_state_dict",
        "critic_state_dict",
        "infos",
        "iter",
        "optimizer_state_dict",
    ]  # weights only: no
    # adaptation_optimizer_state_dict (docs/deploy.md)
    runner, env, infos = _rsl_rl_runner(out)
    assert infos["optimizer"] == "fresh" and runner.current_learning_iteration == 1000
    _same_actions(runner, env, Store(other), "runs/film-cpu")
    env.close()


def test_rsl_rl_export_refuses_robot_options(run_cli, smoke_store):
    code, _, err = run_cli(
        "export", "runs/film-s0", "--to", "rsl-rl", "--robot", "go1", "--store", str(smoke_store.root)
    )
    assert code == 1 and "Error:" in err and "--robot" in err
