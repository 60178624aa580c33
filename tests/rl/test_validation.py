"""Config value rules (morfic_cli/validation.py): boundaries by hand, every rule names a real key, memory estimate."""

from __future__ import annotations

import math

import pytest

from morfic_cli import validation as V
from morfic_cli.errors import MorficError
from morfic_cli.rl.config import apply_overrides, preset_cfg, valid_keys


def test_every_rule_names_a_config_key():
    keys = set(valid_keys(preset_cfg("smoke")))
    assert set(V.RULES) <= keys, sorted(set(V.RULES) - keys)


def test_every_preset_passes():
    for preset in ("smoke", "cpu"):
        V.validate_train_cfg(preset_cfg(preset))


@pytest.mark.parametrize(
    ("rule", "good", "bad"),
    [
        (V.number(0, 1, lo_open=True), [1e-12, 0.5, 1], [0, -1, 1.0000001, math.nan, math.inf, True, "0.5", None]),
        (V.number(0, 1), [0, 1], [-1e-9, 1.5]),
        (V.number(0, 1, lo_open=True, hi_open=True), [0.5], [0, 1]),
        (V.integer(1, 3), [1, 3], [0, 4, 2.0, True]),
        (V.one_of("adaptive", "fixed"), ["fixed"], ["Fixed", "", None]),
        (V.LAYERS, [[1], (512, 256, 128)], [[], [0], [1.5], [16385], "512", [1] * 9]),
        (V.ordered_pair(-10, 10), [[-1, 1], (2, 2)], [[2, 1], [1], [-11, 0], [0, math.nan]]),
        (V.optional(V.number(0, lo_open=True)), [None, 3.0], [0, -1]),
    ],
)
def test_rule_boundaries(rule, good, bad):
    assert all(rule.test(v) for v in good), [v for v in good if not rule.test(v)]
    assert not any(rule.test(v) for v in bad), [v for v in bad if rule.test(v)]


def test_all_broken_rules_are_listed_in_one_error():
    with pytest.raises(MorficError) as info:
        apply_overrides(preset_cfg("smoke"), ["ppo.gamma=2", "env.decimation=0", "env.rewards.w_lin=NaN"])
    text = str(info.value)
    assert "ppo.gamma = 2.0: must be a finite number in (0, 1]" in text
    assert "env.decimation = 0: must be an integer in [1, 100]" in text
    assert "env.rewards.w_lin = nan: must be finite" in text


def test_mini_batches_may_not_exceed_the_batch():
    cfg = preset_cfg("smoke")  # 8 envs x 8 steps = 64 transitions
    apply_overrides(cfg, ["ppo.num_mini_batches=64"])
    with pytest.raises(MorficError, match="at most the 64 transitions"):
        apply_overrides(cfg, ["ppo.num_mini_batches=65"])


def test_env_count_memory_estimate(monkeypatch):
    monkeypatch.setattr(V, "available_memory", lambda: 1000 * V.TRAIN_BYTES_PER_ENV)
    apply_overrides(preset_cfg("smoke"), ["env.num_envs=1000"])
    with pytest.raises(MorficError, match=r"env.num_envs = 1001 needs about .* use at most about 1000 envs"):
        apply_overrides(preset_cfg("smoke"), ["env.num_envs=1001"])
    monkeypatch.setattr(V, "available_memory", lambda: 10 * V.SIM_BYTES_PER_ENV)
    V.check_args(envs=10)
    with pytest.raises(MorficError, match="--envs = 11 needs"):
        V.check_args(envs=11)


def test_command_vx_parsing():
    assert V.parse_commands_vx("2.0,2.5") == [2.0, 2.5]
    assert V.parse_commands_vx("-10") == [-10.0]
    for bad in ("nan", "inf", "", "2,,", "10.5", "a"):
        with pytest.raises(MorficError, match="--command-vx"):
            V.parse_commands_vx(bad)


# ---------------------------------------------------------------------------- stored configs (issue 53)
def test_network_weights_by_hand():
    # (16 x 48 + 128) x 512 + 512 x 256 + 256 x 128: the paper's trunk on a 16-frame history
    assert V.network_weights(16, [512, 256, 128]) == 896 * 512 + 512 * 256 + 256 * 128 == 622592
    assert V.network_weights(1, [2]) == (48 + 128) * 2


def test_the_network_bound_applies_to_training_configs_too():
    cfg = preset_cfg("smoke")
    assert cfg.env.obs.history_len == 15
    # (15 x 48 + 128) x 16384 + 16384 x 2048 = 47448064 <= 2^26 = 67108864
    apply_overrides(cfg, ["model.actor_hidden_dims=[16384,2048]"])
    # (15 x 48 + 128) x 16384 + 16384 x 16384 = 13893632 + 268435456 = 282329088
    with pytest.raises(
        MorficError,
        match=r"model.actor_hidden_dims = \[16384, 16384\] with env.obs.history_len = "
        r"15: 282329088 weights, more than the 67108864",
    ):
        apply_overrides(cfg, ["model.actor_hidden_dims=[16384,16384]"])


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"model.actor_hidden_dims": [-5]}, "model.actor_hidden_dims = [-5]: must be a list of 1 to 8 layer widths"),
        ({"env.obs.history_len": -3}, "env.obs.history_len = -3: must be an integer in [1, 1000]"),
        ({"env.sim.physics_dt": 0}, "env.sim.physics_dt = 0.0: must be a finite number in (0, 0.1]"),
        ({"model.critic_hidden_dims": []}, "model.critic_hidden_dims = []: must be null or a list of 1 to 8"),
        ({"variants": ["film"]}, "unknown config key 'variants'"),
        ({"seed": "0"}, "config key 'seed' takes an integer; got '0'"),
        ({"env": {}}, None),  # every field missing: the legacy values fill them (a record of an older morfic)
    ],
)
def test_a_stored_config_is_checked_like_a_training_config(change, problem):
    from crafted_bundles import run_config

    found = V.stored_cfg_problem(run_config(**change))
    assert found == problem or (problem is not None and found.startswith(problem)), found


def test_check_stored_cfg_names_the_run_and_returns_the_config():
    from crafted_bundles import run_config

    assert V.check_stored_cfg(run_config(), "runs/x").variant == "film"
    with pytest.raises(MorficError, match=r"^run runs/x@2 has an invalid stored config: env.obs.history_len = -3"):
        V.check_stored_cfg(run_config(**{"env.obs.history_len": -3}), "runs/x@2")
    assert V.stored_cfg_problem([1]) == "its config is list, not an object"
