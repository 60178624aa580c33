"""Does evaluation agree with training? A checkpoint under its own training conditions, then one change at a time.

``morfic eval RUN --training-conditions`` (docs/eval.md, "Training conditions"). The first row runs the checkpoint
exactly as its training rollouts did — the training env (morphology sampled from the support at every reset,
domain randomisation, pushes, latency 0..max, sensor noise, commands from the curriculum range the run had reached,
with no further widening), actions *sampled* from the actor's Gaussian and the actor in train mode (latent dropout
on, as rsl-rl's runner keeps it during rollouts) — and compares its mean episode length with the training curve's
(:func:`~morfic_cli.evaluation.episodes.agrees`). Each next row moves one condition to the evaluation protocol's;
the last row is the protocol itself (``morfic eval``'s conditions, with the run's episode length). Where the episode
length drops tells which difference between training and evaluation matters.

Every row: N envs from a fresh reset, the run's own episode length (T = max episode length steps, so every env's
first episode ends inside the rollout), seed ``seed`` for the env and the actions. The result is a ``table``
manifest (ref ``checks/training-conditions/<run>``, file ``training_check.csv``, input ``checkpoint``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from morfic_cli.config import EnvCfg
from morfic_cli.evaluation.episodes import (
    EpisodeStats,
    TrainingReference,
    agrees,
    curriculum_range,
    episode_stats,
    training_reference,
)
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.load import TrainedModels

CHECK_REF_PREFIX = "checks/training-conditions/"

#: Columns of ``training_check.csv``, in order.
CHECK_COLUMNS: tuple[str, ...] = (
    "conditions",
    "change",
    "length_s",
    "length_se_s",
    "train_length_s",
    "train_sd_s",
    "agrees",
    "time_out_fraction",
    "fall_fraction",
    "survival_5s",
    "n",
    "steps",
    "morphology",
    "randomisation",
    "latency",
    "actions",
    "dropout",
    "command",
)


@dataclass(frozen=True)
class Conditions:
    """The conditions of one row; every field True = as in training.

    Attributes:
        name: Row label.
        change: What differs from the training conditions.
        train_morphology: Morphology sampled from the training support at each reset (else ``robot``'s descriptor
            on the Go2 template, the protocol's descriptor mode).
        randomisation: Domain randomisation, pushes and sensor noise as trained (the env ties latency to it too).
        latency: Action latency sampled in 0..max_latency_steps as trained (else 0).
        sampled_actions: Actions sampled from the actor's Gaussian (else its mean).
        dropout: Actor in train mode: latent dropout on z_priv_hat as in training rollouts (else eval mode).
        curriculum_commands: Commands sampled from the curriculum range (else fixed (vx, 0, 0)).
    """

    name: str
    change: str
    train_morphology: bool = True
    randomisation: bool = True
    latency: bool = True
    sampled_actions: bool = True
    dropout: bool = True
    curriculum_commands: bool = True


def ladder(robot: str, command_vx: float) -> list[Conditions]:
    """Training conditions, then one change at a time toward the protocol, then the protocol itself."""
    return [
        Conditions("training", "none: as the training rollouts"),
        Conditions("no dropout", "actor in eval mode (latent dropout off)", dropout=False),
        Conditions("mean actions", "the actor's mean action, not a sample", sampled_actions=False),
        Conditions("no latency", "action latency 0", latency=False),
        Conditions(
            "no randomisation",
            "no friction/restitution/COM/joint-friction draws, pushes, noise (nor latency)",
            randomisation=False,
            latency=False,
        ),
        Conditions(f"{robot} template", f"every env {robot}'s descriptor on the Go2 template", train_morphology=False),
        Conditions(f"command {command_vx:g}", f"command fixed to ({command_vx:g}, 0, 0)", curriculum_commands=False),
        Conditions(
            "eval protocol",
            "all of the above (morfic eval's conditions)",
            train_morphology=False,
            randomisation=False,
            latency=False,
            sampled_actions=False,
            dropout=False,
            curriculum_commands=False,
        ),
    ]


@dataclass(frozen=True)
class CheckCfg:
    """A training-conditions check.

    Attributes:
        num_envs: Envs per row.
        seed: Env and action seed.
        robot: Target of the template rows.
        command_vx: Command of the fixed-command rows (m/s).
        window: Training-curve iterations the reference averages.
        full_ladder: All rows of :func:`ladder`; else the training row only.
    """

    num_envs: int = 64
    seed: int = 0
    robot: str = "go2"
    command_vx: float = 1.0
    window: int = 50
    full_ladder: bool = True


def check_env_cfg(
    train_env: EnvCfg, cond: Conditions, num_envs: int, vx_range: tuple[float, float], command_vx: float
) -> EnvCfg:
    """The env config of one row: the run's training env with the row's changes, on the CPU backend."""
    rand, obs, commands = train_env.rand, train_env.obs, train_env.commands
    if cond.curriculum_commands:  # start at the run's range and stay there (no widening during the check)
        commands = dataclasses.replace(commands, vx_init=vx_range, curriculum_step=0.0, fixed=None)
    else:
        commands = dataclasses.replace(commands, fixed=(float(command_vx), 0.0, 0.0))
    if not cond.randomisation:
        rand = dataclasses.replace(rand, enabled=False, pushes=False)
        obs = dataclasses.replace(obs, noise=False)
    if not cond.latency:
        rand = dataclasses.replace(rand, max_latency_steps=0)
    return dataclasses.replace(
        train_env,
        num_envs=num_envs,
        rand=rand,
        obs=obs,
        commands=commands,
        sim=dataclasses.replace(train_env.sim, backend="cpu", device="cpu"),
    )


def run_conditions(
    trained: TrainedModels,
    cond: Conditions,
    cfg: CheckCfg,
    vx_range: tuple[float, float],
    on_step: Callable[[int], None] | None = None,
) -> tuple[EpisodeStats, int]:
    """Roll the checkpoint out under ``cond`` for one episode length; its first-episode stats and the steps run."""
    from morfic_cli.envs.locomotion import LocomotionEnv

    env_cfg = check_env_cfg(trained.cfg.env, cond, cfg.num_envs, vx_range, cfg.command_vx)
    mode = "train" if cond.train_morphology else "descriptor"
    env = LocomotionEnv(env_cfg, mode=mode, robot=cfg.robot, seed=cfg.seed)
    actor = trained.actor
    was_training = actor.training
    try:
        steps = env.max_episode_length
        done_rec, timeout_rec = [], []
        obs = env.get_observations()
        actor.train(cond.dropout)
        with torch.random.fork_rng(), torch.inference_mode():
            torch.manual_seed(cfg.seed)
            for t in range(steps):
                action = actor(obs, stochastic_output=cond.sampled_actions)
                obs, _, done, extras = env.step(action)
                done_rec.append(done.bool().cpu().numpy())
                timeout_rec.append(extras["time_outs"].bool().cpu().numpy())
                if on_step is not None:
                    on_step(t)
        dt = env.dt
    finally:
        actor.train(was_training)
        env.close()
    return episode_stats(np.stack(done_rec), np.stack(timeout_rec), dt), steps


@dataclass
class CheckResult:
    """What :func:`training_check` measured and stored."""

    rows: list[dict[str, Any]]
    reference: TrainingReference
    vx_range: tuple[float, float]
    id: str
    ref: str
    version: int


def check_rows(cfg: CheckCfg) -> list[Conditions]:
    """The rows a check runs."""
    rows = ladder(cfg.robot, cfg.command_vx)
    return rows if cfg.full_ladder else rows[:1]


def training_check(
    store: Store,
    spec: str,
    cfg: CheckCfg,
    *,
    trained: TrainedModels | None = None,
    on_row_start: Callable[[str], None] | None = None,
    on_step: Callable[[int], None] | None = None,
) -> CheckResult:
    """Run the check on checkpoint ``spec`` and store it (see the module docstring).

    Raises:
        MorficError: ``spec`` is not a checkpoint, or its training curve logged no episode length.
    """
    from morfic_cli.errors import MorficError
    from morfic_cli.recording.curves import read_curve_csv
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.rl.load import load_trained

    if trained is None:
        trained = load_trained(store, spec)
    curve = read_curve_csv(store.read_file(trained.checkpoint_id, "curve.csv"))
    try:
        ref = training_reference(curve, cfg.window)
    except ValueError as exc:
        raise MorficError(f"checkpoint '{spec}': {exc}; train longer before comparing with training.") from exc
    commands = trained.cfg.env.commands
    vx_max = ref.vx_max if ref.vx_max is not None else float(trained.meta.get("vx_max", commands.vx_init[1]))
    vx_range = curriculum_range(vx_max, commands.vx_init, commands.vx_limit, commands.curriculum_step)
    rows: list[dict[str, Any]] = []
    for cond in check_rows(cfg):
        if on_row_start is not None:
            on_row_start(cond.name)
        stats, steps = run_conditions(trained, cond, cfg, vx_range, on_step)
        rows.append(
            {
                "conditions": cond.name,
                "change": cond.change,
                "length_s": stats.length_s,
                "length_se_s": stats.length_se_s,
                "train_length_s": ref.length_s,
                "train_sd_s": ref.sd_s,
                "agrees": agrees(stats.length_s, stats.length_se_s, ref.length_s, ref.sd_s),
                "time_out_fraction": stats.time_out_fraction,
                "fall_fraction": stats.fall_fraction,
                "survival_5s": stats.survival_5s,
                "n": stats.n,
                "steps": steps,
                "morphology": "train support" if cond.train_morphology else f"{cfg.robot} descriptor",
                "randomisation": cond.randomisation,
                "latency": cond.latency,
                "actions": "sampled" if cond.sampled_actions else "mean",
                "dropout": cond.dropout,
                "command": f"vx in [{vx_range[0]:g}, {vx_range[1]:g}]"
                if cond.curriculum_commands
                else f"({cfg.command_vx:g}, 0, 0)",
            }
        )
    run_name = trained.meta.get("run") or spec.split("@")[0].removeprefix("runs/")
    config = {"check": "training-conditions", "spec": spec, **dataclasses.asdict(cfg)}
    meta = {
        "run": run_name,
        "iteration": trained.meta.get("iteration"),
        "train_iterations": list(ref.iterations),
        "vx_range": list(vx_range),
    }
    with store.writing():
        mid = store.put_manifest(
            "table",
            config=config,
            inputs={"checkpoint": trained.checkpoint_id},
            files={"training_check.csv": rows_to_csv(rows, CHECK_COLUMNS)},
            meta=meta,
        )
        name = CHECK_REF_PREFIX + run_name
        version = store.set_ref(name, mid)
    return CheckResult(rows, ref, vx_range, mid, name, version)


def steps_per_row(trained: TrainedModels) -> int:
    """Policy steps of one row: the run's max episode length (the env's ``max_episode_length``)."""
    env = trained.cfg.env
    return int(math.ceil(env.episode_length_s / (env.sim.physics_dt * env.decimation)))
