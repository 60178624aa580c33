"""Diagnostic samples: the rollout opt-ins, the stored observation groups, and scoring models on them."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from morfic_cli.diagnostics.samples import OBS_GROUPS, decode_obs, encode_obs
from morfic_cli.diagnostics.scoring import actor_gradients, batch_obs, critic_values
from morfic_cli.envs.observations import history_frames

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def models():
    """Fresh (untrained) film actor and critic at paper sizes, eval mode, and their config."""
    from morfic_cli.rl.build import build_models
    from morfic_cli.rl.config import smoke_preset

    torch.manual_seed(0)
    cfg = smoke_preset("film")
    actor, critic = build_models(cfg)
    actor.eval()
    critic.eval()
    return actor, critic, cfg


def _rollout(models, **kwargs):
    from morfic_cli.evaluation.rollout import run_rollout

    actor, critic, cfg = models
    return run_rollout(
        actor, critic, cfg.env, robot="go1", mode="descriptor", command_vx=1.0, num_envs=2, steps=5, seed=3, **kwargs
    )


def test_rollout_records_the_models_inputs_only_when_asked(models):
    plain = _rollout(models)
    assert plain.obs == {}
    kept = _rollout(models, keep_obs=OBS_GROUPS)
    assert set(kept.obs) == set(OBS_GROUPS)
    h = history_frames(models[2].env.obs)
    assert kept.obs["critic"].shape == (5, 2, h, 48) and kept.obs["history"].shape == (5, 2, h, 48)
    assert kept.obs["privileged"].shape == (5, 2, 18) and kept.obs["morphology"].shape == (5, 2, 11)
    assert all(a.dtype == np.float32 for a in kept.obs.values())
    # keeping the inputs changes nothing else: same mean actions, values and rewards
    for key in ("action", "value", "reward", "base_pos"):
        np.testing.assert_array_equal(plain.arrays[key], kept.arrays[key])


def test_recorded_critic_inputs_reproduce_the_recorded_values(models):
    _, critic, _ = models
    rollout = _rollout(models, keep_obs=OBS_GROUPS)
    np.testing.assert_allclose(
        critic_values(critic, rollout.obs).numpy(), rollout.arrays["value"], rtol=1e-6, atol=1e-6
    )
    # the mean actions too: row t of the kept groups is the actor's input at step t
    actor = models[0]
    with torch.no_grad():
        mean = actor(batch_obs(rollout.obs)).reshape(5, 2, 12).numpy()
    np.testing.assert_allclose(mean, rollout.arrays["action"], rtol=1e-6, atol=1e-6)


def test_sampled_actions_are_seeded_draws_around_the_mean(models):
    mean = _rollout(models, keep_obs=("history", "morphology"))
    a = _rollout(models, keep_obs=("history", "morphology"), sample_actions=True)
    b = _rollout(models, keep_obs=("history", "morphology"), sample_actions=True)
    np.testing.assert_array_equal(a.arrays["action"], b.arrays["action"])  # same seed, same draws
    assert not np.allclose(a.arrays["action"][1:], mean.arrays["action"][1:])
    # the first step starts from the same state: the draw is mean + std * noise, std = init_std = 1.0
    noise = a.arrays["action"][0] - mean.arrays["action"][0]
    assert 0.3 < float(noise.std()) < 3.0


def test_obs_encoding_round_trips_and_stores_equal_groups_once():
    rng = np.random.default_rng(0)
    hist = rng.normal(size=(6, 3, 4, 5)).astype(np.float32)
    obs = {
        "history": hist,
        "critic": hist.copy(),
        "privileged": rng.normal(size=(6, 3, 18)).astype(np.float32),
        "morphology": np.zeros((6, 3, 11), np.float32),
    }
    data = encode_obs(obs)
    back = decode_obs(data)
    assert set(back) == set(obs)
    for k, v in obs.items():
        np.testing.assert_array_equal(back[k], v)
        assert back[k].dtype == np.float32
    import io

    with np.load(io.BytesIO(data)) as npz:
        assert "critic" not in npz.files  # an alias of history
    obs["critic"] = obs["critic"] + 1.0
    np.testing.assert_array_equal(decode_obs(encode_obs(obs))["critic"], obs["critic"])


def test_actor_gradients_in_chunks_equal_the_full_batch_gradient(models):
    actor = models[0]
    rng = np.random.default_rng(1)
    h = history_frames(models[2].env.obs)
    obs = {
        "history": rng.normal(size=(4, 3, h, 48)).astype(np.float32),
        "morphology": rng.uniform(-1, 1, size=(4, 3, 11)).astype(np.float32),
    }
    actions = rng.normal(size=(4, 3, 12)).astype(np.float32)
    mask = rng.uniform(size=(4, 3)) < 0.7
    n = int(mask.sum())
    adv = [torch.from_numpy(rng.normal(size=n)), torch.from_numpy(rng.normal(size=n))]
    whole = actor_gradients(actor, obs, actions, mask, adv, chunk=10_000)
    chunked = actor_gradients(actor, obs, actions, mask, adv, chunk=2)
    for a, b in zip(whole, chunked, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)
    # and it is -mean(A grad log pi) over the masked samples, row-major
    td = batch_obs(obs, mask)
    actor.distribution.update(actor(td))
    lp = actor.get_output_log_prob(torch.from_numpy(actions[mask]))
    params = [p for p in actor.parameters() if p.requires_grad]
    direct = torch.autograd.grad(-(adv[0].float() * lp).mean(), params, allow_unused=True)
    flat = torch.cat(
        [(torch.zeros_like(p) if g is None else g).reshape(-1) for g, p in zip(direct, params, strict=True)]
    )
    torch.testing.assert_close(whole[0].float(), flat, rtol=1e-4, atol=1e-6)
