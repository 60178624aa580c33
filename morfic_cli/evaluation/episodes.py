"""Episode-length statistics of a rollout and of a training curve, and whether the two agree (pure functions).

Used by :mod:`morfic_cli.evaluation.training_check`. A rollout here starts every env from a fresh reset at step 0 and
runs the run's own episode length, so each env's *first* episode ends inside it (by a fall or by the time-out).

Why first episodes compare with training: rsl-rl's runner logs the mean length of the last 100 *completed*
episodes (curve column ``episode_length_s``). In a steady state, the episodes that complete in any window are a
sample of the episode-length distribution itself (each episode is counted once, when it ends; it is the episode
*covering* a fixed time that is length-biased), so their mean estimates E[L], which is what the mean first-episode
length of envs started fresh estimates too.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


def first_episode_lengths(done: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Length (steps) of each env's first episode, and whether it ended inside the rollout.

    Args:
        done: Episode ended at this step. Shape: (T, N) bool.

    Returns:
        ``(length, ended)``: length[i] = 1 + the first t with done[t, i] (T when it never ended), int64; ended[i]
        bool. Shapes: (N,), (N,).
    """
    done = np.asarray(done, dtype=bool)
    ended = np.asarray(done.any(axis=0))
    first = np.where(ended, done.argmax(axis=0) + 1, done.shape[0])
    return first.astype(np.int64), ended


@dataclass(frozen=True)
class EpisodeStats:
    """First-episode statistics of a rollout.

    Attributes:
        length_s: Mean first-episode length (s).
        length_se_s: Its standard error, population std / sqrt(n) (s).
        n: Envs.
        time_out_fraction: Envs whose first episode ended by the time-out (survived the whole episode).
        fall_fraction: Envs whose first episode ended by a fall (termination).
        survival_5s: Envs whose first episode did not end in a fall within its first 5 s (S as ``morfic eval
            --steps 250`` counts it; an episode shorter than 5 s that timed out counts as survived).
    """

    length_s: float
    length_se_s: float
    n: int
    time_out_fraction: float
    fall_fraction: float
    survival_5s: float


def episode_stats(done: np.ndarray, time_out: np.ndarray, dt: float) -> EpisodeStats:
    """:class:`EpisodeStats` of a rollout (every env from a fresh reset at step 0).

    Args:
        done: Shape: (T, N) bool.
        time_out: The end was a time-out. Shape: (T, N) bool.
        dt: Policy step (s).
    """
    length, ended = first_episode_lengths(done)
    idx = np.arange(done.shape[1])
    by_time_out = ended & np.asarray(time_out, dtype=bool)[np.maximum(length - 1, 0), idx]
    seconds = length * dt
    n = int(seconds.size)
    se = float(seconds.std() / math.sqrt(n)) if n else math.nan
    return EpisodeStats(
        length_s=float(seconds.mean()) if n else math.nan,
        length_se_s=se,
        n=n,
        time_out_fraction=float(by_time_out.mean()) if n else math.nan,
        fall_fraction=float((ended & ~by_time_out).mean()) if n else math.nan,
        survival_5s=float((~(ended & ~by_time_out & (length <= round(5.0 / dt)))).mean()) if n else math.nan,
    )


@dataclass(frozen=True)
class TrainingReference:
    """The training episode length of a run over its last iterations (curve column ``episode_length_s``).

    Attributes:
        length_s: Mean over the window's iterations of the logged mean episode length (s).
        sd_s: Std over those iterations (sample std; 0 with one): the noise of one logged 100-episode mean.
        iterations: (first, last) iteration of the window.
        vx_max: Upper end of the vx command range most of the window trained with (curve ``curriculum.vx_max``),
            None when the curve does not log it.
    """

    length_s: float
    sd_s: float
    iterations: tuple[int, int]
    vx_max: float | None


def training_reference(rows: Sequence[dict[str, Any]], window: int = 50) -> TrainingReference:
    """:class:`TrainingReference` of the last ``window`` curve rows that logged an episode length.

    Raises:
        ValueError: No row logged an episode length (no episode ended during training).
    """
    usable = [r for r in rows if _finite(r.get("episode_length_s"))]
    if not usable:
        raise ValueError("the training curve has no episode length (no episode ended during training)")
    tail = usable[-max(1, window) :]
    lengths = [float(r["episode_length_s"]) for r in tail]
    reach = [float(r["curriculum.vx_max"]) for r in tail if _finite(r.get("curriculum.vx_max"))]
    vx_max = statistics.mode(reach) if reach else None  # the range that held over most of the window
    sd = statistics.stdev(lengths) if len(lengths) > 1 else 0.0
    return TrainingReference(
        statistics.fmean(lengths), sd, (int(tail[0]["iteration"]), int(tail[-1]["iteration"])), vx_max
    )


def curriculum_range(
    vx_max: float, vx_init: tuple[float, float], vx_limit: tuple[float, float], step: float
) -> tuple[float, float]:
    """The vx command range of a curriculum whose upper end has reached ``vx_max``.

    The curriculum widens both ends by ``step`` per update, each clamped to ``vx_limit``
    (:func:`~morfic_cli.envs.commands.widen_vx`); k = round((vx_max - vx_init[1]) / step) updates have happened.
    E.g. init (-1, 1), limit (-1, 3), step 0.5, vx_max 2.5 -> (-1.0, 2.5).
    """
    if step <= 0:
        return float(vx_init[0]), float(vx_max)
    k = max(0, round((vx_max - vx_init[1]) / step))
    return max(float(vx_limit[0]), vx_init[0] - k * step), float(vx_max)


def agrees(check_s: float, check_se_s: float, train_s: float, train_sd_s: float, z: float = 2.0) -> bool:
    """Whether a check's mean episode length matches training's within noise.

    ``|check - train| <= z * sqrt(se_check² + sd_train²)``: the two standard errors combined (training's is the
    spread of its logged 100-episode means), z = 2 (about 95 % for normal errors).
    """
    return abs(check_s - train_s) <= z * math.sqrt(check_se_s**2 + train_sd_s**2)


def _finite(value: Any) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False
