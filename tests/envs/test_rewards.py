"""Reward terms, checked against hand-computed numbers (arithmetic in the comments)."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import pytest
import torch

from morfic_cli.config import RewardCfg
from morfic_cli.envs import rewards as R
from morfic_cli.envs.rewards import TERMS, TERMS_BY_NAME, compute_rewards
from morfic_cli.envs.state import EnvState
from morfic_cli.sim.backend import CONTACT_BODIES

CFG = RewardCfg()
E1 = math.exp(-1.0)

# A Go2-sized standing robot: feet under the hips at x +-0.19, y +-0.14 (width 0.28 m).
NOMINAL_XY = [[0.19, 0.14], [0.19, -0.14], [-0.19, 0.14], [-0.19, -0.14]]
Q0 = [0.0, 0.8, -1.5] * 4
Q_MIN = [-1.0, -1.5, -2.7] * 4
Q_MAX = [1.0, 3.4, -0.8] * 4
MASS = 15.0
H0 = 0.30


def make_state(n: int = 1, **overrides: torch.Tensor | float) -> EnvState:
    """A batch of ``n`` identical robots standing still at the default pose, then ``overrides``.

    Base upright at (0, 0, h0) facing +x, feet at their nominal xy on the ground carrying a quarter
    of the weight each, all feet in contact, commands / actions / velocities zero, nothing else
    touching the ground. Gait: FL and RR mid-stance (phase 0.25, d = 1), FR and RL mid-swing
    (phase 0.75, d = 0), 2 Hz.
    """
    nominal = torch.tensor(NOMINAL_XY).expand(n, 4, 2).clone()
    foot_pos = torch.zeros(n, 4, 3)
    foot_pos[..., :2] = nominal
    foot_pos[..., 2] = 0.02
    foot_force = torch.zeros(n, 4, 3)
    foot_force[..., 2] = MASS * 9.81 / 4
    fields: dict[str, torch.Tensor | float] = {
        "base_pos_w": torch.tensor([0.0, 0.0, H0]).expand(n, 3).clone(),
        "base_quat_w": torch.tensor([1.0, 0.0, 0.0, 0.0]).expand(n, 4).clone(),
        "base_lin_vel_b": torch.zeros(n, 3),
        "base_ang_vel_b": torch.zeros(n, 3),
        "projected_gravity_b": torch.tensor([0.0, 0.0, -1.0]).expand(n, 3).clone(),
        "joint_pos": torch.tensor(Q0).expand(n, 12).clone(),
        "joint_vel": torch.zeros(n, 12),
        "joint_vel_prev": torch.zeros(n, 12),
        "joint_torque": torch.zeros(n, 12),
        "default_joint_pos": torch.tensor(Q0).expand(n, 12).clone(),
        "joint_pos_min": torch.tensor(Q_MIN).expand(n, 12).clone(),
        "joint_pos_max": torch.tensor(Q_MAX).expand(n, 12).clone(),
        "foot_pos_w": foot_pos,
        "foot_vel_w": torch.zeros(n, 4, 3),
        "foot_vel_w_prev": torch.zeros(n, 4, 3),
        "foot_force_w": foot_force,
        "foot_contact": torch.ones(n, 4, dtype=torch.bool),
        "body_contact_force": torch.zeros(n, len(CONTACT_BODIES)),
        "command": torch.zeros(n, 3),
        "action": torch.zeros(n, 12),
        "action_prev": torch.zeros(n, 12),
        "gait_phase": torch.tensor([0.25, 0.75, 0.75, 0.25]).expand(n, 4).clone(),
        "desired_contact": torch.tensor([1.0, 0.0, 0.0, 1.0]).expand(n, 4).clone(),
        "gait_frequency": torch.full((n,), 2.0),
        "nominal_foot_pos_b": nominal,
        "nominal_height": torch.full((n,), H0),
        "total_mass": torch.full((n,), MASS),
        "dt": 0.02,
    }
    unknown = set(overrides) - set(fields)
    assert not unknown, unknown
    fields.update(overrides)
    return EnvState(**fields)


def t(*rows) -> torch.Tensor:
    return torch.tensor(rows, dtype=torch.float32)


def close(actual: torch.Tensor, expected, atol: float = 1e-6) -> None:
    torch.testing.assert_close(actual, torch.as_tensor(expected, dtype=actual.dtype), atol=atol, rtol=1e-5)


def yaw_quat(yaw: float) -> torch.Tensor:
    return torch.tensor([[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]])


def rotate_xy(xy: torch.Tensor, yaw: float) -> torch.Tensor:
    c, s = math.cos(yaw), math.sin(yaw)
    return torch.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], dim=-1)


# ---- registry -----------------------------------------------------------------------------------

PAPER_TABLE = [
    "r_lin", "r_yaw", "p_vz", "p_omega_xy", "p_ori", "p_tau", "p_qddot", "p_da", "p_coll", "p_jl",
    "r_upright", "r_cop", "r_width", "r_gaitF", "r_gaitV", "p_slip", "p_impact", "p_f", "p_q", "p_qdot",
    "r_jump", "r_raibert",
]  # fmt: skip


def test_terms_are_the_paper_table_in_order():
    assert [t.name for t in TERMS] == PAPER_TABLE
    for term in TERMS:
        assert term.func.__name__ == term.name
        assert term.group in ("task", "penalty", "stability")
        assert term.weight_of(CFG) >= 0.0
    assert {t.name for t in TERMS if t.group == "stability"} == {"r_upright", "r_cop", "r_width"}
    assert TERMS_BY_NAME["r_raibert"].group == "penalty"  # non-negative distance -> subtracted
    assert TERMS_BY_NAME["r_jump"].group == "task"  # non-positive -> added


def test_every_config_field_belongs_to_a_term():
    # each RewardCfg field is one term's weight or a parameter a term reads: no orphan, no weight used twice
    names = {f.name for f in dataclasses.fields(RewardCfg)}
    weights = [t.weight for t in TERMS]
    params = {p for t in TERMS for p in t.params}
    assert len(set(weights)) == len(TERMS) and set(weights) <= names
    assert params <= names and not params & set(weights)
    assert set(weights) | params == names
    with pytest.raises(dataclasses.FrozenInstanceError):
        CFG.w_lin = 2.0  # type: ignore[misc]


def test_the_parameter_a_term_names_is_the_one_it_reads():
    term = TERMS_BY_NAME["r_lin"]
    assert term.params == ("sigma_lin",)
    s = make_state(base_lin_vel_b=t([0.5, 0.0, 0.0]))  # vx error 0.5 against a zero command: err^2 = 0.25
    close(term.func(s, CFG), [4 * math.exp(-1.0)])  # sigma_lin 0.25
    close(term.func(s, dataclasses.replace(CFG, sigma_lin=0.5)), [4 * math.exp(-0.5)])


def test_docs_table_matches_the_defaults():
    # docs/rewards.md has one row per term: | `name` | formula | group | default weight | ...
    doc = (Path(__file__).parents[2] / "docs" / "rewards.md").read_text()
    rows = {}
    for line in doc.splitlines():
        m = re.match(r"\| `(\w+)` \|", line)
        if m and m.group(1) in TERMS_BY_NAME:
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            rows[m.group(1)] = cells
    assert set(rows) == set(TERMS_BY_NAME)
    for term in TERMS:
        assert rows[term.name][2] == term.group, term.name
        assert rows[term.name][3] == format(term.weight_of(CFG), "g"), term.name


def test_standing_state_is_a_quiet_baseline():
    s = make_state()
    for name in ["p_vz", "p_omega_xy", "p_ori", "p_tau", "p_qddot", "p_da", "p_coll", "p_jl", "p_slip",
                 "p_impact", "p_f", "p_q", "p_qdot", "r_jump", "r_raibert", "r_gaitV"]:  # fmt: skip
        close(TERMS_BY_NAME[name].func(s, CFG), [0.0])
    close(R.r_upright(s, CFG), [1.0])
    close(R.r_cop(s, CFG), [1.0])  # equal loads: CoP = centroid
    close(R.r_width(s, CFG), [1.0])


# ---- task ---------------------------------------------------------------------------------------


def test_r_lin():
    # perfect tracking: 4 exp(0) = 4
    close(R.r_lin(make_state(command=t([0.8, -0.2, 0.0]), base_lin_vel_b=t([0.8, -0.2, 0.3])), CFG), [4.0])
    # error (0.3, 0.4): 0.09 + 0.16 = 0.25 = sigma_lin -> 4 exp(-1); v_z is ignored
    s = make_state(command=t([0.3, 0.4, 0.0]), base_lin_vel_b=t([0.0, 0.0, 1.0]))
    close(R.r_lin(s, CFG), [4.0 * E1])


def test_r_yaw():
    # (1.0 - 0.5)^2 = 0.25 = sigma_yaw -> exp(-1)
    close(R.r_yaw(make_state(command=t([0.0, 0.0, 1.0]), base_ang_vel_b=t([0.0, 0.0, 0.5])), CFG), [E1])
    close(R.r_yaw(make_state(command=t([0, 0, 0.7]), base_ang_vel_b=t([3.0, 1.0, 0.7])), CFG), [1.0])


def test_r_gaitF_penalises_force_on_swing_feet_only():
    # d = (1, 0, 0, 1); FR (swing) 10 N: 1 - exp(-100/100) = 1 - e^-1; RL (swing) 0 N: 0;
    # FL, RR in stance carry 500 N but (1 - d) = 0.  -> -1/4 (1 - e^-1)
    force = torch.zeros(1, 4, 3)
    force[0, 0, 2] = force[0, 3, 2] = 500.0
    force[0, 1] = torch.tensor([6.0, 0.0, 8.0])  # |f| = 10
    close(R.r_gaitF(make_state(foot_force_w=force), CFG), [-0.25 * (1 - E1)])
    # half-desired contact d = 0.5 on FR: -1/4 * 0.5 (1 - e^-1)
    s = make_state(foot_force_w=force, desired_contact=t([1.0, 0.5, 0.0, 1.0]))
    close(R.r_gaitF(s, CFG), [-0.125 * (1 - E1)])


def test_r_gaitV_penalises_velocity_of_stance_feet_only():
    # d = (1, 0, 0, 1); FL (stance) |v|^2 = 1 + 9 + 0 = 10 = sigma_V -> 1 - e^-1; FR (swing) moves freely
    vel = torch.zeros(1, 4, 3)
    vel[0, 0] = torch.tensor([1.0, 3.0, 0.0])
    vel[0, 1] = torch.tensor([5.0, 0.0, 2.0])
    close(R.r_gaitV(make_state(foot_vel_w=vel), CFG), [-0.25 * (1 - E1)])


def test_r_jump_base_height_above_ground():
    # z = 0.25, h0 = 0.30, h_cmd = 0: -(0.25 - 0.30)^2 = -0.0025
    close(R.r_jump(make_state(base_pos_w=t([5.0, 1.0, 0.25])), CFG), [-0.0025])
    # h_cmd = 0.05: target 0.35, z = 0.35 -> 0
    cfg = dataclasses.replace(CFG, h_cmd=0.05)
    close(R.r_jump(make_state(base_pos_w=t([0.0, 0.0, 0.35])), cfg), [0.0])


# ---- penalties ----------------------------------------------------------------------------------


def test_base_motion_penalties():
    s = make_state(base_lin_vel_b=t([1.0, 1.0, 0.3]), base_ang_vel_b=t([0.3, 0.4, 2.0]),
                   projected_gravity_b=t([0.6, 0.0, -0.8]))  # fmt: skip
    close(R.p_vz(s, CFG), [0.09])  # 0.3^2
    close(R.p_omega_xy(s, CFG), [0.25])  # 0.3^2 + 0.4^2
    close(R.p_ori(s, CFG), [0.36])  # 0.6^2 + 0^2


def test_joint_penalties():
    qdot_prev = torch.full((1, 12), 0.1)
    action = torch.zeros(1, 12)
    action[0, :2] = 0.5
    q = torch.tensor([Q0])
    q[0, :3] += 0.1
    qdot = torch.zeros(1, 12)
    qdot[0, 4:6] = 2.0
    s = make_state(joint_torque=torch.full((1, 12), 2.0), joint_vel_prev=qdot_prev, action=action, joint_pos=q)
    close(R.p_tau(s, CFG), [48.0])  # 12 * 2^2
    close(R.p_qddot(s, CFG), [300.0], atol=1e-3)  # 12 * ((0.1 - 0) / 0.02)^2 = 12 * 25
    close(R.p_da(s, CFG), [0.5])  # 2 * 0.5^2
    close(R.p_q(s, CFG), [0.03])  # 3 * 0.1^2
    close(R.p_qdot(make_state(joint_vel=qdot), CFG), [8.0])  # 2 * 2^2


def test_p_coll_counts_bodies_over_0_1_newton():
    # base 0, FL_thigh 0.05, FR_thigh 0.1 (not over), RL_thigh 0.11, RR_thigh 5, calves 0, 0, 0, 200 -> 3
    forces = t([0.0, 0.05, 0.1, 0.11, 5.0, 0.0, 0.0, 0.0, 200.0])
    close(R.p_coll(make_state(body_contact_force=forces), CFG), [3.0])
    close(R.p_coll(make_state(body_contact_force=torch.full((1, 9), 1.0)), CFG), [9.0])


def test_p_jl_uses_per_env_limits():
    # Both envs: FL thigh q = 1.2, FL calf q = -2.9. Env 0 limits thigh <= 1.5, calf >= -3.0: inside -> 0.
    # Env 1 limits thigh <= 1.0, calf >= -2.7: excess (1.2 - 1.0) + (-2.7 - -2.9) = 0.2 + 0.2 = 0.4.
    q = torch.tensor([Q0, Q0])
    q[:, 1], q[:, 2] = 1.2, -2.9
    q_max = torch.tensor([Q_MAX, Q_MAX])
    q_min = torch.tensor([Q_MIN, Q_MIN])
    q_max[0, 1], q_min[0, 2] = 1.5, -3.0
    q_max[1, 1], q_min[1, 2] = 1.0, -2.7
    s = make_state(n=2, joint_pos=q, joint_pos_max=q_max, joint_pos_min=q_min)
    close(R.p_jl(s, CFG), [0.0, 0.4])


def test_p_slip_counts_planar_speed_of_contact_feet():
    # FL in contact, (0.3, 0.4) -> 0.25 (z ignored); FR in contact 0.1 -> 0.01; RL (1, 1) not in contact -> 0
    vel = torch.zeros(1, 4, 3)
    vel[0, 0] = torch.tensor([0.3, 0.4, 5.0])
    vel[0, 1] = torch.tensor([0.1, 0.0, 0.0])
    vel[0, 2] = torch.tensor([1.0, 1.0, 0.0])
    contact = torch.tensor([[True, True, False, False]])
    close(R.p_slip(make_state(foot_vel_w=vel, foot_contact=contact), CFG), [0.26])


def test_p_impact_uses_previous_velocity_and_clips():
    # previous z-velocities: FL -0.5 (contact) -> 0.25; FR +0.3 (contact) -> clipped to 0;
    # RL -200 (contact) -> clipped to -100 -> 10000; RR -1 (no contact) -> 0. Total 10000.25.
    prev = torch.zeros(1, 4, 3)
    prev[0, :, 2] = torch.tensor([-0.5, 0.3, -200.0, -1.0])
    now = torch.full((1, 4, 3), -7.0)  # the current velocity must not matter
    contact = torch.tensor([[True, True, True, False]])
    s = make_state(foot_vel_w_prev=prev, foot_vel_w=now, foot_contact=contact)
    close(R.p_impact(s, CFG), [10000.25], atol=1e-3)


def test_p_f_excess_over_body_weight_factor():
    # mass 10 kg: f_max = 1.5 * 9.81 * 10 = 147.15 N. FL |f| = 200 -> 52.85; FR |(30, 40, 0)| = 50 -> 0
    force = torch.zeros(1, 4, 3)
    force[0, 0, 2] = 200.0
    force[0, 1] = torch.tensor([30.0, 40.0, 0.0])
    close(R.p_f(make_state(foot_force_w=force, total_mass=t(10.0)), CFG), [52.85], atol=1e-4)


# ---- r_raibert ----------------------------------------------------------------------------------


def test_r_raibert_feet_on_targets_is_zero_and_forward_offset():
    # zero command: targets are the nominal footholds, where the feet are -> 0
    close(R.r_raibert(make_state(), CFG), [0.0])
    # vx = 1, f = 2 Hz, duty 0.5 -> T_st = 0.25 s; phases FL 0 (s = +0.5), FR 0.25 (0), RL 0.5 (-0.5), RR 0.75 (0)
    # FL target x +0.125, RL -0.125, feet at nominal: 0.125^2 + 0.125^2 = 0.03125
    s = make_state(command=t([1.0, 0.0, 0.0]), gait_phase=t([0.0, 0.25, 0.5, 0.75]))
    close(R.r_raibert(s, CFG), [0.03125])


def test_r_raibert_is_in_the_base_yaw_frame():
    # The same robot turned by 90 degrees about z and moved: the same value as unrotated (0.03125).
    yaw = math.pi / 2
    base = t([1.0, 2.0, H0])
    foot = torch.zeros(1, 4, 3)
    foot[..., :2] = rotate_xy(torch.tensor([NOMINAL_XY]), yaw) + base[:, :2]
    s = make_state(command=t([1.0, 0.0, 0.0]), gait_phase=t([0.0, 0.25, 0.5, 0.75]),
                   base_quat_w=yaw_quat(yaw), base_pos_w=base, foot_pos_w=foot)  # fmt: skip
    close(R.r_raibert(s, CFG), [0.03125], atol=1e-5)


def test_r_raibert_yaw_command_and_velocity_gain():
    # wz = 1, FL at touchdown (s = 0.5), others mid-phase (s = 0): v_foot_FL = (-0.14, 0.19),
    # offset = 0.5 * 0.25 * v = (-0.0175, 0.02375) -> 0.00030625 + 0.0005640625 = 0.0008703125
    s = make_state(command=t([0.0, 0.0, 1.0]), gait_phase=t([0.0, 0.25, 0.25, 0.25]))
    close(R.r_raibert(s, CFG), [0.0008703125])
    # k_v = 0.1, v = (0.5, 0), command 0, s = 0 for all: every target moves 0.05 in x -> 4 * 0.0025 = 0.01
    s = make_state(base_lin_vel_b=t([0.5, 0.0, 0.0]), gait_phase=t([0.25, 0.25, 0.75, 0.75]))
    close(R.r_raibert(s, dataclasses.replace(CFG, raibert_kv=0.1)), [0.01])


# ---- stability ----------------------------------------------------------------------------------


def test_r_upright():
    close(R.r_upright(make_state(), CFG), [1.0])
    # |g_xy| = sin(0.3): exp(-sin^2(0.3) / sin^2(0.3)) = exp(-1), whatever the direction in xy
    sx = math.sin(0.3)
    g = t([sx, 0.0, -math.cos(0.3)], [0.6 * sx, -0.8 * sx, -math.cos(0.3)])
    close(R.r_upright(make_state(n=2, projected_gravity_b=g), CFG), [E1, E1])


def test_r_cop_needs_two_contacts():
    # one contact or none -> 0, whatever the forces
    for contact in ([True, False, False, False], [False, False, False, False]):
        close(R.r_cop(make_state(foot_contact=torch.tensor([contact])), CFG), [0.0])


def test_r_cop_force_weighted_vs_centroid():
    # Contacts FL (0.19, 0.14) with 30 N and RR (-0.19, -0.14) with 10 N; FR, RL off the ground but
    # with (ignored) forces. centre = midpoint = (0, 0); CoP = (30 * FL + 10 * RR) / 40 = 0.5 * FL = (0.095, 0.07);
    # ||CoP - centre|| = sqrt(0.095^2 + 0.07^2) = sqrt(0.013925) = 0.118004 -> exp(-0.118004 / 0.1)
    force = torch.zeros(1, 4, 3)
    force[0, :, 2] = torch.tensor([30.0, 99.0, 99.0, 10.0])
    contact = torch.tensor([[True, False, False, True]])
    s = make_state(foot_force_w=force, foot_contact=contact)
    close(R.r_cop(s, CFG), [math.exp(-math.sqrt(0.013925) / 0.1)], atol=1e-5)
    # Equal loads on three feet FL, FR, RL: CoP = centroid -> 1
    contact3 = torch.tensor([[True, True, True, False]])
    close(R.r_cop(make_state(foot_contact=contact3), CFG), [1.0], atol=1e-5)


def test_r_width_is_one_when_gate_is_off():
    # upright, still: gate off -> 1 even with the front feet 12 cm apart
    foot = make_state().foot_pos_w.clone()
    foot[0, 0, 1], foot[0, 1, 1] = 0.06, -0.06
    close(R.r_width(make_state(foot_pos_w=foot), CFG), [1.0])
    close(R.width_gate(make_state(foot_pos_w=foot), CFG), [0.0])


def test_r_width_gated_by_speed_or_tilt():
    # narrow front pair: w = min(0.06 + 0.06, 0.14 + 0.14) = 0.12; w_min = 0.8 * 0.28 = 0.224;
    # (0.224 - 0.12) / 0.05 = 2.08 -> exp(-2.08)
    foot = make_state(n=3).foot_pos_w.clone()
    foot[:, 0, 1], foot[:, 1, 1] = 0.06, -0.06
    # env 0: speed |(1.2, 0.9)| = 1.5 > v_th = 1; env 1: ||g_xy||^2 = 0.06 > eta = 0.05; env 2: both below
    vel = t([1.2, 0.9, 0.0], [0.5, 0.0, 0.0], [0.6, 0.0, 0.0])
    g = t([0.0, 0.0, -1.0], [0.0, math.sqrt(0.06), -math.sqrt(0.94)], [0.2, 0.0, -math.sqrt(0.96)])
    s = make_state(n=3, foot_pos_w=foot, base_lin_vel_b=vel, projected_gravity_b=g)
    close(R.width_gate(s, CFG), [1.0, 1.0, 0.0])
    close(R.r_width(s, CFG), [math.exp(-2.08), math.exp(-2.08), 1.0], atol=1e-5)
    # gate on but feet at nominal (w = 0.28 >= 0.224) -> 1
    close(R.r_width(make_state(base_lin_vel_b=t([2.0, 0.0, 0.0])), CFG), [1.0])


def test_r_width_in_the_base_yaw_frame():
    # the narrow-front robot turned by 120 degrees and moving fast: same exp(-2.08)
    yaw = 2 * math.pi / 3
    xy = torch.tensor([NOMINAL_XY])
    xy[0, 0, 1], xy[0, 1, 1] = 0.06, -0.06
    foot = torch.zeros(1, 4, 3)
    foot[..., :2] = rotate_xy(xy, yaw)
    s = make_state(foot_pos_w=foot, base_quat_w=yaw_quat(yaw), base_pos_w=t([0.0, 0.0, H0]),
                   base_lin_vel_b=t([1.5, 0.0, 0.0]))  # fmt: skip
    close(R.r_width(s, CFG), [math.exp(-2.08)], atol=1e-5)


# ---- the sum, eq. (rews) ------------------------------------------------------------------------


def _busy_state(n: int = 3, seed: int = 0) -> EnvState:
    """A state where every term is non-zero-ish."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *shape: torch.randn(*shape, generator=g)  # noqa: E731
    grav = torch.tensor([0.2, -0.1, -1.0]) + 0.05 * r(n, 3)
    return make_state(
        n=n,
        base_lin_vel_b=r(n, 3), base_ang_vel_b=r(n, 3), projected_gravity_b=grav / grav.norm(dim=1, keepdim=True),
        joint_pos=torch.tensor(Q0) + r(n, 12), joint_vel=r(n, 12), joint_vel_prev=r(n, 12),
        joint_torque=5 * r(n, 12), foot_pos_w=make_state(n).foot_pos_w + 0.05 * r(n, 4, 3),
        foot_vel_w=r(n, 4, 3), foot_vel_w_prev=r(n, 4, 3), foot_force_w=60 * r(n, 4, 3).abs(),
        foot_contact=r(n, 4) > -0.5, body_contact_force=r(n, 9).abs(), command=r(n, 3),
        action=r(n, 12), action_prev=r(n, 12), gait_phase=torch.rand(n, 4, generator=g),
        desired_contact=torch.rand(n, 4, generator=g), base_pos_w=t([0.0, 0.0, 0.27]).expand(n, 3),
    )  # fmt: skip


def test_total_is_the_hand_weighted_sum_with_penalties_subtracted():
    s, c = _busy_state(), dataclasses.replace(CFG, w_gaitF=2.0, w_gaitV=2.0, w_raibert=5.0)  # clock terms on too
    total, parts, raw = compute_rewards(s, c)
    # eq. (rews), written out term by term (no dt: the env applies it)
    expected = (
        c.w_lin * R.r_lin(s, c) + c.w_yaw * R.r_yaw(s, c) + c.w_gaitF * R.r_gaitF(s, c)
        + c.w_gaitV * R.r_gaitV(s, c) + c.w_jump * R.r_jump(s, c)
        - c.w_vz * R.p_vz(s, c) - c.w_omega_xy * R.p_omega_xy(s, c) - c.w_ori * R.p_ori(s, c)
        - c.w_tau * R.p_tau(s, c) - c.w_qddot * R.p_qddot(s, c) - c.w_da * R.p_da(s, c)
        - c.w_coll * R.p_coll(s, c) - c.w_jl * R.p_jl(s, c) - c.w_slip * R.p_slip(s, c)
        - c.w_impact * R.p_impact(s, c) - c.w_f * R.p_f(s, c) - c.w_q * R.p_q(s, c)
        - c.w_qdot * R.p_qdot(s, c) - c.w_raibert * R.r_raibert(s, c)
        + c.w_upright * R.r_upright(s, c) + c.w_cop * R.r_cop(s, c) + c.w_width * R.r_width(s, c)
    )  # fmt: skip
    close(total, expected, atol=1e-5)
    assert list(parts) == PAPER_TABLE
    close(sum(parts.values()), total, atol=1e-5)
    for term in TERMS:
        if term.group == "penalty":
            assert (parts[term.name] <= 0).all(), term.name
        close(raw[term.name], term.func(s, c))  # raw = before weighting
        close(parts[term.name], term.sign() * term.weight_of(c) * raw[term.name])


def test_total_small_hand_example():
    # Only w_lin = 2, w_vz = 3, w_upright = 1: perfect tracking (r_lin = 4), v_z = 0.1 (p_vz = 0.01), upright (1):
    # 2 * 4 - 3 * 0.01 + 1 * 1 = 8.97
    zero = {t.weight: 0.0 for t in TERMS}
    cfg = dataclasses.replace(CFG, **{**zero, "w_lin": 2.0, "w_vz": 3.0, "w_upright": 1.0})
    s = make_state(base_lin_vel_b=t([0.0, 0.0, 0.1]))
    total, parts, raw = compute_rewards(s, cfg)
    close(total, [8.97], atol=1e-5)
    close(raw["p_tau"], [0.0])  # raw values whatever the weight: no torque, perfect yaw tracking
    close(raw["r_yaw"], [1.0])
    close(parts["r_lin"], [8.0])  # 2 * 4
    close(parts["p_vz"], [-0.03])  # -3 * 0.01
    close(parts["r_upright"], [1.0])


def test_zero_weight_contributes_nothing_but_its_raw_value_is_kept():
    s = make_state(joint_torque=torch.full((1, 12), 3.0))
    total0, parts0, raw0 = compute_rewards(s, dataclasses.replace(CFG, w_tau=0.0))
    total, parts, raw = compute_rewards(s, CFG)
    close(parts0["p_tau"], [0.0])
    close(raw0["p_tau"], [12 * 9.0])  # ||tau||^2 = 12 joints x 3^2
    close(raw["p_tau"], [12 * 9.0])
    close(total0 - total, [CFG.w_tau * 108.0], atol=1e-6)  # the penalty, no longer subtracted


@pytest.mark.parametrize("seed", range(5))
def test_finite_for_random_finite_states(seed):
    g = torch.Generator().manual_seed(seed)
    n = 64

    def r(*shape, scale=1.0):
        return scale * torch.randn(*shape, generator=g)

    s = EnvState(
        base_pos_w=r(n, 3), base_quat_w=r(n, 4), base_lin_vel_b=r(n, 3, scale=5), base_ang_vel_b=r(n, 3, scale=5),
        projected_gravity_b=r(n, 3), joint_pos=r(n, 12, scale=3), joint_vel=r(n, 12, scale=30),
        joint_vel_prev=r(n, 12, scale=30), joint_torque=r(n, 12, scale=50), default_joint_pos=r(n, 12),
        joint_pos_min=r(n, 12) - 1, joint_pos_max=r(n, 12) + 1, foot_pos_w=r(n, 4, 3),
        foot_vel_w=r(n, 4, 3, scale=10), foot_vel_w_prev=r(n, 4, 3, scale=10), foot_force_w=r(n, 4, 3, scale=500),
        foot_contact=r(n, 4) > 0, body_contact_force=r(n, 9, scale=100).abs(), command=r(n, 3, scale=2),
        action=r(n, 12, scale=10), action_prev=r(n, 12, scale=10), gait_phase=torch.rand(n, 4, generator=g),
        desired_contact=torch.rand(n, 4, generator=g), gait_frequency=torch.rand(n, generator=g) * 4,
        nominal_foot_pos_b=r(n, 4, 2, scale=0.2), nominal_height=r(n).abs(), total_mass=r(n).abs() * 20,
        dt=0.02,
    )  # fmt: skip
    total, parts, _ = compute_rewards(s, CFG)
    assert total.shape == (n,)
    assert torch.isfinite(total).all()
    for name, value in parts.items():
        assert value.shape == (n,), name
        assert torch.isfinite(value).all(), name


def test_default_weights_give_a_positive_reward_when_standing_on_command():
    # Standing still with a zero command: tracking and stability earn, the gait terms cost a little.
    total, parts, _ = compute_rewards(make_state(), CFG)
    assert total.item() > 0
    assert parts["r_lin"].item() == pytest.approx(4 * CFG.w_lin)
