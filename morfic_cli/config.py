"""Typed configuration dataclasses. Presets are factory functions; overrides fail on unknown keys.

Every config is a frozen dataclass with documented attributes (unit, default). The resolved config
is serialised as sorted-key JSON into run manifests (:func:`to_dict`).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from morfic_cli.envs.gait import GaitCfg
    from morfic_cli.envs.rewards import RewardCfg


def _default_threads() -> int:
    return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class SimCfg:
    """Physics backend settings (SPEC section 3)."""

    backend: str = "cpu"
    """"cpu" (MuJoCo C, one MjModel per env, all cores) or "warp" (MuJoCo Warp, per-world model fields, on
    ``device``; alias "gpu"). ``--device cuda`` selects "warp" on the GPU."""
    num_threads: int = field(default_factory=_default_threads)
    """Worker threads of the CPU backend (default: every core)."""
    physics_dt: float = 0.005
    """Physics time step (s)."""
    device: str = "cpu"
    """Torch device of the tensors the backend returns ("cpu", "cuda", "cuda:N"); the warp backend also
    simulates on it."""


def to_dict(cfg: object) -> dict:
    """A config as a plain, JSON-serialisable dict (nested dataclasses included)."""
    return dataclasses.asdict(cfg)  # type: ignore[arg-type]


@dataclass(frozen=True)
class CommandCfg:
    """Velocity commands c = (vx, vy, yaw rate) and their curriculum (SPEC section 3)."""

    resample_time_s: float = 10.0
    """Commands are resampled every this many seconds (and at reset)."""
    vx_init: tuple[float, float] = (-1.0, 1.0)
    """Initial forward-velocity range (m/s)."""
    vx_limit: tuple[float, float] = (-1.0, 3.0)
    """Widest forward-velocity range the curriculum reaches (m/s); 2.0 and 2.5 m/s evaluations lie inside."""
    vy: tuple[float, float] = (-0.6, 0.6)
    """Lateral-velocity range (m/s)."""
    yaw_rate: tuple[float, float] = (-1.0, 1.0)
    """Yaw-rate range (rad/s)."""
    curriculum_step: float = 0.5
    """How much each end of the vx range widens per curriculum update (m/s)."""
    curriculum_threshold: float = 0.8
    """Widen (checked once per max episode length) when the finished episodes' r_lin, summed and divided by the
    max episode length, reaches this fraction of its maximum (legged_gym's rule: a fall counts as poor tracking)."""
    zero_fraction: float = 0.1
    """Fraction of envs commanded to stand still, so standing is learned too."""
    small_command: float = 0.1
    """Planar commands below this norm (m/s) are set to zero."""
    fixed: tuple[float, float, float] | None = None
    """When set, every env is always commanded exactly this (vx, vy, yaw rate) (evaluation); ranges are ignored."""


@dataclass(frozen=True)
class DomainRandCfg:
    """Domain randomisation (SPEC section 3; paper appendix "Domain Randomization")."""

    enabled: bool = True
    """Master switch (evaluation turns it off)."""
    friction: tuple[float, float] = (0.5, 1.25)
    """Ground friction coefficient, uniform (paper)."""
    restitution: tuple[float, float] = (0.0, 0.4)
    """Contact restitution, uniform; mapped to the contact damping ratio by the backend."""
    com_offset: float = 0.03
    """Base centre-of-mass offset, uniform in [-x, x] per axis (m)."""
    joint_friction: tuple[float, float] = (0.0, 0.2)
    """Joint dry friction (N m), uniform per joint."""
    push_interval_s: float = 15.0
    """Seconds between pushes (paper: 15 s)."""
    push_vel: float = 1.0
    """Maximum planar push velocity per axis (m/s) (paper: 1.0)."""
    pushes: bool = True
    """Whether pushes happen at all (evaluation turns them off)."""
    max_latency_steps: int = 6
    """Action latency sampled per episode in 0..max policy steps (paper: up to 6)."""
    init_joint_scale: tuple[float, float] = (0.5, 1.5)
    """Reset joint positions are the default pose times this uniform factor (clamped into limits)."""
    random_reset_pose: bool = True
    """Apply ``init_joint_scale`` at reset even when ``enabled`` is off, so evaluation envs start apart (else
    the N envs of an evaluation would be identical copies and their spread meaningless)."""


@dataclass(frozen=True)
class ObsCfg:
    """Observation scales and noise (legged_gym conventions)."""

    lin_vel_scale: float = 2.0
    ang_vel_scale: float = 0.25
    joint_pos_scale: float = 1.0
    joint_vel_scale: float = 0.05
    command_scale: tuple[float, float, float] = (2.0, 2.0, 0.25)
    noise: bool = True
    """Add uniform sensor noise to the actor's observations (the critic's are clean)."""
    noise_lin_vel: float = 0.1
    noise_ang_vel: float = 0.2
    noise_gravity: float = 0.05
    noise_joint_pos: float = 0.01
    noise_joint_vel: float = 1.5
    history_len: int = 15
    """Length of the observation history h_t (paper: 15)."""
    clip: float = 100.0
    """Observations are clipped to [-clip, clip]."""


@dataclass(frozen=True)
class TerminationCfg:
    """When an episode ends early (SPEC section 3)."""

    contact_force: float = 1.0
    """Ground force (N) on the base or a thigh that ends the episode."""
    max_tilt_rad: float = 1.0
    """Tilt of the base (angle between its z axis and world up) that ends the episode."""
    min_height_fraction: float = 0.35
    """Episode ends when the base falls below this fraction of its nominal height."""


@dataclass(frozen=True)
class EnvCfg:
    """The locomotion environment (SPEC section 3)."""

    num_envs: int = 64
    decimation: int = 4
    """Physics steps per policy step (50 Hz policy at dt 0.005)."""
    episode_length_s: float = 20.0
    """Episode length (s): 1000 policy steps."""
    action_scale: float = 0.25
    """Joint target = q0 + action_scale * a."""
    action_clip: float = 100.0
    """Actions are clipped to [-clip, clip] before scaling."""
    sim: SimCfg = field(default_factory=SimCfg)
    commands: CommandCfg = field(default_factory=CommandCfg)
    rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    obs: ObsCfg = field(default_factory=ObsCfg)
    terminations: TerminationCfg = field(default_factory=TerminationCfg)
    rewards: RewardCfg = field(default_factory=lambda: _reward_cfg())
    gait: GaitCfg = field(default_factory=lambda: _gait_cfg())


def _reward_cfg() -> RewardCfg:
    from morfic_cli.envs.rewards import RewardCfg

    return RewardCfg()


def _gait_cfg() -> GaitCfg:
    from morfic_cli.envs.gait import GaitCfg

    return GaitCfg()


def eval_env_cfg(cfg: EnvCfg) -> EnvCfg:
    """The evaluation variant of an env config: no pushes, no randomisation, no sensor noise (SPEC 5).

    Evaluation simulates on the CPU backend whatever the run trained on (a run trained with
    ``--device cuda`` stores the warp backend on a GPU), so its numbers and rollout logs come from
    one simulator and the machine evaluating needs no GPU.
    """
    return dataclasses.replace(
        cfg,
        rand=dataclasses.replace(cfg.rand, enabled=False, pushes=False, max_latency_steps=0),
        obs=dataclasses.replace(cfg.obs, noise=False),
        sim=dataclasses.replace(cfg.sim, backend="cpu", device="cpu"),
    )
