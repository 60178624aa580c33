"""Live training curves for TensorBoard / Weights & Biases, as rsl-rl users expect (docs/training.md).

The store keeps each run's curve (``curve.csv`` in every checkpoint); this module adds what rsl-rl's own
``Logger`` writes while training, so ``tensorboard --logdir logs`` shows the run as it trains. Tags are
rsl-rl's (5.5.1 ``rsl_rl/utils/logger.py``): ``Loss/<key>`` for every loss-dict entry and
``Loss/learning_rate``, ``Policy/mean_std``, ``Perf/total_fps``, ``Perf/collection_time``,
``Perf/learning_time``, ``Train/mean_reward``, ``Train/mean_episode_length`` (steps), and the env's episode
extras under their own key when it holds a ``/`` (leading ``/`` dropped: ``curriculum/vx_max``; ``Episode/<key>``
otherwise); the step is rsl-rl's 0-based
iteration. The writer is rsl-rl's choice too: torch's ``SummaryWriter`` for ``tensorboard``, rsl-rl's
``WandbLogWriter`` for ``wandb`` (the optional ``morfic[wandb]`` extra).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

from morfic_cli.errors import MorficError

LOGGERS: tuple[str, ...] = ("tensorboard", "wandb", "none")
"""``morfic train --logger`` values."""

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
        raise MorficError("--logger wandb needs the wandb package; `pip install 'morfic[wandb]'` (and `wandb login`), "
                          "or use --logger tensorboard.")


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


def write_iteration(writer: Any, it: int, size: int, collect_time: float, learn_time: float,
                    loss_dict: dict[str, float], learning_rate: float, action_std: float,
                    extras: dict[str, float], mean_reward: float | None, mean_length: float | None) -> None:
    """Write one iteration's scalars with rsl-rl's tags at step ``it`` (0-based).

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
        mean_reward: Mean episode return of the last 100 episodes, or None before the first one ended.
        mean_length: Their mean length in steps, or None.
    """
    for key, value in extras.items():
        name = key.strip("/")  # morfic's env keys start with "/" ("/curriculum/vx_max"): no empty top group
        writer.add_scalar(name if "/" in name else f"Episode/{name}", value, it)
    for key, value in loss_dict.items():
        writer.add_scalar(f"Loss/{key}", value, it)
    writer.add_scalar("Loss/learning_rate", learning_rate, it)
    writer.add_scalar("Policy/mean_std", action_std, it)
    writer.add_scalar("Perf/total_fps", int(size / max(collect_time + learn_time, 1e-9)), it)
    writer.add_scalar("Perf/collection_time", collect_time, it)
    writer.add_scalar("Perf/learning_time", learn_time, it)
    if mean_reward is not None:
        writer.add_scalar("Train/mean_reward", mean_reward, it)
        writer.add_scalar("Train/mean_episode_length", mean_length, it)
