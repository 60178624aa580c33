"""MorficActor / MorficCritic: shapes, sizes, conditioning at init, gradient routing, export."""

from __future__ import annotations

import pytest
import torch
from rsl_rl.utils import resolve_class
from tensordict import TensorDict

from morfic_cli.errors import MorficError, UnknownNameError
from morfic_cli.rl.models import MorficActor, MorficCritic
from morfic_cli.rl.variants import STOCK, VARIANTS, model_cfgs

MLP_VARIANTS = tuple(v for v in VARIANTS if not STOCK[v].own_models and "actuation" not in STOCK[v].tables)
"""The variants built of MorficActor / MorficCritic (the external baselines': tests/rl/test_baselines.py); film-act and
ppo-act are film's and ppo's networks on another env (tests/envs/test_actuation.py)."""

N = 8
CONDITIONED = ("concat", "film", "film-scaled", "adaln", "hyper")
MULTIPLICATIVE = ("film", "film-scaled", "adaln", "hyper")


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Tiny models: one intra-op thread is faster and immune to CPU contention (2-thread runs were 30x slower
    next to a busy training process)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def make_obs(n: int = N, seed: int = 0) -> TensorDict:
    """Random observation groups with the env's shapes (morphology in [-1, 1])."""
    g = torch.Generator().manual_seed(seed)
    return TensorDict(
        {
            "policy": torch.randn(n, 48, generator=g),
            "history": torch.randn(n, 15, 48, generator=g),
            "critic": torch.randn(n, 15, 48, generator=g),
            "privileged": torch.randn(n, 18, generator=g),
            "morphology": torch.rand(n, 11, generator=g) * 2 - 1,
        },
        batch_size=[n],
    )


def with_morphology(obs: TensorDict, m: torch.Tensor) -> TensorDict:
    out = obs.clone()
    out["morphology"] = m
    return out


def tiny_cfgs(variant: str) -> tuple[dict, dict, dict]:
    """The variant's configs with tiny widths (the conditioning kind and scale unchanged)."""
    actor_cfg, critic_cfg, obs_groups = model_cfgs(variant)
    actor_cfg.update(
        hidden_dims=[32, 16],
        morphology_hidden_dims=[16],
        morphology_latent_dim=8,
        adaptation_hidden_dims=[16],
        privileged_latent_dim=4,
    )
    critic_cfg.update(
        hidden_dims=[32, 16],
        privileged_hidden_dims=[8],
        privileged_latent_dim=4,
        morphology_hidden_dims=[16],
        morphology_latent_dim=8,
        hyper_rank=2,
        generator_hidden_dim=16,
    )
    return actor_cfg, critic_cfg, obs_groups


def build(variant: str, obs: TensorDict, tiny: bool = True) -> tuple[MorficActor, MorficCritic]:
    """Build the models as rsl-rl's PPO.construct_algorithm does (resolve class_name, then call)."""
    actor_cfg, critic_cfg, obs_groups = tiny_cfgs(variant) if tiny else model_cfgs(variant)
    actor_class, actor_kw = resolve_class(actor_cfg)
    critic_class, critic_kw = resolve_class(critic_cfg)
    actor = actor_class(obs, obs_groups, "actor", 12, **actor_kw)
    return actor, critic_class(obs, obs_groups, "critic", 1, **critic_kw)


def n_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


@pytest.mark.parametrize("variant", MLP_VARIANTS)
def test_forward_shapes_at_paper_sizes(variant):
    obs = make_obs()
    actor, critic = build(variant, obs, tiny=False)
    assert isinstance(actor, MorficActor) and isinstance(critic, MorficCritic)
    assert actor(obs, stochastic_output=True).shape == (N, 12)
    assert actor(obs).shape == (N, 12)
    assert torch.allclose(actor.output_std, torch.ones(N, 12))  # initial action std 1.0
    assert actor.get_output_log_prob(actor(obs, stochastic_output=True)).shape == (N,)
    assert critic(obs).shape == (N, 1)
    assert actor.get_hidden_state() is None and critic.get_hidden_state() is None
    assert not actor.is_recurrent and not critic.is_recurrent


def test_parameter_counts_hand_computed():
    obs = make_obs()
    actor, _ = build("ppo", obs, tiny=False)
    # policy MLP on [history 720, z_priv_hat 16] = 736:
    #   736*512+512 = 377,344; 512*256+256 = 131,328; 256*128+128 = 32,896; 128*12+12 = 1,548 -> 543,116
    # adaptation 720 -> 256 -> 128 -> 16: 184,576 + 32,896 + 2,064 = 219,536; action std: 12
    assert n_params(actor) == 543_116 + 219_536 + 12 == 762_664
    _, critic = build("film", obs, tiny=False)
    # trunk on 736 -> [512, 256, 128] -> 1: 377,344 + 131,328 + 32,896 + 129 = 541,697
    # privileged encoder 18 -> 64 -> 16: 1,216 + 1,040 = 2,256
    # morphology encoder 11 -> 128 -> 64: 1,536 + 8,256 = 9,792
    # FiLM generators 64 -> 128 -> 2H: 3 * 8,320 + 129 * (1024 + 512 + 256) = 24,960 + 231,168 = 256,128
    assert n_params(critic) == 541_697 + 2_256 + 9_792 + 256_128 == 809_873


@pytest.mark.parametrize("variant", MULTIPLICATIVE)
def test_conditioned_critic_is_its_unconditioned_trunk_at_init(variant):
    torch.manual_seed(0)
    obs = make_obs()
    _, critic = build(variant, obs)
    value = critic(obs)
    zeroed = critic(with_morphology(obs, torch.zeros(N, 11)))
    other = critic(with_morphology(obs, torch.rand(N, 11) * 2 - 1))
    unconditioned = critic.trunk(critic.get_latent(obs), None)
    assert torch.equal(value, zeroed)
    assert torch.equal(value, other)
    assert torch.equal(value, unconditioned)
    if variant != "adaln":  # film and hyper reduce exactly to rsl-rl's plain MLP (adaln keeps its LayerNorm)
        assert torch.equal(value, critic.mlp(critic.get_latent(obs)))


@pytest.mark.parametrize("variant", CONDITIONED)
def test_critic_depends_on_morphology_after_one_value_step(variant):
    torch.manual_seed(0)
    obs = make_obs()
    _, critic = build(variant, obs)
    other = with_morphology(obs, torch.rand(N, 11) * 2 - 1)
    optimizer = torch.optim.Adam(critic.parameters(), lr=1e-2)
    loss = (critic(obs) - torch.randn(N, 1)).pow(2).mean()
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    with torch.no_grad():
        assert (critic(obs) - critic(other)).abs().max() > 1e-5


def _value_loss_grads(variant: str) -> tuple[MorficActor, MorficCritic]:
    """Actor and critic after one Adam step on a value loss (one optimiser over both, as rsl-rl), then a second
    value-loss backward whose gradients are left on the parameters."""
    torch.manual_seed(0)
    obs = make_obs()
    actor, critic = build(variant, obs)
    optimizer = torch.optim.Adam([*actor.parameters(), *critic.parameters()], lr=1e-2)
    target = torch.randn(N, 1)
    for _ in range(2):
        optimizer.zero_grad()
        (critic(obs) - target).pow(2).mean().backward()
        if _ == 0:
            optimizer.step()
    return actor, critic


@pytest.mark.parametrize("variant", MLP_VARIANTS)
def test_value_loss_reaches_a_morphology_encoder_only_when_the_critic_is_conditioned(variant):
    actor, critic = _value_loss_grads(variant)
    assert all(p.grad is None for p in actor.parameters())  # separate encoders: the value loss never hits the actor
    if variant in CONDITIONED:
        grads = [p.grad for p in critic.morphology_encoder.parameters()]
        assert all(g is not None for g in grads)
        assert sum(g.abs().sum() for g in grads) > 0
    else:
        assert critic.morphology_encoder is None
        assert "morphology" not in critic.obs_groups


@pytest.mark.parametrize("variant", MULTIPLICATIVE)
def test_value_gradient_to_morphology_encoder_is_zero_at_init(variant):
    # The zero-initialised generator output layer blocks d V / d z_m at init; only the generator's last layer learns
    # on the first step (documented in docs/training.md).
    torch.manual_seed(0)
    obs = make_obs()
    _, critic = build(variant, obs)
    critic(obs).sum().backward()
    assert all(p.grad.abs().sum() == 0 for p in critic.morphology_encoder.parameters())


@pytest.mark.parametrize("variant", MLP_VARIANTS)
def test_actor_morphology_path_exists_except_for_ppo(variant):
    torch.manual_seed(0)
    obs = make_obs()
    actor, _ = build(variant, obs)
    actor.eval()  # no latent dropout
    other = with_morphology(obs, torch.rand(N, 11) * 2 - 1)
    if not STOCK[variant].actor_morphology:  # ppo, and genloco (ppo's networks)
        assert actor.morphology_encoder is None
        assert torch.equal(actor(obs), actor(other))
        return
    assert (actor(obs) - actor(other)).abs().max() > 1e-6
    actor(obs).sum().backward()
    assert sum(p.grad.abs().sum() for p in actor.morphology_encoder.parameters()) > 0


def test_policy_loss_does_not_reach_the_adaptation_module():
    torch.manual_seed(0)
    obs = make_obs()
    actor, _ = build("film", obs)
    actions = actor(obs, stochastic_output=True)
    actor.get_output_log_prob(actions).sum().backward()
    assert all(p.grad is None for p in actor.adaptation.parameters())
    assert all(p.grad is not None for p in actor.mlp.parameters())
    assert actor.estimate_privileged(obs).shape == (N, 4)


def test_latent_dropout_only_in_train_mode():
    torch.manual_seed(0)
    obs = make_obs()
    actor, _ = build("film", obs)
    assert actor.latent_dropout.p == 0.2
    actor.train()
    assert not torch.equal(actor(obs), actor(obs))
    actor.eval()
    assert torch.equal(actor(obs), actor(obs))


def test_unknown_variant_lists_the_valid_ones():
    with pytest.raises(UnknownNameError) as info:
        model_cfgs("film-xl")
    assert isinstance(info.value, MorficError)
    assert "film-xl" in str(info.value)
    for name in VARIANTS:
        assert name in str(info.value)


def test_model_cfgs_class_names_and_groups():
    actor_cfg, critic_cfg, obs_groups = model_cfgs("film-scaled")
    assert actor_cfg["class_name"] == "morfic_cli.rl.models:MorficActor"
    assert critic_cfg["class_name"] == "morfic_cli.rl.models:MorficCritic"
    assert critic_cfg["hidden_dims"] == [1024, 512, 256] and critic_cfg["conditioning_scale"] == 0.1
    assert obs_groups == {"actor": ["history", "morphology"], "critic": ["critic", "privileged", "morphology"]}
    assert model_cfgs("ppo")[2] == {"actor": ["history"], "critic": ["critic", "privileged"]}
    assert model_cfgs("actor-only")[1]["conditioning"] == "none"
    assert model_cfgs("hyper")[1]["hyper_rank"] == 16
    assert model_cfgs("film")[0] is not model_cfgs("film")[0]  # fresh dicts


def test_critic_rejects_a_conditioning_without_morphology():
    obs = make_obs()
    _, critic_cfg, obs_groups = tiny_cfgs("film")
    critic_cfg.pop("class_name")
    critic_cfg["morphology_group"] = None
    with pytest.raises(ValueError, match="morphology_group"):
        MorficCritic(obs, obs_groups, "critic", 1, **critic_cfg)


@pytest.mark.filterwarnings("ignore:`torch.jit.script` is deprecated:DeprecationWarning")
@pytest.mark.parametrize("variant", ["ppo", "film"])
def test_jit_export_matches_the_deterministic_actor(variant):
    torch.manual_seed(0)
    obs = make_obs()
    actor, _ = build(variant, obs)
    actor.eval()
    exported = torch.jit.script(actor.as_jit())
    assert torch.allclose(exported(actor.export_input(obs)), actor(obs), atol=1e-6)


def test_obs_normalization_updates_from_flattened_history():
    obs = make_obs()
    actor_cfg, critic_cfg, obs_groups = tiny_cfgs("concat")
    actor_cfg["obs_normalization"] = critic_cfg["obs_normalization"] = True
    actor = MorficActor(obs, obs_groups, "actor", 12, **{k: v for k, v in actor_cfg.items() if k != "class_name"})
    critic = MorficCritic(obs, obs_groups, "critic", 1, **{k: v for k, v in critic_cfg.items() if k != "class_name"})
    actor.update_normalization(obs)
    critic.update_normalization(obs)
    assert actor(obs).shape == (N, 12) and critic(obs).shape == (N, 1)
    assert actor.obs_dim == critic.obs_dim == 15 * 48
