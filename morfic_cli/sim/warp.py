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
import math
import os
import sys
import time
from collections.abc import Iterator
from typing import Any

import mujoco
import numpy as np
import torch

from morfic_cli.config import SimCfg
from morfic_cli.errors import DescriptorError, MorficError
from morfic_cli.morphology.apply import (
    DESCRIPTOR_MASS_INDEX,
    TemplateInfo,
    apply_descriptor,
    model_joint_ranges,
    summarize,
)
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.descriptor import LIMIT_PAIRS, SANE_MAX, SANE_MIN, as_descriptor
from morfic_cli.morphology.robots import LEGS, LINKS, RobotSpec
from morfic_cli.quaternion_torch import quat_rotate_inverse
from morfic_cli.sim import sync
from morfic_cli.sim.backend import CONTACT_BODIES, SimFrame, SimParams
from morfic_cli.sim.cpu import NUM_JOINTS, SensorLayout
from morfic_cli.sim.floor import STATE_SPEC

PER_WORLD_FIELDS: tuple[str, ...] = (
    # set_morphology
    "body_mass",
    "body_inertia",
    "jnt_range",
    "actuator_ctrlrange",
    # set_dynamics
    "geom_friction",
    "geom_solref",
    "body_ipos",
    "dof_frictionloss",
    # derived constants that set_const recomputes from the fields above
    "body_subtreemass",
    "body_invweight0",
    "dof_invweight0",
    "actuator_acc0",
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

        if hasattr(wp.config, "quiet"):  # no banner (older warp; newer warp logs it at INFO, below)
            wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):  # no banner or per-module "load ... (compiled)" lines (warp >= 1.18)
            wp.config.log_level = wp.LOG_WARNING
        import mujoco_warp as mjw
    except ImportError as exc:
        raise MorficError(
            f"the warp simulation backend needs mujoco_warp, which is not installed: {INSTALL_HINT}; "
            f"or use the cpu backend ({exc})."
        ) from exc
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
        raise MorficError(
            f"device '{device}': no CUDA device is available to torch on this machine (or torch is a "
            "CPU build); use --device cpu, or a GPU machine with a CUDA build of torch."
        )
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
    return (
        os.environ.get("MORFIC_WARP_GRAPHS", "1") != "0"
        and wp.is_mempool_enabled(device)
        and driver is not None
        and tuple(driver) >= GRAPH_MIN_DRIVER
    )


def _axis_angle(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rotation matrices about unit axes (Rodrigues). Shapes: axis (L, 3), angle (k, L) -> (k, L, 3, 3)."""
    x, y, z = axis.unbind(-1)
    zero = torch.zeros_like(x)
    cross = torch.stack(
        [torch.stack([zero, -z, y], -1), torch.stack([z, zero, -x], -1), torch.stack([-y, x, zero], -1)], -2
    )  # (L, 3, 3)
    s, c = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device)
    return eye + s * cross + (1.0 - c) * (cross @ cross)


def _leg_chains(model: mujoco.MjModel, info: TemplateInfo, device: torch.device) -> dict[str, Any]:
    """The four legs' kinematic chains below the base, as float64 device tensors (for ``_standing_height``).

    Returns:
        ``links``: one entry per depth (every leg has the same depth): ``pos`` (4, 3), ``rot`` (4, 3, 3) of each
        leg's body at that depth in its parent, and ``joint`` = (axis (4, 3), anchor (4, 3), joint column in the
        12-joint order (4,), qpos0 (4,)) of its hinge, or None; ``site_pos`` (4, 3), each foot site in its body.

    Raises:
        MorficError: a leg has another joint type than hinges, a body with two joints, or the legs differ in depth.
    """

    def f64(arr: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.array(arr, dtype=np.float64), device=device)

    column = {int(adr): i for i, adr in enumerate(info.qpos_adr)}
    chains = []
    for site in info.foot_sites:
        body, chain = int(model.site_bodyid[site]), []
        while body != info.base_body:
            chain.append(body)
            body = int(model.body_parentid[body])
        chains.append(chain[::-1])
    if len({len(c) for c in chains}) != 1:
        raise MorficError("the warp backend needs legs of equal depth below the base.")
    links = []
    for depth in range(len(chains[0])):
        bodies = [c[depth] for c in chains]
        rots = []
        for b in bodies:
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, model.body_quat[b])
            rots.append(mat.reshape(3, 3))
        nj = {int(model.body_jntnum[b]) for b in bodies}
        joint = None
        if nj == {1}:
            js = [int(model.body_jntadr[b]) for b in bodies]
            if any(model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE for j in js):
                raise MorficError("the warp backend's leg kinematics supports hinge joints only.")
            adr = [int(model.jnt_qposadr[j]) for j in js]
            joint = (
                f64(model.jnt_axis[js]),
                f64(model.jnt_pos[js]),
                torch.as_tensor([column[a] for a in adr], device=device),
                f64(model.qpos0[adr]),
            )
        elif nj != {0}:
            raise MorficError("the warp backend's leg kinematics supports one hinge per leg body.")
        links.append({"pos": f64(model.body_pos[bodies]), "rot": f64(np.stack(rots)), "joint": joint})
    return {"links": links, "site_pos": f64(model.site_pos[info.foot_sites])}


def restitution_to_dampratio(e: torch.Tensor) -> torch.Tensor:
    """:func:`morfic_cli.sim.cpu.restitution_to_dampratio` on tensors (any device). Shape: any -> like ``e``."""
    safe = torch.where(e > 0, e, torch.ones_like(e))
    log_e = torch.log(safe)
    return torch.where(e > 0, -log_e / torch.sqrt(math.pi**2 + log_e**2), torch.ones_like(e))


GEOMETRY_NEEDS_CPU = (
    "procedural geometry (env.rand.geometry.enabled) runs on the cpu backend only; train it with "
    "--set env.sim.backend=cpu (no --device cuda), or turn it off with "
    "--set env.rand.geometry.enabled=false."
)


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
        self._nominal_ipos = torch.as_tensor(nominal.body_ipos[self.info.base_body], device=self.device)
        self._nstate = mujoco.mj_stateSize(first, STATE_SPEC)
        if self._nstate != 1 + first.nq + first.nv or first.na:
            raise MorficError("the warp backend supports models whose state is time, qpos and qvel only.")
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
        self._qpos_adr = torch.tensor(self.info.qpos_adr, device=self.device)
        self._dof_adr = torch.tensor(self.info.dof_adr, device=self.device)
        self._act_ids = torch.tensor(self.info.actuator_ids, device=self.device)
        self._key_qpos = torch.as_tensor(first.key_qpos[first.key("home").id], dtype=torch.float32, device=self.device)
        self._views()
        self._init_template_tensors(nominal)
        self._const_dirty = False
        self._graphs: dict[str, Any] = {}
        self._use_graphs = self.device.type == "cuda" and _graphs_supported(wp, self._wp_device)
        self._bad = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._step_bad = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._before: torch.Tensor | None = None
        self.warnings: list[str] = []
        with self._on_stream():
            everyone = torch.ones(n, dtype=torch.bool, device=self.device)
            self._write_home(everyone)
            self._refresh(everyone)

    # ------------------------------------------------------------------------------------------
    # set-up
    # ------------------------------------------------------------------------------------------

    def _init_params(self, model: mujoco.MjModel) -> None:
        """Per-env parameters in effect, float64 tensors on the device (the CPU backend's bookkeeping, as numbers)."""
        n = self.num_envs
        summary = summarize(model, self._scratch, self.info, self.robot.default_qpos, self.robot.foot_radius)

        def rows(value: np.ndarray | float, *shape: int) -> torch.Tensor:
            row = torch.as_tensor(np.asarray(value, dtype=np.float64), device=self.device)
            return row.expand(n, *shape).clone()

        self._descriptor = rows(self.robot.descriptor, 11)
        self._joint_range = rows(model_joint_ranges(model, self.info), NUM_JOINTS, 2)
        self._default_qpos = rows(summary.default_joint_pos, NUM_JOINTS)
        self._nominal_height = rows(summary.nominal_height)
        self._total_mass = rows(summary.total_mass)
        self._base_mass = rows(summary.base_mass)
        self._torque_limit = rows(model.actuator_forcerange[self.info.actuator_ids, 1], NUM_JOINTS)
        self._friction = rows(model.geom_friction[model.geom("floor").id, 0])
        self._restitution = rows(0.0)
        self._com_offset = rows(np.zeros(3), 3)
        self._joint_friction = rows(model.dof_frictionloss[self.info.dof_adr], NUM_JOINTS)

    def _init_template_tensors(self, nominal: mujoco.MjModel) -> None:
        """The template's nominal values and ids as device tensors (what :meth:`set_morphology` computes from)."""
        info, dev = self.info, self.device

        def t(arr: np.ndarray, dtype: torch.dtype = torch.float64) -> torch.Tensor:
            return torch.as_tensor(np.array(arr), dtype=dtype, device=dev)

        self._t_body_mass, self._t_body_inertia = t(info.body_mass), t(info.body_inertia)
        self._t_jnt_range, self._t_ctrlrange = t(info.jnt_range), t(info.ctrlrange)
        self._t_link_bodies = t(info.link_bodies, torch.long)
        self._t_changed = t(np.append(info.link_bodies.reshape(-1), info.base_body), torch.long)
        self._t_joint_ids = t(info.joint_ids.reshape(-1), torch.long)
        self._t_limit_cols = t(np.array(LIMIT_PAIRS), torch.long)
        self._t_sane = (t(SANE_MIN), t(SANE_MAX))
        self._t_robot_q0 = t(self.robot.default_qpos)
        self._fk = _leg_chains(nominal, info, dev)
        home = self._key_qpos.expand(self.num_envs, -1).clone()
        home[:, self._qpos_adr] = self._d_default_qpos
        self._home_qpos = home
        """The home state's qpos of every world (default pose, clamped into its limits, at the init height)."""
        lay = self.layout
        self._cols = {
            name: t(getattr(lay, name).reshape(-1), torch.long)
            for name in ("torque", "foot_pos", "foot_vel", "foot_force", "body_force")
        }

    def _views(self) -> None:
        """Zero-copy torch views of the warp arrays this backend reads and writes."""
        to_torch = self._wp.to_torch
        d, m = self.data, self.model
        self._qpos, self._qvel, self._qacc = to_torch(d.qpos), to_torch(d.qvel), to_torch(d.qacc)
        self._ctrl, self._time = to_torch(d.ctrl), to_torch(d.time)
        self._sensordata = to_torch(d.sensordata)
        self.fields: dict[str, torch.Tensor] = {name: to_torch(getattr(m, name)) for name in PER_WORLD_FIELDS}
        """Per-world model fields as torch views, shape (N, ...) each (read them; change them through this class)."""
        self._d_default_qpos = self._default_qpos.float()
        self._d_joint_range = self._joint_range.float()

    @contextlib.contextmanager
    def _on_stream(self) -> Iterator[None]:
        """Run torch and warp work on the backend's stream (CUDA), ordered after and before the caller's."""
        if self._stream is None:
            with self._wp.ScopedDevice(self._wp_device):
                yield
            return
        outer = torch.cuda.current_stream(self.device)
        self._stream.wait_stream(outer)
        with (
            torch.cuda.stream(self._stream),
            self._wp.ScopedDevice(self._wp_device),
            self._wp.ScopedStream(self._wp_stream),
        ):
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

    def _write_home(self, mask: torch.Tensor) -> None:
        """Home state (default pose, clamped into the limits, at the init height, at rest, time 0) where ``mask``.

        Masked writes over every world: no host read of which worlds, so the call queues the same work whatever
        the mask holds. Shape of ``mask``: (N,), bool.
        """
        self._qpos.copy_(torch.where(mask[:, None], self._home_qpos, self._qpos))
        self._qvel.masked_fill_(mask[:, None], 0.0)
        self._time.masked_fill_(mask, 0.0)

    def _refresh(self, mask: torch.Tensor) -> None:
        """Recompute the sensors where ``mask`` at the current state with ctrl = default pose (all others kept).

        One forward pass of every world; the sensor values are kept only where ``mask``. Shape: (N,), bool.
        """
        self._set_const()
        keep = self._sensordata.clone()
        ctrl = self._ctrl.clone()
        self._ctrl[:, self._act_ids] = torch.where(mask[:, None], self._d_default_qpos, ctrl[:, self._act_ids])
        self._forward()
        self._sensordata.copy_(torch.where(mask[:, None], self._sensordata, keep))
        self._ctrl.copy_(ctrl)

    def _state_rows(self) -> torch.Tensor:
        """``mjSTATE_FULLPHYSICS`` of every env: [time, qpos, qvel]. Shape: (N, nstate), float64."""
        return torch.cat([self._time[:, None], self._qpos, self._qvel], dim=1).double()

    def _check(self, ok: torch.Tensor, exc: type[Exception], msg: str) -> None:
        """Raise ``exc(msg)`` unless ``ok`` (a 0-d bool tensor) is true, without a host read on a GPU.

        On the CPU the value is in host memory and checked now. On CUDA the check is queued on the device
        (``torch._assert_async``): a failure stops the process at a later launch. Only morfic's own callers reach
        these checks (a user's input is checked in the CLI and the configs), so a failure there is a bug.
        """
        if ok.device.type != "cpu":
            torch._assert_async(ok)
            return
        try:
            torch._assert_async(ok)
        except RuntimeError:
            raise exc(msg) from None

    def _ids(self, env_ids: torch.Tensor | np.ndarray) -> torch.Tensor:
        """Env ids as an int64 device tensor, checked to be in [0, N). Shape: (k,)."""
        ids = torch.as_tensor(env_ids, device=self.device).reshape(-1).long()
        n = self.num_envs
        self._check(((ids >= 0) & (ids < n)).all(), ValueError, f"env ids must be in [0, {n}).")
        return ids

    def _device_rows(
        self,
        value: torch.Tensor,
        k: int,
        shape: tuple[int, ...],
        what: str,
        dtype: torch.dtype = torch.float32,
        exc: type[Exception] = MorficError,
    ) -> torch.Tensor:
        """``value`` as (k, *shape) rows of ``dtype`` on the device; ``exc`` naming ``what`` for another shape."""
        if tuple(value.shape) != (k, *shape):
            raise exc(f"{what}: expected shape {(k, *shape)}, got {tuple(value.shape)}.")
        return torch.as_tensor(value, device=self.device).to(dtype)

    def _rows64(self, value: torch.Tensor, k: int, shape: tuple[int, ...], what: str) -> torch.Tensor:
        return self._device_rows(torch.as_tensor(value), k, shape, what, torch.float64, ValueError)

    def _standing_height(self, joint_pos: torch.Tensor) -> torch.Tensor:
        """Base height above the lowest foot bottom, base upright at the origin (m), in float64 on the device.

        :func:`morfic_cli.morphology.apply.standing_height` (``mj_kinematics`` of the legs) as batched forward
        kinematics of the four leg chains (geometry is the same in every world; only the pose differs).

        Args:
            joint_pos: Joint angles (rad), model order. Shape: (k, 12).

        Returns:
            Heights, float64. Shape: (k,).
        """
        q = joint_pos.double()
        k = q.shape[0]
        rot = torch.eye(3, dtype=torch.float64, device=self.device).expand(k, len(LEGS), 3, 3)
        pos = torch.zeros(k, len(LEGS), 3, dtype=torch.float64, device=self.device)
        for link in self._fk["links"]:
            pos = pos + (rot @ link["pos"][..., None])[..., 0]
            rot = rot @ link["rot"]
            if link["joint"] is not None:
                axis, anchor, col, q0 = link["joint"]
                turn = _axis_angle(axis, q[:, col] - q0)  # (k, 4, 3, 3)
                new = rot @ turn
                pos = pos + (rot @ anchor[..., None])[..., 0] - (new @ anchor[..., None])[..., 0]
                rot = new
        feet_z = (pos + (rot @ self._fk["site_pos"][..., None])[..., 0])[..., 2]
        return -(feet_z.min(dim=1).values - self.robot.foot_radius)

    def _descriptor_fields(self, m: torch.Tensor) -> dict[str, torch.Tensor]:
        """:func:`morfic_cli.morphology.apply.descriptor_fields` on the device (the same float64 arithmetic).

        Args:
            m: Validated raw descriptors (kg, rad), float64. Shape: (k, 11).

        Returns:
            ``body_mass`` (k, nbody), ``body_inertia`` (k, nbody, 3), ``jnt_range`` (k, njnt, 2) and
            ``actuator_ctrlrange`` (k, nu, 2), float64.
        """
        k = m.shape[0]
        mass = self._t_body_mass.expand(k, -1).clone()
        for li, link in enumerate(LINKS):
            mass[:, self._t_link_bodies[:, li]] = m[:, DESCRIPTOR_MASS_INDEX[link], None].expand(-1, len(LEGS))
        mass[:, self.info.base_body] = m[:, DESCRIPTOR_MASS_INDEX["base"]]
        changed = self._t_changed
        nominal = self._t_body_mass[changed]
        scale = torch.ones_like(mass)
        scale[:, changed] = torch.where(nominal > 0, mass[:, changed] / nominal, torch.zeros_like(nominal))
        ranges = m[:, self._t_limit_cols].repeat(1, len(LEGS), 1)  # (k, 12, 2)
        jnt_range = self._t_jnt_range.expand(k, -1, -1).clone()
        jnt_range[:, self._t_joint_ids] = ranges
        ctrlrange = self._t_ctrlrange.expand(k, -1, -1).clone()
        ctrlrange[:, self._act_ids] = ranges
        return {
            "body_mass": mass,
            "body_inertia": self._t_body_inertia[None] * scale[..., None],
            "jnt_range": jnt_range,
            "actuator_ctrlrange": ctrlrange,
        }

    # ------------------------------------------------------------------------------------------
    # SimBackend
    # ------------------------------------------------------------------------------------------

    def step(self, joint_targets: torch.Tensor, nsteps: int) -> SimFrame:
        """Hold position targets for ``nsteps`` physics steps in every env and return the new frame.

        Everything stays on the device; one flag is read back (:func:`morfic_cli.sim.sync.any_true`: did a
        world diverge?), so that the forward pass that recomputes the sensors of restored worlds runs only then.

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
            self._write_home(bad)  # MuJoCo Warp never sees a non-finite state
            self._ctrl[:, self._act_ids] = targets
            self._set_const()
            self._physics(nsteps)
            bad |= self._diverged()
            self._before, self._step_bad, self._bad = before, bad, bad.clone()
            if sync.any_true(bad):
                self._write_home(bad)
                self._refresh(bad)
            return self._frame()

    @property
    def bad_states(self) -> dict[int, np.ndarray]:
        """Pre-step states (``mjSTATE_FULLPHYSICS``, float64) of the envs flagged ``bad`` by the last step.

        Read back from the device when asked (not part of the step).
        """
        if self._before is None:
            return {}
        ids = self._step_bad.nonzero().flatten().cpu()
        rows = self._before[ids.to(self.device)].cpu().numpy()
        return {int(env): row for env, row in zip(ids.tolist(), rows, strict=True)}

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
        qpos, qvel, sd = self._qpos, self._qvel, self._sensordata
        n = self.num_envs
        quat, lin_vel_w = qpos[:, 3:7].clone(), qvel[:, 0:3].clone()

        def cols(name: str, *shape: int) -> torch.Tensor:
            return sd[:, self._cols[name]].reshape(n, *shape)

        return SimFrame(
            base_pos_w=qpos[:, 0:3].clone(),
            base_quat_w=quat,
            base_lin_vel_w=lin_vel_w,
            base_lin_vel_b=quat_rotate_inverse(quat, lin_vel_w),
            base_ang_vel_b=qvel[:, 3:6].clone(),
            joint_pos=qpos[:, self._qpos_adr],
            joint_vel=qvel[:, self._dof_adr],
            joint_torque=cols("torque", NUM_JOINTS),
            foot_pos_w=cols("foot_pos", len(LEGS), 3),
            foot_vel_w=cols("foot_vel", len(LEGS), 3),
            foot_force_w=cols("foot_force", len(LEGS), 3),
            body_contact_force=torch.linalg.norm(cols("body_force", len(CONTACT_BODIES), 3), dim=-1),
            bad=self._bad.clone(),
        )

    def params(self) -> SimParams:
        """The per-env physical parameters now in effect, as exact float64 tensors on the device (frames are float32).

        The backend's own bookkeeping, not copies: they change when :meth:`set_morphology` or
        :meth:`set_dynamics` next writes the same envs.
        """
        return SimParams(
            joint_range=self._joint_range,
            default_joint_pos=self._default_qpos,
            torque_limit=self._torque_limit,
            base_mass=self._base_mass,
            total_mass=self._total_mass,
            nominal_height=self._nominal_height,
            friction=self._friction,
            restitution=self._restitution,
            com_offset=self._com_offset,
            joint_friction=self._joint_friction,
            descriptor=self._descriptor,
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
        """Set the state of some envs; time and warm start are zeroed, sensors recomputed.

        Args:
            env_ids: Envs to reset. Shape: (k,), int64.
            base_pos: Base position, world frame (m). Shape: (k, 3).
            base_quat: Base orientation (w, x, y, z). Shape: (k, 4).
            base_vel: Linear (world) then angular (base frame) velocity. Shape: (k, 6).
            joint_pos: Joint positions (rad), written as given. Shape: (k, 12).
            joint_vel: Joint velocities (rad/s). Shape: (k, 12).
        """
        with self._on_stream():
            ids = self._ids(env_ids)
            k = len(ids)
            qpos = torch.zeros(k, self.host_model.nq, device=self.device)
            qpos[:, 0:3] = self._device_rows(base_pos, k, (3,), "base_pos")
            qpos[:, 3:7] = self._device_rows(base_quat, k, (4,), "base_quat")
            qpos[:, self._qpos_adr] = self._device_rows(joint_pos, k, (NUM_JOINTS,), "joint_pos")
            qvel = torch.zeros(k, self.host_model.nv, device=self.device)
            qvel[:, 0:6] = self._device_rows(base_vel, k, (6,), "base_vel")
            qvel[:, self._dof_adr] = self._device_rows(joint_vel, k, (NUM_JOINTS,), "joint_vel")
            self._qpos[ids], self._qvel[ids], self._time[ids] = qpos, qvel, 0.0
            self._bad[ids] = False
            if k:
                mask = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
                mask[ids] = True
                self._refresh(mask)

    def _check_descriptors(self, m: torch.Tensor) -> None:
        """:func:`morfic_cli.morphology.descriptor.as_descriptor`'s checks on every row, without a host read on a GPU.

        Raises:
            DescriptorError: (on the CPU) a row is non-finite, outside the sane ranges or has a min limit above its
                max; the message is as_descriptor's for the first such row.
        """
        lo, hi = self._t_sane
        ok = (torch.isfinite(m) & (m >= lo) & (m <= hi)).all()
        ok &= (m[:, self._t_limit_cols[:, 0]] <= m[:, self._t_limit_cols[:, 1]]).all()
        try:
            self._check(ok, DescriptorError, "descriptors: invalid")
        except DescriptorError:
            for row in m.cpu().numpy():  # the failure path only: as_descriptor's precise message
                as_descriptor(row)
            raise

    def set_morphology(self, env_ids: torch.Tensor, descriptors: torch.Tensor) -> None:
        """Apply 11-D descriptors (raw units) to some worlds' model fields (docs/robots.md), on the device.

        The fields are :func:`morfic_cli.morphology.apply.descriptor_fields`' arithmetic, computed on the device
        (:meth:`_descriptor_fields`); the standing height of the new default pose is MuJoCo Warp's kinematics.

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
        with self._on_stream():
            ids = self._ids(env_ids)
            m = self._rows64(descriptors, len(ids), (11,), "descriptors")
            self._check_descriptors(m)
            fields = self._descriptor_fields(m)
            for name, value in fields.items():
                self.fields[name][ids] = value.float()
            joint_range = fields["jnt_range"][:, self._t_joint_ids]
            default = torch.clamp(self._t_robot_q0, joint_range[..., 0], joint_range[..., 1])
            self._descriptor[ids] = m
            self._joint_range[ids] = joint_range
            self._default_qpos[ids] = default
            self._nominal_height[ids] = self._standing_height(default)
            self._total_mass[ids] = fields["body_mass"].sum(dim=1)
            self._base_mass[ids] = fields["body_mass"][:, self.info.base_body]
            self._d_default_qpos[ids] = default.float()
            self._d_joint_range[ids] = joint_range.float()
            self._home_qpos[ids[:, None], self._qpos_adr] = default.float()
        self._const_dirty = True

    def set_geometry_pool(self, robots) -> None:
        """Not supported: procedural geometry runs on the CPU backend only.

        Its robots differ in body positions and geom sizes, which this backend keeps shared across worlds
        (docs/robots.md, "Procedural geometry").

        Raises:
            MorficError: always.
        """
        raise MorficError(GEOMETRY_NEEDS_CPU)

    def set_geometry(self, env_ids: torch.Tensor, robot_ids: torch.Tensor) -> None:
        """See :meth:`set_geometry_pool`. Raises MorficError."""
        raise MorficError(GEOMETRY_NEEDS_CPU)

    def set_actuation(
        self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor, torque_limit: torch.Tensor
    ) -> None:
        """Not supported: per-env gains and torque limits run on the CPU backend only.

        (``env.rand.actuation``, eval mode ``actuation-matched``.) Raises MorficError.
        """
        raise MorficError(
            "per-env gains and torque limits (env.rand.actuation, eval mode actuation-matched) run on "
            "the cpu backend only; train with --set env.sim.backend=cpu (no --device cuda), or turn "
            "them off with --set env.rand.actuation.enabled=false."
        )

    def body_description(self, env_ids: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Not supported: URMA's joint and foot descriptions (``env.obs.body_tokens``, variant ``urma``).

        They are read from per-env ``MjModel`` objects, which only the CPU backend keeps.

        Raises:
            MorficError: always.
        """
        raise MorficError(
            "variant urma's joint descriptions (env.obs.body_tokens) need the CPU backend, which keeps "
            "one MjModel per env; train it with --device cpu (--set env.sim.backend=cpu)."
        )

    def set_dynamics(
        self,
        env_ids: torch.Tensor,
        friction: torch.Tensor,
        restitution: torch.Tensor,
        com_offset: torch.Tensor,
        joint_friction: torch.Tensor,
    ) -> None:
        """Domain randomisation of contact and joint properties for some worlds (see :mod:`morfic_cli.sim.cpu`).

        Args:
            env_ids: Envs to change. Shape: (k,).
            friction: Ground sliding friction coefficient. Shape: (k,).
            restitution: Contact restitution in [0, 1). Shape: (k,).
            com_offset: Base COM offset from its nominal position (m). Shape: (k, 3).
            joint_friction: Joint dry friction (frictionloss, N m). Shape: (k, 12).

        Raises:
            ValueError: wrong shapes, negative friction or restitution outside [0, 1).
        """
        with self._on_stream():
            ids = self._ids(env_ids)
            k = len(ids)
            mu, e = self._rows64(friction, k, (), "friction"), self._rows64(restitution, k, (), "restitution")
            com = self._rows64(com_offset, k, (3,), "com_offset")
            jf = self._rows64(joint_friction, k, (NUM_JOINTS,), "joint_friction")
            self._check(
                (torch.isfinite(mu) & (mu >= 0)).all() & (torch.isfinite(jf) & (jf >= 0)).all(),
                ValueError,
                "friction and joint_friction must be finite and >= 0.",
            )
            self._check(
                (torch.isfinite(e) & (e >= 0) & (e < 1)).all() & torch.isfinite(com).all(),
                ValueError,
                "restitution must be in [0, 1) and com_offset finite.",
            )
            f = self.fields
            f["geom_friction"][ids, :, 0] = mu.float()[:, None]
            f["geom_solref"][ids, :, 1] = restitution_to_dampratio(e).float()[:, None]
            f["body_ipos"][ids, self.info.base_body] = (self._nominal_ipos + com).float()
            f["dof_frictionloss"][ids[:, None], self._dof_adr] = jf.float()
            self._friction[ids], self._restitution[ids] = mu, e
            self._com_offset[ids], self._joint_friction[ids] = com, jf
        self._const_dirty = True  # the COM moved: inverse weights change

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
            self._qpos.copy_(rows[:, 1 : 1 + nq])
            self._qvel.copy_(rows[:, 1 + nq :])
            self._sensordata.copy_(torch.as_tensor(state["sensordata"], device=self.device).to(torch.float32))

    def push(self, env_ids: torch.Tensor, delta_vel_xy: torch.Tensor) -> None:
        """Add a planar velocity kick to some envs' bases (world frame). Shapes: (k,), (k, 2) in m/s."""
        with self._on_stream():
            ids = self._ids(env_ids)
            kick = self._device_rows(torch.as_tensor(delta_vel_xy), len(ids), (2,), "delta_vel_xy")
            self._qvel[ids, 0:2] += kick

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
            staged = [
                torch.clamp(self._device_rows(c, self.num_envs, (NUM_JOINTS,), "controls"), lo, hi) for c in controls
            ]
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
