"""Monte-Carlo returns and I_eps: hand-computed small cases, the fixed window, and the truncation property."""

from __future__ import annotations

import pytest
import torch

from morfic_cli.diagnostics.returns import (
    discounted_returns,
    mc_returns,
    min_horizon,
    remaining_horizon,
    sample_window,
)

F, T_ = False, True

# T = 4 steps x N = 2 envs, gamma = 0.5.
# env 0: r = 1, 2, 3, 4; falls at t = 1 (done, no time-out); a new episode runs t = 2..3 and the recording ends.
# env 1: r = 1, 1, 1, 1; times out at t = 1 (done + time_out); a new episode runs t = 2..3.
REWARD = torch.tensor([[1.0, 1.0], [2.0, 1.0], [3.0, 1.0], [4.0, 1.0]])
DONE = torch.tensor([[F, F], [T_, T_], [F, F], [F, F]])
TIME_OUT = torch.tensor([[F, F], [F, T_], [F, F], [F, F]])


def test_discounted_returns_by_hand():
    G = discounted_returns(REWARD, DONE, gamma=0.5)
    # env 0: G3 = 4; G2 = 3 + 0.5 * 4 = 5; G1 = 2 (episode ends); G0 = 1 + 0.5 * 2 = 2
    # env 1: G3 = 1; G2 = 1 + 0.5 * 1 = 1.5; G1 = 1 (episode ends); G0 = 1 + 0.5 * 1 = 1.5
    assert G.dtype == torch.float64
    assert G.tolist() == [[2.0, 1.5], [2.0, 1.0], [5.0, 1.5], [4.0, 1.0]]


def test_remaining_horizon_by_hand():
    H, truncated = remaining_horizon(DONE, TIME_OUT)
    # env 0: t0 -> episode ends at t1 by a fall: H = 2, complete; t1: H = 1, complete;
    #        t2, t3: the recording ends after t3: H = 2, 1, truncated
    # env 1: t0, t1: the time-out at t1 truncates: H = 2, 1; t2, t3: the recording's end: H = 2, 1
    assert H.tolist() == [[2, 2], [1, 1], [2, 2], [1, 1]]
    assert truncated.tolist() == [[F, T_], [F, T_], [T_, T_], [T_, T_]]


def test_min_horizon_by_hand():
    # gamma^H <= eps: ln(0.3) / ln(0.5) = 1.74 -> H = 2 (0.5^2 = 0.25 <= 0.3, 0.5^1 = 0.5 > 0.3)
    assert min_horizon(0.5, 0.3) == 2
    # ln(0.05) / ln(0.99) = 298.07 -> 299 (0.99^299 = 0.0495 <= 0.05 < 0.99^298 = 0.0500)
    assert min_horizon(0.99, 0.05) == 299
    assert 0.99**299 <= 0.05 < 0.99**298
    with pytest.raises(ValueError):
        min_horizon(1.0, 0.05)
    with pytest.raises(ValueError):
        min_horizon(0.99, 0.0)


def test_i_eps_by_hand():
    mask = sample_window(DONE, TIME_OUT, gamma=0.5, eps=0.3)  # H_eps = 2: the window is t <= T - 2 = 2
    # env 0: t0..t2 in the window; t3 out (also under the old rule it was out: truncated with H = 1)
    # env 1: t0 in; t1 is in the window but its episode is cut by the time-out at t1 after H = 1 < 2 rewards -> out;
    #        t2 in (H = 2 to the recording's end); t3 out of the window
    assert mask.tolist() == [[T_, T_], [T_, F], [T_, T_], [F, F]]
    G, mask2 = mc_returns(REWARD, DONE, TIME_OUT, gamma=0.5, eps=0.3)
    assert mask2.tolist() == mask.tolist()
    assert G.tolist() == discounted_returns(REWARD, DONE, 0.5).tolist()


def test_the_window_does_not_depend_on_falls_where_the_old_rule_did():
    """T = 6, N = 2, gamma = 0.5, eps = 0.2 -> H_eps = 3 (0.5^2 = 0.25 > 0.2 >= 0.5^3): window t <= 3.

    env 0 never falls, r = 1. env 1: r = 1, 1, 1, 1, -10 (falls at t4), then a new episode with r = 1 at t5.
    The old rule (every sample of a fallen episode, plus truncated ones with H >= 3) also took env 1's t4 — the
    fall — because it fell before the log ended: 9 samples, mean G = -0.6354. The window takes t0..t3 of both envs:
    8 = N (T - H_eps + 1) samples.
    """
    reward = torch.tensor([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, -10.0], [1.0, 1.0]])
    done = torch.zeros(6, 2, dtype=torch.bool)
    done[4, 1] = True
    no = torch.zeros(6, 2, dtype=torch.bool)
    assert min_horizon(0.5, 0.2) == 3
    G, mask = mc_returns(reward, done, no, gamma=0.5, eps=0.2)
    assert mask.tolist() == [[T_, T_]] * 4 + [[F, F]] * 2
    # env 0: G_t = sum_{k=t}^{5} 0.5^(k-t) = 2 (1 - 0.5^(6-t)): 1.96875, 1.9375, 1.875, 1.75 (t0..t3), cut at the end
    # env 1: G4 = -10, G3 = 1 - 5 = -4, G2 = 1 - 2 = -1, G1 = 1 - 0.5 = 0.5, G0 = 1 + 0.25 = 1.25 (complete)
    assert G[:4, 0].tolist() == [1.96875, 1.9375, 1.875, 1.75]
    assert G[:5, 1].tolist() == [1.25, 0.5, -1.0, -4.0, -10.0]
    # new rule: mean over the 8 window samples = (7.53125 - 3.25) / 8 = 0.53515625
    assert G[mask].mean().item() == pytest.approx(0.53515625)
    # the old rule, for comparison: the same 8 plus the fall sample (t4, env 1): (4.28125 - 10) / 9
    H, truncated = remaining_horizon(done, no)
    old = ~truncated | (H >= 3)
    assert old.tolist() == [[T_, T_]] * 4 + [[F, T_], [F, F]]
    assert G[old].mean().item() == pytest.approx((4.28125 - 10.0) / 9)
    # and the window is the same for every fall pattern: move the fall to t1 or remove it
    for fall in (1, None):
        d = torch.zeros(6, 2, dtype=torch.bool)
        if fall is not None:
            d[fall, 1] = True
        assert sample_window(d, no, 0.5, 0.2).tolist() == mask.tolist()


def test_truncated_tail_is_excluded_from_i_eps():
    # constant r = 1, no episode end, gamma = 0.9, eps = 0.5 -> H_eps = ceil(ln 0.5 / ln 0.9) = ceil(6.58) = 7
    # over T = 10 steps: G_hat[t] = (1 - 0.9^(10 - t)) / (1 - 0.9), H[t] = 10 - t; the true return is 1 / 0.1 = 10
    reward = torch.ones(10, 1)
    no = torch.zeros(10, 1, dtype=torch.bool)
    G, mask = mc_returns(reward, no, no, gamma=0.9, eps=0.5)
    assert min_horizon(0.9, 0.5) == 7
    assert mask[:, 0].tolist() == [True] * 4 + [False] * 6  # the window t <= 10 - 7 = 3: H = 10, 9, 8, 7 are in
    # in: G_hat[3] = (1 - 0.9^7) / 0.1 = 5.217, missing 0.9^7 * 10 = 4.78 <= eps * 10 = 5
    assert G[3, 0].item() == pytest.approx((1 - 0.9**7) / 0.1)
    assert 10 - G[3, 0].item() <= 0.5 * 10
    # out: G_hat[9] = 1 misses 9 = 90 % of the true return
    assert G[9, 0].item() == pytest.approx(1.0)


@pytest.mark.parametrize("seed", range(5))
def test_cutting_a_rollout_moves_returns_in_i_eps_by_at_most_eps(seed):
    """Cut a long random rollout short: on I_eps the returns move by at most eps * max|r| / (1 - gamma)."""
    gen = torch.Generator().manual_seed(seed)
    gamma, eps, n_full, n_cut, n_envs = 0.9, 0.2, 400, 60, 16
    reward = torch.randn(n_full, n_envs, generator=gen)
    done = torch.rand(n_full, n_envs, generator=gen) < 0.02
    time_out = done & (torch.rand(n_full, n_envs, generator=gen) < 0.3)
    G_full = discounted_returns(reward, done, gamma)
    G_cut, mask = mc_returns(reward[:n_cut], done[:n_cut], time_out[:n_cut], gamma, eps)
    H, truncated = remaining_horizon(done[:n_cut], time_out[:n_cut])
    h_eps = min_horizon(gamma, eps)
    bound = eps * reward.abs().max() / (1 - gamma)
    assert torch.all((G_cut - G_full[:n_cut]).abs()[mask] <= bound + 1e-12)
    window = (torch.arange(n_cut) <= n_cut - h_eps)[:, None]
    cut = truncated & (H < h_eps)
    assert torch.equal(mask, window & ~cut)  # the window, minus samples a time-out cut short
    fell = ~truncated  # the episode ends by a fall inside the cut recording: its return is exact
    assert torch.equal(G_cut[fell], G_full[:n_cut][fell])
    assert not torch.any(mask & truncated & (H < h_eps))
    assert not mask[n_cut - h_eps + 1 :].any()  # nothing after the window, fall or not
    no_timeouts = torch.zeros_like(done[:n_cut])
    assert torch.equal(sample_window(done[:n_cut], no_timeouts, gamma, eps), window.expand(n_cut, n_envs))
