"""The MJCF builder: names, masses, joint convention, sensors, and every robot standing for 2 s."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from morfic_cli.morphology.builder import (
    TIMESTEP,
    body_names,
    build_model,
    build_spec,
    contact_body_names,
    joint_names,
    nominal_height,
    to_xml,
)
from morfic_cli.morphology.robots import JOINTS, LEGS, list_robots, load_robot

ROBOTS = list_robots()
"""Every robot in the library (a new TOML is built and checked without a test edit)."""

# MuJoCo forward kinematics of the public URDFs at each robot's default pose (the paper's seven robots).
FACTS_NOMINAL_HEIGHT = {
    "go2": 0.3235,
    "go1": 0.3218,
    "a1": 0.3025,
    "aliengo": 0.4258,
    "b1": 0.5162,
    "mini_cheetah": 0.3025,
    "anymal_c": 0.5488,
}


@pytest.fixture(scope="module")
def built():
    """Every robot's spec and model, built once for the module."""
    return {name: (load_robot(name), build_model(load_robot(name))) for name in list_robots()}


def _stand(spec, model, steps: int = 400) -> mujoco.MjData:
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    for _ in range(steps):
        data.ctrl[:] = spec.default_qpos
        mujoco.mj_step(model, data)
    return data


@pytest.mark.parametrize("name", ROBOTS)
def test_robot_stands_for_two_seconds_at_its_default_pose_and_gains(built, name):
    spec, model = built[name]
    data = _stand(spec, model, steps=int(round(2.0 / TIMESTEP)))
    assert np.all(np.isfinite(data.qpos))
    height = nominal_height(spec)
    assert data.qpos[2] > 0.7 * height, f"{name}: base at {data.qpos[2]:.3f} m, nominal {height:.3f} m"
    w, x, y, z = data.qpos[3:7]
    up_z = 1.0 - 2.0 * (x * x + y * y)  # world z of the base z-axis
    assert up_z > 0.95, f"{name} tilted: cos(tilt) = {up_z:.3f}"


@pytest.mark.parametrize("name", ROBOTS)
def test_total_mass_equals_the_spec(built, name):
    spec, model = built[name]
    assert float(model.body_mass.sum()) == pytest.approx(spec.total_mass, abs=1e-9)


def test_go2_model_mass_by_hand(built):
    _, model = built["go2"]
    # base + 4 x (hip + thigh + calf + foot + hip/thigh/calf rotors of 0.089 kg), unitree_ros go2 URDF.
    assert float(model.body_mass.sum()) == pytest.approx(6.921 + 4 * (0.678 + 1.152 + 0.154 + 0.040 + 3 * 0.089))


@pytest.mark.parametrize("name", ROBOTS)
def test_link_bodies_carry_exactly_the_spec_link_masses(built, name):
    spec, model = built[name]
    assert model.body("base").mass[0] == pytest.approx(spec.base_mass)
    for leg in LEGS:
        for link in ("hip", "thigh", "calf", "foot"):
            assert model.body(f"{leg}_{link}").mass[0] == pytest.approx(spec.links[link].mass)
        for ji, joint in enumerate(JOINTS):
            name_ = f"{leg}_{joint}_rotor"
            if spec.rotor_mass[ji] > 0:
                assert model.body(name_).mass[0] == pytest.approx(spec.rotor_mass[ji])
            else:
                with pytest.raises(KeyError):
                    model.body(name_)


def test_rotors_hang_where_the_urdf_puts_them(built):
    _, go2 = built["go2"]
    assert go2.body(go2.body("FL_hip_rotor").parentid[0]).name == "base"
    assert go2.body(go2.body("FL_thigh_rotor").parentid[0]).name == "FL_hip"
    assert go2.body(go2.body("FL_calf_rotor").parentid[0]).name == "FL_thigh"
    np.testing.assert_allclose(go2.body("FL_calf_rotor").pos, 0.0)  # Unitree knee motor at the hip
    spec, anymal = built["anymal_c"]
    np.testing.assert_allclose(anymal.body("FL_calf_rotor").pos, spec.calf_offset[0])  # KFE drive at the knee


@pytest.mark.parametrize("name", ROBOTS)
def test_joints_follow_the_convention(built, name):
    spec, model = built[name]
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert model.nq == 7 + 12 and model.nu == 12
    axes = {"hip": [1, 0, 0], "thigh": [0, 1, 0], "calf": [0, 1, 0]}
    for li, leg in enumerate(LEGS):
        for ji, joint in enumerate(JOINTS):
            jnt = model.joint(f"{leg}_{joint}_joint")
            np.testing.assert_allclose(jnt.axis, axes[joint])
            np.testing.assert_allclose(jnt.range, spec.joint_range[li, ji])
            assert model.jnt_limited[jnt.id]
            assert jnt.armature[0] == pytest.approx(spec.armature[ji])
            # qpos order is leg-major FL, FR, RL, RR x (hip, thigh, calf)
            assert jnt.qposadr[0] == 7 + 3 * li + ji


@pytest.mark.parametrize("name", ROBOTS)
def test_position_actuators(built, name):
    spec, model = built[name]
    assert [model.actuator(i).name for i in range(model.nu)] == joint_names()
    for i in range(model.nu):
        ji = i % 3
        assert model.actuator_trnid[i, 0] == model.joint(joint_names()[i]).id
        assert model.actuator_gainprm[i, 0] == pytest.approx(spec.kp)
        np.testing.assert_allclose(model.actuator_biasprm[i, :3], [0.0, -spec.kp, -spec.kd])
        np.testing.assert_allclose(model.actuator_forcerange[i], [-spec.torque_limit[ji], spec.torque_limit[ji]])
        np.testing.assert_allclose(model.actuator_ctrlrange[i], spec.ctrl_range[i])
        assert model.actuator_ctrllimited[i] and model.actuator_forcelimited[i]


@pytest.mark.parametrize("name", ROBOTS)
def test_home_keyframe_and_physics_options(built, name):
    spec, model = built[name]
    key = model.key("home")
    np.testing.assert_allclose(key.qpos, [0, 0, spec.init_height, 1, 0, 0, 0, *spec.default_qpos])
    np.testing.assert_allclose(key.ctrl, spec.default_qpos)
    assert model.opt.timestep == 0.005
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert spec.init_height >= nominal_height(spec)  # the reset never starts with the feet in the floor


def test_knee_signs_at_the_default_pose(built):
    for name in ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah"):
        spec, _ = built[name]
        assert np.all(spec.default_qpos[2::3] < 0), name
    spec, _ = built["anymal_c"]
    np.testing.assert_allclose(spec.default_qpos[2::3], [-0.8, -0.8, 0.8, 0.8])


@pytest.mark.parametrize("name", sorted(FACTS_NOMINAL_HEIGHT))
def test_nominal_height_matches_the_public_urdf_fk(name):
    assert nominal_height(load_robot(name)) == pytest.approx(FACTS_NOMINAL_HEIGHT[name], abs=2e-3)


def test_names_sites_sensors_and_contact_classes(built):
    spec_, model = built["go2"]
    for body in body_names():
        model.body(body)
    for leg in LEGS:
        model.site(f"{leg}_foot_site")
        for geom in (f"{leg}_foot_geom", f"{leg}_thigh_collision"):
            model.geom(geom)
    model.site("imu")
    model.geom("base_collision")
    model.geom("floor")
    dims = {"base_linvel": 3, "base_gyro": 3, "base_acc": 3, "base_quat": 4}
    dims |= {f"{leg}_foot_{k}": d for leg in LEGS for k, d in (("touch", 1), ("pos", 3), ("vel", 3))}
    for sensor, dim in dims.items():
        assert model.sensor(sensor).dim[0] == dim
    assert model.nsensordata == sum(dims.values())
    spec = build_spec(spec_)
    assert spec.geom("base_collision").classname.name == "body_contact"
    assert spec.geom("FL_thigh_collision").classname.name == "body_contact"
    assert spec.geom("FL_foot_geom").classname.name == "foot"


def test_robot_geoms_touch_the_world_but_not_each_other(built):
    _, model = built["go2"]
    floor = model.geom("floor").id
    for g in range(model.ngeom):
        if g == floor:
            continue
        assert (
            model.geom_contype[g] & model.geom_conaffinity[floor]
            or model.geom_contype[floor] & model.geom_conaffinity[g]
        )
        assert not (model.geom_contype[g] & model.geom_conaffinity[g])


def test_feet_touch_the_ground_when_standing(built):
    spec, model = built["go1"]
    data = _stand(spec, model, steps=200)
    touch = [data.sensor(f"{leg}_foot_touch").data[0] for leg in LEGS]
    assert all(t > 0 for t in touch)
    assert sum(touch) == pytest.approx(spec.total_mass * 9.81, rel=0.2)
    np.testing.assert_allclose(data.sensor("FL_foot_pos").data, data.site("FL_foot_site").xpos)


def test_no_floor_when_asked():
    model = build_model(load_robot("go2"), floor=False)
    with pytest.raises(KeyError):
        model.geom("floor")


@pytest.mark.parametrize("name", ["go1", "anymal_c"])
def test_xml_round_trips(built, name):
    spec, model = built[name]
    xml = to_xml(spec)
    assert "<mujoco" in xml
    again = mujoco.MjModel.from_xml_string(xml)
    assert again.nbody == model.nbody and again.nu == model.nu
    assert float(again.body_mass.sum()) == pytest.approx(spec.total_mass)
    np.testing.assert_allclose(again.jnt_range, model.jnt_range)


def test_sim_sensors_layout():
    spec_ = load_robot("go2")
    plain, model = build_model(spec_), build_model(spec_, sim_sensors=True)
    extra = {f"{leg}_{j}_torque": 1 for leg in LEGS for j in JOINTS}
    extra |= {f"{leg}_foot_force": 3 for leg in LEGS}
    extra |= {f"{body}_contact_force": 3 for body in contact_body_names()}
    assert model.nsensordata == plain.nsensordata + sum(extra.values()) == plain.nsensordata + 12 + 12 + 27
    for sensor, dim in extra.items():
        assert model.sensor(sensor).dim[0] == dim
        assert model.sensor(sensor).adr[0] >= plain.nsensordata  # appended after the existing sensors
    torque = model.sensor("RL_calf_torque")
    assert torque.type[0] == mujoco.mjtSensor.mjSENS_ACTUATORFRC
    assert torque.objid[0] == model.actuator("RL_calf_joint").id
    assert contact_body_names() == [
        "base",
        "FL_thigh",
        "FR_thigh",
        "RL_thigh",
        "RR_thigh",
        "FL_calf",
        "FR_calf",
        "RL_calf",
        "RR_calf",
    ]
    no_floor = build_model(spec_, floor=False, sim_sensors=True)  # torques only without a floor
    assert no_floor.nsensordata == plain.nsensordata + 12


def test_contact_sensors_equal_their_mjcf_spelling():
    """The integer parameters written by the builder mean data="force" reduce="netforce" in MJCF."""
    spec = build_spec(load_robot("go2"), sim_sensors=True)
    spec.compile()
    text = spec.to_xml()
    assert '<contact geom1="floor" geom2="FL_foot_geom" data="force" reduce="netforce"' in text
    assert '<contact geom1="floor" body2="RR_calf" data="force" reduce="netforce"' in text
    parsed = mujoco.MjModel.from_xml_string(text)
    built = build_model(load_robot("go2"), sim_sensors=True)
    np.testing.assert_array_equal(parsed.sensor_intprm, built.sensor_intprm)
    np.testing.assert_array_equal(parsed.sensor_type, built.sensor_type)


def test_contact_sensors_report_the_world_frame_ground_force():
    spec_ = load_robot("go2")
    model = build_model(spec_, sim_sensors=True)
    data = _stand(spec_, model, steps=300)
    force = np.stack([data.sensor(f"{leg}_foot_force").data for leg in LEGS])
    assert np.all(force[:, 2] > 0)  # the floor pushes each foot up (+z, world frame)
    assert force[:, 2].sum() == pytest.approx(spec_.total_mass * 9.81, rel=0.1)
    assert force[:, 1].sum() == pytest.approx(0.0, abs=1e-6)  # left/right splay forces cancel
    for body in contact_body_names():
        assert np.all(data.sensor(f"{body}_contact_force").data == 0.0)
    for leg in LEGS:
        for j in JOINTS:
            assert data.sensor(f"{leg}_{j}_torque").data[0] == pytest.approx(
                data.actuator_force[model.actuator(f"{leg}_{j}_joint").id]
            )
