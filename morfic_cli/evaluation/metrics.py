"""Zero-shot transfer metrics (docs/eval.md; paper tables "Zero-shot cross-morphology transfer" and v_x^max).

Pure functions on recorded arrays, T policy steps x N envs. ``alive[t, i]`` is True when env i has not
terminated at or before step t: the step on which an env terminates is not alive (its post-step state is
the fall), and nothing after it counts (the env was reset into a new episode).

- v_x (per env): mean forward base velocity over its alive steps.
- v_x^max (per env): the maximum of the 1 s moving average of forward velocity over its alive steps
  (window = min(1 s, alive steps)).
- S: fraction of envs alive at the last step.
- tracking ratio: mean v_x / vx_cmd.
- validity (per surviving env): it moves (v_x >= ``min_speed_ratio`` vx_cmd), stays upright and up
  (base tilt below ``max_tilt_rad`` and height above ``min_height_ratio`` of nominal on at least
  ``min_valid_fraction`` of its steps) and does not drag its feet (feet in contact slide slower than
  ``max_foot_slip`` m/s on average). A survivor that stands still, lies down or drags is a failure
  to transfer (paper appendix "Validity of survival-based metrics").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ValidityCfg:
    """Thresholds of the validity verdict."""

    min_speed_ratio: float = 0.25
    """A survivor slower than this fraction of the command 'stands still'."""
    max_tilt_rad: float = 0.6
    """Base tilt (rad) above which a step is not upright."""
    min_height_ratio: float = 0.5
    """Base height below this fraction of the nominal height counts as lying down."""
    min_valid_fraction: float = 0.9
    """Fraction of alive steps that must be upright and up."""
    max_foot_slip: float = 0.3
    """Mean horizontal speed (m/s) of feet in contact above which the robot 'drags' its feet."""


def alive_mask(terminated: np.ndarray) -> np.ndarray:
    """alive[t, i] = env i has not terminated at or before step t. Shapes: (T, N) bool -> (T, N) bool."""
    return np.cumsum(terminated.astype(np.int64), axis=0) == 0


def per_env_mean(x: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Mean of x over each env's alive steps; NaN for an env with none. Shapes: (T, N), (T, N) -> (N,)."""
    n = alive.sum(axis=0)
    total = np.where(alive, x, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def per_env_max_moving_average(vx: np.ndarray, alive: np.ndarray, window: int) -> np.ndarray:
    """v_x^max: max over each env's alive span of the ``window``-step moving average. (T, N) -> (N,).

    Alive steps form a prefix of the rollout (see :func:`alive_mask`); with fewer than ``window`` alive
    steps the window is the whole alive span. NaN for an env with no alive step.
    """
    t_len, n_env = vx.shape
    out = np.full(n_env, np.nan)
    lengths = alive.sum(axis=0)
    for i in range(n_env):
        k = int(lengths[i])
        if k == 0:
            continue
        w = min(window, k)
        c = np.concatenate([[0.0], np.cumsum(vx[:k, i], dtype=np.float64)])
        out[i] = float(np.max((c[w:] - c[:-w]) / w))
    return out


def mean_std(values: np.ndarray) -> tuple[float, float]:
    """Mean and population std over the finite entries; (nan, nan) when there are none."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std())


@dataclass(frozen=True)
class TransferMetrics:
    """One robot x command row of the zero-shot table."""

    vx_mean: float
    vx_std: float
    vx_max_mean: float
    vx_max_std: float
    survival: float
    tracking_ratio: float
    valid: bool
    valid_fraction: float
    """Fraction of all envs that survived with a valid gait."""
    verdict: str
    """"ok", or the most common failure: "falls", "stands still", "lies down", "drags feet"."""


def transfer_metrics(
    vx: np.ndarray,
    terminated: np.ndarray,
    command_vx: float,
    dt: float,
    *,
    tilt: np.ndarray,
    height_ratio: np.ndarray,
    foot_slip: np.ndarray,
    cfg: ValidityCfg = ValidityCfg(),  # noqa: B008 - frozen dataclass
) -> TransferMetrics:
    """The zero-shot metrics of one rollout.

    Args:
        vx: Forward base velocity (body x, m/s) after each step. Shape: (T, N).
        terminated: Env terminated on that step (falls; not time-outs). Shape: (T, N) bool.
        command_vx: The commanded forward velocity (m/s).
        dt: Policy step (s); the v_x^max window is round(1 / dt) steps.
        tilt: Base tilt from upright (rad). Shape: (T, N).
        height_ratio: Base height / nominal height. Shape: (T, N).
        foot_slip: Mean horizontal speed of the feet in contact (m/s; 0 when none is). Shape: (T, N).
        cfg: Validity thresholds.
    """
    alive = alive_mask(terminated)
    env_vx = per_env_mean(vx, alive)
    env_vx_max = per_env_max_moving_average(vx, alive, max(1, round(1.0 / dt)))
    survived = alive[-1]
    upright_up = (tilt < cfg.max_tilt_rad) & (height_ratio > cfg.min_height_ratio)
    up_fraction = per_env_mean(upright_up.astype(np.float64), alive)
    slip = per_env_mean(foot_slip, alive)
    moving = env_vx >= cfg.min_speed_ratio * command_vx
    lying = up_fraction < cfg.min_valid_fraction
    dragging = slip > cfg.max_foot_slip
    valid_env = survived & moving & ~lying & ~dragging
    vx_mean, vx_std = mean_std(env_vx)
    vmax_mean, vmax_std = mean_std(env_vx_max)
    valid_fraction = float(valid_env.mean())
    failures = {
        "falls": int((~survived).sum()),
        "stands still": int((survived & ~moving).sum()),
        "lies down": int((survived & moving & lying).sum()),
        "drags feet": int((survived & moving & ~lying & dragging).sum()),
    }
    verdict = "ok" if valid_fraction >= 0.5 else max(failures, key=lambda k: failures[k])
    return TransferMetrics(
        vx_mean=vx_mean, vx_std=vx_std, vx_max_mean=vmax_mean, vx_max_std=vmax_std,
        survival=float(survived.mean()),
        tracking_ratio=vx_mean / command_vx if command_vx else math.nan,
        valid=valid_fraction >= 0.5, valid_fraction=valid_fraction, verdict=verdict,
    )


def paper_cell(m: TransferMetrics, *, use_max: bool = False) -> str:
    """The paper's cell format: "2.04 ± 0.37 / 0.984" (v_x or v_x^max ± std / S)."""
    mean, std = (m.vx_max_mean, m.vx_max_std) if use_max else (m.vx_mean, m.vx_std)
    if not math.isfinite(mean):
        return f"- / {m.survival:.3f}"
    return f"{mean:.2f} ± {std:.2f} / {m.survival:.3f}"
