"""Roll a trained policy out on one robot and command (docs/eval.md), recording every step.

Reuses the training env (:class:`~morfic_cli.envs.locomotion.LocomotionEnv`) in its evaluation
configuration (:func:`~morfic_cli.config.eval_env_cfg`: no randomisation, pushes, latency or sensor noise)
with the command fixed to (vx, 0, 0), and the trained models: the actor's mean action and the critic's
value per step. Nothing of the env or the models is re-implemented here.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch

from morfic_cli.config import EnvCfg, eval_env_cfg
from morfic_cli.evaluation.metrics import TransferMetrics, env_outcomes, transfer_metrics

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel

#: Arrays a rollout records per step for all envs, with their per-env shapes (K = reward terms).
RECORDED: dict[str, tuple[int, ...]] = {
    "base_pos": (3,),
    "base_quat": (4,),
    "base_lin_vel": (3,),
    "base_ang_vel": (3,),
    "command": (3,),
    "joint_pos": (12,),
    "joint_vel": (12,),
    "action": (12,),
    "reward": (),
    "value": (),
    "done": (),
    "time_out": (),
    "tilt": (),
    "height_ratio": (),
    "foot_slip": (),
}


@dataclass
class Rollout:
    """A recorded rollout of one robot and command.

    Attributes:
        robot: Target robot.
        mode: "descriptor", "full" or "actuation-matched" (docs/eval.md).
        command_vx: Commanded forward velocity (m/s).
        seed: Env seed.
        dt: Policy step (s).
        term_names: Names of the reward terms (columns of ``arrays["reward_terms"]``).
        descriptor: The 11-D descriptor in effect (raw units). Shape: (11,).
        arrays: :data:`RECORDED` plus ``reward_terms`` and ``terminations`` (each termination term's mask before
            the env reset), each (T, N, ...); float32, ``done``/``time_out``/``terminations`` bool.
    """

    robot: str
    mode: str
    command_vx: float
    seed: int
    dt: float
    term_names: list[str]
    descriptor: np.ndarray
    arrays: dict[str, np.ndarray]
    models: list = dataclasses.field(default_factory=list)
    """``mujoco.MjModel`` copies of the first envs (``keep_models``), for rendering."""
    qpos_adr: np.ndarray | None = None
    """qpos addresses of the 12 joints in those models (the free joint is qpos[0:7]). Shape: (12,)."""
    obs: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    """The observation groups the models saw at each step, before acting (``keep_obs``): group -> (T, N, ...)
    float32, e.g. ``critic`` (T, N, 16, 48). Row t is s_t, the input of ``action[t]`` and ``value[t]``."""
    termination_names: list[str] = dataclasses.field(default_factory=list)
    """Names of the termination terms (columns of ``arrays["terminations"]``), ``nonfinite`` last."""

    def qpos(self, num_envs: int) -> np.ndarray:
        """Full qpos of the first ``num_envs`` envs at each step. Shape: (T, num_envs, nq)."""
        a = self.arrays
        nq = self.models[0].nq
        out = np.zeros((a["done"].shape[0], num_envs, nq))
        out[..., 0:3] = a["base_pos"][:, :num_envs]
        out[..., 3:7] = a["base_quat"][:, :num_envs]
        out[..., self.qpos_adr] = a["joint_pos"][:, :num_envs]
        return out

    @property
    def terminated(self) -> np.ndarray:
        """Falls (done and not a time-out). Shape: (T, N) bool."""
        return self.arrays["done"] & ~self.arrays["time_out"]

    def metrics(self) -> TransferMetrics:
        """The zero-shot metrics of this rollout (:func:`~morfic_cli.evaluation.metrics.transfer_metrics`)."""
        a = self.arrays
        return transfer_metrics(
            a["base_lin_vel"][..., 0],
            self.terminated,
            self.command_vx,
            self.dt,
            tilt=a["tilt"],
            height_ratio=a["height_ratio"],
            foot_slip=a["foot_slip"],
        )

    def termination_counts(self) -> dict[str, int]:
        """Envs whose first episode each termination term ended; ``{}`` when not recorded.

        :func:`~morfic_cli.evaluation.terminations.termination_counts` of the recorded arrays.
        """
        from morfic_cli.evaluation.terminations import termination_counts

        a = self.arrays
        if "terminations" not in a:
            return {}
        return termination_counts(a["done"], a["time_out"], a["terminations"], self.termination_names)

    def outcomes(self) -> np.ndarray:
        """Each env's validity, ``"ok"`` or its failure (:func:`~morfic_cli.evaluation.metrics.env_outcomes`)."""
        a = self.arrays
        return env_outcomes(
            a["base_lin_vel"][..., 0],
            self.terminated,
            self.command_vx,
            tilt=a["tilt"],
            height_ratio=a["height_ratio"],
            foot_slip=a["foot_slip"],
        )


def step_record(
    env,
    action: torch.Tensor,
    value: torch.Tensor,
    reward: torch.Tensor,
    done: torch.Tensor,
    extras: dict,
    nominal: torch.Tensor,
    term_names: list[str],
) -> dict[str, torch.Tensor]:
    """What a rollout records of one ``env.step``: :data:`RECORDED`, ``reward_terms`` and ``terminations``.

    Each (N, ...); ``terminations`` (N, K) bool, the env's ``last_terminations`` in their order.

    Args:
        env: The :class:`~morfic_cli.envs.locomotion.LocomotionEnv` just stepped (its ``last_state``,
            ``last_reward_terms`` and ``last_terminations`` are read).
        action: The action given to the step. Shape: (N, 12).
        value: Critic value of the state the action was taken in. Shape: (N,).
        reward: The step's reward. Shape: (N,).
        done: The step's episode ends. Shape: (N,).
        extras: The step's extras (``time_outs``).
        nominal: Nominal base height per env (m), for ``height_ratio``. Shape: (N,).
        term_names: Reward-term columns of ``reward_terms``.
    """
    s = env.last_state
    terms = env.last_reward_terms
    contact = s.foot_contact.float()  # (N, 4)
    speed = torch.linalg.norm(s.foot_vel_w[..., :2], dim=-1)  # (N, 4)
    slip = (contact * speed).sum(1) / contact.sum(1).clamp(min=1.0)
    return {
        "base_pos": s.base_pos_w,
        "base_quat": s.base_quat_w,
        "base_lin_vel": s.base_lin_vel_b,
        "base_ang_vel": s.base_ang_vel_b,
        "command": s.command.clone(),
        "joint_pos": s.joint_pos,
        "joint_vel": s.joint_vel,
        "action": action,
        "reward": reward,
        "value": value,
        "done": done.bool(),
        "time_out": extras["time_outs"].bool(),
        "tilt": torch.arccos((-s.projected_gravity_b[:, 2]).clamp(-1.0, 1.0)),
        "height_ratio": s.base_pos_w[:, 2] / nominal,
        "foot_slip": slip,
        "reward_terms": torch.stack([terms[k] * env.dt for k in term_names], dim=1),
        "terminations": torch.stack(list(env.last_terminations.values()), dim=1),
    }


def rollout_env_cfg(train_env: EnvCfg, num_envs: int, steps: int, command_vx: float) -> EnvCfg:
    """The evaluation env config: the run's env, evaluation settings, fixed command, no time-out inside ``steps``."""
    cfg = eval_env_cfg(train_env)
    dt = cfg.sim.physics_dt * cfg.decimation
    return dataclasses.replace(
        cfg,
        num_envs=num_envs,
        episode_length_s=max(cfg.episode_length_s, (steps + 1) * dt),
        commands=dataclasses.replace(cfg.commands, fixed=(float(command_vx), 0.0, 0.0)),
    )


def run_rollout(
    actor: MLPModel,
    critic: MLPModel,
    train_env: EnvCfg,
    *,
    robot: str,
    mode: str,
    command_vx: float,
    num_envs: int,
    steps: int,
    seed: int = 0,
    on_step: Callable[[int], None] | None = None,
    keep_models: int = 0,
    keep_obs: tuple[str, ...] = (),
    sample_actions: bool = False,
) -> Rollout:
    """Run the actor's mean action (or a sampled one) for ``steps`` policy steps on ``num_envs`` envs of ``robot``.

    Args:
        actor: Trained actor (eval mode; ``actor(obs)`` is the mean action). Shape: (N, 12).
        critic: Trained critic (``critic(obs)`` is V). Shape: (N, 1).
        train_env: The run's env config (observation settings, gains, rewards).
        robot: Target robot name.
        mode: "descriptor" (Go2 template with the target's descriptor), "full" (the target's own model) or
            "actuation-matched" (descriptor mode with Kp, Kd and torque limits x the target's mass / Go2's).
        command_vx: Forward-velocity command (m/s); vy = yaw rate = 0.
        num_envs: Envs (N).
        steps: Policy steps (T).
        seed: Env seed.
        on_step: Called with the step index after each step (progress).
        keep_models: Keep copies of the first this many envs' MjModels (CPU backend) for rendering.
        keep_obs: Observation groups to record per step into ``Rollout.obs`` (e.g. ``("critic", "privileged",
            "morphology")``, the critic's exact inputs), so other models can be scored on the same samples.
        sample_actions: Act with a ~ N(mean, std) of the actor's Gaussian instead of its mean (a PPO behaviour
            policy, as the critic diagnostics need), drawn from a generator seeded with ``seed``.
    """
    return run_rollouts(
        actor,
        critic,
        train_env,
        robots=(robot,),
        mode=mode,
        command_vx=command_vx,
        num_envs=num_envs,
        steps=steps,
        seed=seed,
        on_step=on_step,
        keep_models=keep_models,
        keep_obs=keep_obs,
        sample_actions=sample_actions,
    )[robot]


def run_rollouts(
    actor: MLPModel,
    critic: MLPModel,
    train_env: EnvCfg,
    *,
    robots: Sequence[str],
    mode: str,
    command_vx: float,
    num_envs: int,
    steps: int,
    seed: int = 0,
    on_step: Callable[[int], None] | None = None,
    keep_models: int = 0,
    keep_obs: tuple[str, ...] = (),
    sample_actions: bool = False,
) -> dict[str, Rollout]:
    """:func:`run_rollout` of several robots at once: one env of ``len(robots) * num_envs`` envs, one batch per step.

    Robot k has envs ``k * num_envs .. (k + 1) * num_envs - 1`` of the joint env (descriptor mode only: every env
    is the Go2 template, with its robot's descriptor) and gets that slice of every recorded array as its own
    :class:`Rollout`. Each env evolves on its own, so a slice is a rollout of that robot with the same protocol; what
    differs from a rollout of the robot alone is the env's random draws (reset poses, gait phases, sampled actions
    come from one generator over the joint batch) and so the sampled start states, not their distribution. One
    robot is exactly :func:`run_rollout`. At 16 envs a policy step costs little more than its fixed Python and
    model-call overhead, so seven robots in one batch cost about 3x one robot instead of 7x
    (docs/benchmarks-history.md, "The shipped preset's quick protocol").

    Args:
        actor: Trained actor, as in :func:`run_rollout`.
        critic: Trained critic.
        train_env: The run's env config.
        robots: Target robots, distinct; more than one needs ``mode`` "descriptor" or "actuation-matched".
        mode: "descriptor", "full" or "actuation-matched".
        command_vx: Forward-velocity command (m/s).
        num_envs: Envs per robot (N); the joint env has ``len(robots) * N``.
        steps: Policy steps (T).
        seed: Env seed (and action-sampling seed).
        on_step: Called with the step index after each joint step.
        keep_models: Kept MjModels per robot (its slice's first envs).
        keep_obs: Observation groups to record per step.
        sample_actions: Act with sampled actions instead of the mean.

    Returns:
        Robot -> its rollout, in the order of ``robots``.

    Raises:
        ValueError: Repeated robots, or several robots outside descriptor mode.
    """
    from morfic_cli.envs.locomotion import LocomotionEnv

    robots = tuple(robots)
    if len(set(robots)) != len(robots) or (len(robots) > 1 and mode == "full"):
        raise ValueError(f"one batch needs distinct robots in descriptor mode, got {robots} in mode '{mode}'.")
    total = len(robots) * num_envs
    cfg = rollout_env_cfg(train_env, total, steps, command_vx)
    per_env = robots[0] if len(robots) == 1 else [r for r in robots for _ in range(num_envs)]
    env = LocomotionEnv(cfg, mode=mode, robot=per_env, seed=seed)
    try:
        term_names = None
        stop_names: list[str] = []
        rec: dict[str, np.ndarray] = {}  # key -> (T, N, ...), filled step by step
        obs_rec: dict[str, np.ndarray] = {}
        obs = env.get_observations()
        nominal = env.params.nominal_height.float()
        gen = torch.Generator().manual_seed(seed) if sample_actions else None
        with torch.no_grad():
            for t in range(steps):
                for group in keep_obs:
                    _record(obs_rec, group, t, steps, obs[group].detach().cpu().numpy())
                action = actor(obs)
                if gen is not None:  # a ~ N(mean, std), rsl-rl's Gaussian with our generator
                    actor.distribution.update(action)
                    noise = torch.randn(action.shape, generator=gen).to(action)
                    action = action + actor.output_std * noise
                value = critic(obs).reshape(-1)
                obs, reward, done, extras = env.step(action)
                if term_names is None:
                    term_names = list(env.last_reward_terms)
                    stop_names = list(env.last_terminations)
                step = step_record(env, action, value, reward, done, extras, nominal, term_names)
                for key, value_t in step.items():
                    arr = value_t.detach().cpu().numpy()
                    _record(rec, key, t, steps, arr)
                if on_step is not None:
                    on_step(t)
        descriptors = env.params.descriptor.double().cpu().numpy()
        dt = env.dt
        all_models = list(getattr(env.backend, "models", []))
        models = [
            [copy.copy(m) for m in all_models[k * num_envs : k * num_envs + min(keep_models, num_envs)]]
            for k in range(len(robots))
        ]
        info = getattr(env.backend, "info", None)
        qpos_adr = None if info is None else np.asarray(info.qpos_adr)
    finally:
        env.close()
    arrays, kept_obs = rec, obs_rec
    out = {}
    whole = len(robots) == 1  # else each robot's envs as views, no copies
    for k, robot in enumerate(robots):
        envs = slice(k * num_envs, (k + 1) * num_envs)
        out[robot] = Rollout(
            robot,
            mode,
            float(command_vx),
            seed,
            dt,
            term_names or [],
            descriptors[envs.start],
            {key: a if whole else a[:, envs] for key, a in arrays.items()},
            models[k],
            qpos_adr,
            {g: a if whole else a[:, envs] for g, a in kept_obs.items()},
            stop_names,
        )
    return out


def _record(buffers: dict[str, np.ndarray], key: str, t: int, steps: int, value: np.ndarray) -> None:
    """Write step ``t``'s ``value`` (N, ...) into ``buffers[key]`` (T, N, ...): bool stays bool, else float32."""
    if key not in buffers:
        buffers[key] = np.empty((steps, *value.shape), dtype=np.bool_ if value.dtype == np.bool_ else np.float32)
    buffers[key][t] = value
