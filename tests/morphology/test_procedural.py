"""Procedural geometry (GenLoco's generator around the Go2 template): ranges, the built model by hand, seeds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from morfic_cli.config import GeometryRandCfg
from morfic_cli.morphology import procedural as P
from morfic_cli.morphology.builder import build_model, nominal_height
from morfic_cli.morphology.robots import LINKS, load_robot

GO2 = load_robot("go2")
CFG = GeometryRandCfg(enabled=True)
SAMPLE = P.GeometrySample(
    scale=1.1,
    base_size=np.array([1.2, 0.8, 1.4]),
    base_density=0.7,
    hip_pos=np.array([0.95, 1.05]),
    thigh_offset=1.08,
    calf_length=1.3,
    thigh_ratio=0.9,
    calf_radius=0.6,
    thigh_radius_ratio=1.2,
    link_mass=np.array([1.4, 0.6, 1.1, 0.5]),
)


@pytest.fixture(scope="module")
def robot():
    return P.generate_robot(GO2, SAMPLE, CFG, "go2_test")


@pytest.fixture(scope="module")
def model(robot):
    return build_model(robot, floor=True, sim_sensors=True)


def test_samples_lie_in_the_configured_ranges():
    rng = np.random.default_rng(3)
    cfg = dataclasses.replace(CFG, scale=(0.9, 1.0), link_mass=(0.2, 0.3))
    for _ in range(50):
        s = P._draw(rng, cfg)
        assert 0.9 <= s.scale <= 1.0
        assert np.all((s.link_mass >= 0.2) & (s.link_mass <= 0.3))
        for value, key in (
            (s.base_size, "base_size"),
            (s.base_density, "base_density"),
            (s.hip_pos, "hip_pos"),
            (s.thigh_offset, "hip_pos"),
            (s.calf_length, "link_length"),
            (s.thigh_ratio, "thigh_length_ratio"),
            (s.calf_radius, "link_radius"),
            (s.thigh_radius_ratio, "thigh_radius_ratio"),
        ):
            lo, hi = getattr(cfg, key)
            assert np.all((np.asarray(value) >= lo) & (np.asarray(value) <= hi)), key


def test_the_built_model_has_the_sampled_lengths_and_radii(model):
    s = SAMPLE.scale
    calf = 0.213 * 1.3 * s  # Go2 calf length 0.213 m x calf factor x scale
    thigh = 0.213 * 1.3 * s * 0.9  # x the thigh/calf ratio
    assert model.body("FL_foot").pos[2] == pytest.approx(-calf)
    assert model.body("FL_calf").pos[2] == pytest.approx(-thigh)
    assert model.body("FL_thigh").pos[1] == pytest.approx(0.0955 * s * 1.08)
    assert model.body("RR_thigh").pos[1] == pytest.approx(-0.0955 * s * 1.08)  # mirrored
    assert model.body("FL_hip").pos[:2] == pytest.approx([0.1934 * 1.2 * s * 0.95, 0.0465 * 0.8 * s * 1.05])
    assert model.geom("FL_calf_geom").size[0] == pytest.approx(0.013 * 0.6 * s)
    assert model.geom("FL_thigh_collision").size[0] == pytest.approx(0.022 * 0.6 * s * 1.2)
    assert model.geom("FL_foot_geom").size[0] == pytest.approx(0.022 * 0.6 * s)
    assert model.geom("base_collision").size == pytest.approx(
        np.array([0.3762, 0.0935, 0.114]) * [1.2, 0.8, 1.4] * s / 2
    )


def test_masses_scale_with_the_cube_of_the_scale(model, robot):
    s3 = SAMPLE.scale**3
    for leg in ("FL", "RR"):
        assert model.body(f"{leg}_hip").mass[0] == pytest.approx(0.678 * 1.4 * s3)
        assert model.body(f"{leg}_thigh").mass[0] == pytest.approx(1.152 * 0.6 * s3)
        assert model.body(f"{leg}_calf").mass[0] == pytest.approx(0.154 * 1.1 * s3)
        assert model.body(f"{leg}_foot").mass[0] == pytest.approx(0.040 * 0.5 * s3)
        assert model.body(f"{leg}_thigh_rotor").mass[0] == pytest.approx(0.089 * s3)
    volume = 1.2 * 0.8 * 1.4 * s3
    assert model.body("base").mass[0] == pytest.approx(6.921 * 0.7 * volume)  # density factor x volume ratio
    assert float(model.body_mass.sum()) == pytest.approx(robot.total_mass)
    # the descriptor is the generated robot's: thigh, calf, hip, foot, base masses, then the template's limits
    assert robot.descriptor[:5] == pytest.approx(
        [
            model.body("FL_thigh").mass[0],
            model.body("FL_calf").mass[0],
            model.body("FL_hip").mass[0],
            model.body("FL_foot").mass[0],
            model.body("base").mass[0],
        ]
    )
    assert robot.descriptor[5:] == pytest.approx(GO2.descriptor[5:])


def test_gains_scale_with_the_mass_ratio(model, robot):
    ratio = float(model.body_mass.sum()) / 16.085  # Go2's total mass (base + 4 legs with rotors)
    assert model.actuator_gainprm[:12, 0] == pytest.approx(20.0 * ratio)  # Kp 20
    assert -model.actuator_biasprm[:12, 2] == pytest.approx(0.5 * ratio)  # Kd 0.5
    assert model.actuator_forcerange[:3, 1] == pytest.approx([23.7, 23.7, 45.43])  # motors kept (GenLoco)
    heavy = P.generate_robot(GO2, SAMPLE, dataclasses.replace(CFG, torque_with_mass=True, gains_with_mass=False))
    assert heavy.kp == 20.0 and heavy.torque_limit == pytest.approx(np.array([23.7, 23.7, 45.43]) * ratio)


def test_inertias_stretch_with_the_body():
    m, ext = 2.0, np.array([0.3, 0.1, 0.05])  # a box: I = m/12 (b^2 + c^2, a^2 + c^2, a^2 + b^2)

    def box(mass, e):
        return mass / 12 * np.array([e[1] ** 2 + e[2] ** 2, e[0] ** 2 + e[2] ** 2, e[0] ** 2 + e[1] ** 2])

    f = np.array([1.5, 0.5, 2.0])
    assert P.stretch_inertia(box(m, ext), 3.0, f) == pytest.approx(box(3 * m, ext * f))


def test_init_height_keeps_the_templates_clearance(model, robot):
    standing = nominal_height(robot)
    assert robot.init_height == pytest.approx(standing + 0.34 - nominal_height(GO2))
    assert model.key("home").qpos[2] == pytest.approx(robot.init_height)
    assert model.key("home").qpos[7:] == pytest.approx(GO2.default_qpos)  # the template's default pose


def test_the_nominal_sample_is_the_template():
    same = P.generate_robot(GO2, P.GeometrySample.nominal(), CFG)
    a, b = build_model(GO2), build_model(same)
    for name in (
        "body_pos",
        "body_mass",
        "body_inertia",
        "body_ipos",
        "geom_size",
        "actuator_gainprm",
        "actuator_biasprm",
        "key_qpos",
    ):
        assert getattr(b, name) == pytest.approx(getattr(a, name)), name
    assert same.descriptor == pytest.approx(GO2.descriptor)
    assert {link: same.links[link].mass for link in LINKS} == {link: GO2.links[link].mass for link in LINKS}


def test_a_pool_is_reproducible_from_its_seed():
    cfg = dataclasses.replace(CFG, pool_size=3)
    a, b, c = P.generate_pool(GO2, cfg, 7), P.generate_pool(GO2, cfg, 7), P.generate_pool(GO2, cfg, 8)
    assert np.array_equal(a.descriptors, b.descriptors) and np.array_equal(a.init_height, b.init_height)
    assert [s.scale for s in a.samples] == [s.scale for s in b.samples]
    assert not np.array_equal(a.descriptors, c.descriptors)
    assert [r.name for r in a.robots] == ["go2_gen0", "go2_gen1", "go2_gen2"]
    assert a.nominal_foot_pos_b.shape == (3, 4, 2)
    assert a.nominal_foot_pos_b[0, 0] == pytest.approx(a.robots[0].hip_pos[0, :2] + a.robots[0].thigh_offset[0, :2])
    for robot in a.robots:  # every robot stands with its base clear of the ground
        assert nominal_height(robot) - robot.base_size[2] / 2 >= cfg.min_base_clearance


def test_an_unreachable_clearance_is_an_error(monkeypatch):
    monkeypatch.setattr(P, "MAX_REDRAWS", 3)
    with pytest.raises(ValueError, match="min_base_clearance"):
        P.sample_geometry(np.random.default_rng(0), dataclasses.replace(CFG, min_base_clearance=5.0), GO2)


def test_a_sample_is_one_named_vector():
    v = SAMPLE.vector()
    assert v.shape == (len(P.FACTOR_NAMES),) == (16,)
    named = dict(zip(P.FACTOR_NAMES, v, strict=True))
    assert named["scale"] == 1.1 and named["base_size_y"] == 0.8 and named["thigh_offset"] == 1.08
    assert named["calf_radius"] == 0.6 and named["hip_mass"] == 1.4 and named["foot_mass"] == 0.5
    assert np.array_equal(P.GeometrySample.nominal().vector(), np.ones(16))
