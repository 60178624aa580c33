"""The warp backend: MuJoCo Warp (``mujoco_warp``) on a CUDA GPU, or on warp's CPU device (docs/concepts.md).

Optional: ``pip install 'morfic[gpu]'`` (mujoco-warp, warp-lang). All N envs are the N *worlds* of one
``mujoco_warp`` model and data. Everything the morphology and the randomisation change is a
*per-world model field*: MuJoCo Warp keeps one row per model field, shared by every world, unless
the field is batched; :data:`PER_WORLD_FIELDS` are allocated with one row per world at
construction (``mujoco_warp.put_model(..., batch_sizes=...)``). Those rows are written in place
through zero-copy torch views (``warp.to_torch``), so the arrays never move: a captured CUDA graph
keeps reading the current values and is captured once, on first use (a graph holds array
pointers, so it would have to be re-captured if a field were ever re-allocated; :meth:`_capture`
is the one place that does it).

What each call writes (per world, the same quantities as :class:`morfic_cli.sim.cpu.CpuBackend`):

* :meth:`set_morphology`: ``body_mass``, ``body_inertia`` (scaled with the mass),
  ``jnt_range`` and ``actuator_ctrlrange`` (:func:`morfic_cli.morphology.apply.descriptor_fields`,
  the very arithmetic the CPU backend uses).
* :meth:`set_dynamics`: ``geom_friction[:, 0]``, ``geom_solref[:, 1]`` (restitution as a damping
  ratio), the base ``body_ipos`` (COM offset) and ``dof_frictionloss``.
* derived constants: after either call ``mujoco_warp.set_const`` recomputes, on the device and for
  every world, what ``mj_setConst`` recomputes on the CPU (``body_subtreemass``,
  ``dof_invweight0``, ``body_invweight0``, ``actuator_acc0``); it runs once, lazily, before the
  next step or forward, however many changes came before.

Semantics kept identical to the CPU backend, so the env code is the same and checkpoints move
between backends (:meth:`state_dict` has the CPU backend's ``mjSTATE_FULLPHYSICS`` layout):

* each :meth:`step` call starts the constraint solver from a zero warm start, as ``mujoco.rollout``
  does on the CPU;
* the frame's sensors are those of the last physics step (MuJoCo evaluates them before
  integrating), and after a reset they are recomputed at the new state with the default pose as
  control (a forward pass whose sensor values are kept only for the reset envs);
* ``bad`` envs: non-finite state or targets before the step, or after it a non-finite state or
  sensor value, or ``|qpos|``, ``|qvel|`` or ``|qacc|`` above MuJoCo's ``mjMAXVAL`` (1e10, the
  limits of ``mj_checkPos/Vel/Acc``; MuJoCo Warp has no per-world warnings) are restored to their
  home state; their pre-step states go to :attr:`WarpBackend.bad_states`.

Differences that remain (docs/gpu.md, "Parity"): MuJoCo Warp computes in float32 (the CPU backend in
float64), its solver tolerance is at least 1e-6, and its contact ordering may differ; states agree
to the tolerance the parity tests state, not bit for bit, and MuJoCo Warp is not bit-deterministic
on GPUs.

On CUDA the backend works on its own torch stream, which waits for the caller's stream on entry
and makes the caller's stream wait for it on exit, so torch and warp never race on the shared
memory and the step can be replayed as a captured graph (warp's graph capture needs a non-default
stream and CUDA's memory pool).
"""

from __future__ import annotations

import contextlib
import copy
import os
import sys
import time
from collections.abc import Iterator
from typing import Any

import mujoco
import numpy as np
import torch

from morfic_cli.config import SimCfg
from morfic_cli.errors import MorficError
from morfic_cli.morphology.apply import (
    TemplateInfo,
    apply_descriptor,
    descriptor_fields,
    model_joint_ranges,
    standing_height,
    summarize,
)
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.descriptor import as_descriptor
from morfic_cli.morphology.robots import LEGS, RobotSpec
from morfic_cli.sim.args import dynamics_rows, env_index, env_rows
from morfic_cli.sim.backend import CONTACT_BODIES, SimFrame, SimParams
from morfic_cli.sim.cpu import NUM_JOINTS, SensorLayout, restitution_to_dampratio
from morfic_cli.sim.floor import STATE_SPEC

PER_WORLD_FIELDS: tuple[str, ...] = (
    # set_morphology
    "body_mass", "body_inertia", "jnt_range", "actuator_ctrlrange",
    # set_dynamics
    "geom_friction", "geom_solref", "body_ipos", "dof_frictionloss",
    # derived constants that set_const recomputes from the fields above
    "body_subtreemass", "body_invweight0", "dof_invweight0", "actuator_acc0",
)
"""Model fields with one row per world (everything morphology and randomisation change, and what depends on it)."""

MAX_VAL = 1e10
"""MuJoCo's ``mjMAXVAL``: a |qpos|, |qvel| or |qacc| above it is a diverged simulation."""

NCONMAX = 48
"""Contacts allocated per world (pooled over worlds): a fallen quadruple touches the floor with its box, eight
capsules and four spheres, at most 4 + 8 x 2 + 4 = 24 contacts."""

NJMAX = 3 * NCONMAX + 2 * NUM_JOINTS
"""Constraint rows per world: 3 per contact (elliptic cone, condim 3), plus joint limits and joint friction."""

INSTALL_HINT = "install it with `pip install 'morfic[gpu]'` (mujoco-warp, warp-lang; Python >= 3.11)"


def import_warp() -> tuple[Any, Any]:
    """Import ``warp`` and ``mujoco_warp`` (quietly).

    Returns:
        ``(warp, mujoco_warp)``.

    Raises:
        MorficError: mujoco_warp is not installed.
    """
    try:
        import warp as wp

        wp.config.quiet = True  # no banner
        if hasattr(wp, "LOG_WARNING"):  # no per-module "load ... (compiled)" lines (warp >= 1.18)
            wp.config.log_level = wp.LOG_WARNING
        import mujoco_warp as mjw
    except ImportError as exc:
        raise MorficError(f"the warp simulation backend needs mujoco_warp, which is not installed: {INSTALL_HINT}; "
                          f"or use the cpu backend ({exc}).") from exc
    with _native_stderr_to(os.devnull if not torch.cuda.is_available() else None):
        wp.init()  # without a GPU its C library prints a "no CUDA driver" warning: expected, so hidden
    return wp, mjw


@contextlib.contextmanager
def _native_stderr_to(path: str | None) -> Iterator[None]:
    """Point file descriptor 2 (what C code writes to) at ``path`` for a while; None leaves it alone."""
    if path is None:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    target = os.open(path, os.O_WRONLY)
    os.dup2(target, 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(target)


def warp_device(device: str) -> str:
    """The warp device name for a torch device string, checking that it exists.

    Args:
        device: "cpu", "cuda" or "cuda:N".

    Returns:
        "cpu" or "cuda:N".

    Raises:
        MorficError: CUDA was asked for and is not available to torch or to warp.
    """
    dev = torch.device(device)
    if dev.type == "cpu":
        return "cpu"
    if dev.type != "cuda":
        raise MorficError(f"unknown device '{device}' for the warp backend; valid devices are: cpu, cuda.")
    if not torch.cuda.is_available():
        raise MorficError(f"device '{device}': no CUDA device is available to torch on this machine (or torch is a "
                          "CPU build); use --device cpu, or a GPU machine with a CUDA build of torch.")
    wp, _ = import_warp()
    if not wp.is_cuda_available():
        raise MorficError(f"device '{device}': warp finds no CUDA driver; check `nvidia-smi`, or use --device cpu.")
    return f"cuda:{dev.index or 0}"


GRAPH_MIN_DRIVER = (12, 4)
"""CUDA driver needed for the conditional graph nodes MuJoCo Warp's solver loop uses inside a captured step."""


def _graphs_supported(wp: Any, device: str) -> bool:
    """Whether the step can be replayed as a CUDA graph.

    Needs the memory pool on, a driver >= 12.4, and ``MORFIC_WARP_GRAPHS`` not set to 0 (without
    graphs every step launches its kernels one by one: slower, same results).
    """
    driver = wp.get_cuda_driver_version()
    return (os.environ.get("MORFIC_WARP_GRAPHS", "1") != "0" and wp.is_mempool_enabled(device)
            and driver is not None and tuple(driver) >= GRAPH_MIN_DRIVER)


def quat_rotate_inverse(quat: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors into the frame of unit quaternions (w, x, y, z). Shapes: (N, 4), (N, 3) -> (N, 3)."""
    w, u = quat[:, :1], quat[:, 1:]
    uv = torch.cross(u, vec, dim=1)
    return vec - 2.0 * w * uv + 2.0 * torch.cross(u, uv, dim=1)


class WarpBackend:
    """Batched quadruped physics on MuJoCo Warp (implements :class:`morfic_cli.sim.backend.SimBackend`).

    Args:
        cfg: Simulation config (``device`` is the warp and torch device: "cpu", "cuda", "cuda:N").
        robot: The Go2 template (``template=True``) or the target's own spec (``full`` mode).
        num_envs: Number of envs (worlds) N.
        template: Allow :meth:`set_morphology`; every env starts with the robot's own descriptor applied.

    Attributes:
        host_model: The model every world started from (the template with the robot's descriptor).
        bad_states: Pre-step states (``mjSTATE_FULLPHYSICS``) of the envs flagged ``bad`` by the last step.
        warnings: Always empty (MuJoCo Warp raises no per-world warnings); kept for parity with the CPU backend.
    """

    def __init__(self, cfg: SimCfg, robot: RobotSpec, num_envs: int, *, template: bool) -> None:
        if num_envs < 1:
            raise MorficError(f"num_envs must be at least 1, got {num_envs}.")
        if not cfg.physics_dt > 0:
            raise MorficError(f"sim.physics_dt must be positive, got {cfg.physics_dt}.")
        self._wp_device = warp_device(cfg.device)
        self._wp, self._mjw = import_warp()
        wp, mjw = self._wp, self._mjw
        self.num_envs = int(num_envs)
        self.device = torch.device(self._wp_device)
        self.physics_dt = float(cfg.physics_dt)
        self.morphology_mutable = bool(template)
        self.robot = robot

        nominal = build_model(robot, floor=True, sim_sensors=True)
        nominal.opt.timestep = self.physics_dt
        self.info = TemplateInfo.from_model(nominal)
        self.layout = SensorLayout.from_model(nominal)
        self._scratch = mujoco.MjData(nominal)
        first = copy.copy(nominal)
        if template:
            apply_descriptor(first, self._scratch, robot.descriptor, self.info)
        self.host_model = first
        self._nominal_ipos = nominal.body_ipos[self.info.base_body].copy()
        self._nstate = mujoco.mj_stateSize(first, STATE_SPEC)
        if self._nstate != 1 + first.nq + first.nv or first.na:
            raise MorficError("the warp backend supports models whose state is time, qpos and qvel only.")
        self._height_cache: dict[bytes, float] = {}
        self._init_params(first)

        n = self.num_envs
        self._stream: torch.cuda.Stream | None = None
        with wp.ScopedDevice(self._wp_device):
            if self.device.type == "cuda":
                self._stream = torch.cuda.Stream(device=self.device)
                self._wp_stream = wp.stream_from_torch(self._stream)
            with self._on_stream():
                self.model = mjw.put_model(first, batch_sizes=dict.fromkeys(PER_WORLD_FIELDS, n))
                data = mujoco.MjData(first)
                mujoco.mj_resetDataKeyframe(first, data, first.key("home").id)
                self.data = mjw.put_data(first, data, nworld=n, nconmax=NCONMAX, njmax=NJMAX)
        self._views()
        self._key_qpos = torch.as_tensor(first.key_qpos[first.key("home").id], dtype=torch.float32,
                                         device=self.device)
        self._qpos_adr = torch.tensor(self.info.qpos_adr, device=self.device)
        self._dof_adr = torch.tensor(self.info.dof_adr, device=self.device)
        self._act_ids = torch.tensor(self.info.actuator_ids, device=self.device)
        self._const_dirty = False
        self._graphs: dict[str, Any] = {}
        self._use_graphs = self.device.type == "cuda" and _graphs_supported(wp, self._wp_device)
        self._bad = torch.zeros(n, dtype=torch.bool, device=self.device)
        self.bad_states: dict[int, np.ndarray] = {}
        self.warnings: list[str] = []
        all_ids = torch.arange(n, device=self.device)
        with self._on_stream():
            self._write_home(all_ids)
            self._refresh(all_ids)

    # ------------------------------------------------------------------------------------------
    # set-up
    # ------------------------------------------------------------------------------------------

    def _init_params(self, model: mujoco.MjModel) -> None:
        """Per-env parameters in effect, float64 on the host (the CPU backend's bookkeeping)."""
        n = self.num_envs
        summary = summarize(model, self._scratch, self.info, self.robot.default_qpos, self.robot.foot_radius)
        self._descriptor = np.tile(self.robot.descriptor, (n, 1))
        self._joint_range = np.tile(model_joint_ranges(model, self.info), (n, 1, 1))
        self._default_qpos = np.tile(summary.default_joint_pos, (n, 1))
        self._nominal_height = np.full(n, summary.nominal_height)
        self._total_mass = np.full(n, summary.total_mass)
        self._base_mass = np.full(n, summary.base_mass)
        self._torque_limit = np.tile(model.actuator_forcerange[self.info.actuator_ids, 1], (n, 1))
        self._friction = np.full(n, model.geom_friction[model.geom("floor").id, 0])
        self._restitution = np.zeros(n)
        self._com_offset = np.zeros((n, 3))
        self._joint_friction = np.tile(model.dof_frictionloss[self.info.dof_adr], (n, 1))

    def _views(self) -> None:
        """Zero-copy torch views of the warp arrays this backend reads and writes."""
        to_torch = self._wp.to_torch
        d, m = self.data, self.model
        self._qpos, self._qvel, self._qacc = to_torch(d.qpos), to_torch(d.qvel), to_torch(d.qacc)
        self._ctrl, self._time = to_torch(d.ctrl), to_torch(d.time)
        self._sensordata = to_torch(d.sensordata)
        self.fields: dict[str, torch.Tensor] = {name: to_torch(getattr(m, name)) for name in PER_WORLD_FIELDS}
        """Per-world model fields as torch views, shape (N, ...) each (read them; change them through this class)."""
        self._d_default_qpos = self._device_f32(self._default_qpos)
        self._d_joint_range = self._device_f32(self._joint_range)

    def _device_f32(self, arr: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(arr), dtype=torch.float32, device=self.device)

    @contextlib.contextmanager
    def _on_stream(self) -> Iterator[None]:
        """Run torch and warp work on the backend's stream (CUDA), ordered after and before the caller's."""
        if self._stream is None:
            with self._wp.ScopedDevice(self._wp_device):
                yield
            return
        outer = torch.cuda.current_stream(self.device)
        self._stream.wait_stream(outer)
        with torch.cuda.stream(self._stream), self._wp.ScopedDevice(self._wp_device), \
                self._wp.ScopedStream(self._wp_stream):
            yield
        outer.wait_stream(self._stream)

    def _capture(self, key: str, fn) -> None:
        """Run ``fn`` (warp launches only), as a CUDA graph replay where graphs are available.

        The graph is captured on first use and kept: every array it touches is allocated once, at
        construction, and written in place afterwards. A backend that re-allocated a field would have
        to drop ``self._graphs`` here.
        """
        if not self._use_graphs:
            fn()
            return
        graph = self._graphs.get(key)
        if graph is None:  # captured, not run: the launches are recorded (as mujoco_warp's own benchmark does)
            with self._wp.ScopedCapture(device=self._wp_device, stream=self._wp_stream) as capture:
                fn()
            graph = self._graphs[key] = capture.graph
        self._wp.capture_launch(graph, stream=self._wp_stream)

    def _physics(self, nsteps: int) -> None:
        """``nsteps`` MuJoCo Warp steps of every world from a zero warm start (no env logic)."""
        mjw, m, d = self._mjw, self.model, self.data

        def run() -> None:
            d.qacc_warmstart.zero_()
            for _ in range(nsteps):
                mjw.step(m, d)

        self._capture(f"step{nsteps}", run)

    def _forward(self) -> None:
        mjw, m, d = self._mjw, self.model, self.data

        def run() -> None:
            d.qacc_warmstart.zero_()
            mjw.forward(m, d)

        self._capture("forward", run)

    def _set_const(self) -> None:
        """Recompute the derived constants of every world after model fields changed (mj_setConst on the device)."""
        if self._const_dirty:
            self._mjw.set_const(self.model, self.data)
            self._const_dirty = False

    # ------------------------------------------------------------------------------------------
    # per-env bookkeeping
    # ------------------------------------------------------------------------------------------

    def _write_home(self, ids: torch.Tensor) -> None:
        """Home state (default pose, clamped into the limits, at the init height, at rest, time 0) of some envs."""
        qpos = self._key_qpos.expand(len(ids), -1).clone()
        qpos[:, self._qpos_adr] = self._d_default_qpos[ids]
        self._qpos[ids] = qpos
        self._qvel[ids] = 0.0
        self._time[ids] = 0.0

    def _refresh(self, ids: torch.Tensor) -> None:
        """Recompute the sensors of some envs at their current state with ctrl = default pose (all others kept)."""
        if len(ids) == 0:
            return
        self._set_const()
        keep = self._sensordata.clone()
        ctrl = self._ctrl.clone()
        self._ctrl[ids[:, None], self._act_ids] = self._d_default_qpos[ids]
        self._forward()
        mask = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        mask[ids] = True
        self._sensordata.copy_(torch.where(mask[:, None], self._sensordata, keep))
        self._ctrl.copy_(ctrl)

    def _state_rows(self) -> torch.Tensor:
        """``mjSTATE_FULLPHYSICS`` of every env: [time, qpos, qvel]. Shape: (N, nstate), float64."""
        return torch.cat([self._time[:, None], self._qpos, self._qvel], dim=1).double()

    def _ids(self, env_ids: torch.Tensor | np.ndarray) -> np.ndarray:
        return env_index(env_ids, self.num_envs)

    _rows = staticmethod(env_rows)

    def _device_rows(self, value: torch.Tensor, k: int, shape: tuple[int, ...], what: str) -> torch.Tensor:
        if tuple(value.shape) != (k, *shape):
            raise MorficError(f"{what}: expected shape {(k, *shape)}, got {tuple(value.shape)}.")
        return torch.as_tensor(value, device=self.device).to(torch.float32)

    def _tensor(self, arr: np.ndarray, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """A host tensor (the CPU backend's convention): the env computes with :meth:`params` on the CPU."""
        return torch.as_tensor(np.ascontiguousarray(arr)).to(dtype=dtype)

    def _nominal_height_of(self, q0: np.ndarray) -> float:
        """Base height above the feet at pose q0 (kinematics only: geometry is the same in every world)."""
        key = q0.tobytes()
        if key not in self._height_cache:
            self._height_cache[key] = standing_height(self.host_model, self._scratch, self.info, q0,
                                                      self.robot.foot_radius)
        return self._height_cache[key]

    # ------------------------------------------------------------------------------------------
    # SimBackend
    # ------------------------------------------------------------------------------------------

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
        nsteps = int(nsteps)
        if nsteps < 1:
            raise ValueError(f"nsteps must be >= 1, got {nsteps}.")
        with self._on_stream():
            targets = self._device_rows(joint_targets, self.num_envs, (NUM_JOINTS,), "joint_targets")
            finite_targets = torch.isfinite(targets).all(dim=1)
            targets = torch.where(finite_targets[:, None], targets, self._d_default_qpos)
            targets = torch.clamp(targets, self._d_joint_range[..., 0], self._d_joint_range[..., 1])
            before = self._state_rows()
            bad = ~torch.isfinite(before).all(dim=1) | ~finite_targets
            if bool(bad.any()):  # MuJoCo Warp never sees a non-finite state
                self._write_home(bad.nonzero().flatten())
            self._ctrl[:, self._act_ids] = targets
            self._set_const()
            self._physics(nsteps)
            bad |= self._diverged()
            self._bad = bad
            self.bad_states = {}
            if bool(bad.any()):
                ids = bad.nonzero().flatten()
                rows = before[ids].cpu().numpy()
                self.bad_states = {int(env): row for env, row in zip(ids.tolist(), rows, strict=True)}
                self._write_home(ids)
                self._refresh(ids)
            return self._frame()

    def _diverged(self) -> torch.Tensor:
        """Envs whose state or sensors are non-finite or beyond mjMAXVAL after a step. Shape: (N,), bool."""
        out = ~torch.isfinite(self._sensordata).all(dim=1)
        for arr in (self._qpos, self._qvel, self._qacc):
            out |= ~(arr.abs() <= MAX_VAL).all(dim=1)  # NaN compares False
        return out

    def frame(self) -> SimFrame:
        """The current frame without stepping (see :mod:`morfic_cli.sim.cpu` for where each field comes from)."""
        with self._on_stream():
            return self._frame()

    def _frame(self) -> SimFrame:
        qpos, qvel, sd, lay = self._qpos, self._qvel, self._sensordata, self.layout
        n = self.num_envs
        quat, lin_vel_w = qpos[:, 3:7].clone(), qvel[:, 0:3].clone()

        def cols(idx: np.ndarray, *shape: int) -> torch.Tensor:
            return sd[:, torch.as_tensor(idx.reshape(-1), device=self.device)].reshape(n, *shape)

        return SimFrame(
            base_pos_w=qpos[:, 0:3].clone(),
            base_quat_w=quat,
            base_lin_vel_w=lin_vel_w,
            base_lin_vel_b=quat_rotate_inverse(quat, lin_vel_w),
            base_ang_vel_b=qvel[:, 3:6].clone(),
            joint_pos=qpos[:, self._qpos_adr],
            joint_vel=qvel[:, self._dof_adr],
            joint_torque=cols(lay.torque, NUM_JOINTS),
            foot_pos_w=cols(lay.foot_pos, len(LEGS), 3),
            foot_vel_w=cols(lay.foot_vel, len(LEGS), 3),
            foot_force_w=cols(lay.foot_force, len(LEGS), 3),
            body_contact_force=torch.linalg.norm(cols(lay.body_force, len(CONTACT_BODIES), 3), dim=-1),
            bad=self._bad.clone(),
        )

    def params(self) -> SimParams:
        """The per-env physical parameters now in effect, as exact float64 tensors (frames are float32).

        On the host whatever the device, as the CPU backend's: ``LocomotionEnv`` computes on CPU tensors
        (it moves each frame to the CPU), and device parameters would meet host buffers in its step.
        """
        return SimParams(
            joint_range=self._tensor(self._joint_range),
            default_joint_pos=self._tensor(self._default_qpos),
            torque_limit=self._tensor(self._torque_limit),
            base_mass=self._tensor(self._base_mass),
            total_mass=self._tensor(self._total_mass),
            nominal_height=self._tensor(self._nominal_height),
            friction=self._tensor(self._friction),
            restitution=self._tensor(self._restitution),
            com_offset=self._tensor(self._com_offset),
            joint_friction=self._tensor(self._joint_friction),
            descriptor=self._tensor(self._descriptor),
        )

    def reset_envs(self, env_ids: torch.Tensor, base_pos: torch.Tensor, base_quat: torch.Tensor,
                   base_vel: torch.Tensor, joint_pos: torch.Tensor, joint_vel: torch.Tensor) -> None:
        """Set the state of some envs; time and warm start are zeroed, sensors recomputed.

        Args:
            env_ids: Envs to reset. Shape: (k,), int64.
            base_pos: Base position, world frame (m). Shape: (k, 3).
            base_quat: Base orientation (w, x, y, z). Shape: (k, 4).
            base_vel: Linear (world) then angular (base frame) velocity. Shape: (k, 6).
            joint_pos: Joint positions (rad), written as given. Shape: (k, 12).
            joint_vel: Joint velocities (rad/s). Shape: (k, 12).
        """
        ids_np = self._ids(env_ids)
        k = ids_np.size
        with self._on_stream():
            ids = torch.as_tensor(ids_np, device=self.device)
            qpos = torch.zeros(k, self.host_model.nq, device=self.device)
            qpos[:, 0:3] = self._device_rows(base_pos, k, (3,), "base_pos")
            qpos[:, 3:7] = self._device_rows(base_quat, k, (4,), "base_quat")
            qpos[:, self._qpos_adr] = self._device_rows(joint_pos, k, (NUM_JOINTS,), "joint_pos")
            qvel = torch.zeros(k, self.host_model.nv, device=self.device)
            qvel[:, 0:6] = self._device_rows(base_vel, k, (6,), "base_vel")
            qvel[:, self._dof_adr] = self._device_rows(joint_vel, k, (NUM_JOINTS,), "joint_vel")
            self._qpos[ids], self._qvel[ids], self._time[ids] = qpos, qvel, 0.0
            self._bad[ids] = False
            self._refresh(ids)

    def set_morphology(self, env_ids: torch.Tensor, descriptors: torch.Tensor) -> None:
        """Apply 11-D descriptors (raw units) to some worlds' model fields (docs/robots.md).

        Args:
            env_ids: Envs to change. Shape: (k,).
            descriptors: Raw descriptors (kg, rad). Shape: (k, 11).

        Raises:
            MorficError: the backend is in ``full`` mode, or a descriptor is invalid.
        """
        if not self.morphology_mutable:
            raise MorficError(f"set_morphology needs the template backend; this one simulates "
                              f"'{self.robot.name}' in full mode with its own morphology.")
        ids = self._ids(env_ids)
        rows = self._rows(descriptors, ids.size, (11,), "descriptors")
        m = np.stack([as_descriptor(row) for row in rows]) if ids.size else rows
        fields = descriptor_fields(m, self.info)
        with self._on_stream():
            d_ids = torch.as_tensor(ids, device=self.device)
            for name, value in (("body_mass", fields.body_mass), ("body_inertia", fields.body_inertia),
                                ("jnt_range", fields.jnt_range), ("actuator_ctrlrange", fields.ctrlrange)):
                self.fields[name][d_ids] = self._device_f32(value)
        self._const_dirty = True
        joint_range = fields.jnt_range[:, self.info.joint_ids.reshape(-1)]
        default = np.clip(self.robot.default_qpos, joint_range[..., 0], joint_range[..., 1])
        self._descriptor[ids] = m
        self._joint_range[ids] = joint_range
        self._default_qpos[ids] = default
        self._nominal_height[ids] = [self._nominal_height_of(q0) for q0 in default]
        self._total_mass[ids] = fields.body_mass.sum(axis=1)
        self._base_mass[ids] = fields.body_mass[:, self.info.base_body]
        with self._on_stream():
            self._d_default_qpos[d_ids] = self._device_f32(default)
            self._d_joint_range[d_ids] = self._device_f32(joint_range)

    def set_dynamics(self, env_ids: torch.Tensor, friction: torch.Tensor, restitution: torch.Tensor,
                     com_offset: torch.Tensor, joint_friction: torch.Tensor) -> None:
        """Domain randomisation of contact and joint properties for some worlds (see :mod:`morfic_cli.sim.cpu`).

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
        with self._on_stream():
            d_ids = torch.as_tensor(ids, device=self.device)
            f = self.fields
            f["geom_friction"][d_ids, :, 0] = self._device_f32(mu)[:, None]
            f["geom_solref"][d_ids, :, 1] = self._device_f32(restitution_to_dampratio(e))[:, None]
            f["body_ipos"][d_ids, self.info.base_body] = self._device_f32(self._nominal_ipos + com)
            f["dof_frictionloss"][d_ids[:, None], self._dof_adr] = self._device_f32(jf)
        self._const_dirty = True  # the COM moved: inverse weights change
        self._friction[ids], self._restitution[ids] = mu, e
        self._com_offset[ids], self._joint_friction[ids] = com, jf

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Physics state (N, nstate) and the last sensor readings (N, nsensordata), float64 CPU copies.

        The layout is the CPU backend's, so a checkpoint moves between backends.
        """
        with self._on_stream():
            state, sensors = self._state_rows(), self._sensordata.double()
        return {"state": state.cpu(), "sensordata": sensors.cpu()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore :meth:`state_dict`'s arrays (from either backend); shapes must match this backend's."""
        nq = self.host_model.nq
        for key, width in (("state", self._nstate), ("sensordata", self._sensordata.shape[1])):
            shape = tuple(np.shape(state[key]))
            if shape != (self.num_envs, width):
                raise ValueError(f"backend {key} has shape {shape}, expected {(self.num_envs, width)}.")
        with self._on_stream():
            rows = torch.as_tensor(state["state"], device=self.device).to(torch.float32)
            self._time.copy_(rows[:, 0])
            self._qpos.copy_(rows[:, 1:1 + nq])
            self._qvel.copy_(rows[:, 1 + nq:])
            self._sensordata.copy_(torch.as_tensor(state["sensordata"], device=self.device).to(torch.float32))

    def push(self, env_ids: torch.Tensor, delta_vel_xy: torch.Tensor) -> None:
        """Add a planar velocity kick to some envs' bases (world frame). Shapes: (k,), (k, 2) in m/s."""
        ids = self._ids(env_ids)
        with self._on_stream():
            kick = self._device_rows(torch.as_tensor(delta_vel_xy), ids.size, (2,), "delta_vel_xy")
            self._qvel[torch.as_tensor(ids, device=self.device), 0:2] += kick

    def close(self) -> None:
        """Drop the graphs and device arrays."""
        if self._stream is not None:
            self._stream.synchronize()
        self._graphs = {}
        self.fields = {}

    # ------------------------------------------------------------------------------------------
    # benchmarks
    # ------------------------------------------------------------------------------------------

    def physics_floor(self, controls: list[torch.Tensor], nsteps: int) -> float:
        """Raw physics throughput: the given controls held ``nsteps`` steps each, from the current state, no env logic.

        The same stepping as :meth:`step` (zero warm start, graph replay where available) without
        target clipping, divergence checks, resets or frames. The state is restored afterwards.

        Args:
            controls: Joint targets per call (clipped to the joint ranges, as :meth:`step` does), each
                shape (N, 12).
            nsteps: Physics steps per call.

        Returns:
            Physics steps per second, summed over worlds.
        """
        saved = self.state_dict()
        ctrl_saved = self._ctrl.clone()
        with self._on_stream():
            self._set_const()
            lo, hi = self._d_joint_range[..., 0], self._d_joint_range[..., 1]
            staged = [torch.clamp(self._device_rows(c, self.num_envs, (NUM_JOINTS,), "controls"), lo, hi)
                      for c in controls]
            self._ctrl[:, self._act_ids] = staged[0]
            self._physics(nsteps)  # warm-up: kernels and graphs
            self._synchronize()
            t0 = time.perf_counter()
            for ctrl in staged:
                self._ctrl[:, self._act_ids] = ctrl
                self._physics(nsteps)
            self._synchronize()
            wall = time.perf_counter() - t0
        self.load_state_dict(saved)
        with self._on_stream():
            self._ctrl.copy_(ctrl_saved)
        return self.num_envs * nsteps * len(staged) / wall

    def _synchronize(self) -> None:
        if self._stream is not None:
            self._stream.synchronize()
        else:
            self._wp.synchronize_device(self._wp_device)
