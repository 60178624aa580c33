#!/usr/bin/env python3
"""A minimal 50 Hz control loop for a policy exported with ``morfic export`` (see docs/deploy.md).

It runs the exported ONNX policy against a MuJoCo model of the target robot, a sim-to-sim check of everything a
robot stack has to get right. Every control step (``control.dt`` = 20 ms):

1. read the state: base orientation, base linear and angular velocity, joint positions and velocities
   (here from MuJoCo's qpos/qvel; on a robot from the IMU, a velocity estimator and the joint encoders);
2. build o_t (48) by the metadata's observation layout, scales and clip;
3. push o_t into the history of ``observation.history_len`` frames (16; 15 for runs trained before issue 16),
   oldest first, o_t last; filled with the first o_t at start;
4. run the policy with onnxruntime: ``actions = session.run(history[, morphology])``;
5. joint targets ``q* = clamp(q0 + action_scale * clip(a), q_min, q_max)``, held for ``decimation`` physics steps
   by PD with the metadata's Kp / Kd and torque limits.

Only numpy, mujoco and onnxruntime are needed; morfic is imported only to build the robot's model by name when
no ``--mjcf`` file is given (``morfic robots show go1 --xml > go1.xml`` writes one).

Usage::

    morfic export runs/film-cpu-s0 --robot go1 --out deploy/go1
    python examples/deploy_loop.py deploy/go1 --vx 1.0 --seconds 10
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

#: A policy: history (1, H, 48) float32 -> actions (12,) float32.
Policy = Callable[[np.ndarray], np.ndarray]

#: What :func:`run` records per control step.
LOGGED = (
    "action",
    "joint_targets",
    "joint_pos",
    "joint_vel",
    "base_pos",
    "base_quat",
    "base_lin_vel",
    "tilt",
    "policy_ms",
)

TILT_LIMIT = 1.0
"""Tilt (rad) between the base z axis and world up that counts as a fall (the training env's termination)."""


# ---------------------------------------------------------------------------------------------- export files
def load_export(path: str | Path) -> tuple[dict[str, Any], Path]:
    """Read ``policy.json`` from an export directory (or the file itself); returns (metadata, model path)."""
    path = Path(path)
    meta_path = path / "policy.json" if path.is_dir() else path
    meta = json.loads(meta_path.read_text())
    return meta, meta_path.parent / meta["model_file"]


def pick_robot(meta: dict[str, Any], robot: str | None) -> str:
    """The robot to run: ``robot``, else the baked one, else the only one described."""
    robot = robot or meta["baked_robot"]
    if robot is None:
        if len(meta["robots"]) != 1:
            raise SystemExit(f"give --robot, one of: {', '.join(meta['robots'])}")
        robot = next(iter(meta["robots"]))
    if robot not in meta["robots"]:
        raise SystemExit(f"robot '{robot}' is not in this export; it describes: {', '.join(meta['robots'])}")
    if meta["baked_robot"] not in (None, robot):
        raise SystemExit(f"this export has {meta['baked_robot']}'s descriptor built in; it cannot drive {robot}")
    return robot


class OnnxPolicy:
    """The exported policy in onnxruntime, with the robot's normalised descriptor fed when it is an input.

    Args:
        model_path: ``policy.onnx``.
        meta: The export metadata.
        robot: Robot whose ``morphology`` vector is fed (when the model takes one).
    """

    def __init__(self, model_path: Path, meta: dict[str, Any], robot: str) -> None:
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1  # one small MLP per step: threads cost more than they give
        self.session = ort.InferenceSession(str(model_path), sess_options=opts, providers=["CPUExecutionProvider"])
        names = [i.name for i in self.session.get_inputs()]
        morphology = np.asarray(meta["robots"][robot]["morphology"], dtype=np.float32)[None]
        self.extra = {"morphology": morphology} if "morphology" in names else {}

    def __call__(self, history: np.ndarray) -> np.ndarray:
        """Actions for one history. Shapes: (1, H, 48) -> (12,)."""
        return self.session.run(["actions"], {"history": history, **self.extra})[0][0]


# ---------------------------------------------------------------------------------------------- the robot
@dataclass(frozen=True)
class RobotIO:
    """Where the metadata's joints live in a MuJoCo model (addresses in joint_names order)."""

    base_qpos: int
    """qpos address of the free joint: position [0:3], quaternion (w, x, y, z) [3:7]."""
    base_dof: int
    """qvel address of the free joint: world linear velocity [0:3], base-frame angular velocity [3:6]."""
    qpos: np.ndarray
    dof: np.ndarray
    actuators: np.ndarray
    torque_mode: bool
    """True for motor actuators (PD torques computed here), False for position actuators (PD in MuJoCo)."""


def bind(model: mujoco.MjModel, joint_names: list[str]) -> RobotIO:
    """Find the free joint, the 12 joints and the actuator driving each (by transmission, not by name)."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise SystemExit("the model needs exactly one free joint (the floating base)")
    joints = [model.joint(name).id for name in joint_names]
    drives = {
        int(model.actuator_trnid[a, 0]): a
        for a in range(model.nu)
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
    }
    missing = [joint_names[i] for i, j in enumerate(joints) if j not in drives]
    if missing:
        raise SystemExit(f"no actuator drives {', '.join(missing)}")
    actuators = np.array([drives[j] for j in joints])
    position = model.actuator_biastype[actuators] == mujoco.mjtBias.mjBIAS_AFFINE
    if position.any() and not position.all():
        raise SystemExit("mixed actuator types: use all position or all motor actuators")
    return RobotIO(
        int(model.jnt_qposadr[free[0]]),
        int(model.jnt_dofadr[free[0]]),
        model.jnt_qposadr[joints].copy(),
        model.jnt_dofadr[joints].copy(),
        actuators,
        not bool(position.all()),
    )


def apply_gains(model: mujoco.MjModel, io: RobotIO, robot: dict[str, Any]) -> None:
    """Put the metadata's Kp, Kd, torque limits and joint limits into the model's actuators.

    Position actuators get ``kp``/``kv`` (PD in MuJoCo, with implicit damping, as in training); motor actuators
    get the torque limits as force range (the PD is then computed in :func:`hold_targets`).
    """
    kp, kd = np.asarray(robot["kp"]), np.asarray(robot["kd"])
    limit = np.asarray(robot["torque_limit"])
    a = io.actuators
    model.actuator_forcelimited[a] = 1
    model.actuator_forcerange[a] = np.stack([-limit, limit], axis=1)
    if io.torque_mode:
        model.actuator_ctrllimited[a] = 0
        return
    model.actuator_gainprm[a, 0] = kp
    model.actuator_biasprm[a, 0:3] = np.stack([np.zeros_like(kp), -kp, -kd], axis=1)
    model.actuator_ctrllimited[a] = 1
    model.actuator_ctrlrange[a] = np.asarray(robot["joint_limits"])


# ---------------------------------------------------------------------------------------------- one step
def quat_rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate a world vector into the frame of unit quaternion q = (w, x, y, z): R(q)^T v (in q's dtype)."""
    w, u = q[:1], q[1:]
    t = 2.0 * np.cross(u, v)
    return v - w * t + np.cross(u, t)


def observation(
    data: mujoco.MjData, io: RobotIO, meta: dict[str, Any], q0: np.ndarray, command: np.ndarray, last_action: np.ndarray
) -> np.ndarray:
    """o_t by the metadata's layout: raw terms in ``observation.terms`` order, times their scales, clipped.

    Computed in float32 like the training env (base velocity rotated in float64 first, as its simulator does).

    Returns:
        Shape: (48,), float32.
    """
    quat = data.qpos[io.base_qpos + 3 : io.base_qpos + 7]
    raw = {
        "base_lin_vel": quat_rotate_inverse(quat, data.qvel[io.base_dof : io.base_dof + 3]).astype(np.float32),
        "base_ang_vel": data.qvel[io.base_dof + 3 : io.base_dof + 6].astype(np.float32),
        "projected_gravity": quat_rotate_inverse(quat.astype(np.float32), np.array([0.0, 0.0, -1.0], np.float32)),
        "command": command.astype(np.float32),
        "joint_pos": data.qpos[io.qpos].astype(np.float32) - q0.astype(np.float32),
        "joint_vel": data.qvel[io.dof].astype(np.float32),
        "last_action": last_action.astype(np.float32),
    }
    spec = meta["observation"]
    terms = spec["terms"]
    o = np.concatenate([raw[t["name"]] for t in terms])
    scale = np.concatenate([np.asarray(t["scale"], dtype=np.float32) for t in terms])
    return np.clip(o * scale, -spec["clip"], spec["clip"]).astype(np.float32)


def joint_targets(action: np.ndarray, robot: dict[str, Any], control: dict[str, Any]) -> np.ndarray:
    """q* = clamp(q0 + action_scale * a, q_min, q_max), a already clipped. Shape: (12,) -> (12,), float64."""
    limits = np.asarray(robot["joint_limits"])
    targets = np.asarray(robot["default_joint_pos"]) + np.float32(control["action_scale"]) * action
    return np.clip(targets, limits[:, 0], limits[:, 1])


def hold_targets(
    model: mujoco.MjModel, data: mujoco.MjData, io: RobotIO, targets: np.ndarray, robot: dict[str, Any], decimation: int
) -> None:
    """Hold ``targets`` for ``decimation`` physics steps (PD by the actuators, or computed here for motors).

    Each control step starts MuJoCo's solver from a zero warm start, as morfic's batched simulator does, so this
    loop reproduces ``morfic eval`` exactly; on a robot the motor drivers run the PD at their own rate.
    """
    data.qacc_warmstart[:] = 0.0
    if not io.torque_mode:
        data.ctrl[io.actuators] = targets
        for _ in range(decimation):
            mujoco.mj_step(model, data)
        return
    kp, kd = np.asarray(robot["kp"]), np.asarray(robot["kd"])
    limit = np.asarray(robot["torque_limit"])
    for _ in range(decimation):
        tau = kp * (targets - data.qpos[io.qpos]) - kd * data.qvel[io.dof]
        data.ctrl[io.actuators] = np.clip(tau, -limit, limit)
        mujoco.mj_step(model, data)


# ---------------------------------------------------------------------------------------------- the loop
def reset(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    io: RobotIO,
    q0: np.ndarray,
    qpos: np.ndarray | None,
    qvel: np.ndarray | None,
) -> None:
    """Start from (qpos, qvel) when given, else the ``home`` keyframe, else q0 at the model's initial base pose."""
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(model, data, key)
    else:
        mujoco.mj_resetData(model, data)
        data.qpos[io.qpos] = q0
    if qpos is not None:
        data.qpos[:] = qpos
    if qvel is not None:
        data.qvel[:] = qvel
    data.ctrl[io.actuators] = 0.0 if io.torque_mode else q0
    mujoco.mj_forward(model, data)


def run(
    model: mujoco.MjModel,
    policy: Policy,
    meta: dict[str, Any],
    robot: str,
    *,
    command: tuple[float, ...],
    steps: int,
    qpos: np.ndarray | None = None,
    qvel: np.ndarray | None = None,
    realtime: bool = False,
) -> dict[str, np.ndarray]:
    """Run the control loop for ``steps`` control steps and record what happened.

    Args:
        model: MuJoCo model of the robot (its actuators get the metadata's gains).
        policy: history (1, H, 48) -> actions (12,).
        meta: The export metadata.
        robot: Which of ``meta["robots"]``.
        command: (vx, vy, yaw rate) in m/s, m/s, rad/s.
        steps: Control steps (50 per second).
        qpos: Initial qpos (default: the ``home`` keyframe).
        qvel: Initial qvel (default: zero).
        realtime: Pace the loop at ``control.dt`` (as on a robot) instead of running as fast as possible.

    Returns:
        Per step, after it: ``action`` (T, 12), ``joint_targets`` (T, 12), ``joint_pos`` (T, 12), ``joint_vel``
        (T, 12), ``base_pos`` (T, 3), ``base_quat`` (T, 4), ``base_lin_vel`` (T, 3, base frame), ``tilt`` (T,)
        and ``policy_ms`` (T,).
    """
    section, control = meta["robots"][robot], meta["control"]
    io = bind(model, meta["joint_names"])
    apply_gains(model, io, section)
    data = mujoco.MjData(model)
    q0 = np.asarray(section["default_joint_pos"])
    reset(model, data, io, q0, qpos, qvel)
    cmd = np.asarray(command, dtype=np.float32)
    action = np.zeros(12, dtype=np.float32)
    o = observation(data, io, meta, q0, cmd, action)
    history = np.repeat(o[None, None], meta["observation"]["history_len"], axis=1)  # (1, H, 48)
    log: dict[str, list] = {k: [] for k in LOGGED}
    clip, dt = control["action_clip"], control["dt"]
    next_tick = time.perf_counter()
    for _ in range(steps):
        start = time.perf_counter()
        action = np.clip(np.asarray(policy(history), dtype=np.float32), -clip, clip)
        policy_ms = 1e3 * (time.perf_counter() - start)
        targets = joint_targets(action, section, control)
        hold_targets(model, data, io, targets, section, control["decimation"])
        o = observation(data, io, meta, q0, cmd, action)
        history = np.concatenate([history[:, 1:], o[None, None]], axis=1)
        quat = data.qpos[io.base_qpos + 3 : io.base_qpos + 7]
        gravity_z = quat_rotate_inverse(quat, np.array([0.0, 0.0, -1.0]))[2]
        step = {
            "action": action,
            "joint_targets": targets,
            "joint_pos": data.qpos[io.qpos],
            "joint_vel": data.qvel[io.dof],
            "base_pos": data.qpos[io.base_qpos : io.base_qpos + 3],
            "base_quat": quat,
            "base_lin_vel": quat_rotate_inverse(quat, data.qvel[io.base_dof : io.base_dof + 3]),
            "tilt": np.arccos(np.clip(-gravity_z, -1.0, 1.0)),
            "policy_ms": policy_ms,
        }
        for key, value in step.items():
            log[key].append(np.array(value, dtype=np.float64 if key == "joint_targets" else np.float32))
        if realtime:
            next_tick += dt
            time.sleep(max(0.0, next_tick - time.perf_counter()))
    return {k: np.stack(v) for k, v in log.items()}


def summarize(log: dict[str, np.ndarray], meta: dict[str, Any], robot: str, command: tuple[float, ...]) -> dict:
    """Forward speed over the second half, falls (tilt > 1 rad or base below 35 % of its start height), timing."""
    dt = meta["control"]["dt"]
    steps = len(log["tilt"])
    height0 = float(log["base_pos"][0, 2])
    fallen = (log["tilt"] > TILT_LIMIT) | (log["base_pos"][:, 2] < 0.35 * height0)
    first_fall = int(np.argmax(fallen)) if fallen.any() else None
    return {
        "robot": robot,
        "command": list(command),
        "seconds": round(steps * dt, 3),
        "vx_mean": float(log["base_lin_vel"][steps // 2 :, 0].mean()),
        "vx_tracking": float(log["base_lin_vel"][steps // 2 :, 0].mean() / command[0]) if command[0] else None,
        "fell": first_fall is not None,
        "fell_at_s": None if first_fall is None else round(first_fall * dt, 3),
        "max_tilt_rad": float(log["tilt"].max()),
        "min_base_height_m": float(log["base_pos"][:, 2].min()),
        "policy_ms_mean": float(log["policy_ms"].mean()),
        "policy_ms_max": float(log["policy_ms"].max()),
    }


def robot_model(meta: dict[str, Any], robot: str, mjcf: str | None) -> mujoco.MjModel:
    """The MuJoCo model: ``--mjcf`` when given, else morfic's generated model of ``robot``."""
    if mjcf:
        return mujoco.MjModel.from_xml_path(mjcf)
    try:
        from morfic_cli.morphology.builder import build_model
        from morfic_cli.morphology.robots import load_robot
    except ImportError:
        raise SystemExit("morfic is not installed: pass the robot's MJCF with --mjcf") from None
    model = build_model(load_robot(robot), floor=True)
    model.opt.timestep = meta["control"]["physics_dt"]
    return model


def main(argv: list[str] | None = None) -> int:
    """Command line: run the loop on one robot and print a summary."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("export", help="directory written by `morfic export --out` (or its policy.json)")
    parser.add_argument("--robot", help="robot to drive (default: the export's baked robot)")
    parser.add_argument("--mjcf", help="MJCF of the robot (default: morfic's generated model of --robot)")
    parser.add_argument("--vx", type=float, default=1.0, help="forward command, m/s")
    parser.add_argument("--vy", type=float, default=0.0, help="lateral command, m/s")
    parser.add_argument("--yaw-rate", type=float, default=0.0, help="yaw-rate command, rad/s")
    parser.add_argument("--seconds", type=float, default=10.0, help="how long to run")
    parser.add_argument("--realtime", action="store_true", help="pace the loop at 50 Hz")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    args = parser.parse_args(argv)

    meta, model_path = load_export(args.export)
    robot = pick_robot(meta, args.robot)
    model = robot_model(meta, robot, args.mjcf)
    policy = OnnxPolicy(model_path, meta, robot)
    command = (args.vx, args.vy, args.yaw_rate)
    steps = max(1, round(args.seconds / meta["control"]["dt"]))
    log = run(model, policy, meta, robot, command=command, steps=steps, realtime=args.realtime)
    summary = summarize(log, meta, robot, command)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        fell = f"fell at {summary['fell_at_s']} s" if summary["fell"] else "did not fall"
        print(
            f"{robot}: {summary['seconds']} s at vx={args.vx} m/s -> mean vx {summary['vx_mean']:.2f} m/s "
            f"(second half), {fell}, max tilt {summary['max_tilt_rad']:.2f} rad; policy "
            f"{summary['policy_ms_mean']:.2f} ms mean, {summary['policy_ms_max']:.2f} ms max"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
