"""Several robots' descriptor-mode rollouts as one env (``batch_robots``): each robot's slice is its rollout."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from morfic_cli.diagnostics.samples import OBS_GROUPS, DiagnoseCfg, diagnose_config, rollout_config
from morfic_cli.evaluation.protocol import EvalCfg, eval_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def models():
    """Fresh (untrained) film actor and critic, eval mode, and their config."""
    from morfic_cli.rl.build import build_models
    from morfic_cli.rl.config import smoke_preset

    torch.manual_seed(0)
    cfg = smoke_preset("film")
    actor, critic = build_models(cfg)
    actor.eval()
    critic.eval()
    return actor, critic, cfg


def _run(models, robots, **kwargs):
    from morfic_cli.evaluation.rollout import run_rollouts

    actor, critic, cfg = models
    return run_rollouts(
        actor, critic, cfg.env, robots=robots, mode="descriptor", command_vx=1.0, num_envs=2, steps=4, seed=3, **kwargs
    )


def test_one_env_per_robot_slice_has_that_robots_morphology():
    from morfic_cli.config import EnvCfg, eval_env_cfg
    from morfic_cli.envs.locomotion import LocomotionEnv

    cfg = eval_env_cfg(EnvCfg(num_envs=4))
    joint = LocomotionEnv(cfg, mode="descriptor", robot=["a1", "a1", "aliengo", "aliengo"], seed=0)
    try:
        for robot, envs in (("a1", slice(0, 2)), ("aliengo", slice(2, 4))):
            alone = LocomotionEnv(eval_env_cfg(EnvCfg(num_envs=2)), mode="descriptor", robot=robot, seed=0)
            try:
                for field in (
                    "descriptor",
                    "nominal_height",
                    "total_mass",
                    "base_mass",
                    "default_joint_pos",
                    "joint_range",
                ):
                    torch.testing.assert_close(
                        getattr(joint.params, field)[envs], getattr(alone.params, field), rtol=0, atol=0, msg=field
                    )
                torch.testing.assert_close(
                    joint.get_observations()["morphology"][envs], alone.get_observations()["morphology"], rtol=0, atol=0
                )
            finally:
                alone.close()
        assert not torch.equal(joint.params.descriptor[0], joint.params.descriptor[2])
    finally:
        joint.close()
    with pytest.raises(ValueError, match="one robot per env"):
        LocomotionEnv(cfg, mode="full", robot=["a1"] * 4)
    with pytest.raises(ValueError, match="one robot per env"):
        LocomotionEnv(cfg, mode="descriptor", robot=["a1"] * 3)


def test_a_batched_rollout_is_each_robots_slice(models):
    from morfic_cli.evaluation.rollout import run_rollout

    actor, critic, cfg = models
    both = _run(models, ("go1", "a1"), keep_obs=OBS_GROUPS, keep_models=1)
    assert list(both) == ["go1", "a1"]
    for robot, r in both.items():
        alone = run_rollout(
            actor, critic, cfg.env, robot=robot, mode="descriptor", command_vx=1.0, num_envs=2, steps=4, seed=3
        )
        assert (r.robot, r.mode, r.command_vx, r.seed, r.dt) == (robot, "descriptor", 1.0, 3, alone.dt)
        np.testing.assert_array_equal(r.descriptor, alone.descriptor)
        assert {k: a.shape for k, a in r.arrays.items()} == {k: a.shape for k, a in alone.arrays.items()}
        assert r.obs["critic"].shape[:2] == (4, 2) and len(r.models) == 1
        # every env of the slice sees its robot's morphology, as the robot alone does
        np.testing.assert_array_equal(r.obs["morphology"], np.broadcast_to(r.obs["morphology"][0, 0], (4, 2, 11)))
        assert r.term_names == alone.term_names
    assert not np.array_equal(both["go1"].obs["morphology"], both["a1"].obs["morphology"])
    # one robot is exactly run_rollout
    (one,) = _run(models, ("go1",)).values()
    again = run_rollout(
        actor, critic, cfg.env, robot="go1", mode="descriptor", command_vx=1.0, num_envs=2, steps=4, seed=3
    )
    for key in one.arrays:
        np.testing.assert_array_equal(one.arrays[key], again.arrays[key])


def test_a_batch_needs_distinct_robots_in_descriptor_mode(models):
    from morfic_cli.evaluation.rollout import run_rollouts

    actor, critic, cfg = models
    with pytest.raises(ValueError, match="distinct robots in descriptor mode"):
        _run(models, ("go1", "go1"))
    with pytest.raises(ValueError, match="distinct robots in descriptor mode"):
        run_rollouts(actor, critic, cfg.env, robots=("go1", "a1"), mode="full", command_vx=1.0, num_envs=2, steps=2)


def test_unbatched_configs_keep_their_keys_and_batched_ones_say_so():
    """An unbatched eval or diagnosis keeps the config (so the content address) it had before ``batch_robots``."""
    plain = eval_config("runs/x", EvalCfg(robots=("go1", "a1")))
    assert set(plain) == {"spec", "robots", "modes", "command_vx", "num_envs", "steps", "seed", "scene_envs"}
    assert eval_config("runs/x", EvalCfg(robots=("go1", "a1"), batch_robots=True))["batch_robots"] is True
    assert set(diagnose_config(DiagnoseCfg())) == {
        "robots",
        "mode",
        "command_vx",
        "num_envs",
        "steps",
        "seed",
        "trunc_eps",
        "sigma_eps",
    }
    joint = DiagnoseCfg(robots=("go1",), batch=("go1", "a1"))
    assert diagnose_config(joint)["batch"] == ("go1", "a1")
    assert rollout_config("go1", joint)["batch"] == ["go1", "a1"]
    assert "batch" not in rollout_config("go2", joint)  # not in the batch: collected alone
    assert "batch" not in rollout_config("go1", DiagnoseCfg(mode="full", batch=("go1", "a1")))
    assert "batch" not in rollout_config("go1", DiagnoseCfg())
