"""LocomotionEnv: observation groups, morphology modes, episodes, determinism, non-finite resets."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from paper_facts import PAPER_DESCRIPTORS

from morfic_cli.config import EnvCfg, SimCfg, eval_env_cfg
from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.envs.terminations import NONFINITE, TERMINATIONS
from morfic_cli.morphology.robots import list_robots, load_robot

ROBOTS = list_robots()


def _cfg(n: int = 4, threads: int = 1, **kw) -> EnvCfg:
    return dataclasses.replace(EnvCfg(num_envs=n, sim=SimCfg(num_threads=threads)), **kw)


def _check_obs(env: LocomotionEnv) -> None:
    obs = env.get_observations()
    n = env.num_envs
    assert obs["policy"].shape == (n, 48)
    assert obs["history"].shape == (n, 16, 48)  # [h_t (15 previous), o_t]
    assert obs["critic"].shape == (n, 16, 48)
    assert obs["privileged"].shape == (n, 18)
    assert obs["morphology"].shape == (n, 11)
    for key in ("policy", "history", "critic", "privileged", "morphology"):
        assert torch.isfinite(obs[key]).all(), key


@pytest.mark.parametrize(
    "mode, robot",
    [("train", "go2")] + [("descriptor", r) for r in ROBOTS] + [("full", r) for r in ROBOTS],
)
def test_observation_shapes_and_finite_values(mode, robot):
    env = LocomotionEnv(_cfg(n=3), mode=mode, robot=robot, seed=0)
    try:
        _check_obs(env)
        gen = torch.Generator().manual_seed(1)
        for _ in range(5):
            obs, rew, dones, extras = env.step(torch.rand((3, 12), generator=gen) * 2 - 1)
            assert rew.shape == (3,) and torch.isfinite(rew).all()
            assert dones.shape == (3,) and extras["time_outs"].shape == (3,)
            assert all(k.startswith("/") for k in extras["log"])
        _check_obs(env)
    finally:
        env.close()


def test_descriptor_mode_applies_the_targets_descriptor_b1():
    env = LocomotionEnv(_cfg(n=2), mode="descriptor", robot="b1", seed=0)
    try:
        p = env.backend.params()
        b1 = np.array(PAPER_DESCRIPTORS["b1"])
        np.testing.assert_allclose(p.descriptor.numpy()[0], b1, atol=1e-9)
        # joint ranges (hip, thigh, calf) of every leg follow the B1 descriptor
        rng = p.joint_range.numpy()[0].reshape(4, 3, 2)
        for leg in range(4):
            np.testing.assert_allclose(rng[leg, 0], [-0.75, 0.75])
            np.testing.assert_allclose(rng[leg, 1], [-1.0, 3.5])
            np.testing.assert_allclose(rng[leg, 2], [-2.6, -0.6])
        # total mass: Go2 total - Go2 link+base masses + B1's, rotors unchanged
        go2 = load_robot("go2")
        link_go2 = 4 * (0.678 + 1.152 + 0.154 + 0.040) + 6.921  # hip, thigh, calf, foot x 4 + base
        link_b1 = 4 * (2.150 + 4.300 + 1.050 + 0.050) + 29.450
        assert float(p.total_mass[0]) == pytest.approx(go2.total_mass - link_go2 + link_b1, abs=1e-6)
        # the morphology observation is the normalised B1 descriptor: base mass 29.45 kg is far above +1
        assert float(env.get_observations()["morphology"][0, 4]) > 1.0
    finally:
        env.close()


def test_train_mode_samples_descriptors_inside_the_support():
    env = LocomotionEnv(_cfg(n=16), mode="train", seed=3)
    try:
        m = env.get_observations()["morphology"]
        assert (m >= -1 - 1e-5).all() and (m <= 1 + 1e-5).all()
        assert m.std(dim=0).min() > 0.05  # envs differ
    finally:
        env.close()


def test_standing_with_zero_actions_survives_a_full_episode():
    cfg = eval_env_cfg(_cfg(n=2))
    env = LocomotionEnv(cfg, mode="descriptor", robot="go2", seed=0)
    try:
        env.commands.zero_()
        zeros = torch.zeros((2, 12))
        for step in range(1, env.max_episode_length + 1):
            _, _, dones, extras = env.step(zeros)
            if step < env.max_episode_length:
                assert not dones.any(), f"terminated at step {step}"
        assert env.max_episode_length == 1000
        assert dones.all() and extras["time_outs"].all()
    finally:
        env.close()


def _rollout(seed: int, threads: int, steps: int = 15) -> list[torch.Tensor]:
    env = LocomotionEnv(_cfg(n=4, threads=threads), mode="train", seed=seed)
    gen = torch.Generator().manual_seed(seed)
    out = []
    try:
        for _ in range(steps):
            obs, rew, dones, _ = env.step(torch.rand((4, 12), generator=gen) * 2 - 1)
            out += [obs["policy"].clone(), obs["privileged"].clone(), rew.clone(), dones.clone()]
    finally:
        env.close()
    return out


def test_same_seed_gives_identical_rollouts():
    a, b = _rollout(7, threads=1), _rollout(7, threads=2)
    for x, y in zip(a, b, strict=True):
        assert torch.equal(x, y)
    c = _rollout(8, threads=1)
    assert not all(torch.equal(x, y) for x, y in zip(a, c, strict=True))


def test_unknown_mode_is_an_error():
    with pytest.raises(ValueError, match="valid modes"):
        LocomotionEnv(_cfg(n=1), mode="sideways")  # type: ignore[arg-type]


def test_nan_in_one_envs_state_resets_that_env_only():
    env = LocomotionEnv(eval_env_cfg(_cfg(n=3)), mode="descriptor", robot="go2", seed=0)
    try:
        zeros = torch.zeros((3, 12))
        for _ in range(3):
            env.step(zeros)
        before = env.episode_length_buf.clone()
        env.backend.state[1, 3] = float("nan")  # base z of env 1 (state = [time, qpos...])
        obs, rew, dones, extras = env.step(zeros)
        assert dones.tolist() == [0, 1, 0]
        assert env.episode_length_buf.tolist() == [int(before[0]) + 1, 0, int(before[2]) + 1]
        assert extras["log"]["/env/nonfinite_resets"] == 1.0
        # the pre-reset view of the step's ends (evaluation's termination counts) still says why env 1 ended
        assert list(env.last_terminations) == [*TERMINATIONS, NONFINITE]
        assert env.last_terminations[NONFINITE].tolist() == [False, True, False]
        assert rew[1] == 0.0 and torch.isfinite(rew).all()
        for key in ("policy", "history", "critic", "privileged", "morphology"):
            assert torch.isfinite(obs[key]).all(), key
        # the batch carries on
        obs, rew, dones, _ = env.step(zeros)
        assert not dones.any() and torch.isfinite(rew).all()
    finally:
        env.close()


def test_the_curriculum_reads_the_raw_tracking_term_whatever_its_weight():
    # --set env.rewards.w_lin=0 must not freeze the curriculum: the tracking it accumulates is r_lin unweighted,
    # the same numbers as with the default weight (rewards do not act on the dynamics).
    base = _cfg(n=3)
    zero = dataclasses.replace(base, rewards=dataclasses.replace(base.rewards, w_lin=0.0))
    envs = [LocomotionEnv(c, mode="train", seed=3) for c in (base, zero)]
    logs = []
    for env in envs:
        for _ in range(5):
            _, _, _, extras = env.step(torch.zeros(3, 12))
        logs.append(extras["log"])
    assert torch.equal(envs[0].episode_lin_tracking, envs[1].episode_lin_tracking)
    assert (envs[1].episode_lin_tracking > 0).all()
    assert logs[1]["/reward/r_lin"] == 0.0 and logs[1]["/reward_raw/r_lin"] == logs[0]["/reward_raw/r_lin"] > 0
    for env in envs:
        env.close()
