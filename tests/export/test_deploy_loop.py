"""examples/deploy_loop.py, the 50 Hz sim-to-sim loop of docs/deploy.md, against `morfic eval`'s rollout."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from morfic_cli.evaluation.rollout import rollout_env_cfg, run_rollout
from morfic_cli.export.artifact import ExportCfg, export_policy, plan_export
from morfic_cli.rl.load import load_trained
from morfic_cli.store import Store

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "deploy_loop.py"
STEPS = 25
COMPARED = ("action", "joint_pos", "joint_vel", "base_pos", "base_quat", "base_lin_vel")


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("deploy_loop", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules["deploy_loop"] = module  # dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop("deploy_loop", None)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def smoke(smoke_runs, tmp_path_factory):
    """A smoke-trained film run, its go1 ONNX export (out/go1) and its descriptor-input export (out/any)."""
    base = tmp_path_factory.mktemp("deploy")
    store = smoke_runs.store(base / "store")
    export_policy(store, "runs/film-s0", ExportCfg(robot="go1"), out=base / "go1")
    export_policy(store, "runs/film-s0", ExportCfg(), out=base / "any")
    return base


def _eval_start(trained, robot: str, vx: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """qpos, qvel of env 0 of `morfic eval`'s env (full mode) right after its reset."""
    from morfic_cli.envs.locomotion import LocomotionEnv

    env = LocomotionEnv(rollout_env_cfg(trained.cfg.env, 1, STEPS, vx), mode="full", robot=robot, seed=seed)
    try:
        state, nq, nv = env.backend.state[0].copy(), env.backend.models[0].nq, env.backend.models[0].nv
    finally:
        env.close()
    return state[1 : 1 + nq], state[1 + nq : 1 + nq + nv]


def _torch_policy(actor, morphology):
    m = torch.as_tensor(np.asarray(morphology, dtype=np.float32))[None]

    def policy(history: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = TensorDict({"history": torch.from_numpy(history), "morphology": m}, batch_size=[1])
            return actor(obs)[0].numpy()

    return policy


def _alive_steps(rollout) -> int:
    done = rollout.arrays["done"][:, 0]
    return int(np.argmax(done)) if done.any() else len(done)


@pytest.mark.parametrize(("robot", "vx", "seed"), [("go1", 1.0, 0), ("go2", 2.0, 3)])
def test_loop_with_the_torch_actor_is_identical_to_morfic_eval(example, smoke, robot, vx, seed):
    """Same seed, no noise: the loop's observations, targets and physics are morfic's, bit for bit."""
    trained = load_trained(Store(smoke / "store"), "runs/film-s0")
    rollout = run_rollout(
        trained.actor,
        trained.critic,
        trained.cfg.env,
        robot=robot,
        mode="full",
        command_vx=vx,
        num_envs=1,
        steps=STEPS,
        seed=seed,
    )
    _, meta = plan_export(trained, robot, False)
    qpos, qvel = _eval_start(trained, robot, vx, seed)
    model = example.robot_model(meta, robot, None)
    log = example.run(
        model,
        _torch_policy(trained.actor, meta["robots"][robot]["morphology"]),
        meta,
        robot,
        command=(vx, 0.0, 0.0),
        steps=STEPS,
        qpos=qpos,
        qvel=qvel,
    )
    alive = _alive_steps(rollout)
    assert alive >= 10
    for key in COMPARED:
        np.testing.assert_array_equal(log[key][:alive], rollout.arrays[key][:alive, 0], err_msg=key)


def test_loop_with_onnxruntime_follows_morfic_eval(example, smoke):
    """The exported ONNX policy in the example loop stays on `morfic eval`'s trajectory for the first steps."""
    trained = load_trained(Store(smoke / "store"), "runs/film-s0")
    vx, seed = 1.0, 0
    rollout = run_rollout(
        trained.actor,
        trained.critic,
        trained.cfg.env,
        robot="go1",
        mode="full",
        command_vx=vx,
        num_envs=1,
        steps=STEPS,
        seed=seed,
    )
    qpos, qvel = _eval_start(trained, "go1", vx, seed)
    alive = _alive_steps(rollout)
    for export_dir in ("go1", "any"):
        meta, model_path = example.load_export(smoke / export_dir)
        policy = example.OnnxPolicy(model_path, meta, "go1")
        log = example.run(
            example.robot_model(meta, "go1", None),
            policy,
            meta,
            "go1",
            command=(vx, 0.0, 0.0),
            steps=STEPS,
            qpos=qpos,
            qvel=qvel,
        )
        for key in COMPARED:
            diff = np.abs(log[key][:alive] - rollout.arrays[key][:alive, 0]).max()
            assert diff < 1e-4, (export_dir, key, diff)


def test_targets_follow_the_metadata_rule(example, smoke):
    meta, model_path = example.load_export(smoke / "go1")
    log = example.run(
        example.robot_model(meta, "go1", None),
        example.OnnxPolicy(model_path, meta, "go1"),
        meta,
        "go1",
        command=(0.5, 0.0, 0.0),
        steps=5,
    )
    robot = meta["robots"]["go1"]
    limits = np.asarray(robot["joint_limits"])
    expected = np.clip(np.asarray(robot["default_joint_pos"]) + 0.25 * log["action"], limits[:, 0], limits[:, 1])
    np.testing.assert_allclose(log["joint_targets"], expected, atol=1e-12)
    assert log["policy_ms"].shape == (5,) and (log["policy_ms"] > 0).all()


def test_motor_actuated_model_gets_pd_torques_from_the_metadata(example, smoke):
    """A model with torque (motor) actuators: the loop computes the PD itself and tracks the same targets."""
    import mujoco

    meta, model_path = example.load_export(smoke / "go1")
    policy = example.OnnxPolicy(model_path, meta, "go1")
    position = example.run(
        example.robot_model(meta, "go1", None), policy, meta, "go1", command=(0.5, 0.0, 0.0), steps=3
    )
    motors = example.robot_model(meta, "go1", None)
    motors.actuator_gaintype[:] = mujoco.mjtGain.mjGAIN_FIXED
    motors.actuator_gainprm[:, 0] = 1.0
    motors.actuator_biastype[:] = mujoco.mjtBias.mjBIAS_NONE
    motors.actuator_biasprm[:] = 0.0
    torque = example.run(motors, policy, meta, "go1", command=(0.5, 0.0, 0.0), steps=3)
    np.testing.assert_array_equal(torque["action"][0], position["action"][0])  # same start, same first action
    assert np.abs(torque["joint_pos"] - position["joint_pos"]).max() < 0.05  # explicit vs implicit PD damping


def test_example_runs_as_a_script(smoke, tmp_path):
    out = tmp_path / "go1"
    shutil.copytree(smoke / "go1", out)
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), str(out), "--vx", "0.5", "--seconds", "0.4", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["robot"] == "go1" and summary["seconds"] == 0.4 and summary["command"] == [0.5, 0.0, 0.0]
    assert {"vx_mean", "fell", "max_tilt_rad", "policy_ms_mean"} <= set(summary)
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), str(smoke / "any"), "--seconds", "0.1"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode != 0 and "give --robot" in proc.stderr
