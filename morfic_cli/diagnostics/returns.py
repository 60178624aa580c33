"""Discounted Monte-Carlo returns of a recorded rollout and the truncation-safe sample set I_eps (docs/metrics.md).

Arrays are (T, N): T policy steps of N envs. Step t of env i took action a_{t,i} in s_{t,i}, received r_{t,i} and
ended its episode when ``done[t, i]`` (the env was reset, row t+1 starts a new episode). An episode ends

- by *termination* (a fall: ``done`` and not ``time_out``): nothing follows, the return is complete;
- by *truncation*: a time-out (``done`` and ``time_out``) or the end of the recording (row T-1 without ``done``).
  The rewards after the cut are unknown, so the recorded return misses a tail.

The return of (t, i) is summed up to the end e of its episode, eq. (mc_return) in docs/metrics.md::

    G_hat[t, i] = sum_{k=t}^{e} gamma^(k-t) r[k, i]

If that episode was truncated after H = e - t + 1 rewards, the true return differs from G_hat by the missing tail
gamma^H * G(s_{e+1}): at most a fraction gamma^H of the largest possible |G| (max|r| / (1 - gamma)). I_eps keeps the
samples where that fraction is at most eps, i.e. every sample of a terminated episode and the samples of a truncated
one with H >= H_eps = ceil(ln eps / ln gamma) (299 steps for gamma = 0.99, eps = 0.05).
"""

from __future__ import annotations

import math

import torch


def discounted_returns(reward: torch.Tensor, done: torch.Tensor, gamma: float) -> torch.Tensor:
    """G_hat: the discounted return of each sample up to the end of its episode (or of the recording).

    ``G[t] = r[t] + gamma * (1 - done[t]) * G[t+1]``, ``G[T] = 0``, computed backwards in float64.

    Args:
        reward: r. Shape: (T, N).
        done: Episode ended at this step (termination or time-out). Shape: (T, N) bool.
        gamma: Discount factor.

    Returns:
        G_hat, float64. Shape: (T, N).
    """
    r = reward.double()
    cont = 1.0 - done.double()
    out = torch.zeros_like(r)
    acc = torch.zeros_like(r[0])
    for t in range(r.shape[0] - 1, -1, -1):
        acc = r[t] + gamma * cont[t] * acc
        out[t] = acc
    return out


def remaining_horizon(done: torch.Tensor, time_out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rewards left in each sample's episode within the recording, and whether that episode was truncated.

    Args:
        done: Episode ended at this step. Shape: (T, N) bool.
        time_out: The end was a time-out (truncation), not a fall. Shape: (T, N) bool.

    Returns:
        ``(H, truncated)``: H[t, i] = e - t + 1 >= 1 with e the last step of the episode (int64); truncated[t, i]
        when that episode ended by a time-out or by the end of the recording (bool). Shapes: (T, N), (T, N).
    """
    num_steps = done.shape[0]
    horizon = torch.zeros(done.shape, dtype=torch.int64)
    truncated = torch.zeros(done.shape, dtype=torch.bool)
    h = torch.zeros(done.shape[1:], dtype=torch.int64)
    trunc = torch.ones(done.shape[1:], dtype=torch.bool)  # past the last row: the recording's end truncates
    for t in range(num_steps - 1, -1, -1):
        ends = done[t].bool()
        h = torch.where(ends, torch.ones_like(h), h + 1)
        trunc = torch.where(ends, time_out[t].bool(), trunc)
        horizon[t], truncated[t] = h, trunc
    return horizon, truncated


def min_horizon(gamma: float, eps: float) -> int:
    """H_eps: the fewest remaining rewards for which a truncation moves G by at most eps (relative).

    The smallest integer H with ``gamma^H <= eps``, i.e. ``ceil(ln eps / ln gamma)``; 299 for (0.99, 0.05).

    Raises:
        ValueError: gamma not in (0, 1) or eps not in (0, 1).
    """
    if not 0.0 < gamma < 1.0 or not 0.0 < eps < 1.0:
        raise ValueError(f"need 0 < gamma < 1 and 0 < eps < 1, got gamma={gamma}, eps={eps}")
    h = math.ceil(math.log(eps) / math.log(gamma))
    return h if gamma**h <= eps else h + 1  # guard against rounding in the logs


def valid_samples(horizon: torch.Tensor, truncated: torch.Tensor, gamma: float, eps: float) -> torch.Tensor:
    """The mask of I_eps: samples whose return is complete or misses at most a fraction eps of a tail.

    ``I_eps = {(t, i): not truncated[t, i] or H[t, i] >= H_eps}`` with H_eps = :func:`min_horizon`.

    Args:
        horizon: H from :func:`remaining_horizon`. Shape: (T, N).
        truncated: From :func:`remaining_horizon`. Shape: (T, N) bool.
        gamma: Discount factor.
        eps: Relative truncation tolerance.

    Returns:
        Shape: (T, N) bool.
    """
    return ~truncated | (horizon >= min_horizon(gamma, eps))


def mc_returns(
    reward: torch.Tensor, done: torch.Tensor, time_out: torch.Tensor, gamma: float, eps: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """G_hat and the mask of I_eps of a recording (:func:`discounted_returns`, :func:`valid_samples`).

    Args:
        reward: r. Shape: (T, N).
        done: Shape: (T, N) bool.
        time_out: Shape: (T, N) bool.
        gamma: Discount factor.
        eps: Relative truncation tolerance.

    Returns:
        ``(G_hat, in_I_eps)``: float64 and bool. Shapes: (T, N), (T, N).
    """
    done, time_out = done.bool(), time_out.bool()
    horizon, truncated = remaining_horizon(done, time_out)
    return discounted_returns(reward, done, gamma), valid_samples(horizon, truncated, gamma, eps)
