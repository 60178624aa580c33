"""Issue 16 items 1-3 and the legacy rule: FiLM scale 0.1, MorFiC-H's generated head, one shared z, old configs.

Numbers are computed by hand in the comments.
"""

from __future__ import annotations

import dataclasses

import pytest
import torch
import torch.nn as nn
from tensordict import TensorDict

from morfic_cli.rl.build import build_models, dummy_observations, rsl_rl_cfg
from morfic_cli.rl.config import LEGACY_VALUES, fill_legacy, preset_cfg, train_cfg_from_dict, train_cfg_to_dict
from morfic_cli.rl.models import FiLM, HyperHead, MorficCritic


@pytest.fixture(autouse=True)
def _one_torch_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _set_linear(linear: nn.Linear, weight: list, bias: list) -> None:
    with torch.no_grad():
        linear.weight.copy_(torch.tensor(weight, dtype=torch.float32))
        linear.bias.copy_(torch.tensor(bias, dtype=torch.float32))


def _obs(cfg, n: int = 4, seed: int = 0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    obs = dummy_observations(cfg, n)
    return TensorDict({k: torch.randn(v.shape, generator=g) for k, v in obs.items()}, batch_size=[n])


# ---------------------------------------------------------------------------------------------- item 1: FiLM 0.1
def test_film_at_scale_0p1_on_a_two_unit_layer_by_hand():
    film = FiLM(latent_dim=1, hidden_dim=2, generator_hidden_dim=1, scale=0.1, activation="elu")
    lin_in, _, lin_out = list(film.generator)  # z (1) -> 1 -> (gamma_1, gamma_2, beta_1, beta_2)
    _set_linear(lin_in, [[1.0]], [0.0])  # ELU(z) = z for z = 2 > 0
    _set_linear(lin_out, [[1.0], [-1.0], [0.5], [3.0]], [0.0, 0.0, 0.0, 0.0])  # gamma = (2, -2), beta = (1, 6)
    layer = nn.Linear(2, 2)
    _set_linear(layer, [[1.0, 0.0], [0.0, 2.0]], [0.0, 1.0])  # h = (x1, 2 x2 + 1) = (3, 1) for x = (3, 0)
    out = film(layer, torch.tensor([[3.0, 0.0]]), torch.tensor([[2.0]]))
    # h (1 + 0.1 gamma) + 0.1 beta = (3 * 1.2 + 0.1, 1 * 0.8 + 0.6) = (3.7, 1.4)
    assert out[0].tolist() == pytest.approx([3.7, 1.4], abs=1e-6)


def test_film_and_film_scaled_differ_only_in_the_trunk():
    film = rsl_rl_cfg(preset_cfg("cpu", "film"))["critic"]
    scaled = rsl_rl_cfg(preset_cfg("cpu", "film-scaled"))["critic"]
    assert film["conditioning_scale"] == scaled["conditioning_scale"] == 0.1
    assert {k for k in film if film[k] != scaled[k]} == {"hidden_dims"}
    _, critic = build_models(preset_cfg("smoke", "film"))
    assert [m.scale for m in critic.modulators] == [0.1, 0.1, 0.1]
    other = dataclasses.replace(
        preset_cfg("smoke", "film"), model=dataclasses.replace(preset_cfg("smoke", "film").model, film_scale=1.0)
    )  # the other reading, one config field
    assert [m.scale for m in build_models(other)[1].modulators] == [1.0, 1.0, 1.0]


# ---------------------------------------------------------------------------------------------- item 2: MorFiC-H
def test_hyper_head_by_hand():
    head = HyperHead(latent_dim=1, in_dim=2, out_dim=1, rank=1, generator_hidden_dim=1, scale=0.1, activation="elu")
    base = nn.Linear(2, 1)
    _set_linear(base, [[1.0, 2.0]], [0.5])  # A_0 = (1, 2), c_0 = 0.5
    with torch.no_grad():
        head.basis.copy_(torch.tensor([[1.0, -1.0]]))  # U
    lin_in, _, lin_out = list(head.generator)
    _set_linear(lin_in, [[1.0]], [0.0])
    _set_linear(lin_out, [[3.0], [10.0]], [0.0, 0.0])  # z = 1: k = 3, k_c = 10
    h, z = torch.tensor([[1.0, 1.0]]), torch.tensor([[1.0]])
    # A_m = (1, 2) + 0.1 * 3 * (1, -1) = (1.3, 1.7); c_m = 0.5 + 0.1 * 10 = 1.5; V = 1.3 + 1.7 + 1.5 = 4.5
    a_m, c_m = (t.detach() for t in head.weights(base, z))
    assert a_m[0, 0].tolist() == pytest.approx([1.3, 1.7]) and float(c_m) == pytest.approx(1.5)
    with torch.no_grad():
        assert float(head(base, h, z)) == pytest.approx(4.5, abs=1e-6)
    assert float(head(base, h, torch.tensor([[0.0]])).detach()) == pytest.approx(3.5)  # z = 0: k = 0, the base head


def test_morfic_h_head_changes_with_z_while_the_trunk_does_not():
    cfg = preset_cfg("smoke", "hyper")
    assert rsl_rl_cfg(cfg)["critic"]["conditioning"] == "hyper_head"
    _, critic = build_models(cfg)
    assert isinstance(critic, MorficCritic) and critic.modulators is None and critic.head is not None
    with torch.no_grad():
        nn.init.normal_(critic.head.generator[-1].weight)  # move H_eta off its zero initialisation
    obs = _obs(cfg)
    latent = critic._latent(obs, None)
    z1, z2 = torch.randn(4, 64), torch.randn(4, 64)
    assert torch.equal(critic.features(latent, z1), critic.features(latent, z2))  # h_t: no z in the trunk
    assert not torch.allclose(critic.trunk(latent, z1), critic.trunk(latent, z2))  # V = A_m h_t + c_m: it moves
    a1, _ = critic.head.weights(critic.mlp[-1], z1)
    a2, _ = critic.head.weights(critic.mlp[-1], z2)
    assert not torch.allclose(a1, a2)


# ---------------------------------------------------------------------------------------------- item 3: one z
@pytest.mark.parametrize("variant", ["concat", "film", "film-scaled", "adaln", "hyper"])
def test_the_same_z_tensor_reaches_actor_and_critic(variant):
    cfg = preset_cfg("smoke", variant)
    actor, critic = build_models(cfg)
    actor.train(), critic.train()
    assert critic.morphology_encoder is None  # the critic owns no encoder
    encoder_params = {id(p) for p in actor.morphology_encoder.parameters()}
    all_params = [id(p) for p in (*actor.parameters(), *critic.parameters())]
    assert len(all_params) == len(set(all_params))  # each parameter once in PPO's optimiser
    assert encoder_params <= set(all_params)
    obs = _obs(cfg)
    z_actor = actor.encode_morphology(obs)
    assert critic.encode_morphology(obs) is z_actor
    assert actor.encode_morphology(_obs(cfg, seed=1)) is not z_actor  # other observations, another z


def test_both_losses_reach_the_shared_encoder():
    cfg = preset_cfg("smoke", "film")
    actor, critic = build_models(cfg)
    with torch.no_grad():
        for m in critic.modulators:
            nn.init.normal_(m.generator[-1].weight, std=0.1)  # so V depends on z_m
    actor.eval()  # no latent dropout: the three actor passes below are the same function
    obs = _obs(cfg)
    enc = actor.morphology_encoder[0].weight

    def grad_of(loss_fn) -> torch.Tensor:
        actor.zero_grad(), critic.zero_grad()
        loss_fn().backward()
        return enc.grad.clone()

    g_value = grad_of(lambda: critic(obs).square().mean())
    g_policy = grad_of(lambda: actor(obs).square().mean())
    g_both = grad_of(lambda: actor(obs).square().mean() + critic(obs).square().mean())
    assert g_value.abs().sum() > 0 and g_policy.abs().sum() > 0
    torch.testing.assert_close(g_both, g_value + g_policy)  # one z: the gradients of both losses add


def test_separate_encoders_remain_an_option():
    cfg = preset_cfg("smoke", "film")
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, shared_morphology_encoder=False))
    actor, critic = build_models(cfg)
    assert critic.morphology_encoder is not None
    obs = _obs(cfg)
    assert critic.encode_morphology(obs) is not actor.encode_morphology(obs)


# ---------------------------------------------------------------------------------------------- legacy configs
def test_a_config_recorded_before_the_new_fields_reads_as_the_old_method():
    doc = train_cfg_to_dict(preset_cfg("cpu", "film"))
    for key in LEGACY_VALUES:
        *parents, leaf = key.split(".")
        node = doc
        for part in parents:
            node = node[part]
        del node[leaf]
    old = train_cfg_from_dict(doc)
    assert old.model.film_scale == 1.0 and old.model.hyper_conditions == "layers"
    assert not old.model.shared_morphology_encoder
    assert old.env.obs.history_includes_current and old.env.rand.rerandomize_interval_s == 0.0
    doc["variant"] = "film-scaled"
    assert train_cfg_from_dict(doc).model.film_scale == 0.1  # film-scaled always had 0.1
    new = train_cfg_to_dict(preset_cfg("cpu", "film"))
    assert fill_legacy(new) == new  # a complete record is untouched: new runs keep the paper's values
    fresh = preset_cfg("cpu", "film")
    assert fresh.model.film_scale == 0.1 and fresh.model.shared_morphology_encoder
    assert not fresh.env.obs.history_includes_current and fresh.env.rand.rerandomize_interval_s == 10.0


def test_in_a_training_iteration_the_critic_encodes_no_morphology_of_its_own(tmp_path):
    """Rollout steps and PPO mini-batches: the critic reuses the actor's z_m (one encoder pass per actor pass)."""
    from morfic_cli.rl.runner import new_run
    from morfic_cli.store import Store

    cfg = dataclasses.replace(preset_cfg("smoke", "film"), max_iterations=1)
    run = new_run(Store(tmp_path / "s"), cfg, "z")
    actor, critic = run.runner.alg._raw_actor, run.runner.alg._raw_critic
    assert critic._shared_source == (actor,)
    calls = {"encoder": 0, "actor": 0, "critic": 0}
    actor.morphology_encoder.register_forward_hook(lambda *_: calls.__setitem__("encoder", calls["encoder"] + 1))
    actor.register_forward_hook(lambda *_: calls.__setitem__("actor", calls["actor"] + 1))
    critic.register_forward_hook(lambda *_: calls.__setitem__("critic", calls["critic"] + 1))
    run.train()
    # 8 rollout steps + 2 mini-batches x 1 epoch = 10 actor and 10 critic passes, plus the critic's bootstrap
    # value on the last observation (no actor pass there): 11 critic passes, 10 + 1 encoder passes.
    assert calls == {"actor": 10, "critic": 11, "encoder": 11}
