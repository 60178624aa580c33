"""Zero-shot transfer metrics (docs/eval.md; paper tables "Zero-shot cross-morphology transfer" and v_x^max).

Pure functions on recorded arrays, T policy steps x N envs. ``alive[t, i]`` is True when env i has not
terminated at or before step t: the step on which an env terminates is not alive (its post-step state is
the fall), and nothing after it counts (the env was reset into a new episode).

- v_x (per env): mean forward base velocity over its alive steps; the table's v_x is the mean over envs.
- sigma (the paper's ± term, "standard deviations over rollout-level measurements"): the population std of the
  forward velocity over every alive (env, step) sample, pooled over envs. The std of the per-env means is kept
  apart (``vx_env_std``): in a deterministic evaluation it is nearly zero and is not the paper's sigma.
- v_x^max: the paper never defines it; its v_x^max cells at 2.0 m/s (Table "Effect of expanded morphology ranges")
  equal its v_x cells, so it is the forward speed v_x measured under the higher command (2.5 m/s), not a peak.
  morfic reports it as the v_x of the 2.5 m/s rows; no separate column.
- peak 1 s (per env, an extra of morfic's): the maximum of the 1 s moving average of forward velocity over its
  alive steps (window = min(1 s, alive steps)); always >= v_x.
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
    """The 1 s peak: max over each env's alive span of the ``window``-step moving average. (T, N) -> (N,).

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


def alive_step_stats(x: np.ndarray, alive: np.ndarray) -> tuple[float, float, int]:
    """Mean, population std and count of x over every alive (env, step) sample pooled over envs.

    Shapes: (T, N), (T, N) bool -> (mean, std, n); (nan, nan, 0) when no sample is alive.
    """
    v = x[alive & np.isfinite(x)].astype(np.float64)
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), float(v.std()), int(v.size)


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
    """v_x: mean over envs of each env's mean forward velocity over its alive steps (m/s)."""
    vx_std: float
    """sigma, the paper's ± term: population std of v_x over all alive (env, step) samples (m/s)."""
    vx_env_std: float
    """Population std over envs of the per-env means (m/s); not the paper's sigma."""
    vx_step_mean: float
    """Mean of v_x over all alive (env, step) samples (the centre of ``vx_std``; pools seeds exactly)."""
    n_alive: int
    """Alive (env, step) samples behind ``vx_std``."""
    vx_peak_1s_mean: float
    """Mean over envs of the best 1 s moving average of v_x (morfic's extra; not the paper's v_x^max)."""
    vx_peak_1s_std: float
    """Population std over envs of that peak."""
    survival: float
    tracking_ratio: float
    valid: bool
    valid_fraction: float
    """Fraction of all envs that survived with a valid gait."""
    verdict: str
    """"ok", or the most common failure: "falls", "stands still", "lies down", "drags feet"."""


FAILURES = ("falls", "stands still", "lies down", "drags feet")
"""Failure classes of an env, in the order they are checked (an env gets the first that applies)."""


def env_outcomes(
    vx: np.ndarray,
    terminated: np.ndarray,
    command_vx: float,
    *,
    tilt: np.ndarray,
    height_ratio: np.ndarray,
    foot_slip: np.ndarray,
    cfg: ValidityCfg = ValidityCfg(),  # noqa: B008 - frozen dataclass
) -> np.ndarray:
    """Each env's validity: ``"ok"`` (survived with a valid gait) or its failure, the first of :data:`FAILURES`.

    Args:
        vx: Forward base velocity (body x, m/s) after each step. Shape: (T, N).
        terminated: Env terminated on that step (falls; not time-outs). Shape: (T, N) bool.
        command_vx: The commanded forward velocity (m/s).
        tilt: Base tilt from upright (rad). Shape: (T, N).
        height_ratio: Base height / nominal height. Shape: (T, N).
        foot_slip: Mean horizontal speed of the feet in contact (m/s; 0 when none is). Shape: (T, N).
        cfg: Validity thresholds.

    Returns:
        Shape: (N,), str objects.
    """
    alive = alive_mask(terminated)
    survived = alive[-1]
    moving = per_env_mean(vx, alive) >= cfg.min_speed_ratio * command_vx
    upright_up = (tilt < cfg.max_tilt_rad) & (height_ratio > cfg.min_height_ratio)
    lying = per_env_mean(upright_up.astype(np.float64), alive) < cfg.min_valid_fraction
    dragging = per_env_mean(foot_slip, alive) > cfg.max_foot_slip
    out = np.full(survived.shape, "ok", dtype=object)
    out[survived & moving & ~lying & dragging] = "drags feet"
    out[survived & moving & lying] = "lies down"
    out[survived & ~moving] = "stands still"
    out[~survived] = "falls"
    return out


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
        dt: Policy step (s); the peak's moving-average window is round(1 / dt) steps.
        tilt: Base tilt from upright (rad). Shape: (T, N).
        height_ratio: Base height / nominal height. Shape: (T, N).
        foot_slip: Mean horizontal speed of the feet in contact (m/s; 0 when none is). Shape: (T, N).
        cfg: Validity thresholds.
    """
    alive = alive_mask(terminated)
    env_vx = per_env_mean(vx, alive)
    env_peak = per_env_max_moving_average(vx, alive, max(1, round(1.0 / dt)))
    survived = alive[-1]
    outcomes = env_outcomes(
        vx, terminated, command_vx, tilt=tilt, height_ratio=height_ratio, foot_slip=foot_slip, cfg=cfg
    )
    vx_mean, vx_env_std = mean_std(env_vx)
    step_mean, step_std, n_alive = alive_step_stats(vx, alive)
    peak_mean, peak_std = mean_std(env_peak)
    valid_fraction = float((outcomes == "ok").mean())
    failures = {k: int((outcomes == k).sum()) for k in FAILURES}
    verdict = "ok" if valid_fraction >= 0.5 else max(failures, key=lambda k: failures[k])
    return TransferMetrics(
        vx_mean=vx_mean,
        vx_std=step_std,
        vx_env_std=vx_env_std,
        vx_step_mean=step_mean,
        n_alive=n_alive,
        vx_peak_1s_mean=peak_mean,
        vx_peak_1s_std=peak_std,
        survival=float(survived.mean()),
        tracking_ratio=vx_mean / command_vx if command_vx else math.nan,
        valid=valid_fraction >= 0.5,
        valid_fraction=valid_fraction,
        verdict=verdict,
    )


def paper_cell(m: TransferMetrics) -> str:
    """The paper's cell format: "2.04 ± 0.37 / 0.984" (v_x ± sigma / S).

    At the higher command (2.5 m/s) this is also the paper's v_x^max cell (see the module docstring).
    """
    if not math.isfinite(m.vx_mean):
        return f"- / {m.survival:.3f}"
    return f"{m.vx_mean:.2f} ± {m.vx_std:.2f} / {m.survival:.3f}"
