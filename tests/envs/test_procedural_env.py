"""The env with procedural geometry (env.rand.geometry): off changes nothing, on gives each env a pool robot."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from morfic_cli.config import EnvCfg, GeometryRandCfg, SimCfg
from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.errors import MorficError
from morfic_cli.morphology.descriptor import TRAIN_MAX, TRAIN_MIN


def _cfg(n: int = 6, **geometry) -> EnvCfg:
    cfg = EnvCfg(num_envs=n, sim=SimCfg(num_threads=1))
    return dataclasses.replace(cfg, rand=dataclasses.replace(cfg.rand, geometry=GeometryRandCfg(**geometry)))


def _rollout(env: LocomotionEnv, steps: int = 30) -> list[torch.Tensor]:
    gen = torch.Generator().manual_seed(5)
    out = []
    for _ in range(steps):  # large random actions: some envs fall and reset within the rollout
        obs, rew, dones, _ = env.step(3.0 * torch.randn(env.num_envs, 12, generator=gen))
        out += [obs["history"].clone(), obs["critic"].clone(), obs["morphology"].clone(), rew.clone(), dones.clone()]
    return out


def _same(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return len(a) == len(b) and all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


@pytest.fixture(scope="module")
def default_rollout():
    env = LocomotionEnv(_cfg(), seed=2)
    try:
        return _rollout(env), env.backend.state.copy()
    finally:
        env.close()


@pytest.mark.parametrize("mode", ["train", "descriptor"])
def test_geometry_off_is_bit_identical_to_the_default_env(default_rollout, mode):
    # off, whatever its other fields; and on in descriptor mode (evaluation never generates robots)
    geometry = {"enabled": False, "pool_size": 3, "scale": (0.5, 2.0)} if mode == "train" else {"enabled": True}
    env = LocomotionEnv(_cfg(**geometry), mode=mode, seed=2)
    try:
        assert env.geometry_pool is None
        if mode == "train":
            steps, state = default_rollout
            assert sum(int(d.sum()) for d in steps[4::5]) > 0  # resets happened in the compared steps
            assert _same(_rollout(env), steps) and np.array_equal(env.backend.state, state)
    finally:
        env.close()


def test_a_default_rollout_is_not_one_with_geometry(default_rollout):
    env = LocomotionEnv(_cfg(enabled=True, pool_size=4), seed=2)
    try:
        assert not _same(_rollout(env), default_rollout[0])  # the comparison above can fail
    finally:
        env.close()


def test_each_env_is_its_pool_robot():
    env = LocomotionEnv(_cfg(n=8, enabled=True, pool_size=3), seed=1)
    try:
        pool = env.geometry_pool
        assert pool is not None and len(pool.robots) == 3
        for _ in range(3):
            ids = env.geometry_ids.numpy()
            p = env.params
            np.testing.assert_allclose(p.descriptor.numpy(), pool.descriptors[ids])
            np.testing.assert_allclose(p.total_mass.numpy(), [pool.robots[i].total_mass for i in ids])
            np.testing.assert_allclose(env.nominal_foot_pos_b.numpy(), pool.nominal_foot_pos_b[ids], rtol=1e-6)
            for env_id, i in enumerate(ids):
                model = env.backend.models[env_id]
                assert model.actuator_gainprm[0, 0] == pytest.approx(pool.robots[i].kp)
                assert model.geom("FL_calf_geom").size[0] == pytest.approx(pool.robots[i].link_radius[2])
            env._reset_envs(torch.arange(8))  # a new draw
            heights = env.backend.frame().base_pos_w[:, 2].numpy()
            np.testing.assert_allclose(heights, pool.init_height[env.geometry_ids.numpy()], rtol=1e-6)
        assert len(set(env.geometry_ids.tolist())) > 1
    finally:
        env.close()


def test_limits_from_the_support_keep_the_generated_masses():
    env = LocomotionEnv(_cfg(n=8, enabled=True, pool_size=3, limits_from_support=True), seed=1)
    try:
        desc = env.params.descriptor.numpy()
        np.testing.assert_allclose(desc[:, :5], env.geometry_pool.descriptors[env.geometry_ids.numpy(), :5])
        assert np.all((desc[:, 5:] >= TRAIN_MIN[5:] - 1e-9) & (desc[:, 5:] <= TRAIN_MAX[5:] + 1e-9))
        assert not np.allclose(desc[:, 5:], env.geometry_pool.descriptors[0, 5:])
    finally:
        env.close()


def test_a_checkpointed_env_continues_exactly():
    cfg = _cfg(enabled=True, pool_size=4)
    a, b = LocomotionEnv(cfg, seed=3), LocomotionEnv(cfg, seed=3)
    try:
        _rollout(a, 10)
        b.load_state_dict(a.state_dict())
        assert torch.equal(a.geometry_ids, b.geometry_ids)
        assert _same(_rollout(a, 10), _rollout(b, 10))
    finally:
        a.close()
        b.close()


def test_geometry_on_the_warp_backend_is_a_user_error():
    from morfic_cli.rl.config import apply_overrides, preset_cfg

    with pytest.raises(MorficError, match="cpu backend only"):
        apply_overrides(preset_cfg("smoke", "genloco"), ["env.sim.backend=warp"])


def test_set_geometry_makes_an_env_model_equal_its_pool_robots():
    from morfic_cli.morphology.procedural import generate_pool
    from morfic_cli.morphology.robots import load_robot
    from morfic_cli.sim.cpu import STAT_FIELDS, CpuBackend

    go2 = load_robot("go2")
    pool = generate_pool(go2, GeometryRandCfg(enabled=True, pool_size=3), 0)
    backend = CpuBackend(SimCfg(num_threads=1), go2, 2, template=True)
    try:
        backend.set_geometry_pool(pool.robots)
        ids = torch.tensor([0, 1])
        backend.set_geometry(ids, torch.tensor([2, 1]))
        backend.set_morphology(ids, torch.as_tensor(pool.descriptors[[0, 0]]) * 1.1)  # change what can change
        backend.set_dynamics(
            ids, torch.full((2,), 0.7), torch.full((2,), 0.3), torch.full((2, 3), 0.02), torch.full((2, 12), 0.1)
        )
        backend.set_geometry(ids, torch.tensor([0, 2]))
        for env, pick in ((0, 0), (1, 2)):
            model, source = backend.models[env], backend._pool[pick].model
            fields = [n for n in dir(source) if not n.startswith("_") and isinstance(getattr(source, n), np.ndarray)]
            assert len(fields) > 400
            for name in fields:
                assert np.array_equal(getattr(model, name), getattr(source, name)), name
            for name in STAT_FIELDS:
                assert np.array_equal(getattr(model.stat, name), getattr(source.stat, name)), name
        np.testing.assert_allclose(backend.params().descriptor.numpy(), pool.descriptors[[0, 2]])
    finally:
        backend.close()
