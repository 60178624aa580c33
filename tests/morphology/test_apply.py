"""Descriptor application: masses, inertia scaling, limits, ctrlrange, mj_setConst, idempotence."""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np
import pytest

from morfic_cli.errors import DescriptorError
from morfic_cli.morphology.apply import (
    TemplateInfo,
    apply_descriptor,
    clamp_to_limits,
    descriptor_ranges,
    joint_ranges,
    summarize,
)
from morfic_cli.morphology.builder import build_model, build_spec, nominal_height
from morfic_cli.morphology.robots import JOINTS, LEGS, load_robot

LINK_MASS_INDEX = {"thigh": 0, "calf": 1, "hip": 2, "foot": 3}


@pytest.fixture(scope="module")
def go2():
    robot = load_robot("go2")
    model = build_model(robot)
    return robot, model, TemplateInfo.from_model(model)


def _applied(go2, descriptor):
    _, nominal, info = go2
    model = copy.copy(nominal)
    apply_descriptor(model, mujoco.MjData(model), descriptor, info)
    return model


def test_b1_descriptor_sets_b1_link_masses_and_limits(go2):
    b1 = load_robot("b1")
    model = _applied(go2, b1.descriptor)
    assert model.body("base").mass[0] == pytest.approx(29.45)
    for leg in LEGS:
        for link, mass in (("hip", 2.15), ("thigh", 4.30), ("calf", 1.05), ("foot", 0.05)):
            assert model.body(f"{leg}_{link}").mass[0] == pytest.approx(mass)
        for joint, rng in zip(JOINTS, ([-0.75, 0.75], [-1.0, 3.5], [-2.6, -0.6]), strict=True):
            np.testing.assert_allclose(model.joint(f"{leg}_{joint}_joint").range, rng)
            np.testing.assert_allclose(model.actuator(f"{leg}_{joint}_joint").ctrlrange, rng)
    # rotors are not part of the descriptor and keep the Go2 values
    assert model.body("FL_thigh_rotor").mass[0] == pytest.approx(0.089)


def test_inertia_is_scaled_by_the_mass_ratio(go2):
    _, nominal, _ = go2
    model = _applied(go2, load_robot("b1").descriptor)
    for body, ratio in (
        ("base", 29.45 / 6.921),
        ("RR_thigh", 4.30 / 1.152),
        ("FL_calf", 1.05 / 0.154),
        ("FR_hip", 2.15 / 0.678),
        ("RL_foot", 0.05 / 0.040),
    ):
        np.testing.assert_allclose(model.body(body).inertia, nominal.body(body).inertia * ratio, rtol=1e-12)
        np.testing.assert_array_equal(model.body(body).iquat, nominal.body(body).iquat)


def test_total_mass_by_hand(go2):
    model = _applied(go2, load_robot("b1").descriptor)
    # Go2 total minus Go2's base and link masses plus B1's: only the 12 Go2 rotors (0.089 kg) remain.
    go2_total = 6.921 + 4 * (0.678 + 1.152 + 0.154 + 0.040 + 3 * 0.089)
    expected = go2_total - 6.921 - 4 * (0.678 + 1.152 + 0.154 + 0.040) + 29.45 + 4 * (2.15 + 4.30 + 1.05 + 0.05)
    assert expected == pytest.approx(60.718)
    assert float(model.body_mass.sum()) == pytest.approx(expected)
    assert model.body_subtreemass[model.body("base").id] == pytest.approx(expected)  # mj_setConst ran


def test_derived_constants_match_a_freshly_compiled_model(go2):
    """mj_setConst after the edit gives what the compiler gives for a spec with those masses."""
    robot, _, _ = go2
    b1 = load_robot("b1").descriptor
    applied = _applied(go2, b1)
    links = {
        link: dataclasses.replace(
            robot.links[link], mass=b1[i], inertia=robot.links[link].inertia * b1[i] / robot.links[link].mass
        )
        for link, i in LINK_MASS_INDEX.items()
    }
    b1_go2 = dataclasses.replace(
        robot,
        base_mass=b1[4],
        base_inertia=robot.base_inertia * b1[4] / robot.base_mass,
        links=links,
        joint_range=np.tile(descriptor_ranges(b1), (4, 1, 1)),
    )
    spec = build_spec(b1_go2)
    fresh = spec.compile()
    for field in (
        "body_mass",
        "body_inertia",
        "body_subtreemass",
        "dof_invweight0",
        "body_invweight0",
        "actuator_acc0",
        "jnt_range",
        "actuator_ctrlrange",
    ):
        np.testing.assert_allclose(getattr(applied, field), getattr(fresh, field), rtol=1e-9, atol=1e-12, err_msg=field)


def test_applying_twice_equals_applying_once(go2):
    _, nominal, info = go2
    b1 = load_robot("b1").descriptor
    once = _applied(go2, b1)
    twice = copy.copy(nominal)
    data = mujoco.MjData(twice)
    apply_descriptor(twice, data, load_robot("a1").descriptor, info)
    apply_descriptor(twice, data, b1, info)
    apply_descriptor(twice, data, b1, info)
    for field in (
        "body_mass",
        "body_inertia",
        "jnt_range",
        "actuator_ctrlrange",
        "body_subtreemass",
        "dof_invweight0",
        "actuator_acc0",
    ):
        np.testing.assert_array_equal(getattr(twice, field), getattr(once, field), err_msg=field)


def test_go2_own_descriptor_restores_the_nominal_masses(go2):
    robot, nominal, _ = go2
    model = _applied(go2, load_robot("b1").descriptor)
    apply_descriptor(model, mujoco.MjData(model), robot.descriptor, go2[2])
    np.testing.assert_allclose(model.body_mass, nominal.body_mass, rtol=1e-12)
    np.testing.assert_allclose(model.body_inertia, nominal.body_inertia, rtol=1e-12)
    ranges = model.jnt_range[go2[2].joint_ids.reshape(-1)].reshape(4, 3, 2)
    # hip and calf limits and the front thighs agree with the spec (to the descriptor's 3 decimals) ...
    np.testing.assert_allclose(ranges[:, [0, 2]], robot.joint_range[:, [0, 2]], atol=6e-4)
    np.testing.assert_allclose(ranges[:2, 1], robot.joint_range[:2, 1], atol=6e-4)
    # ... the rear thighs do not: the paper's descriptor has one thigh range for all legs.
    np.testing.assert_allclose(ranges[2:, 1], [[-1.571, 3.491]] * 2)
    assert not np.allclose(robot.joint_range[2:, 1], [[-1.571, 3.491]] * 2)


def test_zero_masses_are_handled(go2):
    robot, nominal, _ = go2
    descriptor = robot.descriptor.copy()
    descriptor[3] = 0.0  # foot mass 0 (the training support's minimum)
    model = _applied(go2, descriptor)
    foot = model.body("FL_foot").id
    assert model.body_mass[foot] == 0.0 and np.all(model.body_inertia[foot] == 0.0)
    # a template whose nominal foot mass is zero keeps a zero (point-mass) inertia for any mass
    zero = copy.copy(nominal)
    info = TemplateInfo.from_model(zero)
    zero.body_mass[info.link_bodies[:, 3]] = 0.0
    zero.body_inertia[info.link_bodies[:, 3]] = 0.0
    zero_info = TemplateInfo.from_model(zero)
    data = mujoco.MjData(zero)
    apply_descriptor(zero, data, robot.descriptor, zero_info)
    assert zero.body_mass[foot] == pytest.approx(0.040) and np.all(zero.body_inertia[foot] == 0.0)
    mujoco.mj_resetDataKeyframe(zero, data, 0)
    data.ctrl[:] = robot.default_qpos
    mujoco.mj_step(zero, data, 200)
    assert np.all(np.isfinite(data.qpos)) and data.qpos[2] > 0.2


@pytest.mark.parametrize(
    "bad", [np.zeros(10), [1.0] * 5 + [0.5, -0.5, -1.0, 1.0, -2.0, -1.0], [np.nan] + [1.0] * 10, [-1.0] + [1.0] * 10]
)
def test_invalid_descriptors_are_rejected(go2, bad):
    _, nominal, info = go2
    model = copy.copy(nominal)
    with pytest.raises(DescriptorError):
        apply_descriptor(model, mujoco.MjData(model), np.asarray(bad, dtype=float), info)
    np.testing.assert_array_equal(model.body_mass, nominal.body_mass)  # untouched


def test_joint_ranges_are_the_descriptor_pairs_for_every_leg():
    m = np.array([1, 1, 1, 0, 5, -0.9, 0.9, -1.2, 3.6, -2.65, -0.9])
    np.testing.assert_allclose(descriptor_ranges(m), [[-0.9, 0.9], [-1.2, 3.6], [-2.65, -0.9]])
    np.testing.assert_allclose(joint_ranges(m), np.tile(descriptor_ranges(m), (4, 1)))


def test_clamp_to_limits_by_hand():
    ranges = np.array([[-1.0, 1.0], [0.0, 2.0], [-2.0, -1.0]] * 4)
    q = np.array([1.5, -0.5, -0.5] * 4)
    np.testing.assert_allclose(clamp_to_limits(q, ranges), [1.0, 0.0, -1.0] * 4)
    batch = clamp_to_limits(np.stack([q, np.zeros(12)]), np.stack([ranges, ranges]))
    np.testing.assert_allclose(batch[1], [0.0, 0.0, -1.0] * 4)


def test_summary_gives_height_mass_and_clamped_pose(go2):
    robot, _, info = go2
    model = _applied(go2, robot.descriptor)
    summary = summarize(model, mujoco.MjData(model), info, robot.default_qpos, robot.foot_radius)
    np.testing.assert_allclose(summary.default_joint_pos, robot.default_qpos)  # inside the limits
    assert summary.nominal_height == pytest.approx(nominal_height(robot), abs=1e-9)
    assert summary.total_mass == pytest.approx(robot.total_mass)
    assert summary.base_mass == pytest.approx(6.921)
    tight = robot.descriptor.copy()
    tight[10] = -1.6  # calf max below the default knee angle -1.5
    model = _applied(go2, tight)
    summary = summarize(model, mujoco.MjData(model), info, robot.default_qpos, robot.foot_radius)
    np.testing.assert_allclose(summary.default_joint_pos[2::3], -1.6)
    assert summary.nominal_height != pytest.approx(nominal_height(robot))
