"""Build a MuJoCo model of a robot spec with :class:`mujoco.MjSpec` (no string-templated XML).

The model (names are the contract with the env and the descriptor-application code):

* ``base``: a free body (freejoint ``base_freejoint``) with a box geom ``base_collision``, an
  ``imu`` site at the base origin and the spec's explicit trunk inertial.
* per leg ``{leg}`` in FL, FR, RL, RR: bodies ``{leg}_hip`` -> ``{leg}_thigh`` -> ``{leg}_calf`` ->
  ``{leg}_foot``, joints ``{leg}_hip_joint`` (axis +x), ``{leg}_thigh_joint`` and
  ``{leg}_calf_joint`` (axis +y), limited to the spec's ranges, with armature and damping.
  Geoms: capsules ``{leg}_hip_geom``, ``{leg}_thigh_collision``, ``{leg}_calf_geom`` and the sphere
  ``{leg}_foot_geom``; site ``{leg}_foot_site`` at the foot centre.
* rotors/drives as separate welded bodies, ``{leg}_hip_rotor`` (child of ``base``),
  ``{leg}_thigh_rotor`` (child of ``{leg}_hip``) and ``{leg}_calf_rotor`` (child of
  ``{leg}_thigh``), so that the masses of ``base`` and the link bodies are exactly the spec's
  (bare) link masses; a descriptor is applied by setting those body masses.
* position actuators named like the joints, kp = Kp, kv = Kd, forcerange = +-torque limit,
  ctrlrange = the joint range. Actuator and joint order: FL, FR, RL, RR x (hip, thigh, calf).
* keyframe ``home``: the default pose with the base at the init height.
* sensors: ``base_linvel`` (velocimeter), ``base_gyro``, ``base_acc`` (accelerometer),
  ``base_quat`` (framequat) at ``imu``; per foot ``{leg}_foot_touch``, ``{leg}_foot_pos``
  (framepos) and ``{leg}_foot_vel`` (framelinvel) at ``{leg}_foot_site``.
* simulation sensors, only with ``sim_sensors=True`` (what the batched backends read from
  ``sensordata`` so that no Python loops over contacts are needed), after the sensors above:
  ``{leg}_{joint}_torque`` (actuatorfrc of each actuator, N m, 12 x 1, actuator order);
  with a floor, ``{leg}_foot_force`` (contact sensor floor -> ``{leg}_foot_geom``, data force,
  reduce netforce: the net ground force on the foot in the world frame, N, 4 x 3) and
  ``{body}_contact_force`` for each of :func:`contact_body_names` (contact sensor floor -> every
  geom of that body, netforce, world frame, N, 9 x 3).
* physics: dt 0.005 s, implicitfast integrator, inertias only from the explicit inertials
  (``inertiafromgeom`` false), a ``floor`` plane when asked.

Contact classes: every robot geom has contype 2 / conaffinity 1, the floor contype 1 / conaffinity 1,
so the robot touches the world but never itself. ``base_collision`` and ``{leg}_thigh_collision``
are in the default class ``body_contact`` (terminate on ground contact), feet in ``foot``, the rest
in ``limb``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from morfic_cli.morphology.robots import JOINTS, LEGS, RobotSpec

TIMESTEP = 0.005
"""Physics time step, s (docs/concepts.md)."""

JOINT_AXES: dict[str, tuple[float, float, float]] = {
    "hip": (1.0, 0.0, 0.0),
    "thigh": (0.0, 1.0, 0.0),
    "calf": (0.0, 1.0, 0.0),
}
"""Joint axes of the library's convention, in the (aligned) joint frames."""

IMPRATIO = 100.0
"""Frictional-to-normal impedance ratio with an elliptic friction cone: stops the slow foot creep
that lets a PD-held robot splay and sink (menagerie's unitree_go2/a1 and unitree_mujoco's go2.xml
use ``cone="elliptic" impratio="100"``)."""

CONTACT_CLASSES: tuple[str, ...] = ("body_contact", "foot", "limb")
"""Default classes of the robot's geoms: ground contact of ``body_contact`` terminates an episode."""

ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1
WORLD_CONTYPE, WORLD_CONAFFINITY = 1, 1
TOUCH_SITE_SCALE = 1.25
"""The foot site is this much larger than the foot sphere so the touch sensor sees its contacts."""


def joint_names() -> list[str]:
    """Joint (and actuator) names in model order: FL_hip_joint, FL_thigh_joint, ..., RR_calf_joint."""
    return [f"{leg}_{j}_joint" for leg in LEGS for j in JOINTS]


def body_names() -> list[str]:
    """Names of the bodies whose masses are the spec's: ``base`` and every leg link."""
    return ["base"] + [f"{leg}_{link}" for leg in LEGS for link in ("hip", "thigh", "calf", "foot")]


def contact_body_names() -> list[str]:
    """Bodies with a ground-contact sensor (``sim_sensors``): ``base``, the four thighs, the four calves."""
    return ["base"] + [f"{leg}_thigh" for leg in LEGS] + [f"{leg}_calf" for leg in LEGS]


def build_spec(robot: RobotSpec, *, floor: bool = True, sim_sensors: bool = False) -> mujoco.MjSpec:
    """Build the robot as an editable MuJoCo spec.

    Args:
        robot: The validated robot.
        floor: Add a ``floor`` plane (and a light) to the world.
        sim_sensors: Add the simulation sensors (actuator torques; with a floor, foot and body
            ground-contact forces), see the module docstring.

    Returns:
        The spec; ``spec.compile()`` gives the model.
    """
    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.autolimits = True
    spec.compiler.degree = False  # every angle in the spec is in rad
    spec.option.timestep = TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = IMPRATIO
    _add_defaults(spec)
    if floor:
        _add_floor(spec)
    base = _add_base(spec, robot)
    for li, leg in enumerate(LEGS):
        _add_leg(spec, base, robot, li, leg)
    _add_actuators(spec, robot)
    _add_sensors(spec)
    if sim_sensors:
        _add_sim_sensors(spec, floor=floor)
    _add_keyframe(spec, robot)
    return spec


def build_model(robot: RobotSpec, *, floor: bool = True, sim_sensors: bool = False) -> mujoco.MjModel:
    """Compile the robot into a MuJoCo model (see :func:`build_spec`)."""
    return build_spec(robot, floor=floor, sim_sensors=sim_sensors).compile()


def to_xml(robot: RobotSpec) -> str:
    """The generated MJCF of the robot with a floor, as printed by ``morfic robots show NAME --xml``."""
    spec = build_spec(robot, floor=True)
    spec.compile()
    return spec.to_xml()


def nominal_height(robot: RobotSpec) -> float:
    """Standing height by forward kinematics at the default pose.

    The base is upright at the origin; the height is the base origin's height above the lowest
    foot bottom (foot-sphere centre minus the foot radius).

    Args:
        robot: The robot.

    Returns:
        Height in m.
    """
    model = build_model(robot, floor=False)
    data = mujoco.MjData(model)
    data.qpos[:] = 0.0
    data.qpos[3] = 1.0
    data.qpos[7:] = robot.default_qpos
    mujoco.mj_kinematics(model, data)
    feet = [model.site(f"{leg}_foot_site").id for leg in LEGS]
    lowest = float(np.min(data.site_xpos[feet, 2])) - robot.foot_radius
    return -lowest


# --------------------------------------------------------------------------------------------------
# pieces
# --------------------------------------------------------------------------------------------------


def _add_defaults(spec: mujoco.MjSpec) -> None:
    for name in CONTACT_CLASSES:
        default = spec.add_default(name, spec.default)
        default.geom.contype = ROBOT_CONTYPE
        default.geom.conaffinity = ROBOT_CONAFFINITY
        default.geom.condim = 3
    spec.find_default("foot").geom.rgba = [0.2, 0.2, 0.2, 1.0]
    spec.find_default("body_contact").geom.rgba = [0.4, 0.5, 0.7, 1.0]
    spec.find_default("limb").geom.rgba = [0.6, 0.6, 0.65, 1.0]


def _add_floor(spec: mujoco.MjSpec) -> None:
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        rgba=[0.8, 0.8, 0.8, 1.0],
        contype=WORLD_CONTYPE,
        conaffinity=WORLD_CONAFFINITY,
    )
    spec.worldbody.add_light(
        name="sun", pos=[0.0, 0.0, 3.0], dir=[0.0, 0.0, -1.0], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    )


def _inertial(body: mujoco.MjsBody, mass: float, com: np.ndarray, full_inertia: np.ndarray) -> None:
    """Explicit inertial: mass, COM and full inertia (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) about the COM."""
    body.explicitinertial = True
    body.mass = float(mass)
    body.ipos = np.asarray(com, dtype=float)
    full_inertia = np.asarray(full_inertia, dtype=float)
    if np.any(full_inertia[3:]):
        body.fullinertia = full_inertia
    else:  # diagonal: keep the body axes as principal axes (iquat identity, no reordering)
        body.inertia = full_inertia[:3]


def _sphere_inertia(mass: float, radius: float) -> np.ndarray:
    moment = 0.4 * mass * radius**2
    return np.array([moment, moment, moment, 0.0, 0.0, 0.0])


def _add_base(spec: mujoco.MjSpec, robot: RobotSpec) -> mujoco.MjsBody:
    base = spec.worldbody.add_body(name="base", pos=[0.0, 0.0, robot.init_height])
    base.add_freejoint(name="base_freejoint")
    _inertial(base, robot.base_mass, robot.base_com, np.concatenate([robot.base_inertia, np.zeros(3)]))
    base.add_geom(
        name="base_collision",
        default=spec.find_default("body_contact"),
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=robot.base_size / 2,
    )
    base.add_site(name="imu", pos=[0.0, 0.0, 0.0], size=[0.01, 0.01, 0.01])
    return base


def _add_rotor(parent: mujoco.MjsBody, name: str, pos: np.ndarray, mass: float, radius: float) -> None:
    if mass <= 0:
        return
    rotor = parent.add_body(name=name, pos=np.asarray(pos, dtype=float))
    _inertial(rotor, mass, np.zeros(3), _sphere_inertia(mass, radius))


def _add_joint(body: mujoco.MjsBody, robot: RobotSpec, li: int, ji: int, leg: str) -> None:
    joint = JOINTS[ji]
    body.add_joint(
        name=f"{leg}_{joint}_joint",
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=JOINT_AXES[joint],
        range=robot.joint_range[li, ji],
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        armature=float(robot.armature[ji]),
        damping=float(robot.damping[ji]),
    )


def _link_body(
    parent: mujoco.MjsBody, robot: RobotSpec, li: int, leg: str, link: str, pos: np.ndarray
) -> mujoco.MjsBody:
    body = parent.add_body(name=f"{leg}_{link}", pos=np.asarray(pos, dtype=float))
    inertial = robot.links[link]
    _inertial(body, inertial.mass, inertial.com[li], inertial.inertia[li])
    return body


def _capsule(spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, cls: str, end: np.ndarray, radius: float) -> None:
    body.add_geom(
        name=name,
        default=spec.find_default(cls),
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=[0.0, 0.0, 0.0, *np.asarray(end, dtype=float)],
        size=[radius, 0.0, 0.0],
    )


def _add_leg(spec: mujoco.MjSpec, base: mujoco.MjsBody, robot: RobotSpec, li: int, leg: str) -> None:
    rotor_r = robot.rotor_radius
    _add_rotor(base, f"{leg}_hip_rotor", robot.hip_pos[li], robot.rotor_mass[0], rotor_r)

    hip = _link_body(base, robot, li, leg, "hip", robot.hip_pos[li])
    _add_joint(hip, robot, li, 0, leg)
    _capsule(spec, hip, f"{leg}_hip_geom", "limb", robot.thigh_offset[li], robot.link_radius[0])
    _add_rotor(hip, f"{leg}_thigh_rotor", robot.thigh_offset[li], robot.rotor_mass[1], rotor_r)

    thigh = _link_body(hip, robot, li, leg, "thigh", robot.thigh_offset[li])
    _add_joint(thigh, robot, li, 1, leg)
    _capsule(spec, thigh, f"{leg}_thigh_collision", "body_contact", robot.calf_offset[li], robot.link_radius[1])
    calf_rotor_pos = np.zeros(3) if robot.calf_rotor_at == "thigh_joint" else robot.calf_offset[li]
    _add_rotor(thigh, f"{leg}_calf_rotor", calf_rotor_pos, robot.rotor_mass[2], rotor_r)

    calf = _link_body(thigh, robot, li, leg, "calf", robot.calf_offset[li])
    _add_joint(calf, robot, li, 2, leg)
    _capsule(spec, calf, f"{leg}_calf_geom", "limb", robot.foot_offset[li], robot.link_radius[2])

    foot = _link_body(calf, robot, li, leg, "foot", robot.foot_offset[li])
    foot.add_geom(
        name=f"{leg}_foot_geom",
        default=spec.find_default("foot"),
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[robot.foot_radius, 0.0, 0.0],
    )
    foot.add_site(
        name=f"{leg}_foot_site",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[robot.foot_radius * TOUCH_SITE_SCALE, 0.0, 0.0],
        rgba=[1.0, 0.3, 0.3, 0.0],
    )


def _add_actuators(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    for li, leg in enumerate(LEGS):
        for ji, joint in enumerate(JOINTS):
            name = f"{leg}_{joint}_joint"
            act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=robot.kp, kv=robot.kd)
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = robot.joint_range[li, ji]
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [-robot.torque_limit[ji], robot.torque_limit[ji]]


def _sensor(spec: mujoco.MjSpec, name: str, kind: mujoco.mjtSensor, site: str) -> None:
    spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)


def _add_sensors(spec: mujoco.MjSpec) -> None:
    s = mujoco.mjtSensor
    _sensor(spec, "base_linvel", s.mjSENS_VELOCIMETER, "imu")
    _sensor(spec, "base_gyro", s.mjSENS_GYRO, "imu")
    _sensor(spec, "base_acc", s.mjSENS_ACCELEROMETER, "imu")
    _sensor(spec, "base_quat", s.mjSENS_FRAMEQUAT, "imu")
    for leg in LEGS:
        site = f"{leg}_foot_site"
        _sensor(spec, f"{leg}_foot_touch", s.mjSENS_TOUCH, site)
        _sensor(spec, f"{leg}_foot_pos", s.mjSENS_FRAMEPOS, site)
        _sensor(spec, f"{leg}_foot_vel", s.mjSENS_FRAMELINVEL, site)


CONTACT_DATA_FORCE = 1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE)
"""Contact-sensor ``data`` bit mask selecting only the 3-D force (MJCF ``data="force"``)."""

CONTACT_REDUCE_NETFORCE = 3
"""Contact-sensor ``reduce`` mode ``netforce`` (MJCF ``reduce="netforce"``: none 0, mindist 1,
maxforce 2, netforce 3): all matching contacts summed into one synthetic contact whose frame is
the world frame."""


def _contact_sensor(spec: mujoco.MjSpec, name: str, reftype: mujoco.mjtObj, refname: str) -> None:
    """Net ground force on ``refname`` in the world frame.

    MuJoCo reports the force geom1 (the floor) exerts on geom2 (the robot part): +z when the floor
    pushes the robot up.
    """
    spec.add_sensor(
        name=name,
        type=mujoco.mjtSensor.mjSENS_CONTACT,
        objtype=mujoco.mjtObj.mjOBJ_GEOM,
        objname="floor",
        reftype=reftype,
        refname=refname,
        intprm=[CONTACT_DATA_FORCE, CONTACT_REDUCE_NETFORCE, 1],
    )


def _add_sim_sensors(spec: mujoco.MjSpec, *, floor: bool) -> None:
    for name in joint_names():
        spec.add_sensor(
            name=name.removesuffix("_joint") + "_torque",
            type=mujoco.mjtSensor.mjSENS_ACTUATORFRC,
            objtype=mujoco.mjtObj.mjOBJ_ACTUATOR,
            objname=name,
        )
    if not floor:
        return
    for leg in LEGS:
        _contact_sensor(spec, f"{leg}_foot_force", mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot_geom")
    for body in contact_body_names():
        _contact_sensor(spec, f"{body}_contact_force", mujoco.mjtObj.mjOBJ_BODY, body)


def _add_keyframe(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    qpos = np.concatenate([[0.0, 0.0, robot.init_height, 1.0, 0.0, 0.0, 0.0], robot.default_qpos])
    spec.add_key(name="home", qpos=qpos, ctrl=robot.default_qpos)
