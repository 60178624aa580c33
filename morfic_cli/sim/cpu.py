"""The CPU backend: MuJoCo C on every core, one ``MjModel`` per env (docs/concepts.md).

Each env owns a copy of the robot model, so its morphology (template mode) and its randomised
dynamics can differ from every other env. With procedural geometry (docs/robots.md) an env's model
becomes a generated robot's at reset (:meth:`CpuBackend.set_geometry` copies the fields that differ);
every generated model has the template's structure, so they are stepped together. All envs are stepped in C by
:class:`morfic_cli.sim.floor.BatchStepper` (``mujoco.rollout`` with a persistent thread pool); the
physics state of all envs is one float64 array ``state`` of shape (N, nstate) in MuJoCo's
``mjSTATE_FULLPHYSICS`` layout ``[time, qpos (19), qvel (18)]``, so resets and pushes are array
writes, and everything the env needs per step comes from ``state`` and ``sensordata`` with no
Python loop over envs or contacts.

Where the frame comes from:

* base pose, base and joint velocities: the state after the step (``base_lin_vel_b`` is the world
  velocity rotated into the base frame, what the velocimeter at ``imu`` reads at that same state;
  ``base_ang_vel_b`` is the free joint's angular velocity, already in the base frame = the gyro).
* joint torques, foot positions/velocities, foot and body contact forces: the builder's simulation
  sensors (``sim_sensors=True``). MuJoCo evaluates sensors at the start of the last physics step,
  so foot positions/velocities lag the state by one physics step (5 ms) and the forces are those
  applied during that step; all sensor quantities are mutually consistent.

``bad`` envs: an env whose state is non-finite before the step (it is then not given to MuJoCo),
whose step raised a MuJoCo warning (MuJoCo resets such an env itself; detected from its time, see
:mod:`morfic_cli.sim.floor`), or whose result is non-finite is flagged, restored to its home state
(default pose at the init height) so that it stays finite, and its pre-step state is kept in
:attr:`CpuBackend.bad_states` for a dump. Envs never share data, so other envs are unaffected.

Restitution: MuJoCo contacts are springs-dampers with ``solref = (timeconst, dampratio)``. A
restitution coefficient e maps to the damping ratio of a linear spring-damper that bounces with
that coefficient, zeta = -ln(e) / sqrt(pi^2 + ln(e)^2) (e = 0 gives zeta = 1, critically damped,
MuJoCo's default; e -> 1 gives zeta -> 0). It is written to every geom's ``solref[1]`` so the
combined contact (MuJoCo mixes both geoms' solref) has exactly that ratio. Ground friction is
likewise written to every geom's sliding friction, so every ground contact (MuJoCo takes the
larger of the two geoms' values) has exactly that coefficient.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from morfic_cli.config import SimCfg
from morfic_cli.errors import MorficError
from morfic_cli.morphology.apply import (
    MorphologySummary,
    TemplateInfo,
    apply_descriptor,
    clamp_to_limits,
    model_joint_ranges,
    summarize,
)
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.description import FOOT_FIELDS, JOINT_FIELDS, body_description
from morfic_cli.morphology.robots import JOINTS, LEGS, RobotSpec
from morfic_cli.quaternion import quat_rotate_inverse
from morfic_cli.sim.args import NUM_JOINTS, dynamics_rows, env_index, env_rows
from morfic_cli.sim.backend import CONTACT_BODIES, SimFrame, SimParams
from morfic_cli.sim.floor import STATE_SPEC, BatchStepper


def restitution_to_dampratio(e: np.ndarray) -> np.ndarray:
    """Contact damping ratio zeta for a restitution coefficient e (module docstring).

    zeta = -ln(e) / sqrt(pi^2 + ln(e)^2), with zeta = 1 at e = 0.

    Args:
        e: Restitution in [0, 1). Shape: any.

    Returns:
        zeta in (0, 1]. Shape: like ``e``.
    """
    e = np.asarray(e, dtype=np.float64)
    safe = np.where(e > 0, e, 1.0)
    log_e = np.log(safe)
    return np.where(e > 0, -log_e / np.sqrt(math.pi**2 + log_e**2), 1.0)


@dataclass(frozen=True)
class SensorLayout:
    """Where each frame quantity lives in ``sensordata`` (index arrays, same for every env).

    Attributes:
        torque: Actuator torques, model joint order. Shape: (12,).
        foot_pos: Foot-site positions. Shape: (4, 3).
        foot_vel: Foot-site linear velocities. Shape: (4, 3).
        foot_force: Net ground force on each foot (world frame). Shape: (4, 3).
        body_force: Net ground force on each of CONTACT_BODIES (world frame). Shape: (9, 3).
    """

    torque: np.ndarray
    foot_pos: np.ndarray
    foot_vel: np.ndarray
    foot_force: np.ndarray
    body_force: np.ndarray

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> SensorLayout:
        """Read the sensor addresses of a model built with ``sim_sensors=True``."""

        def idx(name: str) -> np.ndarray:
            sensor = model.sensor(name)
            return int(sensor.adr[0]) + np.arange(int(sensor.dim[0]))

        return cls(
            torque=np.concatenate([idx(f"{leg}_{j}_torque") for leg in LEGS for j in JOINTS]),
            foot_pos=np.stack([idx(f"{leg}_foot_pos") for leg in LEGS]),
            foot_vel=np.stack([idx(f"{leg}_foot_vel") for leg in LEGS]),
            foot_force=np.stack([idx(f"{leg}_foot_force") for leg in LEGS]),
            body_force=np.stack([idx(f"{body}_contact_force") for body in CONTACT_BODIES]),
        )


MUTABLE_FIELDS: tuple[str, ...] = (
    "body_mass",
    "body_inertia",
    "jnt_range",
    "actuator_ctrlrange",  # set_morphology (apply_descriptor)
    "geom_friction",
    "geom_solref",
    "body_ipos",
    "dof_frictionloss",  # set_dynamics
)
"""Model fields this backend writes after construction: :meth:`CpuBackend.set_geometry` always restores them."""

STAT_FIELDS: tuple[str, ...] = ("meaninertia", "meanmass", "meansize", "extent", "center")
"""``MjModel.stat``: the compiler's statistics of a model (the solver scales by ``meaninertia``)."""


def geometry_fields(template: mujoco.MjModel, models: Sequence[mujoco.MjModel]) -> tuple[str, ...]:
    """The array fields of ``MjModel`` in which any of ``models`` differs from ``template``, plus MUTABLE_FIELDS.

    Copying these (and :data:`STAT_FIELDS`) from one of ``models`` into a model that started as a copy of
    ``template`` or of any of ``models`` and was changed only in :data:`MUTABLE_FIELDS` and by ``mj_setConst``
    (whose outputs derive from the masses, so they differ between generated robots) makes it equal that model.
    """
    names = [n for n in dir(template) if not n.startswith("_") and isinstance(getattr(template, n), np.ndarray)]
    # byte equality: the models share every field's shape and dtype (same sizes), and a NaN equals itself
    differ = {n for n in names if any(getattr(m, n).tobytes() != getattr(template, n).tobytes() for m in models)}
    return tuple(sorted(differ | set(MUTABLE_FIELDS)))


@dataclass(frozen=True, eq=False)
class _PoolRobot:
    """One compiled robot of the geometry pool, with what :meth:`CpuBackend.set_geometry` reads from it."""

    model: mujoco.MjModel
    info: TemplateInfo
    robot: RobotSpec
    summary: MorphologySummary


class CpuBackend:
    """Batched quadruped physics on the CPU (implements :class:`morfic_cli.sim.backend.SimBackend`).

    Args:
        cfg: Simulation config (threads, physics dt, torch device).
        robot: The Go2 template (``template=True``) or the target's own spec (``full`` mode).
        num_envs: Number of envs N.
        template: Allow :meth:`set_morphology`. In template mode every env starts with the robot's
            own descriptor applied (so :meth:`params` reports the descriptor actually in effect);
            in full mode the robot's own model is used unchanged.

    Attributes:
        models: One ``MjModel`` per env (read them; change them only through this class).
        state: Physics state of every env, ``mjSTATE_FULLPHYSICS``. Shape: (N, nstate), float64.
        bad_states: Pre-step states of the envs flagged ``bad`` by the last :meth:`step`, by env id.
        warnings: MuJoCo warning messages of the last :meth:`step`.
    """

    def __init__(self, cfg: SimCfg, robot: RobotSpec, num_envs: int, *, template: bool) -> None:
        if num_envs < 1:
            raise MorficError(f"num_envs must be at least 1, got {num_envs}.")
        if not cfg.physics_dt > 0:
            raise MorficError(f"sim.physics_dt must be positive, got {cfg.physics_dt}.")
        self.num_envs = int(num_envs)
        self.device = torch.device(cfg.device)
        self.physics_dt = float(cfg.physics_dt)
        self.morphology_mutable = bool(template)
        self.robot = robot

        nominal = build_model(robot, floor=True, sim_sensors=True)
        nominal.opt.timestep = self.physics_dt
        self.info = TemplateInfo.from_model(nominal)
        self.layout = SensorLayout.from_model(nominal)
        self._scratch = mujoco.MjData(nominal)
        self._nominal_ipos = np.tile(nominal.body_ipos[self.info.base_body], (self.num_envs, 1))
        self._env_info = [self.info] * self.num_envs  # per env: the nominal values its model started from
        self._env_robot = [robot] * self.num_envs  # per env: the robot its model was built from
        self._pool: list[_PoolRobot] = []
        self._geometry_fields: tuple[str, ...] = ()
        self._qvel0 = 1 + nominal.nq  # first qvel entry in the state vector

        first = copy.copy(nominal)
        if template:
            apply_descriptor(first, self._scratch, robot.descriptor, self.info)
        self.models = [copy.copy(first) for _ in range(self.num_envs)]
        self._init_arrays(first)
        self._stepper = BatchStepper(self.models, max(1, int(cfg.num_threads)))
        self.state = np.tile(self._home_state(0), (self.num_envs, 1))
        self._sensordata = np.zeros((self.num_envs, nominal.nsensordata))
        self._refresh_sensors(np.arange(self.num_envs))
        self._bad = np.zeros(self.num_envs, dtype=bool)
        self.bad_states: dict[int, np.ndarray] = {}
        self.warnings: list[str] = []

    # ------------------------------------------------------------------------------------------
    # per-env bookkeeping
    # ------------------------------------------------------------------------------------------

    def _init_arrays(self, model: mujoco.MjModel) -> None:
        n = self.num_envs
        summary = summarize(model, self._scratch, self.info, self.robot.default_qpos, self.robot.foot_radius)
        self._descriptor = np.tile(self.robot.descriptor, (n, 1))
        self._joint_range = np.tile(model_joint_ranges(model, self.info), (n, 1, 1))
        self._default_qpos = np.tile(summary.default_joint_pos, (n, 1))
        self._nominal_height = np.full(n, summary.nominal_height)
        self._total_mass = np.full(n, summary.total_mass)
        self._base_mass = np.full(n, summary.base_mass)
        self._torque_limit = np.tile(model.actuator_forcerange[self.info.actuator_ids, 1], (n, 1))
        floor = model.geom("floor").id
        self._friction = np.full(n, model.geom_friction[floor, 0])
        self._restitution = np.zeros(n)  # MuJoCo's default dampratio 1 <-> e = 0
        self._com_offset = np.zeros((n, 3))
        self._joint_friction = np.tile(model.dof_frictionloss[self.info.dof_adr], (n, 1))

    def _home_state(self, env: int) -> np.ndarray:
        """Default pose (clamped into the env's limits) at the init height, at rest. Shape: (nstate,)."""
        model, data = self.models[env], self._scratch
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        data.qpos[self.info.qpos_adr] = self._default_qpos[env]
        state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
        mujoco.mj_getState(model, data, state, STATE_SPEC)
        return state

    def _refresh_sensors(self, env_ids: np.ndarray) -> None:
        """Recompute the sensors of some envs at their current state (after a reset), ctrl = default pose."""
        data = self._scratch
        for env in env_ids:
            model = self.models[env]
            mujoco.mj_setState(model, data, self.state[env], STATE_SPEC)
            data.ctrl[self.info.actuator_ids] = self._default_qpos[env]
            data.qacc_warmstart[:] = 0.0
            mujoco.mj_forward(model, data)
            self._sensordata[env] = data.sensordata

    def _ids(self, env_ids: torch.Tensor | np.ndarray) -> np.ndarray:
        return env_index(env_ids, self.num_envs)

    _rows = staticmethod(env_rows)

    def _tensor(self, arr: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(arr)).to(device=self.device, dtype=dtype)

    # ------------------------------------------------------------------------------------------
    # SimBackend
    # ------------------------------------------------------------------------------------------

    @property
    def stepper(self) -> BatchStepper:
        """The C stepping engine (benchmarks record and replay its calls)."""
        return self._stepper

    def step(self, joint_targets: torch.Tensor, nsteps: int) -> SimFrame:
        """Hold position targets for ``nsteps`` physics steps in every env and return the new frame.

        Args:
            joint_targets: Position-actuator targets (rad), clipped to each env's joint range;
                a non-finite row is replaced by the env's default pose and the env flagged bad.
                Shape: (N, 12).
            nsteps: Physics steps (the decimation), >= 1.

        Returns:
            The frame after the step.
        """
        targets = self._rows(joint_targets, self.num_envs, (NUM_JOINTS,), "joint_targets")
        finite_targets = np.isfinite(targets).all(axis=1)
        targets = np.where(finite_targets[:, None], targets, self._default_qpos)
        targets = clamp_to_limits(targets, self._joint_range)
        before = self.state.copy()
        bad = ~np.isfinite(before).all(axis=1) | ~finite_targets
        for env in np.flatnonzero(bad).tolist():  # MuJoCo never sees a non-finite state
            self.state[env] = self._home_state(env)
        ctrl = np.empty((self.num_envs, self._stepper.nu))
        ctrl[:, self.info.actuator_ids] = targets
        new_state, sensors, ok = self._stepper.step(self.state, ctrl, nsteps)
        self.warnings = self._stepper.warnings
        bad |= ~ok | ~np.isfinite(new_state).all(axis=1) | ~np.isfinite(sensors).all(axis=1)
        self.state[:] = new_state
        self._sensordata[:] = sensors
        self._restore(np.flatnonzero(bad), before)
        self._bad = bad
        return self.frame()

    def _restore(self, env_ids: np.ndarray, before: np.ndarray) -> None:
        self.bad_states = {int(env): before[env].copy() for env in env_ids}
        for env in env_ids:
            self.state[env] = self._home_state(env)
        self._refresh_sensors(env_ids)

    def frame(self) -> SimFrame:
        """The current frame without stepping (see the module docstring for where each field comes from)."""
        nq = self.models[0].nq
        qpos, qvel = self.state[:, 1 : 1 + nq], self.state[:, self._qvel0 : self._qvel0 + self.models[0].nv]
        quat, lin_vel_w = qpos[:, 3:7], qvel[:, 0:3]
        sd, lay = self._sensordata, self.layout
        n = self.num_envs
        return SimFrame(
            base_pos_w=self._tensor(qpos[:, 0:3]),
            base_quat_w=self._tensor(quat),
            base_lin_vel_w=self._tensor(lin_vel_w),
            base_lin_vel_b=self._tensor(quat_rotate_inverse(quat, lin_vel_w)),
            base_ang_vel_b=self._tensor(qvel[:, 3:6]),
            joint_pos=self._tensor(qpos[:, self.info.qpos_adr]),
            joint_vel=self._tensor(qvel[:, self.info.dof_adr]),
            joint_torque=self._tensor(sd[:, lay.torque]),
            foot_pos_w=self._tensor(sd[:, lay.foot_pos.reshape(-1)].reshape(n, len(LEGS), 3)),
            foot_vel_w=self._tensor(sd[:, lay.foot_vel.reshape(-1)].reshape(n, len(LEGS), 3)),
            foot_force_w=self._tensor(sd[:, lay.foot_force.reshape(-1)].reshape(n, len(LEGS), 3)),
            body_contact_force=self._tensor(
                np.linalg.norm(sd[:, lay.body_force.reshape(-1)].reshape(n, len(CONTACT_BODIES), 3), axis=-1)
            ),
            bad=self._tensor(self._bad.copy(), torch.bool),  # a copy: resets clear the backend's flags in place
        )

    def params(self) -> SimParams:
        """The per-env physical parameters now in effect, as exact float64 tensors (frames are float32)."""
        f64 = torch.float64
        return SimParams(
            joint_range=self._tensor(self._joint_range, f64),
            default_joint_pos=self._tensor(self._default_qpos, f64),
            torque_limit=self._tensor(self._torque_limit, f64),
            base_mass=self._tensor(self._base_mass, f64),
            total_mass=self._tensor(self._total_mass, f64),
            nominal_height=self._tensor(self._nominal_height, f64),
            friction=self._tensor(self._friction, f64),
            restitution=self._tensor(self._restitution, f64),
            com_offset=self._tensor(self._com_offset, f64),
            joint_friction=self._tensor(self._joint_friction, f64),
            descriptor=self._tensor(self._descriptor, f64),
        )

    def reset_envs(
        self,
        env_ids: torch.Tensor,
        base_pos: torch.Tensor,
        base_quat: torch.Tensor,
        base_vel: torch.Tensor,
        joint_pos: torch.Tensor,
        joint_vel: torch.Tensor,
    ) -> None:
        """Set the state of some envs; time, actuator activations and warm start are zeroed.

        Args:
            env_ids: Envs to reset. Shape: (k,), int64.
            base_pos: Base position, world frame (m). Shape: (k, 3).
            base_quat: Base orientation (w, x, y, z). Shape: (k, 4).
            base_vel: Linear (world) then angular (base frame) velocity. Shape: (k, 6).
            joint_pos: Joint positions (rad), written as given. Shape: (k, 12).
            joint_vel: Joint velocities (rad/s). Shape: (k, 12).
        """
        ids = self._ids(env_ids)
        k = ids.size
        model = self.models[0]
        qpos = np.zeros((k, model.nq))
        qpos[:, 0:3] = self._rows(base_pos, k, (3,), "base_pos")
        qpos[:, 3:7] = self._rows(base_quat, k, (4,), "base_quat")
        qpos[:, self.info.qpos_adr] = self._rows(joint_pos, k, (NUM_JOINTS,), "joint_pos")
        qvel = np.zeros((k, model.nv))
        qvel[:, 0:6] = self._rows(base_vel, k, (6,), "base_vel")
        qvel[:, self.info.dof_adr] = self._rows(joint_vel, k, (NUM_JOINTS,), "joint_vel")
        state = np.zeros((k, self.state.shape[1]))
        state[:, 1 : 1 + model.nq] = qpos
        state[:, self._qvel0 : self._qvel0 + model.nv] = qvel
        self.state[ids] = state
        self._bad[ids] = False
        self._refresh_sensors(ids)

    def set_morphology(self, env_ids: torch.Tensor, descriptors: torch.Tensor) -> None:
        """Apply 11-D descriptors (raw units) to some envs' models (docs/robots.md).

        Args:
            env_ids: Envs to change. Shape: (k,).
            descriptors: Raw descriptors (kg, rad). Shape: (k, 11).

        Raises:
            MorficError: the backend is in ``full`` mode, or a descriptor is invalid.
        """
        if not self.morphology_mutable:
            raise MorficError(
                f"set_morphology needs the template backend; this one simulates "
                f"'{self.robot.name}' in full mode with its own morphology."
            )
        ids = self._ids(env_ids)
        rows = self._rows(descriptors, ids.size, (11,), "descriptors")
        for env, m in zip(ids, rows, strict=True):
            model, robot = self.models[env], self._env_robot[env]
            self._descriptor[env] = apply_descriptor(model, self._scratch, m, self._env_info[env])
            summary = summarize(model, self._scratch, self.info, robot.default_qpos, robot.foot_radius)
            self._joint_range[env] = model_joint_ranges(model, self.info)
            self._default_qpos[env] = summary.default_joint_pos
            self._nominal_height[env] = summary.nominal_height
            self._total_mass[env] = summary.total_mass
            self._base_mass[env] = summary.base_mass

    def set_geometry_pool(self, robots: Sequence[RobotSpec]) -> None:
        """Compile generated robots (:mod:`morfic_cli.morphology.procedural`) for :meth:`set_geometry`.

        Each is compiled under the template's model name (so every model's name tables match) and summarised once;
        the model fields that differ between the template and any of them, plus :data:`MUTABLE_FIELDS`, are what
        :meth:`set_geometry` copies.

        Args:
            robots: K specs with the template's structure (made by ``procedural.generate_robot``).

        Raises:
            MorficError: the backend is in ``full`` mode.
            ValueError: a robot's model differs from the template's in its sizes.
        """
        if not self.morphology_mutable:
            raise MorficError(
                f"procedural geometry needs the template backend; this one simulates "
                f"'{self.robot.name}' in full mode with its own morphology."
            )
        template = build_model(self.robot, floor=True, sim_sensors=True)
        template.opt.timestep = self.physics_dt
        pool = []
        for robot in robots:
            model = build_model(dataclasses.replace(robot, name=self.robot.name), floor=True, sim_sensors=True)
            model.opt.timestep = self.physics_dt
            sizes = [(m.nq, m.nv, m.nu, m.nsensordata, m.nbody, m.ngeom, m.nnames) for m in (model, template)]
            if sizes[0] != sizes[1]:
                raise ValueError(f"generated robot '{robot.name}' does not have the template's structure.")
            summary = summarize(model, self._scratch, self.info, robot.default_qpos, robot.foot_radius)
            pool.append(_PoolRobot(model, TemplateInfo.from_model(model), robot, summary))
        self._pool = pool
        self._geometry_fields = geometry_fields(template, [entry.model for entry in pool])

    def set_geometry(self, env_ids: torch.Tensor, robot_ids: torch.Tensor) -> None:
        """Make some envs' models a pool robot's (:meth:`set_geometry_pool`), at rest at its home.

        The fields that can differ are copied into the env's own model, which then equals a fresh copy of the pool
        robot's (tested field by field). The env's descriptor, limits, default pose, heights, masses and torque
        limits become that robot's; dynamics are the model's own until the next :meth:`set_dynamics`, morphology
        until :meth:`set_morphology`. Call :meth:`reset_envs` next (as the env's reset does): it computes the new
        model's sensors, which :meth:`frame` reports from the previous model until then.

        Args:
            env_ids: Envs to change. Shape: (k,).
            robot_ids: Index of each env's robot in the pool. Shape: (k,), in [0, K).
        """
        ids = self._ids(env_ids)
        picks = env_index(robot_ids, len(self._pool))
        if picks.size != ids.size:
            raise ValueError(f"set_geometry: {ids.size} envs but {picks.size} robot ids.")
        for env, pick in zip(ids, picks, strict=True):
            entry = self._pool[pick]
            model, source = self.models[env], entry.model
            for name in self._geometry_fields:
                np.copyto(getattr(model, name), getattr(source, name))
            for name in STAT_FIELDS:
                setattr(model.stat, name, getattr(source.stat, name))
            self._env_info[env], self._env_robot[env] = entry.info, entry.robot
            self._nominal_ipos[env] = source.body_ipos[self.info.base_body]
            self._descriptor[env] = entry.robot.descriptor
            self._joint_range[env] = model_joint_ranges(source, self.info)
            self._default_qpos[env] = entry.summary.default_joint_pos
            self._nominal_height[env] = entry.summary.nominal_height
            self._total_mass[env] = entry.summary.total_mass
            self._base_mass[env] = entry.summary.base_mass
            self._torque_limit[env] = source.actuator_forcerange[self.info.actuator_ids, 1]
            self._friction[env] = source.geom_friction[source.geom("floor").id, 0]
            self._restitution[env] = 0.0
            self._com_offset[env] = 0.0
            self._joint_friction[env] = source.dof_frictionloss[self.info.dof_adr]
            self.state[env] = self._home_state(env)
            self._bad[env] = False

    def set_actuation(
        self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor, torque_limit: torch.Tensor
    ) -> None:
        """Set some envs' position-actuator gains and torque limits (absolute values, every leg alike).

        Kp is ``actuator_gainprm[0]`` and ``-actuator_biasprm[1]``, Kd ``-actuator_biasprm[2]`` (MuJoCo's position
        actuator with ``kv``), the limit ``actuator_forcerange`` = +-limit. They last until the next call or
        :meth:`set_geometry` (which copies a generated robot's own).

        Args:
            env_ids: Envs to change. Shape: (k,).
            kp: Stiffness (N m/rad). Shape: (k,).
            kd: Damping (N m s/rad). Shape: (k,).
            torque_limit: Hip, thigh and calf limits (N m). Shape: (k, 3).

        Raises:
            ValueError: wrong shapes, or a non-finite or non-positive gain or limit (Kd may be 0).
        """
        ids = self._ids(env_ids)
        k = ids.size
        kp_, kd_ = self._rows(kp, k, (), "kp"), self._rows(kd, k, (), "kd")
        tau = np.tile(self._rows(torque_limit, k, (3,), "torque_limit"), (1, len(LEGS)))
        if not (
            np.isfinite(kp_).all()
            and np.isfinite(kd_).all()
            and np.isfinite(tau).all()
            and (kp_ > 0).all()
            and (kd_ >= 0).all()
            and (tau > 0).all()
        ):
            raise ValueError("set_actuation needs finite gains and limits, Kp and limits > 0 and Kd >= 0.")
        act = self.info.actuator_ids
        for j, env in enumerate(ids):
            model = self.models[env]
            model.actuator_gainprm[act, 0] = kp_[j]
            model.actuator_biasprm[act, 1] = -kp_[j]
            model.actuator_biasprm[act, 2] = -kd_[j]
            model.actuator_forcerange[act, 0] = -tau[j]
            model.actuator_forcerange[act, 1] = tau[j]
        self._torque_limit[ids] = tau

    def body_description(self, env_ids: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """URMA's raw joint and foot descriptions of some envs' models (:mod:`morfic_cli.morphology.description`).

        Read from each env's own model at its default pose (``mj_kinematics`` on the scratch data); the velocity
        limits are the env's robot spec's (the model has none). Call it when a model changes, not per step.

        Args:
            env_ids: Envs to describe. Shape: (k,).

        Returns:
            Joint descriptions (k, 12, 18) and foot descriptions (k, 4, 6), float32 on the backend's device.
        """
        ids = self._ids(env_ids)
        rows = [
            body_description(
                self.models[env],
                self._scratch,
                self._env_info[env],
                self._default_qpos[env],
                np.asarray(self._env_robot[env].velocity_limit, dtype=np.float64),
            )
            for env in ids
        ]
        joints = np.stack([r[0] for r in rows]) if rows else np.zeros((0, NUM_JOINTS, len(JOINT_FIELDS)))
        feet = np.stack([r[1] for r in rows]) if rows else np.zeros((0, len(LEGS), len(FOOT_FIELDS)))
        return self._tensor(joints), self._tensor(feet)

    def set_dynamics(
        self,
        env_ids: torch.Tensor,
        friction: torch.Tensor,
        restitution: torch.Tensor,
        com_offset: torch.Tensor,
        joint_friction: torch.Tensor,
    ) -> None:
        """Domain randomisation of contact and joint properties for some envs (module docstring).

        Args:
            env_ids: Envs to change. Shape: (k,).
            friction: Ground sliding friction coefficient. Shape: (k,).
            restitution: Contact restitution in [0, 1). Shape: (k,).
            com_offset: Base COM offset from its nominal position (m). Shape: (k, 3).
            joint_friction: Joint dry friction (frictionloss, N m). Shape: (k, 12).

        Raises:
            MorficError: wrong shapes, negative friction or restitution outside [0, 1).
        """
        ids = self._ids(env_ids)
        k = ids.size
        mu, e, com, jf = dynamics_rows(k, friction, restitution, com_offset, joint_friction)
        zeta = restitution_to_dampratio(e)
        for j, env in enumerate(ids):
            model = self.models[env]
            model.geom_friction[:, 0] = mu[j]
            model.geom_solref[:, 1] = zeta[j]
            model.body_ipos[self.info.base_body] = self._nominal_ipos[env] + com[j]
            model.dof_frictionloss[self.info.dof_adr] = jf[j]
            mujoco.mj_setConst(model, self._scratch)  # the COM moved: inverse weights change
        self._friction[ids], self._restitution[ids] = mu, e
        self._com_offset[ids], self._joint_friction[ids] = com, jf

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Physics state (N, nstate) and the last sensor readings (N, nsensordata), float64 copies."""
        return {"state": torch.from_numpy(self.state.copy()), "sensordata": torch.from_numpy(self._sensordata.copy())}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore :meth:`state_dict`'s arrays; shapes must match this backend's."""
        for key, target in (("state", self.state), ("sensordata", self._sensordata)):
            value = np.asarray(state[key], dtype=np.float64)
            if value.shape != target.shape:
                raise ValueError(f"backend {key} has shape {value.shape}, expected {target.shape}.")
            target[:] = value

    def push(self, env_ids: torch.Tensor, delta_vel_xy: torch.Tensor) -> None:
        """Add a planar velocity kick to some envs' bases (world frame). Shapes: (k,), (k, 2) in m/s."""
        ids = self._ids(env_ids)
        self.state[ids, self._qvel0 : self._qvel0 + 2] += self._rows(delta_vel_xy, ids.size, (2,), "delta_vel_xy")

    def close(self) -> None:
        """Stop the thread pool and drop the models."""
        self._stepper.close()
        self.models = []
