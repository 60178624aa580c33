"""MorficPPO on a dummy VecEnv: end-to-end runner, extra loss-dict metrics, adaptation step, EV arithmetic."""

from __future__ import annotations

import math

import pytest
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from tensordict import TensorDict

from morfic_cli.rl.ppo import EXTRA_LOSS_KEYS, MorficPPO, algorithm_cfg, explained_variance
from morfic_cli.rl.variants import STOCK, VARIANTS, model_cfgs

MLP_VARIANTS = tuple(v for v in VARIANTS if not STOCK[v].own_models and "actuation" not in STOCK[v].tables)
"""film-act and ppo-act are film's and ppo's networks on another env (tests/envs/test_actuation.py)."""
"""The variants built of MorficActor / MorficCritic (the external baselines': tests/rl/test_baselines.py)."""

NUM_ENVS = 8
STEPS = 4


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Tiny models: one intra-op thread is faster and immune to CPU contention (2-thread runs were 30x slower
    next to a busy training process)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


class DummyEnv(VecEnv):
    """rsl-rl VecEnv returning random observation groups with the env's shapes; no physics."""

    def __init__(self, num_envs: int = NUM_ENVS, seed: int = 0) -> None:
        self.num_envs = num_envs
        self.num_actions = 12
        self.max_episode_length = 20
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.device = "cpu"
        self.cfg = {}
        self.gen = torch.Generator().manual_seed(seed)
        self.morphology = torch.rand(num_envs, 11, generator=self.gen) * 2 - 1
        self.obs = self._observe()

    def _observe(self) -> TensorDict:
        n, g = self.num_envs, self.gen
        return TensorDict(
            {
                "policy": torch.randn(n, 48, generator=g),
                "history": torch.randn(n, 15, 48, generator=g),
                "critic": torch.randn(n, 15, 48, generator=g),
                "privileged": torch.randn(n, 18, generator=g),
                "morphology": self.morphology.clone(),
            },
            batch_size=[n],
        )

    def get_observations(self) -> TensorDict:
        return self.obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        assert actions.shape == (self.num_envs, 12)
        self.obs = self._observe()
        rewards = torch.randn(self.num_envs, generator=self.gen)
        dones = (torch.rand(self.num_envs, generator=self.gen) < 0.2).long()
        extras = {"time_outs": torch.zeros(self.num_envs), "log": {}}
        return self.obs, rewards, dones, extras


def tiny_train_cfg(variant: str, **algorithm) -> dict:
    actor_cfg, critic_cfg, obs_groups = model_cfgs(variant)
    actor_cfg.update(hidden_dims=[32, 16], morphology_hidden_dims=[16], adaptation_hidden_dims=[16])
    critic_cfg.update(hidden_dims=[32, 16], privileged_hidden_dims=[8], generator_hidden_dim=16, hyper_rank=2)
    return {
        "num_steps_per_env": STEPS,
        "save_interval": 100,
        "obs_groups": obs_groups,
        "actor": actor_cfg,
        "critic": critic_cfg,
        "algorithm": {**algorithm_cfg(), **algorithm},
    }


def run(variant: str, iterations: int = 2, **algorithm) -> tuple[OnPolicyRunner, list[dict]]:
    """Train on the dummy env; return the runner and the loss dict of every update."""
    torch.manual_seed(0)
    runner = OnPolicyRunner(DummyEnv(), tiny_train_cfg(variant, **algorithm), log_dir=None, device="cpu")
    losses: list[dict] = []
    update = runner.alg.update

    def recording_update() -> dict:
        losses.append(update())
        return losses[-1]

    runner.alg.update = recording_update
    runner.learn(iterations)
    return runner, losses


def test_explained_variance_hand_computed():
    r = torch.tensor([1.0, 2.0, 3.0, 4.0])
    # Var(R) (population) = (2.25 + 0.25 + 0.25 + 2.25) / 4 = 1.25
    # V = R: R - V = 0, Var = 0 -> EV = 1 - 0 / 1.25 = 1
    assert explained_variance(r, r) == 1.0
    # V = mean(R) = 2.5: R - V = R - 2.5 has Var(R) -> EV = 1 - 1.25 / 1.25 = 0
    assert explained_variance(r, torch.full((4,), 2.5)) == 0.0
    # V = [1, 2, 3, 3]: R - V = [0, 0, 0, 1], mean 0.25, Var = (3 * 0.0625 + 0.5625) / 4 = 0.1875
    # EV = 1 - 0.1875 / 1.25 = 0.85
    assert explained_variance(r, torch.tensor([1.0, 2.0, 3.0, 3.0])) == pytest.approx(0.85)
    # V = -R: R - V = 2R, Var = 4 * 1.25 = 5 -> EV = 1 - 5 / 1.25 = -3 (worse than the mean)
    assert explained_variance(r, -r) == pytest.approx(-3.0)
    # shape-agnostic: storage layout (T, N, 1)
    assert explained_variance(r.view(2, 2, 1), r.view(2, 2, 1)) == 1.0


def test_explained_variance_of_constant_returns_is_nan():
    assert math.isnan(explained_variance(torch.ones(4), torch.zeros(4)))


@pytest.mark.parametrize("variant", MLP_VARIANTS)
def test_runner_trains_every_variant_and_logs_the_extra_metrics(variant):
    runner, losses = run(variant)
    assert isinstance(runner.alg, MorficPPO)
    assert len(losses) == 2
    for loss in losses:
        for key in (*EXTRA_LOSS_KEYS, "value", "surrogate", "entropy"):
            assert math.isfinite(loss[key]), (key, loss)
        assert loss["value_loss"] == loss["value"]
        assert loss["kl"] >= 0.0
        assert 0.0 <= loss["clip_fraction"] <= 1.0
        assert loss["adaptation_error"] >= 0.0
        assert loss["explained_variance"] <= 1.0


def test_kl_and_clip_fraction_are_zero_when_nothing_moves():
    # No dropout and zero learning rates: every mini-batch sees the behaviour policy, ratio = 1 exactly.
    torch.manual_seed(0)
    cfg = tiny_train_cfg("film", learning_rate=0.0, adaptation_learning_rate=0.0)
    cfg["actor"]["latent_dropout"] = 0.0
    runner = OnPolicyRunner(DummyEnv(), cfg, log_dir=None, device="cpu")
    losses = []
    update = runner.alg.update
    runner.alg.update = lambda: losses.append(update()) or losses[-1]
    runner.learn(1)
    assert losses[0]["kl"] == 0.0
    assert losses[0]["clip_fraction"] == 0.0


def test_adaptation_step_moves_only_the_adaptation_module():
    torch.manual_seed(0)
    runner = OnPolicyRunner(DummyEnv(), tiny_train_cfg("film"), log_dir=None, device="cpu")
    alg: MorficPPO = runner.alg
    env = runner.env
    obs = env.get_observations()
    with torch.inference_mode():
        for _ in range(STEPS):
            obs, rewards, dones, extras = env.step(alg.act(obs))
            alg.process_env_step(obs, rewards, dones, extras)
        alg.compute_returns(obs)
    batch = next(alg.storage.mini_batch_generator(1, 1))

    def params() -> dict[str, torch.Tensor]:
        return {
            **{f"actor.{n}": p.detach().clone() for n, p in alg.actor.named_parameters()},
            **{f"critic.{n}": p.detach().clone() for n, p in alg.critic.named_parameters()},
        }

    before = params()
    errors = [alg._adaptation_step(batch).item() for _ in range(30)]
    after = params()
    assert errors[-1] < errors[0]  # regression to the (fixed) z_priv makes progress
    moved = sorted(n for n in before if not torch.equal(before[n], after[n]))
    assert moved == sorted(f"actor.adaptation.{n}" for n, _ in alg.actor.adaptation.named_parameters())


def test_save_and_load_keep_the_adaptation_optimizer(tmp_path):
    runner, _ = run("hyper", iterations=1)
    path = tmp_path / "model.pt"
    runner.save(str(path))
    assert "adaptation_optimizer_state_dict" in torch.load(path, weights_only=False)
    fresh = OnPolicyRunner(DummyEnv(seed=1), tiny_train_cfg("hyper"), log_dir=None, device="cpu")
    fresh.load(str(path))
    assert fresh.alg.adaptation_optimizer.state_dict()["state"].keys() == (
        runner.alg.adaptation_optimizer.state_dict()["state"].keys()
    )
    for a, b in zip(fresh.alg.actor.parameters(), runner.alg.actor.parameters(), strict=True):
        assert torch.equal(a, b)


def test_mismatched_latent_sizes_are_rejected():
    cfg = tiny_train_cfg("film")
    cfg["critic"]["privileged_latent_dim"] = 8
    with pytest.raises(ValueError, match="z_priv"):
        OnPolicyRunner(DummyEnv(), cfg, log_dir=None, device="cpu")


def _bf16_exact(x: torch.Tensor) -> bool:
    """True when every entry of x is a bf16 number (would survive a round trip through bf16 unchanged)."""
    return bool(torch.equal(x.to(torch.bfloat16).float(), x))


def test_mixed_precision_keeps_the_output_layers_in_float32_and_restores_them():
    torch.manual_seed(0)
    runner = OnPolicyRunner(DummyEnv(), tiny_train_cfg("film", use_mixed_precision=True), log_dir=None, device="cpu")
    alg = runner.alg
    obs = runner.env.get_observations()
    with torch.inference_mode():
        actions = alg.act(obs)
    # hidden layers ran in bf16, the value and the action mean in float32: not every value is a bf16 number
    assert alg.transition.values.dtype == torch.float32
    assert not _bf16_exact(alg.transition.values)
    assert not _bf16_exact(alg.transition.distribution_params[0])
    assert actions.dtype == torch.float32
    # outside act() the models are the plain rsl-rl modules again (checkpoints and export see nn.Linear)
    assert type(alg.actor.mlp[-1]) is torch.nn.Linear and type(alg.critic.mlp[-1]) is torch.nn.Linear
    # without mixed precision the hidden layers are float32 too: the same input gives a different (unrounded) value
    with torch.inference_mode():
        alg.use_mixed_precision = False
        full = alg.critic(obs)
    assert not torch.equal(full, alg.transition.values)
    torch.testing.assert_close(full, alg.transition.values, rtol=0.05, atol=0.05)


def test_mixed_precision_rollout_and_update_see_the_same_policy():
    # As test_kl_and_clip_fraction_are_zero_when_nothing_moves, in bf16: the rollout's log-probabilities are computed
    # in the update's precision, so a policy that does not move has ratio ~1 (bf16 sums in another order: not exact).
    torch.manual_seed(0)
    cfg = tiny_train_cfg("film", learning_rate=0.0, adaptation_learning_rate=0.0, use_mixed_precision=True)
    cfg["actor"]["latent_dropout"] = 0.0
    runner = OnPolicyRunner(DummyEnv(), cfg, log_dir=None, device="cpu")
    losses = []
    update = runner.alg.update
    runner.alg.update = lambda: losses.append(update()) or losses[-1]
    runner.learn(1)
    assert losses[0]["kl"] < 1e-4
    assert losses[0]["clip_fraction"] == 0.0


def test_mixed_precision_mini_batches_run_on_the_updated_weights():
    # One epoch of two mini-batches, no dropout: the KL of the second mini-batch is measured after the first one's
    # step, so it is > 0 in both precisions and of the same size. (A regression: one autocast region around the whole
    # update kept the bf16 weight copies of the first mini-batch, so KL stayed ~0 and the adaptive rate ran away.)
    kls = {}
    for mixed in (False, True):
        torch.manual_seed(0)
        cfg = tiny_train_cfg(
            "film", num_learning_epochs=1, num_mini_batches=2, use_mixed_precision=mixed, schedule="fixed"
        )
        cfg["actor"]["latent_dropout"] = 0.0
        runner = OnPolicyRunner(DummyEnv(), cfg, log_dir=None, device="cpu")
        losses = []
        update = runner.alg.update
        runner.alg.update = lambda update=update, losses=losses: losses.append(update()) or losses[-1]
        runner.learn(1)
        kls[mixed] = losses[0]["kl"]
    assert kls[False] > 1e-4
    assert 0.5 * kls[False] < kls[True] < 2.0 * kls[False]
