"""``LocomotionEnv``: the batched quadruped locomotion task as an rsl-rl 5.x ``VecEnv``.

One policy step is ``decimation`` (4) physics steps of ``physics_dt`` (0.005 s): 50 Hz. Each env
carries its own morphology: in ``train`` mode an 11-D descriptor is sampled from the paper's
training support at every reset and applied to the Go2 template (with procedural geometry on, ``env.rand.geometry``,
each env instead draws a generated robot from a pool at every reset, docs/robots.md); in ``descriptor`` mode every env
is the Go2 template with one target's descriptor (the paper's zero-shot protocol); in ``full``
mode every env is the target's own generated model; ``actuation-matched`` is descriptor mode with the target's Kp, Kd
and torque limits matched to its mass (docs/eval.md). With ``env.rand.actuation`` (train mode) masses get a heavier
tail and gains and torque limits follow them, under a morphology curriculum (:mod:`morfic_cli.envs.actuation`). See
docs/concepts.md ("The environment").

Every buffer, random draw and log value lives on the backend's device (``backend.device``: the CPU for the CPU
backend, the GPU or warp's CPU device for the warp backend), so a step on the GPU keeps its tensors there. The step
reads device data back only through :mod:`morfic_cli.sim.sync` (how many envs reset, resample or re-randomise);
log values are 0-d tensors that the runner reads once per iteration (docs/gpu.md, "Device-resident step").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from morfic_cli.config import EnvCfg
from morfic_cli.envs import observations as O
from morfic_cli.envs.actuation import (
    Actuation,
    initial_upper,
    matched_actuation,
    sample_actuation,
    scale_masses,
    widen_mass_scale,
)
from morfic_cli.envs.commands import CommandRanges, sample_commands, widen_vx
from morfic_cli.envs.gait import advance_phase, desired_contact, foot_phases
from morfic_cli.envs.math import projected_gravity, yaw_quat
from morfic_cli.envs.randomization import (
    sample_dynamics,
    sample_latency,
    sample_push,
    sample_reset_joint_pos,
)
from morfic_cli.envs.rewards import TRACKING_TERM, compute_rewards
from morfic_cli.envs.state import EnvState
from morfic_cli.envs.terminations import NONFINITE, compute_terminations
from morfic_cli.errors import MorficError
from morfic_cli.morphology.descriptor import DIM as DESCRIPTOR_DIM
from morfic_cli.morphology.descriptor import LIMIT_PAIRS, TRAIN_MAX, TRAIN_MIN, as_descriptor
from morfic_cli.morphology.extended import geometry_vector
from morfic_cli.morphology.procedural import GeometryPool, generate_pool
from morfic_cli.morphology.robots import RobotSpec, load_robot
from morfic_cli.sim import sync
from morfic_cli.sim.args import NUM_JOINTS
from morfic_cli.sim.backend import SimFrame, SimParams
from morfic_cli.sim.factory import make_backend

Mode = Literal["train", "descriptor", "full", "actuation-matched"]
MODES: tuple[str, ...] = ("train", "descriptor", "full", "actuation-matched")
TEMPLATE_MODES: tuple[str, ...] = ("descriptor", "actuation-matched")
"""The evaluation modes that put a target's descriptor on the Go2 template."""
LIMIT_DIMS: list[int] = [i for pair in LIMIT_PAIRS for i in pair]
"""The descriptor's joint-limit dimensions (5..10)."""
TEMPLATE = "go2"
FOOT_CONTACT_FORCE = 1.0
"""A foot is in contact (c_i) when its ground force exceeds this many newtons."""


class LocomotionEnv(VecEnv):
    """Velocity-tracking locomotion with per-env morphology and domain randomisation.

    Observation groups (TensorDict keys), N = num_envs:
        ``policy`` (N, 48), ``history`` (N, 16, 48) = [h_t, o_t], ``critic`` (N, 16, 48, clean),
        ``privileged`` (N, 18), ``morphology`` (N, 11; (N, 28) with ``cfg.obs.extended_morphology``); with
        ``cfg.obs.body_tokens`` (variant ``urma``) also
        ``joint_description`` (N, 12, 18), ``foot_description`` (N, 4, 6) and ``foot_state`` (N, 4, 2)
        (:mod:`morfic_cli.envs.observations`).
    """

    def __init__(
        self,
        cfg: EnvCfg,
        *,
        mode: str = "train",  # one of MODES (Mode), checked: modes come from the command line
        robot: str | Sequence[str] = TEMPLATE,
        seed: int = 0,
    ) -> None:
        """Create the env.

        Args:
            cfg: Env config (``cfg.num_envs`` envs).
            mode: "train" (sample descriptors from the support), "descriptor" (Go2 template with
                ``robot``'s descriptor), "full" (``robot``'s own model) or "actuation-matched" (descriptor mode
                with Kp, Kd and torque limits x the env's total mass / Go2's,
                :func:`~morfic_cli.envs.actuation.matched_actuation`).
            robot: Target robot for "descriptor" / "full" modes (ignored in "train"). In "descriptor" mode also
                one target per env (a sequence of ``cfg.num_envs`` names; also in "actuation-matched"): env i is
                the Go2 template with
                ``robot[i]``'s descriptor, so several targets share one batch (``self.target`` is ``robot[0]``'s).
            seed: Seed of every random draw the env makes.
        """
        if mode not in MODES:
            raise ValueError(f"unknown env mode '{mode}'; valid modes are: {', '.join(MODES)}.")
        per_env = None if isinstance(robot, str) else tuple(robot)
        if per_env is not None and (mode not in TEMPLATE_MODES or len(per_env) != cfg.num_envs):
            raise ValueError(
                f"one robot per env needs descriptor mode and {cfg.num_envs} names, got mode '{mode}' "
                f"and {len(per_env)} names."
            )
        self.cfg = cfg
        self.mode = mode
        self.target: RobotSpec = load_robot(robot if isinstance(robot, str) else robot[0])
        self.spec: RobotSpec = self.target if mode == "full" else load_robot(TEMPLATE)
        self.num_envs = cfg.num_envs
        self.num_actions = NUM_JOINTS
        self.dt = cfg.sim.physics_dt * cfg.decimation
        self.max_episode_length = int(math.ceil(cfg.episode_length_s / self.dt))
        self.backend = make_backend(cfg.sim, self.spec, self.num_envs, template=mode != "full")
        self.device = torch.device(self.backend.device)
        self.gen = torch.Generator(device=self.device).manual_seed(seed)
        self._support_lo = torch.as_tensor(TRAIN_MIN, dtype=torch.float32, device=self.device)
        self._support_hi = torch.as_tensor(TRAIN_MAX, dtype=torch.float32, device=self.device)
        self._alloc_buffers()
        self._init_actuation()
        self.geometry_pool: GeometryPool | None = None
        if mode == "train" and cfg.rand.enabled and cfg.rand.geometry.enabled:
            self._init_geometry(seed)
        if mode in TEMPLATE_MODES and per_env is None:
            desc = torch.as_tensor(as_descriptor(self.target.descriptor), dtype=torch.float64)
            self.backend.set_morphology(self._all_ids, desc.expand(self.num_envs, -1).clone())
        elif mode in TEMPLATE_MODES and per_env is not None:
            specs = {name: load_robot(name) for name in dict.fromkeys(per_env)}
            desc = torch.stack(
                [torch.as_tensor(as_descriptor(specs[name].descriptor), dtype=torch.float64) for name in per_env]
            )
            self.backend.set_morphology(self._all_ids, desc)
        if mode == "actuation-matched":
            self._set_actuation(
                self._all_ids,
                matched_actuation(self.backend.params().total_mass, self._template_actuation, self._template_mass),
            )
        self.params: SimParams = self.backend.params()
        self._reset_envs(self._all_ids)
        if self.body_tokens and mode != "train":
            self._describe(self._all_ids)  # the morphology never changes after this
        self._refresh_observations(self.backend.frame(), reset_ids=self._all_ids)

    # ------------------------------------------------------------------ buffers
    def _alloc_buffers(self) -> None:
        n, h, dev = self.num_envs, O.history_frames(self.cfg.obs), self.device
        f32: dict[str, Any] = {"dtype": torch.float32, "device": dev}
        self._all_ids = torch.arange(n, device=dev)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=dev)
        self.common_step_counter = 0
        self.actions = torch.zeros(n, NUM_JOINTS, **f32)
        self.action_prev = torch.zeros(n, NUM_JOINTS, **f32)
        self.action_buffer = torch.zeros(n, self.cfg.rand.max_latency_steps + 1, NUM_JOINTS, **f32)
        self.latency = torch.zeros(n, dtype=torch.long, device=dev)
        self.commands = torch.zeros(n, 3, **f32)
        self.command_ranges = CommandRanges.initial(self.cfg.commands)
        self.command_ranges.vx = torch.tensor(self.command_ranges.vx, dtype=torch.float64, device=dev)
        self.gait_phase = torch.zeros(n, **f32)
        self.gait_frequency = torch.full((n,), self.cfg.gait.frequency, **f32)
        self.joint_vel_prev = torch.zeros(n, NUM_JOINTS, **f32)
        self.foot_vel_prev = torch.zeros(n, 4, 3, **f32)
        self.history = torch.zeros(n, h, O.POLICY_DIM, **f32)
        self.critic_history = torch.zeros(n, h, O.POLICY_DIM, **f32)
        self.obs_buf = torch.zeros(n, O.POLICY_DIM, **f32)
        self.episode_sums: dict[str, torch.Tensor] = {}
        self.episode_lin_tracking = torch.zeros(n, **f32)
        self._nonfinite = torch.zeros((), dtype=torch.long, device=dev)
        self._tracking_sum = torch.zeros((), dtype=torch.float64, device=dev)
        self._tracking_count = 0
        self.last_state: EnvState | None = None
        self.last_reward_terms: dict[str, torch.Tensor] = {}
        self.last_terminations: dict[str, torch.Tensor] = {}
        """Pre-reset view of the last step's ends (evaluation logs): each termination term's mask, then
        ``NONFINITE``, each (N,) bool on the device."""
        hip_xy = torch.as_tensor(self.spec.hip_pos[:, :2] + self.spec.thigh_offset[:, :2], **f32)
        self.nominal_foot_pos_b = hip_xy.expand(n, 4, 2).clone()
        self._obs = TensorDict({}, batch_size=[n], device=dev)
        self.body_tokens = self.cfg.obs.body_tokens
        if self.body_tokens:  # URMA's tokens: descriptions per env model, foot touchdown clocks
            self.joint_description = torch.zeros(n, NUM_JOINTS, O.JOINT_DESCRIPTION_DIM, **f32)
            self.foot_description = torch.zeros(n, 4, O.FOOT_DESCRIPTION_DIM, **f32)
            self.foot_touchdown_time = torch.zeros(n, 4, **f32)
            self.foot_contact_prev = torch.zeros(n, 4, dtype=torch.bool, device=dev)

    def _describe(self, ids: torch.Tensor) -> None:
        """Read the normalised joint and foot descriptions of some envs' models (after their morphology changed).

        Written out of place, so an observation handed out before keeps the description it had.
        """
        joints, feet = self.backend.body_description(ids)
        self.joint_description = self.joint_description.index_put((ids,), O.joint_description_obs(joints.float()))
        self.foot_description = self.foot_description.index_put((ids,), O.foot_description_obs(feet.float()))

    def _init_actuation(self) -> None:
        """Each env's gains and geometry entries (the extended descriptor's) and the mass curriculum's bound."""
        spec, n, dev = self.spec, self.num_envs, self.device
        act = self.cfg.rand.actuation
        self.actuation_rand = self.mode == "train" and self.cfg.rand.enabled and act.enabled
        """Whether masses, gains and torque limits are drawn at reset (``env.rand.actuation``)."""
        self._template_mass = spec.total_mass
        self._template_actuation = Actuation(
            torch.tensor([spec.kp], dtype=torch.float64, device=dev),
            torch.tensor([spec.kd], dtype=torch.float64, device=dev),
            torch.as_tensor(spec.torque_limit, dtype=torch.float64, device=dev)[None],
        )
        self.kp = torch.full((n,), float(spec.kp), dtype=torch.float64, device=dev)
        """Each env's Kp (N m/rad). Shape: (N,)."""
        self.kd = torch.full((n,), float(spec.kd), dtype=torch.float64, device=dev)
        """Each env's Kd (N m s/rad). Shape: (N,)."""
        geometry = torch.as_tensor(geometry_vector(spec), dtype=torch.float64, device=dev)
        self.geometry_vec = geometry.expand(n, -1).clone()
        """Each env's geometry entries of the extended descriptor (m). Shape: (N, 11)."""
        self.mass_upper = torch.tensor(initial_upper(act), dtype=torch.float64, device=dev)
        """The mass factor's current upper bound (the morphology curriculum's). Shape: ()."""

    def _set_actuation(self, ids: torch.Tensor, act: Actuation) -> None:
        """Write some envs' gains and torque limits to the backend and remember them."""
        self.backend.set_actuation(ids, act.kp, act.kd, act.torque_limit)
        self.kp[ids] = act.kp.to(self.kp)
        self.kd[ids] = act.kd.to(self.kd)

    def _init_geometry(self, seed: int) -> None:
        """Generate and compile the pool of procedural robots (docs/robots.md, "Procedural geometry")."""
        pool = generate_pool(self.spec, self.cfg.rand.geometry, seed)
        self.backend.set_geometry_pool(pool.robots)
        dev = self.device
        self.geometry_pool = pool
        self._pool_descriptor = torch.as_tensor(pool.descriptors, dtype=torch.float64, device=dev)
        self._pool_init_height = torch.as_tensor(pool.init_height, dtype=torch.float32, device=dev)
        self._pool_foot_pos_b = torch.as_tensor(pool.nominal_foot_pos_b, dtype=torch.float32, device=dev)
        self.geometry_ids = torch.zeros(self.num_envs, dtype=torch.long, device=dev)
        """Each env's robot in :attr:`geometry_pool`. Shape: (N,)."""
        f64: dict[str, Any] = {"dtype": torch.float64, "device": dev}
        self._pool_kp = torch.tensor([r.kp for r in pool.robots], **f64)
        self._pool_kd = torch.tensor([r.kd for r in pool.robots], **f64)
        self._pool_geometry = torch.stack([torch.as_tensor(geometry_vector(r), **f64) for r in pool.robots])

    def _reset_geometry(self, ids: torch.Tensor) -> None:
        """Draw each env's robot from the pool and apply it with its descriptor (limits from the support if asked)."""
        k = len(ids)
        pick = torch.randint(0, len(self._pool_descriptor), (k,), generator=self.gen, device=self.device)
        self.geometry_ids[ids] = pick
        self.backend.set_geometry(ids, pick)
        desc = self._pool_descriptor[pick].clone()
        if self.cfg.rand.geometry.limits_from_support:
            u = torch.rand((k, DESCRIPTOR_DIM), generator=self.gen, dtype=torch.float64, device=self.device)
            lo, hi = self._support_lo.double(), self._support_hi.double()
            desc[:, LIMIT_DIMS] = (lo + (hi - lo) * u)[:, LIMIT_DIMS]
        if self.actuation_rand:
            desc = scale_masses(desc, self.mass_upper, self.cfg.rand.actuation, self.gen)
        self.backend.set_morphology(ids, desc)
        self.kp[ids], self.kd[ids] = self._pool_kp[pick], self._pool_kd[pick]
        self.geometry_vec[ids] = self._pool_geometry[pick]
        self.nominal_foot_pos_b[ids] = self._pool_foot_pos_b[pick]

    @property
    def nonfinite_resets(self) -> int:
        """Envs reset because their state became non-finite, since the start (a host read; not in the step)."""
        return int(self._nonfinite)

    # ------------------------------------------------------------------ VecEnv
    def get_observations(self) -> TensorDict:
        """The current observation groups (see the class docstring)."""
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Advance every env by one policy step.

        Args:
            actions: a_t. Shape: (N, 12).

        Returns:
            observations, rewards (N,), dones (N,), extras with ``time_outs`` (N,) and ``log`` (name -> 0-d tensor
            on the env's device), all on the env's device.
        """
        a = torch.clamp(
            actions.detach().to(device=self.device, dtype=torch.float32), -self.cfg.action_clip, self.cfg.action_clip
        )
        self.action_prev = self.actions
        self.actions = a
        self.action_buffer = torch.cat([a[:, None], self.action_buffer[:, :-1]], dim=1)
        applied = self.action_buffer[self._all_ids, self.latency]
        targets = self.params.default_joint_pos + self.cfg.action_scale * applied
        frame = self.backend.step(targets, self.cfg.decimation)
        self.episode_length_buf += 1
        self.common_step_counter += 1
        self.gait_phase = advance_phase(self.gait_phase, self.gait_frequency, self.dt)

        state = self._state(frame)
        reward, terms, raw = compute_rewards(state, self.cfg.rewards)
        self.last_state, self.last_reward_terms = state, terms  # pre-reset view of this step (evaluation logs)
        reward = reward * self.dt
        terminated, term_masks = compute_terminations(state, self.cfg.terminations)
        bad = frame.bad
        self._nonfinite += bad.sum()
        reward = torch.where(bad, torch.zeros_like(reward), reward)
        terminated = terminated | bad
        self.last_terminations = {**term_masks, NONFINITE: bad}  # references, no host read
        reward = torch.nan_to_num(reward, nan=0.0, posinf=0.0, neginf=0.0)
        time_outs = (self.episode_length_buf >= self.max_episode_length) & ~terminated
        dones = terminated | time_outs

        for name, value in terms.items():
            value = torch.nan_to_num(value) * self.dt
            if name in self.episode_sums:
                self.episode_sums[name] += value
            else:  # the first step: one buffer per term (setdefault would allocate a spare one every step)
                self.episode_sums[name] = value.clone()
        self.episode_lin_tracking += torch.nan_to_num(raw[TRACKING_TERM])  # unweighted: --set w_lin=0 keeps it

        log: dict[str, torch.Tensor] = {f"/reward/{k}": m for k, m in _term_means(terms, self.dt).items()}
        log.update({f"/reward_raw/{k}": m for k, m in _term_means(raw).items()})
        vx_err = torch.nan_to_num(state.command[:, 0] - state.base_lin_vel_b[:, 0]).abs()
        log["/tracking/vx_error"] = vx_err.mean()
        reset_ids = sync.nonzero_ids(dones)
        if len(reset_ids):
            log.update(self._episode_log(reset_ids, time_outs, term_masks, bad))
        self._update_curriculum(log)
        self._push_and_resample()
        if len(reset_ids):
            self._reset_envs(reset_ids)
            frame = self.backend.frame()
        self._refresh_observations(frame, reset_ids=reset_ids)
        self.joint_vel_prev = frame.joint_vel.float().clone()
        self.foot_vel_prev = frame.foot_vel_w.float().clone()
        log["/env/nonfinite_resets"] = self._nonfinite.double()
        log["/curriculum/vx_max"] = torch.as_tensor(self.command_ranges.vx[1]).clone()  # the env's vx: a tensor
        extras = {"time_outs": time_outs, "log": log}
        return self._obs, reward, dones.to(torch.long), extras

    # ------------------------------------------------------------------ internals
    def _state(self, frame: SimFrame) -> EnvState:
        p = self.params
        f = {
            k: getattr(frame, k).float()
            for k in (
                "base_pos_w",
                "base_quat_w",
                "base_lin_vel_b",
                "base_ang_vel_b",
                "joint_pos",
                "joint_vel",
                "joint_torque",
                "foot_pos_w",
                "foot_vel_w",
                "foot_force_w",
                "body_contact_force",
            )
        }
        phases = foot_phases(self.gait_phase, self.cfg.gait)
        return EnvState(
            base_pos_w=f["base_pos_w"],
            base_quat_w=f["base_quat_w"],
            base_lin_vel_b=f["base_lin_vel_b"],
            base_ang_vel_b=f["base_ang_vel_b"],
            projected_gravity_b=projected_gravity(f["base_quat_w"]),
            joint_pos=f["joint_pos"],
            joint_vel=f["joint_vel"],
            joint_vel_prev=self.joint_vel_prev,
            joint_torque=f["joint_torque"],
            default_joint_pos=p.default_joint_pos.float(),
            joint_pos_min=p.joint_range[..., 0].float(),
            joint_pos_max=p.joint_range[..., 1].float(),
            foot_pos_w=f["foot_pos_w"],
            foot_vel_w=f["foot_vel_w"],
            foot_vel_w_prev=self.foot_vel_prev,
            foot_force_w=f["foot_force_w"],
            foot_contact=torch.linalg.norm(f["foot_force_w"], dim=-1) > FOOT_CONTACT_FORCE,
            body_contact_force=f["body_contact_force"],
            command=self.commands,
            action=self.actions,
            action_prev=self.action_prev,
            gait_phase=phases,
            desired_contact=desired_contact(phases, self.cfg.gait),
            gait_frequency=self.gait_frequency,
            nominal_foot_pos_b=self.nominal_foot_pos_b,
            nominal_height=p.nominal_height.float(),
            total_mass=p.total_mass.float(),
            dt=self.dt,
        )

    def _reset_envs(self, ids: torch.Tensor) -> None:
        k = len(ids)
        if self.geometry_pool is not None:
            self._reset_geometry(ids)
        elif self.mode == "train":
            u = torch.rand((k, DESCRIPTOR_DIM), generator=self.gen, dtype=torch.float64, device=self.device)
            lo, hi = self._support_lo.double(), self._support_hi.double()
            desc = lo + (hi - lo) * u
            if self.actuation_rand:
                desc = scale_masses(desc, self.mass_upper, self.cfg.rand.actuation, self.gen)
            self.backend.set_morphology(ids, desc)
        dyn = sample_dynamics(k, self.cfg.rand, self.gen)
        self.backend.set_dynamics(ids, dyn.friction, dyn.restitution, dyn.com_offset, dyn.joint_friction)
        self.params = self.backend.params()
        if self.actuation_rand:  # gains and torque limits follow the mass just drawn
            self._set_actuation(
                ids,
                sample_actuation(
                    self.params.total_mass[ids],
                    self._template_actuation,
                    self._template_mass,
                    self.cfg.rand.actuation,
                    self.gen,
                ),
            )
            self.params = self.backend.params()
        if self.body_tokens and self.mode == "train":  # a new morphology at every reset
            self._describe(ids)
        p = self.params
        q = sample_reset_joint_pos(
            p.default_joint_pos[ids].float(), p.joint_range[ids].float(), self.cfg.rand, self.gen
        )
        dev = self.device
        yaw = (torch.rand(k, generator=self.gen, device=dev) * 2.0 - 1.0) * math.pi
        base_pos = torch.zeros(k, 3, device=dev)
        if self.geometry_pool is not None:
            base_pos[:, 2] = self._pool_init_height[self.geometry_ids[ids]]
        else:
            base_pos[:, 2] = self.spec.init_height
        self.backend.reset_envs(
            ids, base_pos, yaw_quat(yaw), torch.zeros(k, 6, device=dev), q, torch.zeros(k, NUM_JOINTS, device=dev)
        )
        self.latency[ids] = sample_latency(k, self.cfg.rand, self.gen)
        self.action_buffer[ids] = 0.0
        self.actions[ids] = 0.0
        self.action_prev[ids] = 0.0
        self.commands[ids] = sample_commands(k, self.command_ranges, self.cfg.commands, self.gen)
        self.gait_phase[ids] = torch.rand(k, generator=self.gen, device=dev)
        self.episode_length_buf[ids] = 0
        self.episode_lin_tracking[ids] = 0.0
        for v in self.episode_sums.values():
            v[ids] = 0.0

    def _refresh_observations(self, frame: SimFrame, reset_ids: torch.Tensor) -> None:
        state = self._state(frame)
        clean = O.policy_obs(state, self.cfg.obs)
        noisy = O.add_noise(clean, self.cfg.obs, self.gen)
        self.history = O.push_history(self.history, noisy)
        self.critic_history = O.push_history(self.critic_history, clean)
        if len(reset_ids):
            frames = O.history_frames(self.cfg.obs)
            self.history[reset_ids] = noisy[reset_ids, None].expand(-1, frames, -1)
            self.critic_history[reset_ids] = clean[reset_ids, None].expand(-1, frames, -1)
        p = self.params
        self.obs_buf = noisy
        self._obs = TensorDict(
            {
                **(self._body_token_groups(state.foot_contact, reset_ids) if self.body_tokens else {}),
                "policy": noisy,
                "history": self.history.clone(),
                "critic": self.critic_history.clone(),
                "privileged": O.privileged_obs(
                    p.friction.float(),
                    p.restitution.float(),
                    p.base_mass.float(),
                    p.com_offset.float(),
                    p.joint_friction.float(),
                ),
                "morphology": (
                    self._extended_obs()
                    if self.cfg.obs.extended_morphology
                    else O.morphology_obs(p.descriptor.float(), self._support_lo, self._support_hi)
                ),
            },
            batch_size=[self.num_envs],
            device=self.device,
        )

    def extended_descriptor(self) -> torch.Tensor:
        """Each env's extended descriptor in raw units (:mod:`morfic_cli.morphology.extended`). Shape: (N, 28)."""
        p = self.params
        return torch.cat(
            [
                p.descriptor.double(),
                p.total_mass.double()[:, None],
                self.kp[:, None],
                self.kd[:, None],
                p.torque_limit.double()[:, :3],
                self.geometry_vec,
            ],
            dim=1,
        )

    def _extended_obs(self) -> torch.Tensor:
        return O.extended_morphology_obs(self.extended_descriptor())

    def _body_token_groups(self, contact: torch.Tensor, reset_ids: torch.Tensor) -> dict[str, torch.Tensor]:
        """Advance the feet's touchdown clocks (0 at reset) and give URMA's three groups. Contact: (N, 4) bool."""
        self.foot_touchdown_time = O.touchdown_time(self.foot_touchdown_time, contact, self.foot_contact_prev, self.dt)
        if len(reset_ids):
            self.foot_touchdown_time[reset_ids] = 0.0
        self.foot_contact_prev = contact
        return {
            "joint_description": self.joint_description,
            "foot_description": self.foot_description,
            "foot_state": torch.stack([contact.float(), self.foot_touchdown_time], dim=-1),
        }

    def _push_and_resample(self) -> None:
        rand = self.cfg.rand
        push_every = max(1, int(round(rand.push_interval_s / self.dt)))
        if rand.enabled and rand.pushes and self.common_step_counter % push_every == 0:
            self.backend.push(self._all_ids, sample_push(self.num_envs, rand, self.gen))
        self._rerandomize()
        every = max(1, int(round(self.cfg.commands.resample_time_s / self.dt)))
        ids = sync.nonzero_ids((self.episode_length_buf % every) == 0)
        if len(ids):
            self.commands[ids] = sample_commands(len(ids), self.command_ranges, self.cfg.commands, self.gen)

    def _rerandomize(self) -> None:
        """Re-draw friction, restitution, COM offset and joint friction (paper: every 10 s).

        For the envs whose episode time is a positive multiple of ``rand.rerandomize_interval_s``; p_t (the
        privileged group) follows.
        """
        rand = self.cfg.rand
        if not rand.enabled or rand.rerandomize_interval_s <= 0:
            return
        every = max(1, int(round(rand.rerandomize_interval_s / self.dt)))
        ids = sync.nonzero_ids((self.episode_length_buf % every) == 0)
        if len(ids):
            dyn = sample_dynamics(len(ids), rand, self.gen)
            self.backend.set_dynamics(ids, dyn.friction, dyn.restitution, dyn.com_offset, dyn.joint_friction)
            self.params = self.backend.params()

    def _episode_log(
        self, ids: torch.Tensor, time_outs: torch.Tensor, masks: dict[str, torch.Tensor], bad: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """The log of the episodes that ended this step (0-d tensors on the device; no host read)."""
        length_s = self.episode_length_buf[ids].float().clamp(min=1) * self.dt
        log = {f"/episode_reward/{k}": (v[ids] / length_s).mean() for k, v in self.episode_sums.items()}
        log["/episode/length_s"] = length_s.mean()
        for name, mask in masks.items():
            log[f"/termination/{name}"] = mask[ids].float().mean()
        log["/termination/time_out"] = time_outs[ids].float().mean()
        log[f"/termination/{NONFINITE}"] = bad[ids].float().mean()
        # legged_gym's rule: r_lin summed over the episode / the *maximum* episode length, over every finished
        # episode, so a fall counts as poor tracking. (Averaging over time-outs only let the envs with easy commands,
        # the ones that survive, widen the range long before the policy walked.)
        # Decided once per max episode length (as legged_gym) on every episode that ended in that window.
        # float64 on the device: the same arithmetic as a Python float sum of the float32 episode sums
        self._tracking_sum = self._tracking_sum + self.episode_lin_tracking[ids].sum().double() / (
            4.0 * self.max_episode_length
        )
        self._tracking_count += len(ids)
        return log

    def _update_curriculum(self, log: dict[str, torch.Tensor]) -> None:
        """Once per max episode length: widen the vx range if the finished episodes tracked well enough.

        Decided on the device (:func:`widen_vx` on the tensor range), so no host read.
        """
        if self.common_step_counter % self.max_episode_length != 0 or self._tracking_count == 0:
            return
        tracking = self._tracking_sum / self._tracking_count
        log["/curriculum/lin_tracking"] = tracking
        widen_vx(self.command_ranges, tracking, self.cfg.commands)
        if self.actuation_rand and self.cfg.rand.actuation.curriculum:
            widen_mass_scale(self.mass_upper, tracking, self.cfg.rand.actuation)
            log["/curriculum/mass_scale_max"] = self.mass_upper.clone()
        self._tracking_sum = torch.zeros_like(self._tracking_sum)
        self._tracking_count = 0

    # ------------------------------------------------------------------ checkpoints
    _TENSORS = (
        "episode_length_buf",
        "actions",
        "action_prev",
        "action_buffer",
        "latency",
        "commands",
        "gait_phase",
        "gait_frequency",
        "joint_vel_prev",
        "foot_vel_prev",
        "history",
        "critic_history",
        "obs_buf",
        "episode_lin_tracking",
        "nominal_foot_pos_b",
    )

    def state_dict(self) -> dict:
        """Everything the env needs to continue exactly where it is: buffers, curriculum, generator, physics.

        Per-env morphology and dynamics are stored as parameters and re-applied on load. Tensors are CPU copies
        whatever the env's device, so a checkpoint loads on a machine without a GPU.
        """
        p = self.params
        return {
            "num_envs": self.num_envs,
            "mode": self.mode,
            "tensors": {k: getattr(self, k).cpu().clone() for k in self._TENSORS},
            "episode_sums": {k: v.cpu().clone() for k, v in self.episode_sums.items()},
            "obs": {k: v.cpu().clone() for k, v in self._obs.items()},
            "counters": {
                "common_step_counter": self.common_step_counter,
                "nonfinite_resets": self.nonfinite_resets,
                "tracking_sum": float(self._tracking_sum),
                "tracking_count": self._tracking_count,
            },
            "command_vx": tuple(float(v) for v in self.command_ranges.vx),
            "generator": self.gen.get_state(),
            "params": {
                "descriptor": p.descriptor.cpu().clone(),
                "friction": p.friction.cpu().clone(),
                "restitution": p.restitution.cpu().clone(),
                "com_offset": p.com_offset.cpu().clone(),
                "joint_friction": p.joint_friction.cpu().clone(),
            },
            "backend": self.backend.state_dict(),
            **({"geometry_ids": self.geometry_ids.cpu().clone()} if self.geometry_pool is not None else {}),
            **(
                {
                    "actuation": {
                        "kp": self.kp.cpu().clone(),
                        "kd": self.kd.cpu().clone(),
                        "torque_limit": p.torque_limit[:, :3].cpu().clone(),
                        "mass_upper": float(self.mass_upper),
                    }
                }
                if self.actuation_rand
                else {}
            ),
            **(
                {
                    "body_tokens": {
                        "foot_touchdown_time": self.foot_touchdown_time.cpu().clone(),
                        "foot_contact_prev": self.foot_contact_prev.cpu().clone(),
                    }
                }
                if self.body_tokens
                else {}
            ),
        }

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` into an env built with the same config, mode and robot.

        Raises:
            MorficError: The state was saved from an env with another size or mode.
        """
        if state["num_envs"] != self.num_envs or state["mode"] != self.mode:
            raise MorficError(
                f"checkpoint env state is for {state['num_envs']} envs in mode '{state['mode']}', this env has "
                f"{self.num_envs} in mode '{self.mode}'; resume with the run's own env settings."
            )
        prm = state["params"]
        if self.geometry_pool is not None:
            self.geometry_ids.copy_(state["geometry_ids"])
            self.backend.set_geometry(self._all_ids, self.geometry_ids)
            self.kp.copy_(self._pool_kp[self.geometry_ids])
            self.kd.copy_(self._pool_kd[self.geometry_ids])
            self.geometry_vec.copy_(self._pool_geometry[self.geometry_ids])
        if self.mode != "full":
            self.backend.set_morphology(self._all_ids, prm["descriptor"])
        self.backend.set_dynamics(
            self._all_ids, prm["friction"], prm["restitution"], prm["com_offset"], prm["joint_friction"]
        )
        if "actuation" in state:
            a, dev = state["actuation"], self.device
            self._set_actuation(self._all_ids, Actuation(a["kp"].to(dev), a["kd"].to(dev), a["torque_limit"].to(dev)))
            self.mass_upper.fill_(float(a["mass_upper"]))
        self.params = self.backend.params()
        self.backend.load_state_dict(state["backend"])
        if self.body_tokens:
            self._describe(self._all_ids)
            self.foot_touchdown_time = state["body_tokens"]["foot_touchdown_time"].to(self.device).clone()
            self.foot_contact_prev = state["body_tokens"]["foot_contact_prev"].to(self.device).clone()
        for k in self._TENSORS:
            getattr(self, k).copy_(state["tensors"][k])
        dev = self.device
        self.episode_sums = {k: v.to(dev).clone() for k, v in state["episode_sums"].items()}
        self._obs = TensorDict(
            {k: v.to(dev).clone() for k, v in state["obs"].items()}, batch_size=[self.num_envs], device=dev
        )
        c = state["counters"]
        self.common_step_counter = c["common_step_counter"]
        self._nonfinite = torch.tensor(int(c["nonfinite_resets"]), dtype=torch.long, device=dev)
        self._tracking_sum = torch.tensor(float(c["tracking_sum"]), dtype=torch.float64, device=dev)
        self._tracking_count = c["tracking_count"]
        self.command_ranges.vx = torch.tensor(tuple(state["command_vx"]), dtype=torch.float64, device=dev)
        _restore_generator(self.gen, state["generator"])

    def close(self) -> None:
        """Release the backend."""
        self.backend.close()


def _term_means(terms: dict[str, torch.Tensor], scale: float = 1.0) -> dict[str, torch.Tensor]:
    """``scale`` x the mean over envs of each term (non-finite values as 0), as 0-d float64 tensors (no host read).

    The means are computed in float32 (as they always were) and widened to float64 before the scaling, so a value
    is the same number the Python float arithmetic gave. Shape: each value (num_envs,) -> ().
    """
    names = list(terms)
    if not names:
        return {}
    means = torch.nan_to_num(torch.stack([terms[k] for k in names])).mean(dim=1).double()
    if scale != 1.0:
        means = means * scale
    return dict(zip(names, means.unbind(), strict=True))


def _restore_generator(gen: torch.Generator, saved: torch.Tensor) -> None:
    """Restore a generator's state; a state saved on another kind of device reseeds it from that state instead.

    A checkpoint written on the CPU and resumed on a GPU (or the other way) cannot continue the same random stream:
    the generator is then seeded, deterministically, with a number drawn from the saved one.
    """
    try:
        gen.set_state(saved)
    except RuntimeError:
        other = torch.Generator()
        try:
            other.set_state(saved)
        except RuntimeError:
            other = torch.Generator(device="cuda")
            other.set_state(saved)
        gen.manual_seed(int(torch.randint(0, 2**62, (1,), generator=other, device=other.device)))
