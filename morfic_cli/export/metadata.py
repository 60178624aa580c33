"""The metadata JSON that travels beside an exported policy (docs/cli.md, ``morfic export``).

Everything a robot stack needs to run the policy and nothing it has to guess: the model's inputs and outputs,
the joint order, how actions become joint targets, the PD gains and limits, the observation layout with its
scales, the history length, the control period and the morphology descriptor. Built by pure functions from a
:class:`~morfic_cli.config.EnvCfg` and :class:`~morfic_cli.morphology.robots.RobotSpec` objects, so the values
are the ones the training env used (``examples/deploy_loop.py`` reads nothing else).

Layout (``schema`` = :data:`SCHEMA`)::

    schema, morfic_version, run, checkpoint, variant, preset, seed, iteration,
    format, model_file, model_sha256, onnx_opset,
    inputs / outputs     [{name, shape (with "batch"), dtype, description}]
    baked_robot          robot whose descriptor is a constant in the model, or null
    joint_names          the 12 joints in model (= action) order
    control              dt, physics_dt, decimation, action_scale, action_clip, target_rule
    observation          size, history_len, history_order, history_reset, clip, terms [{name, start, stop,
                         scale[], unit, frame, description}], command
    descriptor           names, units, train_min, train_max, normalization
    robots               {name: display_name, default_joint_pos, kp, kd, torque_limit, velocity_limit,
                          joint_limits, descriptor (raw), morphology (normalised, the model input)}

``robots`` holds the baked robot only, or every robot of the library when the descriptor is a model input.
All per-joint lists are in ``joint_names`` order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from morfic_cli import __version__
from morfic_cli.config import EnvCfg
from morfic_cli.envs import observations as O
from morfic_cli.morphology.builder import joint_names
from morfic_cli.morphology.descriptor import DESCRIPTOR_NAMES, DESCRIPTOR_UNITS, TRAIN_MAX, TRAIN_MIN
from morfic_cli.morphology.robots import RobotSpec

SCHEMA = "morfic-policy/1"
"""Version tag of the metadata layout."""

TARGET_RULE = (
    "q_target = default_joint_pos + action_scale * clip(actions, -action_clip, action_clip), "
    "then clamped into joint_limits; joints track q_target with tau = kp (q_target - q) - kd qdot, "
    "limited to +-torque_limit"
)
"""How actions become joint commands (what :class:`~morfic_cli.envs.locomotion.LocomotionEnv` does)."""

#: Per-term unit, frame and description of o_t, in :data:`~morfic_cli.envs.observations.POLICY_LAYOUT` order.
_TERM_INFO: dict[str, tuple[str, str, str]] = {
    "base_lin_vel": ("m/s", "base", "linear velocity of the base, expressed in the base frame"),
    "base_ang_vel": ("rad/s", "base", "angular velocity of the base (gyro), base frame"),
    "projected_gravity": ("1", "base", "unit gravity direction (0, 0, -1)_world rotated into the base frame"),
    "command": ("m/s, m/s, rad/s", "base", "velocity command (vx, vy, yaw rate)"),
    "joint_pos": ("rad", "joint", "q - default_joint_pos, joint_names order"),
    "joint_vel": ("rad/s", "joint", "qdot, joint_names order"),
    "last_action": ("1", "joint", "the previous policy action (clipped, unscaled)"),
}


def normalized_descriptor(descriptor: np.ndarray) -> np.ndarray:
    """The model input m: the raw descriptor normalised exactly as the env does (float32).

    Args:
        descriptor: Raw 11-D descriptor (kg, rad). Shape: (11,).

    Returns:
        ``2 (m - train_min) / (train_max - train_min) - 1`` in float32. Shape: (11,).
    """
    m = torch.as_tensor(np.asarray(descriptor), dtype=torch.float64).float()[None]
    lo = torch.as_tensor(TRAIN_MIN, dtype=torch.float32)
    hi = torch.as_tensor(TRAIN_MAX, dtype=torch.float32)
    return O.morphology_obs(m, lo, hi)[0].numpy()


def default_joint_pos(spec: RobotSpec) -> np.ndarray:
    """q0 as the env uses it: the spec's default pose clamped into its joint limits. Shape: (12,), rad."""
    ranges = spec.ctrl_range
    return np.clip(spec.default_qpos, ranges[:, 0], ranges[:, 1])


def robot_section(spec: RobotSpec) -> dict[str, Any]:
    """The per-robot part of the metadata: pose, gains, limits and descriptor, all in joint_names order."""
    per_joint = np.tile  # per-joint (3,) arrays repeat for the four legs, leg-major like joint_names()
    return {
        "display_name": spec.display_name,
        "default_joint_pos": _floats(default_joint_pos(spec)),
        "kp": _floats(np.full(12, spec.kp)),
        "kd": _floats(np.full(12, spec.kd)),
        "torque_limit": _floats(per_joint(spec.torque_limit, 4)),
        "velocity_limit": _floats(per_joint(spec.velocity_limit, 4)),
        "joint_limits": [_floats(r) for r in spec.ctrl_range],
        "descriptor": _floats(spec.descriptor),
        "morphology": _float32s(normalized_descriptor(spec.descriptor)),
    }


def observation_section(env: EnvCfg) -> dict[str, Any]:
    """Layout, scales and history of o_t (docs/concepts.md), as the env builds it without noise."""
    scales = _float32s(O.obs_scales(env.obs))
    terms = []
    for name, start, stop in O.POLICY_LAYOUT:
        unit, frame, text = _TERM_INFO[name]
        terms.append(
            {
                "name": name,
                "start": start,
                "stop": stop,
                "scale": scales[start:stop],
                "unit": unit,
                "frame": frame,
                "description": text,
            }
        )
    return {
        "size": O.POLICY_DIM,
        "history_len": O.history_frames(env.obs),
        "history_order": (
            "oldest first, newest last: history[:, -1] is o_t and history[:, :-1] the paper's h_t = o_{t-15..t-1}"
            if not env.obs.history_includes_current
            else "oldest first, newest last: history[:, -1] is o_t (o_{t-14..t})"
        ),
        "history_reset": "at start (and after a reset) every slot holds the first observation",
        "clip": env.obs.clip,
        "formula": "o_t = clip(raw * scale, -clip, clip), raw terms concatenated in this order",
        "terms": terms,
        "command": {
            "names": ["vx", "vy", "yaw_rate"],
            "units": ["m/s", "m/s", "rad/s"],
            "trained_vx": list(env.commands.vx_limit),
            "trained_vy": list(env.commands.vy),
            "trained_yaw_rate": list(env.commands.yaw_rate),
        },
    }


def control_section(env: EnvCfg) -> dict[str, Any]:
    """Control period and the action -> joint target rule."""
    return {
        "dt": env.sim.physics_dt * env.decimation,
        "physics_dt": env.sim.physics_dt,
        "decimation": env.decimation,
        "action_scale": env.action_scale,
        "action_clip": env.action_clip,
        "target_rule": TARGET_RULE,
    }


def descriptor_section() -> dict[str, Any]:
    """Names, units and normalisation of the 11-D descriptor (docs/robots.md)."""
    return {
        "names": list(DESCRIPTOR_NAMES),
        "units": list(DESCRIPTOR_UNITS),
        "train_min": _floats(TRAIN_MIN),
        "train_max": _floats(TRAIN_MAX),
        "normalization": "morphology = 2 (descriptor - train_min) / (train_max - train_min) - 1 (float32)",
    }


def io_section(history_len: int, morphology_input: bool, targets: bool) -> tuple[list[dict], list[dict]]:
    """The model's named inputs and outputs (ONNX names, TorchScript argument order)."""
    inputs = [
        {
            "name": "history",
            "shape": ["batch", history_len, O.POLICY_DIM],
            "dtype": "float32",
            "description": "the last history_len observations, oldest first, o_t last",
        }
    ]
    if morphology_input:
        inputs.append(
            {
                "name": "morphology",
                "shape": ["batch", len(DESCRIPTOR_NAMES)],
                "dtype": "float32",
                "description": "normalised descriptor: robots[name].morphology",
            }
        )
    outputs = [
        {
            "name": "actions",
            "shape": ["batch", 12],
            "dtype": "float32",
            "description": "policy mean a_t (unscaled), joint_names order",
        }
    ]
    if targets:
        outputs.append(
            {
                "name": "joint_targets",
                "shape": ["batch", 12],
                "dtype": "float32",
                "description": "q_target by control.target_rule (rad), joint_names order",
            }
        )
    return inputs, outputs


def build_metadata(
    *,
    env: EnvCfg,
    robots: dict[str, RobotSpec],
    baked_robot: str | None,
    morphology_input: bool,
    targets: bool,
    model: dict[str, Any],
    source: dict[str, Any],
) -> dict[str, Any]:
    """Assemble the metadata document.

    Args:
        env: The run's env config (observation scales, control period, action scale).
        robots: Robots to describe (the baked one, or the whole library).
        baked_robot: The robot whose descriptor is a constant inside the model, or None.
        morphology_input: Whether the model takes the descriptor as its ``morphology`` input.
        targets: Whether the model also outputs ``joint_targets``.
        model: ``format``, ``model_file``, ``model_sha256``, ``onnx_opset`` (None for TorchScript).
        source: ``run``, ``checkpoint``, ``variant``, ``preset``, ``seed``, ``iteration``.

    Returns:
        The JSON-serialisable metadata (see the module docstring).
    """
    inputs, outputs = io_section(O.history_frames(env.obs), morphology_input, targets)
    return {
        "schema": SCHEMA,
        "morfic_version": __version__,
        **source,
        **model,
        "inputs": inputs,
        "outputs": outputs,
        "baked_robot": baked_robot,
        "joint_names": joint_names(),
        "control": control_section(env),
        "observation": observation_section(env),
        "descriptor": descriptor_section(),
        "robots": {name: robot_section(spec) for name, spec in robots.items()},
    }


def _csv(values: Any) -> str:
    """Comma-separated values, floats as ``repr`` (``float(x)`` gives each back exactly)."""
    return ",".join(repr(float(v)) if isinstance(v, float) else str(v) for v in values)


def onnx_props(meta: dict[str, Any]) -> dict[str, str]:
    """The ONNX ``metadata_props`` of an export: mjlab's keys plus morfic's, every value from ``meta``.

    ``meta`` is the policy.json document (:func:`build_metadata`); the props are a flat string view of it, so
    the two agree by construction (``policy.json`` stays the readable twin). Lists are comma-separated, floats as
    ``repr``. mjlab's keys (``joint_names``, ``joint_stiffness``, ``joint_damping``, ``default_joint_pos``,
    ``action_scale``, ``observation_names``, ``command_names``) describe ONE robot: the baked one, else the
    template the policy was trained on (``robot`` names it); ``robots`` lists every described robot and
    ``robot.<name>.<key>`` gives each one's values. ``model_sha256`` is not a prop (it hashes the file itself).

    Returns:
        Key -> string value.
    """
    obs, control = meta["observation"], meta["control"]
    robots = meta["robots"]
    robot = meta["baked_robot"] or next((n for n in robots if n == "go2"), next(iter(robots)))
    n_joints = len(meta["joint_names"])

    def per_robot(section: dict[str, Any]) -> dict[str, str]:
        return {
            "joint_stiffness": _csv(section["kp"]),
            "joint_damping": _csv(section["kd"]),
            "default_joint_pos": _csv(section["default_joint_pos"]),
            "torque_limit": _csv(section["torque_limit"]),
            "morphology": _csv(section["morphology"]),
        }

    props: dict[str, str] = {
        "joint_names": _csv(meta["joint_names"]),
        **per_robot(robots[robot]),
        "action_scale": _csv([float(control["action_scale"])] * n_joints),
        "observation_names": _csv(t["name"] for t in obs["terms"]),
        "command_names": _csv(obs["command"]["names"]),
        "robot": robot,
        "robots": _csv(robots),
        "baked_robot": meta["baked_robot"] or "",
        "history_length": str(obs["history_len"]),
        "history_order": obs["history_order"],
        "observation_size": str(obs["size"]),
        "observation_scales": _csv(v for t in obs["terms"] for v in t["scale"]),
        "observation_clip": repr(float(obs["clip"])),
        "dt": repr(float(control["dt"])),
        "action_clip": repr(float(control["action_clip"])),
        "inputs": _csv(s["name"] for s in meta["inputs"]),
        "outputs": _csv(s["name"] for s in meta["outputs"]),
        "descriptor_names": _csv(meta["descriptor"]["names"]),
        "schema": meta["schema"],
        "morfic_version": meta["morfic_version"],
    }
    for key in ("run", "checkpoint", "variant", "preset", "seed", "iteration"):
        props[key] = "" if meta.get(key) is None else str(meta[key])
    for name, section in robots.items():
        props.update({f"robot.{name}.{k}": v for k, v in per_robot(section).items()})
    return props


def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def _float32s(values: Any) -> list[float]:
    """float32 values as their shortest decimal (0.05, not 0.0500000007); float32(x) gives them back exactly."""
    return [float(str(np.float32(v))) for v in np.asarray(values, dtype=np.float32).reshape(-1)]
