"""Training-conditions check: episode statistics by hand, the row configs, and every variant end to end."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from morfic_cli.evaluation.episodes import (
    agrees,
    curriculum_range,
    episode_stats,
    first_episode_lengths,
    training_reference,
)
from morfic_cli.evaluation.training_check import check_env_cfg, ladder
from morfic_cli.rl.config import cpu_preset
from morfic_cli.rl.variants import ACTUATION_ABLATIONS, VARIANTS

F, T_ = False, True


def test_first_episode_lengths_and_stats_by_hand():
    # T = 6 steps of dt 1 s, N = 3: env 0 falls on step 2 (index 1) and again later; env 1 times out on step 6;
    # env 2 falls on step 4 (index 3)
    done = np.zeros((6, 3), dtype=bool)
    done[1, 0] = done[4, 0] = True
    done[5, 1] = True
    done[3, 2] = True
    time_out = np.zeros_like(done)
    time_out[5, 1] = True
    length, ended = first_episode_lengths(done)
    assert length.tolist() == [2, 6, 4] and ended.tolist() == [T_, T_, T_]
    s = episode_stats(done, time_out, dt=1.0)
    # lengths 2, 6, 4 s: mean 4, population std sqrt(8/3), se = sqrt(8/3) / sqrt(3) = sqrt(8) / 3
    assert s.length_s == pytest.approx(4.0) and s.length_se_s == pytest.approx(math.sqrt(8) / 3)
    assert s.n == 3 and s.time_out_fraction == pytest.approx(1 / 3) and s.fall_fraction == pytest.approx(2 / 3)
    assert s.survival_5s == pytest.approx(1 / 3)  # envs 0 and 2 fell within 5 s; env 1 did not
    # a time-out before 5 s (a short episode) is not a fall: env 1 times out at 3 s instead
    done2, time_out2 = done.copy(), time_out.copy()
    done2[5, 1] = time_out2[5, 1] = False
    done2[2, 1] = time_out2[2, 1] = True
    s2 = episode_stats(done2, time_out2, dt=1.0)
    assert s2.survival_5s == pytest.approx(1 / 3) and s2.time_out_fraction == pytest.approx(1 / 3)
    # an env whose first episode has not ended counts T steps and neither as a fall nor as a time-out
    length, ended = first_episode_lengths(np.zeros((4, 1), dtype=bool))
    assert length.tolist() == [4] and ended.tolist() == [F]


def test_training_reference_by_hand():
    rows = [
        {"iteration": i, "episode_length_s": v, "curriculum.vx_max": c}
        for i, v, c in [(1, float("nan"), 1.0), (2, 10.0, 1.0), (3, 12.0, 1.5), (4, 14.0, 1.5), (5, 16.0, 2.0)]
    ]
    ref = training_reference(rows, window=3)
    # the last 3 rows that logged a length: 12, 14, 16 -> mean 14, sample std 2; vx_max 1.5 held over most of them
    assert ref.length_s == pytest.approx(14.0) and ref.sd_s == pytest.approx(2.0)
    assert ref.iterations == (3, 5) and ref.vx_max == 1.5
    assert training_reference(rows[:2], window=50).sd_s == 0.0  # one usable row
    with pytest.raises(ValueError):
        training_reference(rows[:1])


def test_curriculum_range_by_hand():
    # init (-1, 1), limit (-1, 3), step 0.5: the lower end is clamped at -1 from the start
    assert curriculum_range(2.5, (-1.0, 1.0), (-1.0, 3.0), 0.5) == (-1.0, 2.5)
    # a wider lower limit: 3 updates moved it from -1 to -2.5, clamped at -2
    assert curriculum_range(2.5, (-1.0, 1.0), (-2.0, 3.0), 0.5) == (-2.0, 2.5)
    assert curriculum_range(1.0, (-1.0, 1.0), (-2.0, 3.0), 0.5) == (-1.0, 1.0)


def test_agreement_is_two_combined_standard_errors():
    # sqrt(0.3^2 + 0.4^2) = 0.5 -> tolerance 1.0
    assert agrees(18.9, 0.3, 18.0, 0.4) and agrees(17.0, 0.3, 18.0, 0.4)
    assert not agrees(16.9, 0.3, 18.0, 0.4)
    assert agrees(0.4, 0.0, 0.4, 0.0) and not agrees(0.39, 0.0, 0.4, 0.0)


def test_each_row_changes_exactly_its_condition():
    env = cpu_preset("film").env
    rows = {c.name: c for c in ladder("go2", 1.0)}
    assert list(rows)[0] == "training" and list(rows)[-1] == "eval protocol" and len(rows) == 8
    train = check_env_cfg(env, rows["training"], 16, (-1.0, 2.5), 1.0)
    assert train.rand == env.rand and train.obs == env.obs and train.num_envs == 16
    assert train.rand.max_latency_steps == 2 and train.rand.enabled and train.rand.pushes and train.obs.noise
    assert train.commands.vx_init == (-1.0, 2.5) and train.commands.curriculum_step == 0.0
    assert train.commands.fixed is None and train.episode_length_s == env.episode_length_s
    lat = check_env_cfg(env, rows["no latency"], 16, (-1.0, 2.5), 1.0)
    assert lat.rand.max_latency_steps == 0 and lat.rand.enabled and lat.obs.noise
    nor = check_env_cfg(env, rows["no randomisation"], 16, (-1.0, 2.5), 1.0)
    assert not nor.rand.enabled and not nor.rand.pushes and not nor.obs.noise
    cmd = check_env_cfg(env, rows["command 1"], 16, (-1.0, 2.5), 1.0)
    assert cmd.commands.fixed == (1.0, 0.0, 0.0) and cmd.rand == env.rand
    protocol = rows["eval protocol"]
    assert not any(
        (
            protocol.train_morphology,
            protocol.randomisation,
            protocol.latency,
            protocol.sampled_actions,
            protocol.dropout,
            protocol.curriculum_commands,
        )
    )
    single = [c for c in rows.values() if c.name not in ("training", "eval protocol", "no randomisation")]
    for c in single:  # exactly one condition differs from training
        flags = (c.train_morphology, c.randomisation, c.latency, c.sampled_actions, c.dropout, c.curriculum_commands)
        assert flags.count(False) == 1, c.name


@pytest.mark.usefixtures("one_torch_thread")
# the ablations of film-act are its networks and env code with one env key changed (tests/rl/test_variants.py)
@pytest.mark.parametrize("variant", [v for v in VARIANTS if v not in ACTUATION_ABLATIONS])
def test_a_smoke_run_under_its_training_conditions_reproduces_its_training_episode_length(run_cli, variant):
    """Smoke preset with 0.2 s episodes (10 steps) so that training completes episodes to compare with."""
    code, _, err = run_cli(
        "train",
        "--variant",
        variant,
        "--preset",
        "smoke",
        "--set",
        "env.episode_length_s=0.2",
        "--set",
        "init_at_random_ep_len=false",
        "--quiet",
    )
    assert code == 0, err
    code, out, err = run_cli(
        "eval", f"runs/{variant}-smoke-s0", "--training-conditions", "--envs", "8", "--format", "json", "--quiet"
    )
    assert code == 0, err
    rows = json.loads(out)
    assert [r["conditions"] for r in rows] == [c.name for c in ladder("go2", 1.0)]
    for row in rows:
        assert row["steps"] == 10 and row["n"] == 8
        assert 0.02 <= row["length_s"] <= 0.2 + 1e-9
    train = rows[0]
    assert train["agrees"], train
    assert train["actions"] == "sampled" and train["dropout"] and train["morphology"] == "train support"
    from morfic_cli.store import Store

    store = Store(os.environ["MORFIC_STORE"])
    manifest = store.read_manifest(f"checks/training-conditions/{variant}-smoke-s0")
    assert manifest.inputs == {"checkpoint": store.read_manifest(f"runs/{variant}-smoke-s0").id}


def test_training_conditions_bad_input(run_cli):
    code, _, err = run_cli("eval", "runs/none", "--training-conditions", "--steps", "10")
    assert code == 1 and "Error:" in err and "--steps" in err
    code, _, err = run_cli("eval", "runs/none", "--training-conditions", "--robots", "go1,a1")
    assert code == 1 and "one robot" in err
    code, _, err = run_cli("eval", "runs/none", "--training-conditions", "--command-vx", "1.0,2.0")
    assert code == 1 and "one --command-vx" in err
