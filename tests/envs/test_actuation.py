"""Issue 58: the extended descriptor, its bounded encoding, heavier bodies with gains by mass, the morphology
curriculum and the eval mode ``actuation-matched`` (values by hand from robots/*.toml)."""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np
import pytest
import torch
from fake_runs import fake_run

from morfic_cli.config import ActuationRandCfg, GeometryRandCfg
from morfic_cli.envs.actuation import (
    Actuation,
    initial_upper,
    log_mass_width,
    sample_actuation,
    widen_mass_scale,
)
from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.envs.observations import extended_morphology_obs
from morfic_cli.morphology import extended as E
from morfic_cli.morphology.procedural import GeometrySample, generate_robot
from morfic_cli.morphology.robots import load_robot
from morfic_cli.rl.config import preset_cfg

GO2_MASS = 6.921 + 4 * (0.678 + 1.152 + 0.154 + 0.040 + 3 * 0.089)  # base + 4 x (links + 3 rotors) = 16.085 kg
B1_MASS = 29.45 + 4 * (2.15 + 4.30 + 1.05 + 0.05 + 0.199 + 0.266 + 0.266)  # 62.574 kg
ALIENGO_DESCRIPTOR_MASS = 11.644 + 4 * (1.000 + 0.639 + 0.207 + 0.060 + 3 * 0.089)  # Go2's rotors: 20.336 kg


def _idx(name: str) -> int:
    return E.EXTENDED_NAMES.index(name)


def test_extended_descriptor_of_go2_and_b1_by_hand():
    go2, b1 = E.extended_descriptor(load_robot("go2")), E.extended_descriptor(load_robot("b1"))
    assert go2.shape == b1.shape == (28,)
    np.testing.assert_allclose(go2[:11], load_robot("go2").descriptor)  # the paper's 11 first, unchanged
    for vec, expect in (
        (
            go2,
            {
                "total_mass": GO2_MASS,
                "kp": 20.0,
                "kd": 0.5,
                "torque_limit_hip": 23.7,
                "torque_limit_calf": 45.43,
                "base_length": 0.3762,
                "hip_x": 0.1934,
                "hip_y": 0.0465,
                "thigh_offset": 0.0955,
                "thigh_length": 0.213,
                "calf_radius": 0.013,
                "foot_radius": 0.022,
            },
        ),
        (
            b1,
            {
                "base_mass": 29.45,
                "total_mass": B1_MASS,
                "kp": 250.0,
                "kd": 10.0,
                "torque_limit_thigh": 93.33,
                "torque_limit_calf": 140.0,
                "base_width": 0.30,
                "calf_length": 0.35,
                "foot_radius": 0.04,
            },
        ),
    ):
        for name, value in expect.items():
            assert vec[_idx(name)] == pytest.approx(value, abs=1e-9), name


def test_generated_robot_geometry_is_template_times_factors():
    go2 = load_robot("go2")
    sample = GeometrySample(
        1.1, np.array([1.2, 0.9, 1.0]), 1.0, np.array([1.05, 0.95]), 1.0, 0.8, 1.25, 1.0, 1.0, np.ones(4)
    )
    vec = E.extended_descriptor(generate_robot(go2, sample, GeometryRandCfg(gains_with_mass=False)))
    assert vec[_idx("base_length")] == pytest.approx(0.3762 * 1.1 * 1.2)
    assert vec[_idx("hip_y")] == pytest.approx(0.0465 * 1.1 * 0.9 * 0.95)
    assert vec[_idx("calf_length")] == pytest.approx(0.213 * 0.8 * 1.1)
    assert vec[_idx("thigh_length")] == pytest.approx(0.213 * 0.8 * 1.1 * 1.25)
    assert vec[_idx("kp")] == 20.0  # gains_with_mass off: Go2's


def test_bounded_encoding_of_a_far_out_input_by_hand():
    b1 = E.extended_descriptor(load_robot("b1"))
    enc = E.encode(b1)
    # Kp 250: eps = 5 % of Go2's 20 = 1; support 10..40 -> z = 2 (ln 251 - ln 11) / (ln 41 - ln 11) - 1 = 3.754
    z = 2 * (math.log(251) - math.log(11)) / (math.log(41) - math.log(11)) - 1
    assert z == pytest.approx(3.754, abs=1e-3)
    assert enc[_idx("kp")] == pytest.approx(3 * math.tanh(z / 3), abs=1e-12)
    assert enc[_idx("kp")] == pytest.approx(2.546, abs=1e-3)
    # joint limits are not logged: B1's hip max 0.75 rad vs the support 0.8..1.1 -> z = 2 (-0.05) / 0.3 - 1 = -4/3
    assert enc[_idx("hip_limit_max")] == pytest.approx(3 * math.tanh(-4 / 9), abs=1e-12)
    # Go2 itself sits at the centre of entries 11-27 (Go2 / 2 .. x 2 in log space, up to eps)
    assert np.abs(E.encode(E.extended_descriptor(load_robot("go2")))[11:]).max() < 0.05


@pytest.mark.parametrize("robot", ["b1", "anymal_c"])
def test_heavy_robots_and_absurd_inputs_stay_finite_and_bounded(robot):
    vec = E.extended_descriptor(load_robot(robot))
    absurd = vec * np.where(E.LOG_SCALED, 1e4, 1.0)  # 10^4 x every mass, gain, torque and length
    raw = torch.as_tensor(np.stack([vec, absurd, np.zeros(28)]))
    enc = extended_morphology_obs(raw)
    assert torch.isfinite(enc).all() and enc.abs().max() <= E.BOUND  # float32 rounds 3 tanh(large) to 3.0
    np.testing.assert_allclose(enc.numpy(), E.encode(raw.numpy()), atol=1e-6)  # torch == numpy
    # the paper's 11-D normalisation puts B1 at +13 to +18 (docs/falls.md); here every entry stays below 3
    assert np.abs(E.encode(vec)).max() < 2.99


def test_sample_actuation_follows_mass_by_hand():
    go2 = Actuation(
        torch.tensor([20.0], dtype=torch.float64),
        torch.tensor([0.5], dtype=torch.float64),
        torch.tensor([[23.7, 23.7, 45.43]], dtype=torch.float64),
    )
    cfg = ActuationRandCfg(enabled=True, torque_mass_exponent=0.75)
    act = sample_actuation(torch.tensor([2 * GO2_MASS, GO2_MASS]), go2, GO2_MASS, cfg, torch.Generator())
    np.testing.assert_allclose(act.kp.numpy(), [40.0, 20.0])
    np.testing.assert_allclose(act.kd.numpy(), [1.0, 0.5])
    np.testing.assert_allclose(act.torque_limit[0].numpy(), np.array([23.7, 23.7, 45.43]) * 2**0.75)  # 39.86 ...
    jitter = dataclasses.replace(cfg, kp_factor=(2.0, 2.0), gains_with_mass=False, torque_mass_exponent=0.0)
    act = sample_actuation(torch.tensor([2 * GO2_MASS]), go2, GO2_MASS, jitter, torch.Generator())
    assert float(act.kp[0]) == pytest.approx(40.0) and float(act.kd[0]) == 0.5
    np.testing.assert_allclose(act.torque_limit[0].numpy(), [23.7, 23.7, 45.43])


def test_curriculum_widens_on_a_crafted_sequence():
    cfg = ActuationRandCfg(
        enabled=True,
        mass_scale=(0.8, 4.0),
        curriculum=True,
        curriculum_init=1.25,
        curriculum_step=1.25,
        curriculum_threshold=0.7,
    )
    upper = torch.tensor(initial_upper(cfg), dtype=torch.float64)
    seen, changed = [], []
    for tracking in (0.5, 0.75, 0.69, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9):
        changed.append(bool(widen_mass_scale(upper, torch.tensor(tracking, dtype=torch.float64), cfg)))
        seen.append(float(upper))
    # 1.25 -> x1.25 on each pass of 0.7: 1.5625, 1.953125, 2.44140625, 3.0517578125, 3.814697265625, then 4.0 (cap)
    assert seen == pytest.approx([1.25, 1.5625, 1.5625, 1.953125, 2.44140625, 3.0517578125, 3.814697265625, 4.0, 4.0])
    assert changed == [False, True, False, True, True, True, True, True, False]
    assert log_mass_width(seen[1], cfg) - log_mass_width(seen[0], cfg) == pytest.approx(math.log(1.25))
    assert initial_upper(dataclasses.replace(cfg, curriculum=False)) == 4.0  # the fixed wide support


def _eval_cfg(num_envs: int = 2):
    cfg = preset_cfg("smoke", "film", 0).env
    return dataclasses.replace(cfg, num_envs=num_envs, sim=dataclasses.replace(cfg.sim, num_threads=1))


def test_actuation_matched_aliengo_gains_are_go2_times_mass_ratio():
    env = LocomotionEnv(_eval_cfg(), mode="actuation-matched", robot="aliengo", seed=0)
    try:
        ratio = ALIENGO_DESCRIPTOR_MASS / GO2_MASS  # 20.336 / 16.085 = 1.2643
        assert ratio == pytest.approx(1.2643, abs=1e-4)
        assert float(env.params.total_mass[0]) == pytest.approx(ALIENGO_DESCRIPTOR_MASS, abs=1e-6)
        ids = env.backend.info.actuator_ids
        for model in env.backend.models:
            np.testing.assert_allclose(model.actuator_gainprm[ids, 0], 20.0 * ratio)  # Kp 25.29
            np.testing.assert_allclose(-model.actuator_biasprm[ids, 1], 20.0 * ratio)
            np.testing.assert_allclose(-model.actuator_biasprm[ids, 2], 0.5 * ratio)  # Kd 0.632
            np.testing.assert_allclose(model.actuator_forcerange[ids[:3], 1], np.array([23.7, 23.7, 45.43]) * ratio)
        np.testing.assert_allclose(env.kp.numpy(), 20.0 * ratio)
        ext = env.extended_descriptor()
        assert float(ext[0, _idx("kp")]) == pytest.approx(20.0 * ratio)
        assert float(ext[0, _idx("torque_limit_thigh")]) == pytest.approx(23.7 * ratio)  # 29.96 N m
    finally:
        env.close()
    plain = LocomotionEnv(_eval_cfg(), mode="descriptor", robot="aliengo", seed=0)
    try:  # descriptor mode keeps Go2's gains
        assert plain.backend.models[0].actuator_gainprm[plain.backend.info.actuator_ids[0], 0] == 20.0
    finally:
        plain.close()


GOLDEN = {  # sha256 of 6 steps of film's smoke env (4 envs, seed 3), recorded before issue 58's code
    "train": "ffbeae94c0453057c72439a55d830645d444189daebd69338dc964b512988f88",
    "descriptor": "aeec69f2b1fef443872fdc120f79a15f3747ecabb31b7432eacaf820d5c49808",
    "full": "28d30feb897acde6bf41f0e1928cde0b95cb2e83cf7bdb41143b4966d56da084",
}


@pytest.mark.parametrize("mode", sorted(GOLDEN))
def test_film_default_env_is_bit_identical(mode):
    cfg = preset_cfg("smoke", "film", 0).env
    cfg = dataclasses.replace(cfg, num_envs=4, sim=dataclasses.replace(cfg.sim, num_threads=1))
    env = LocomotionEnv(cfg, mode=mode, robot="aliengo", seed=3)
    h, gen = hashlib.sha256(), torch.Generator().manual_seed(0)
    try:
        for _ in range(6):
            obs, rew, _, _ = env.step(torch.randn(4, 12, generator=gen) * 0.5)
            for k in ("policy", "privileged", "morphology"):
                h.update(obs[k].numpy().tobytes())
            h.update(rew.numpy().tobytes())
    finally:
        env.close()
    assert h.hexdigest() == GOLDEN[mode]


def test_film_act_env_randomises_mass_gains_and_observes_them():
    cfg = preset_cfg("smoke", "film-act", 0).env
    rand = dataclasses.replace(cfg.rand, geometry=dataclasses.replace(cfg.rand.geometry, pool_size=4))
    cfg = dataclasses.replace(cfg, num_envs=6, sim=dataclasses.replace(cfg.sim, num_threads=1), rand=rand)
    env = LocomotionEnv(cfg, mode="train", seed=1)
    try:
        assert env.actuation_rand and float(env.mass_upper) == 1.25  # the curriculum's start
        obs = env.get_observations()
        assert obs["morphology"].shape == (6, 28) and obs["morphology"].abs().max() < 3
        ext = env.extended_descriptor()
        mass, kp = ext[:, _idx("total_mass")], ext[:, _idx("kp")]
        ratio = kp / (20.0 * mass / GO2_MASS)  # the jitter factor, in [0.8, 3.2]
        assert ((ratio >= 0.8 - 1e-9) & (ratio <= 3.2 + 1e-9)).all()
        ids = env.backend.info.actuator_ids
        for i, model in enumerate(env.backend.models):
            assert model.actuator_gainprm[ids[0], 0] == pytest.approx(float(kp[i]))
        state = env.state_dict()
        assert state["actuation"]["mass_upper"] == 1.25
        env.load_state_dict(state)
        np.testing.assert_allclose(env.extended_descriptor().numpy(), ext.numpy())
    finally:
        env.close()


def test_cli_train_film_act_smoke_and_eval_actuation_matched(tmp_path):
    import json

    from typer.testing import CliRunner

    from morfic_cli.cli import app

    runner, store = CliRunner(), str(tmp_path / "store")
    result = runner.invoke(app, ["train", "--variant", "film-act", "--preset", "smoke", "--quiet", "--store", store])
    assert result.exit_code == 0, result.output
    result = runner.invoke(
        app,
        [
            "eval",
            "runs/film-act-smoke-s0",
            "--mode",
            "actuation-matched",
            "--robots",
            "aliengo",
            "--envs",
            "2",
            "--steps",
            "5",
            "--format",
            "json",
            "--quiet",
            "--store",
            store,
        ],
    )
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output[result.output.index("[") :])
    assert [(r["robot"], r["mode"], r["steps"]) for r in rows] == [("aliengo", "actuation-matched", 5)]
    from morfic_cli.store import Store

    st = Store(tmp_path / "store")
    ev = st.read_manifest("evals/film-act-smoke-s0")
    role = "rollout/aliengo/actuation-matched/vx2"
    assert role in ev.inputs
    assert st.read_manifest(ev.inputs[role]).meta["mode"] == "actuation-matched"  # the MCAP log's metadata too


def test_env_curriculum_widens_on_crafted_episode_stats():
    cfg = preset_cfg("smoke", "film-act", 0).env
    rand = dataclasses.replace(cfg.rand, geometry=dataclasses.replace(cfg.rand.geometry, enabled=False))
    cfg = dataclasses.replace(cfg, num_envs=2, sim=dataclasses.replace(cfg.sim, num_threads=1), rand=rand)
    env = LocomotionEnv(cfg, mode="train", seed=0)
    try:
        seen = []
        for tracking in (0.6, 0.8, 0.8):  # the finished episodes' r_lin / its maximum over one max episode length
            env.common_step_counter = env.max_episode_length * (len(seen) // 2 + 1)
            env._tracking_sum = torch.tensor(2 * tracking, dtype=torch.float64)
            env._tracking_count = 2
            log = {}
            env._update_curriculum(log)
            seen += [float(log["/curriculum/mass_scale_max"]), float(env.command_ranges.vx[1])]
        assert seen == pytest.approx([1.25, 1.0, 1.5625, 1.5, 1.953125, 2.0])  # (mass bound, vx max): widen together
    finally:
        env.close()


def test_both_stays_descriptor_and_full_and_export_refuses_the_extended_descriptor():
    from morfic_cli.cli._options import EvalModes

    assert EvalModes.both.modes() == ("descriptor", "full")
    assert EvalModes("actuation-matched").modes() == ("actuation-matched",)
    from morfic_cli.errors import MorficError
    from morfic_cli.export.artifact import plan_export
    from morfic_cli.rl.build import build_models
    from morfic_cli.rl.load import TrainedModels

    cfg = preset_cfg("smoke", "film-act", 0)
    actor, critic = build_models(cfg)
    trained = TrainedModels(actor=actor, critic=critic, cfg=cfg, meta={"run": "film-act-x"}, checkpoint_id="0" * 64)
    with pytest.raises(MorficError, match="extended descriptor"):
        plan_export(trained, "b1", False)


def test_report_gives_actuation_matched_its_own_table():
    from morfic_cli.report.compare import transfer_rows
    from morfic_cli.report.gather import StoreData
    from morfic_cli.report.tables import transfer_table

    run = fake_run("film-act", checkpoint="a" * 64)
    rows = [
        {
            "run": run.name,
            "variant": run.variant,
            "seed": 0,
            "preset": "cpu",
            "checkpoint": run.checkpoint,
            "robot": "aliengo",
            "mode": mode,
            "command_vx": 2.0,
            "d": 0.3,
            "vx_mean": vx,
            "vx_std": 0.1,
            "vx_env_std": 0.01,
            "vx_step_mean": vx,
            "n_alive": 100,
            "vx_peak_1s_mean": vx,
            "vx_peak_1s_std": 0.1,
            "survival": 1.0,
            "tracking_ratio": vx / 2,
            "valid_fraction": 1.0,
            "num_envs": 64,
            "steps": 500,
        }
        for mode, vx in (("descriptor", 1.2), ("actuation-matched", 1.9))
    ]
    table = transfer_table(
        transfer_rows(StoreData(runs=[run], evals=rows)), key="k", title="t", command_vx=2.0, mode="actuation-matched"
    )
    assert table.columns == ("MorFiC-F(act)",) and table.rows[0].cells[0][0].value == pytest.approx(1.9)
    assert "Kp, Kd and torque limits x the target's mass / Go2's" in table.caption
