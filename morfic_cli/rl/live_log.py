"""Live training curves for TensorBoard / Weights & Biases, as rsl-rl and Isaac Lab / mjlab users expect.

The store keeps each run's curve (``curve.csv`` in every checkpoint); this module adds what rsl-rl's own
``Logger`` writes while training, so ``tensorboard --logdir logs`` shows the run as it trains. The step is rsl-rl's
0-based iteration; the tags (docs/training.md, "Live curves"):

- rsl-rl's: ``Loss/<key>`` for the losses (``value``, ``surrogate``, ``entropy``, ``adaptation_error``; the
  curve's ``value_loss``, a copy of ``value``, is not written twice) and ``Loss/learning_rate``,
  ``Policy/mean_std``, ``Perf/total_fps``, ``Perf/collection_time``, ``Perf/learning_time``, ``Train/mean_reward``,
  ``Train/mean_episode_length`` (steps), and the same two against wall time, ``Train/mean_reward/time`` and
  ``Train/mean_episode_length/time`` (step = whole seconds of the run's wall clock, not on wandb: as rsl-rl). Before
  the first episode ends, the ``Train/`` tags are the mean return and length so far of the episodes under way, so the
  reward curve starts at the first iteration.
- the PPO update's health in a group of its own: ``PPO/explained_variance``, ``PPO/kl``, ``PPO/clip_fraction``.
- the env's episode extras, Isaac Lab / mjlab style (:data:`EXTRA_GROUPS`): ``Episode_Reward/<term>`` (each term's
  episode sum per second of episode), ``Episode_Termination/<term>`` (the fraction of ended episodes ended by it),
  ``Curriculum/vx_max``, ``Curriculum/lin_tracking`` (at the iterations in which the curriculum was decided, once
  per max episode length), ``Metrics/vx_error``, ``Episode/length_s``, and the per-step term means
  ``Step_Reward/<term>`` (weighted) and ``Step_Reward_Raw/<term>``.

The writer is rsl-rl's choice: torch's ``SummaryWriter`` for ``tensorboard``, rsl-rl's ``WandbLogWriter`` for
``wandb`` (the optional ``morfic[wandb]`` extra).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

from morfic_cli.errors import MorficError

LOGGERS: tuple[str, ...] = ("tensorboard", "wandb", "none")
"""``morfic train --logger`` values."""

PPO_KEYS: tuple[str, ...] = ("explained_variance", "kl", "clip_fraction")
"""Loss-dict entries that are statistics of the update, not losses: tagged ``PPO/<key>``."""

SKIPPED_LOSS_KEYS: tuple[str, ...] = ("value_loss",)
"""Loss-dict entries not written: ``value_loss`` is the curve's copy of rsl-rl's ``value`` (``Loss/value``)."""

EXTRA_GROUPS: dict[str, str] = {
    "episode_reward": "Episode_Reward",
    "termination": "Episode_Termination",
    "curriculum": "Curriculum",
    "tracking": "Metrics",
    "episode": "Episode",
    "reward": "Step_Reward",
    "reward_raw": "Step_Reward_Raw",
    "env": "Env",
}
"""The env's extras group (``/episode_reward/<term>``) -> its tag group (``Episode_Reward/<term>``)."""

DEFAULT_LOG_ROOT = Path("logs")
"""Where run folders go by default: ``logs/<run name>`` (a resumed run continues the same folder)."""


def run_log_dir(root: Path, run: str) -> Path:
    """The run folder of run ``run`` under ``root``: ``root/<run>``."""
    return Path(root) / run


def check_logger(kind: str) -> None:
    """Raise MorficError when ``kind`` is unknown or its package is missing (before any work)."""
    if kind not in LOGGERS:
        raise MorficError(f"unknown logger '{kind}'; valid loggers are: {', '.join(LOGGERS)}.")
    if kind == "wandb" and importlib.util.find_spec("wandb") is None:
        raise MorficError(
            "--logger wandb needs the wandb package; `pip install 'morfic[wandb]'` (and `wandb login`), "
            "or use --logger tensorboard."
        )


def open_writer(kind: str, log_dir: Path, cfg: dict[str, Any], project: str = "morfic") -> Any:
    """The writer rsl-rl would open for ``kind`` in ``log_dir`` (created), or None for ``none``.

    Args:
        kind: One of :data:`LOGGERS`.
        log_dir: The run folder.
        cfg: The rsl-rl runner config (wandb stores it with the run).
        project: The wandb project.
    """
    check_logger(kind)
    if kind == "none":
        return None
    log_dir.mkdir(parents=True, exist_ok=True)
    if kind == "tensorboard":
        from torch.utils.tensorboard import SummaryWriter

        return SummaryWriter(log_dir=str(log_dir), flush_secs=10)
    from rsl_rl.utils.wandb_log_writer import WandbLogWriter

    writer = WandbLogWriter(log_dir=str(log_dir), project_name=project)
    writer.store_config({}, cfg)
    return writer


def extra_tag(key: str) -> str:
    """The tag of an env extra: ``/episode_reward/track_lin_vel`` -> ``Episode_Reward/track_lin_vel``.

    The first part is renamed by :data:`EXTRA_GROUPS` (an unknown one is kept); a key without a group goes under
    ``Episode/``.
    """
    name = key.strip("/")  # morfic's env keys start with "/" ("/curriculum/vx_max"): no empty top group
    if "/" not in name:
        return f"Episode/{name}"
    group, rest = name.split("/", 1)
    return f"{EXTRA_GROUPS.get(group, group)}/{rest}"


def loss_tag(key: str) -> str | None:
    """The tag of a loss-dict entry: ``Loss/<key>``, ``PPO/<key>`` (:data:`PPO_KEYS`), or None (not written)."""
    if key in SKIPPED_LOSS_KEYS:
        return None
    return f"PPO/{key}" if key in PPO_KEYS else f"Loss/{key}"


def write_iteration(
    writer: Any,
    it: int,
    size: int,
    collect_time: float,
    learn_time: float,
    loss_dict: dict[str, float],
    learning_rate: float,
    action_std: float,
    extras: dict[str, float],
    mean_reward: float | None,
    mean_length: float | None,
    wall_time_s: float | None = None,
) -> None:
    """Write one iteration's scalars at step ``it`` (0-based) under the tags of the module docstring.

    Args:
        writer: From :func:`open_writer` (``add_scalar(tag, value, step)``).
        it: rsl-rl's iteration index.
        size: Transitions collected this iteration (steps x envs).
        collect_time: Seconds collecting.
        learn_time: Seconds learning.
        loss_dict: The algorithm's loss dict.
        learning_rate: The current learning rate.
        action_std: Mean action standard deviation.
        extras: Episode extras averaged over the iteration, by their env key.
        mean_reward: Mean return of the last 100 finished episodes, or, before the first one ended, of the
            episodes under way so far; None: not written.
        mean_length: Their mean length in steps, likewise.
        wall_time_s: The run's wall seconds so far (the training clock, checkpoints included): the step of the
            ``/time`` tags, whole seconds as rsl-rl's; None: those tags are not written (rsl-rl skips them on wandb).
    """
    for key, value in extras.items():
        writer.add_scalar(extra_tag(key), value, it)
    for key, value in loss_dict.items():
        tag = loss_tag(key)
        if tag is not None:
            writer.add_scalar(tag, value, it)
    writer.add_scalar("Loss/learning_rate", learning_rate, it)
    writer.add_scalar("Policy/mean_std", action_std, it)
    writer.add_scalar("Perf/total_fps", int(size / max(collect_time + learn_time, 1e-9)), it)
    writer.add_scalar("Perf/collection_time", collect_time, it)
    writer.add_scalar("Perf/learning_time", learn_time, it)
    if mean_reward is not None:
        writer.add_scalar("Train/mean_reward", mean_reward, it)
        if wall_time_s is not None:
            writer.add_scalar("Train/mean_reward/time", mean_reward, int(wall_time_s))
    if mean_length is not None:
        writer.add_scalar("Train/mean_episode_length", mean_length, it)
        if wall_time_s is not None:
            writer.add_scalar("Train/mean_episode_length/time", mean_length, int(wall_time_s))
