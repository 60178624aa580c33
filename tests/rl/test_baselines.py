"""The external baselines bot (BodyTransformer) and urma (URMA): sizes, graph mask, descriptions, end to end."""

from __future__ import annotations

import dataclasses
import json
import math

import mujoco
import numpy as np
import pytest
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from tensordict import TensorDict

from morfic_cli.config import EnvCfg
from morfic_cli.envs import observations as O
from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.errors import MorficError
from morfic_cli.morphology.apply import TemplateInfo
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.description import body_description
from morfic_cli.morphology.robots import load_robot
from morfic_cli.rl import bot, urma
from morfic_cli.rl.build import build_models, dummy_observations
from morfic_cli.rl.config import preset_cfg
from morfic_cli.rl.ppo import MorficPPO, algorithm_cfg
from morfic_cli.rl.variants import STOCK, table_variants

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _random_obs(cfg, n: int, seed: int = 0) -> TensorDict:
    obs = dummy_observations(cfg, n)
    gen = torch.Generator().manual_seed(seed)
    for key in obs.keys():
        obs[key] = torch.randn(obs[key].shape, generator=gen)
    return obs


def _count(model: torch.nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


# ---------------------------------------------------------------------------- registry
def test_both_are_stock_external_baselines_outside_the_papers_tables():
    assert {"bot", "urma"} <= set(table_variants("external"))
    for name in ("bot", "urma"):
        assert name not in table_variants("main") and name not in table_variants("ablation")
        assert STOCK[name].own_models and not STOCK[name].multiplicative
    assert preset_cfg("cpu", "urma").env.obs.body_tokens and not preset_cfg("cpu", "bot").env.obs.body_tokens


# ---------------------------------------------------------------------------- bot
def test_bot_parameter_counts_by_hand():
    d, f, layers = 64, 128, 8
    layer = (3 * d * d + 3 * d) + (d * d + d) + (d * f + f) + (f * d + d) + 2 * 2 * d  # attention, FF, 2 LayerNorms
    assert layer == 33_472
    actor = layers * layer + (12 + 1) * d + 12 * (3 + 1) * d + 13 * d + 12 * (d + 1) + 12  # + 12 action stds
    critic = layers * layer + (18 + 1) * d + 12 * (4 + 1) * d + 13 * d + 13 * (d + 1)
    assert (actor, critic) == (273_304, 274_509)
    a, c = build_models(preset_cfg("smoke", "bot"))
    assert (_count(a), _count(c)) == (actor, critic)
    assert (bot.parameter_count(), bot.parameter_count(critic=True)) == (actor, critic)


def test_bot_graph_mask_is_the_kinematic_tree():
    allowed = ~bot.attention_mask()
    names = bot.NODE_NAMES
    assert names[:4] == ("root", "FL_hip", "FL_thigh", "FL_calf") and len(names) == 13
    expect = {
        "root": {"root", "FL_hip", "FR_hip", "RL_hip", "RR_hip"},
        "FL_hip": {"root", "FL_hip", "FL_thigh"},
        "FR_thigh": {"FR_hip", "FR_thigh", "FR_calf"},
        "RR_calf": {"RR_thigh", "RR_calf"},
    }
    for node, neighbours in expect.items():
        i = names.index(node)
        assert {names[j] for j in range(13) if allowed[i, j]} == neighbours
    assert torch.equal(allowed, allowed.T) and int(allowed.sum()) == 13 + 2 * 12  # self + both ends of 12 edges


def test_bot_one_layer_mixes_only_neighbours():
    """Changing a token changes, after one masked layer, exactly the nodes that attend to it."""
    torch.manual_seed(0)
    layer = torch.nn.TransformerEncoderLayer(16, 2, 32, dropout=0.0, batch_first=True)
    mask = bot.attention_mask()
    bias = torch.zeros(13, 13).masked_fill(mask, float("-inf"))
    x = torch.randn(1, 13, 16)
    y = x.clone()
    y[0, 2] += 1.0  # FL_thigh
    changed = (bot.encoder_layer(layer, x, bias) - bot.encoder_layer(layer, y, bias)).abs().amax(-1)[0] > 1e-6
    assert [bot.NODE_NAMES[i] for i in range(13) if changed[i]] == ["FL_hip", "FL_thigh", "FL_calf"]


@pytest.mark.parametrize("train", [True, False])
def test_bot_encoder_computes_torchs_transformer_encoder(train):
    a, c = build_models(preset_cfg("smoke", "bot"))
    torch.manual_seed(1)
    for body in (a.body, c.body):
        for p in body.parameters():
            p.data.normal_(0.0, 0.3)  # away from the near-identity initialisation, so a wrong layer would show
        body.train(train)
        root = torch.randn(5, body.root_embedding.in_features)
        joints = torch.randn(5, 12, body.joint_embedding.weight.shape[1])
        with torch.no_grad():
            ours = body(root, joints)
            torchs = body.encoder(body.tokens(root, joints), mask=body.mask)
        torch.testing.assert_close(ours, torchs, rtol=1e-4, atol=1e-4)


def test_bot_tokens_come_from_o_t():
    frame = torch.arange(48.0)[None]
    root, joints = bot.split_frame(frame)
    assert root.tolist() == [list(range(12))]
    assert joints[0, 4].tolist() == [16.0, 28.0, 40.0]  # joint 4 (FR_thigh): q - q0, qdot, previous action


def test_bot_actor_reads_only_the_newest_frame_and_exports_the_same_actions():
    cfg = preset_cfg("smoke", "bot")
    actor, _ = build_models(cfg)
    actor.eval()
    obs = _random_obs(cfg, 6)
    older = obs.clone()
    older["history"][:, :-1] = 0.0
    with torch.no_grad():
        mean = actor(obs)
        torch.testing.assert_close(actor(older), mean)
        exported = actor.as_onnx()(obs["history"].flatten(1))
    torch.testing.assert_close(exported, mean, rtol=1e-5, atol=1e-5)


# ---------------------------------------------------------------------------- urma
def test_urma_parameter_counts_by_hand():
    def lin(a, b):
        return (a + 1) * b

    pools = (lin(18, 64) + 2 * 64 + lin(64, 64) + lin(3, 4) + 1) + (lin(6, 32) + 2 * 32 + lin(32, 32) + lin(2, 4) + 1)
    latent = 64 * 4 + 32 * 4 + 12
    actor = (
        pools
        + lin(latent, 512)
        + 2 * 512
        + lin(512, 256)
        + lin(256, 128)  # core
        + lin(18, 128)
        + 2 * 128
        + lin(128, 128)  # description latent
        + lin(128 + 4 + 128, 128)
        + 2 * 128
        + lin(128, 1)
        + 12
    )  # decoder, action stds
    critic = pools + lin(latent + 18, 512) + 2 * 512 + lin(512, 256) + lin(256, 128) + lin(128, 1)
    assert (actor, critic) == (428_395, 384_735)
    a, c = build_models(preset_cfg("smoke", "urma"))
    assert (_count(a), _count(c)) == (actor, critic)
    assert (urma.parameter_count(), urma.parameter_count(critic=True)) == (actor, critic)


def test_urma_pooling_weights_are_a_softmax_over_slots_with_the_learned_temperature():
    torch.manual_seed(0)
    pool = urma.AttentionPool(18, 3, 64)
    with torch.no_grad():
        pool.log_temperature.fill_(math.log(0.5 - urma.MIN_TEMPERATURE))  # T = 0.5
    d = torch.randn(7, 12, 18)
    w = pool.weights(d)
    torch.testing.assert_close(w.sum(-1), torch.ones(7, 12))
    logits = torch.tanh(pool.mask(d)) / 0.5
    torch.testing.assert_close(w, logits.exp() / logits.exp().sum(-1, keepdim=True))
    s = torch.randn(7, 12, 3)
    latent, values = pool(d, s)
    by_hand = sum(w[:, j, :, None] * torch.nn.functional.elu(pool.value(s[:, j]))[:, None, :] for j in range(12))
    torch.testing.assert_close(latent, by_hand.flatten(1))
    assert values.shape == (7, 12, 4)


def test_go2_description_by_hand():
    spec = load_robot("go2")
    model = build_model(spec, floor=True, sim_sensors=True)
    joints, feet = body_description(
        model, mujoco.MjData(model), TemplateInfo.from_model(model), spec.default_qpos, np.asarray(spec.velocity_limit)
    )
    hip, thigh = joints[0], joints[1]  # FL hip, FL thigh
    np.testing.assert_allclose(hip[0:6], [*spec.hip_pos[0], 1.0, 0.0, 0.0], atol=1e-9)
    q = spec.default_qpos[0]  # the hip's default angle turns the thigh joint about x
    offset = spec.thigh_offset[0]
    by_hand = spec.hip_pos[0] + [offset[0], offset[1] * math.cos(q), offset[1] * math.sin(q)]
    np.testing.assert_allclose(thigh[0:3], by_hand, atol=1e-9)
    np.testing.assert_allclose(thigh[3:6], [0.0, math.cos(q), math.sin(q)], atol=1e-9)
    np.testing.assert_allclose(
        thigh[6:18],
        [
            1,
            spec.default_qpos[1],
            *spec.joint_range[0, 1],
            spec.torque_limit[1],
            spec.velocity_limit[1],
            0.0,
            spec.armature[1],
            spec.kp,
            spec.kd,
            spec.descriptor[0],
            model.body_subtreemass[1],
        ],
        rtol=1e-6,
    )
    assert (spec.kp, spec.kd) == (20.0, 0.5)
    assert joints[2, 6] == 0 and joints[2, 16] == pytest.approx(spec.descriptor[1])  # calf: no child, calf mass
    np.testing.assert_allclose(feet[:, 3:5], [[spec.foot_radius, spec.descriptor[3]]] * 4, rtol=1e-6)


def test_env_describes_the_model_it_built():
    """Descriptor mode: the Go2 template with AlienGo's masses and limits (Go2's gains); full mode: AlienGo's own
    model (its gains, and its own thigh limit 4.189 rad where its descriptor says 3.142)."""
    cfg = dataclasses.replace(EnvCfg(num_envs=2), obs=dataclasses.replace(EnvCfg().obs, body_tokens=True))
    aliengo = load_robot("aliengo")
    for mode, kp, upper in (
        ("descriptor", 20.0, aliengo.descriptor[8]),
        ("full", aliengo.kp, aliengo.joint_range[0, 1, 1]),
    ):
        env = LocomotionEnv(cfg, mode=mode, robot="aliengo")
        obs = env.get_observations()
        assert obs["joint_description"].shape == (2, 12, 18) and obs["foot_state"].shape == (2, 4, 2)
        thigh = obs["joint_description"][0, 1]
        assert float(thigh[14]) == pytest.approx((kp - 150.0) / 150.0)  # normalised Kp
        assert float(thigh[16]) == pytest.approx((aliengo.descriptor[0] - 0.6) / 0.6, rel=1e-5)  # thigh mass
        assert float(thigh[9]) == pytest.approx(upper / 4.6, rel=1e-5)  # thigh upper limit: the model's
        before = obs["joint_description"].clone()
        env.step(torch.zeros(2, 12))
        torch.testing.assert_close(env.get_observations()["joint_description"], before)  # constant per model
        env.close()


def test_urma_env_state_round_trip():
    """A train-mode env with the token groups continues exactly from its state dict (clocks, descriptions)."""
    cfg = dataclasses.replace(EnvCfg(num_envs=3), obs=dataclasses.replace(EnvCfg().obs, body_tokens=True))
    a, b = LocomotionEnv(cfg, seed=1), LocomotionEnv(cfg, seed=2)
    actions = torch.randn(6, 3, 12, generator=torch.Generator().manual_seed(0)) * 0.3
    for t in range(3):
        a.step(actions[t])
    b.load_state_dict(a.state_dict())
    for t in range(3, 6):
        obs_a, obs_b = a.step(actions[t])[0], b.step(actions[t])[0]
        for group in O.BODY_TOKEN_GROUPS:
            torch.testing.assert_close(obs_a[group], obs_b[group], rtol=0, atol=0)
    assert float(obs_a["foot_state"][..., 1].max()) > 0.0  # the clocks ran
    a.close(), b.close()


def test_touchdown_clock():
    t = torch.tensor([[0.3, 0.0, 1.0, 0.5]])
    now = torch.tensor([[True, True, False, True]])
    before = torch.tensor([[False, True, False, True]])
    assert O.touchdown_time(t, now, before, 0.02)[0].tolist() == pytest.approx([0.0, 0.02, 1.02, 0.52])


def test_urma_export_is_refused_with_an_error():
    actor, _ = build_models(preset_cfg("smoke", "urma"))
    with pytest.raises(MorficError, match="urma cannot be exported"):
        actor.as_onnx()


# ---------------------------------------------------------------------------- PPO
class _RandomEnv(VecEnv):
    """Random observation groups with the shapes a config's env gives; no physics."""

    def __init__(self, cfg, num_envs: int = 8) -> None:
        self.cfg, self.num_envs, self.num_actions, self.max_episode_length = {}, num_envs, 12, 20
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.device = "cpu"
        self.train_cfg, self.step_count = cfg, 0

    def get_observations(self) -> TensorDict:
        return _random_obs(self.train_cfg, self.num_envs, self.step_count)

    def step(self, actions):
        self.step_count += 1
        n = self.num_envs
        return (
            self.get_observations(),
            torch.randn(n),
            (torch.rand(n) < 0.2).long(),
            {"time_outs": torch.zeros(n), "log": {}},
        )


@pytest.mark.parametrize("variant", ["bot", "urma"])
def test_morfic_ppo_trains_a_baseline_without_an_adaptation_module(variant):
    cfg = preset_cfg("smoke", variant)
    actor_cfg, critic_cfg, groups = STOCK[variant].model_cfgs()
    runner_cfg = {
        "num_steps_per_env": 4,
        "save_interval": 100,
        "obs_groups": groups,
        "actor": actor_cfg,
        "critic": critic_cfg,
        "algorithm": {**algorithm_cfg(), "num_learning_epochs": 1, "num_mini_batches": 2, "use_mixed_precision": True},
    }
    torch.manual_seed(0)
    runner = OnPolicyRunner(_RandomEnv(cfg), runner_cfg, log_dir=None, device="cpu")
    assert isinstance(runner.alg, MorficPPO) and runner.alg.adaptation_optimizer is None
    losses = []
    update = runner.alg.update
    runner.alg.update = lambda: losses.append(update()) or losses[-1]
    before = [p.detach().clone() for p in runner.alg.actor.parameters()]
    runner.learn(1)
    (loss,) = losses
    assert math.isnan(loss["adaptation_error"])  # no adaptation module, nothing regressed
    assert all(math.isfinite(loss[k]) for k in ("value", "surrogate", "entropy", "kl", "clip_fraction"))
    assert any(not torch.equal(a, b) for a, b in zip(before, runner.alg.actor.parameters(), strict=True))
    assert "adaptation_optimizer_state_dict" not in runner.alg.save()


# ---------------------------------------------------------------------------- end to end
@pytest.mark.parametrize("variant", ["bot", "urma"])
def test_smoke_train_then_full_mode_eval(run_cli, variant):
    code, out, err = run_cli("train", "--variant", variant, "--preset", "smoke", "--format", "json", "--quiet")
    assert code == 0, err
    code, out, err = run_cli(
        "eval",
        f"runs/{variant}-smoke-s0",
        "--robots",
        "aliengo",
        "--mode",
        "full",
        "--steps",
        "5",
        "--envs",
        "2",
        "--format",
        "json",
        "--quiet",
    )
    assert code == 0, err
    (row,) = json.loads(out)
    assert row["robot"] == "aliengo" and row["mode"] == "full" and row["num_envs"] == 2
    assert math.isfinite(row["vx_mean"])


def test_a_urma_critic_is_scored_on_films_fixed_rollout(run_cli):
    """film's actor does not read URMA's token groups; its rollout records them for the urma critic."""
    for variant in ("film", "urma"):
        code, _, err = run_cli("train", "--variant", variant, "--preset", "smoke", "--quiet")
        assert code == 0, err
    code, out, err = run_cli(
        "diagnose",
        "--fixed-rollout",
        "go2",
        "--actor",
        "runs/film-smoke-s0",
        "--critics",
        "runs/urma-smoke-s0,runs/film-smoke-s0",
        "--steps",
        "30",
        "--envs",
        "2",
        "--trunc-eps",
        "0.9",
        "--format",
        "json",
        "--quiet",
    )
    assert code == 0, err
    rows = {r["variant"]: r for r in json.loads(out)}
    assert set(rows) == {"mc", "urma", "film"}
    assert 0.0 <= rows["urma"]["flip"] <= 1.0 and math.isfinite(rows["urma"]["cos_grad"])


def test_urma_without_its_token_groups_is_an_error(run_cli):
    code, _, err = run_cli("train", "--variant", "urma", "--preset", "smoke", "--set", "env.obs.body_tokens=false")
    assert code == 1
    assert "Error: variant urma reads the observation groups joint_description" in err and "Traceback" not in err
