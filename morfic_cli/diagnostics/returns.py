"""Discounted Monte-Carlo returns of a recorded rollout and the diagnostic sample set I_eps (SPEC section 6).

Arrays are (T, N): T policy steps of N envs. Step t of env i took action a_{t,i} in s_{t,i}, received r_{t,i} and
ended its episode when ``done[t, i]`` (the env was reset, row t+1 starts a new episode). An episode ends

- by *termination* (a fall: ``done`` and not ``time_out``): nothing follows, the return is complete;
- by *truncation*: a time-out (``done`` and ``time_out``) or the end of the recording (row T-1 without ``done``).
  The rewards after the cut are unknown, so the recorded return misses a tail.

The return of (t, i) is summed up to the end e of its episode, eq. (mc_return) in docs/metrics.md::

    G_hat[t, i] = sum_{k=t}^{e} gamma^(k-t) r[k, i]

If that episode was truncated after H = e - t + 1 rewards, the true return differs from G_hat by the missing tail
gamma^H * G(s_{e+1}): at most a fraction gamma^H of the largest possible |G| (max|r| / (1 - gamma)).

I_eps is a *fixed window*, chosen before looking at any outcome (eq. (sample_window) in docs/metrics.md)::

    I_eps = {(t, i) : t <= T - H_eps},   H_eps = min{H : gamma^H <= eps}

Every env contributes the same steps 0..T-H_eps, whether it falls or not; a sample in the window either belongs to
an episode that fell (complete return) or to one the recording's end cut after at least T - t >= H_eps rewards
(a tail of at most eps of the return scale). The earlier rule (every sample of a fallen episode, plus the
truncated ones with H >= H_eps) let falls add late samples, so policies that fall at different rates were scored
on different populations. A time-out inside the window (diagnostic rollouts have none) cuts a return earlier;
such a sample with H < H_eps is left out.
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


def sample_window(done: torch.Tensor, time_out: torch.Tensor, gamma: float, eps: float) -> torch.Tensor:
    """The mask of I_eps: the fixed window t <= T - H_eps of every env, independent of falls.

    ``I_eps = {(t, i): t <= T - H_eps}`` with H_eps = :func:`min_horizon`; a sample of that window whose episode a
    time-out cut after fewer than H_eps rewards is left out (never the case in a diagnostic rollout, which does not
    time out).

    Args:
        done: Episode ended at this step. Shape: (T, N) bool.
        time_out: The end was a time-out (truncation), not a fall. Shape: (T, N) bool.
        gamma: Discount factor.
        eps: Relative truncation tolerance.

    Returns:
        Shape: (T, N) bool; all False when T < H_eps.
    """
    h_eps = min_horizon(gamma, eps)
    num_steps = done.shape[0]
    in_window = (torch.arange(num_steps) <= num_steps - h_eps)[:, None].expand(done.shape)
    horizon, truncated = remaining_horizon(done.bool(), time_out.bool())
    cut_by_time_out = truncated & (horizon < h_eps)  # inside the window only a time-out can cut this short
    return in_window & ~cut_by_time_out


def mc_returns(
    reward: torch.Tensor, done: torch.Tensor, time_out: torch.Tensor, gamma: float, eps: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """G_hat and the mask of I_eps of a recording (:func:`discounted_returns`, :func:`sample_window`).

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
    return discounted_returns(reward, done, gamma), sample_window(done, time_out, gamma, eps)
