"""Calibration metrics: hand-computed small arrays (arithmetic in comments) and properties on random data."""

from __future__ import annotations

import math

import pytest
import torch

from morfic_cli.diagnostics.metrics import (
    cos_grad,
    cosine,
    critic_advantage,
    critic_metrics,
    explained_variance,
    flip_rate,
    mc_advantage,
    normalized_value_bias,
    normalized_value_error,
    policy_gradient,
    sign_agreement,
)

# G = [0, 2, 4, 6]: mean 3, Var(G) = (9 + 1 + 1 + 9) / 4 = 5, sigma_G = sqrt(5) = 2.2360680
G = torch.tensor([0.0, 2.0, 4.0, 6.0])
# V = [2, 3, 5, 6]: V - G = [2, 1, 1, 0]
V = torch.tensor([2.0, 3.0, 5.0, 6.0])


def test_ev_by_hand():
    # G - V = [-2, -1, -1, 0]: mean -1, deviations [-1, 0, 0, 1], Var = 2 / 4 = 0.5; EV = 1 - 0.5 / 5 = 0.9
    assert explained_variance(G, V) == pytest.approx(0.9)
    # V = mean(G) = 3: Var(G - V) = Var(G) -> EV = 0; Var(G) = 0 -> undefined
    assert explained_variance(G, torch.full((4,), 3.0)) == pytest.approx(0.0)
    assert math.isnan(explained_variance(torch.ones(3), torch.zeros(3)))


def test_nvb_and_nve_by_hand():
    # NVB = E[V - G] / sigma_G = 1 / sqrt(5) = 0.4472136 (the critic overestimates: positive)
    assert normalized_value_bias(G, V) == pytest.approx(1 / math.sqrt(5))
    # NVE = sqrt(E[(V - G)^2]) / sigma_G = sqrt((4 + 1 + 1 + 0) / 4) / sqrt(5) = sqrt(1.5 / 5) = 0.5477226
    assert normalized_value_error(G, V) == pytest.approx(math.sqrt(1.5 / 5))
    # underestimating by 1 everywhere: NVB = -1 / sqrt(5), NVE = 1 / sqrt(5)
    assert normalized_value_bias(G, G - 1) == pytest.approx(-1 / math.sqrt(5))
    assert normalized_value_error(G, G - 1) == pytest.approx(1 / math.sqrt(5))
    # eps keeps sigma_G = 0 finite: E[V - G] = 1, sigma_G = 0 -> 1 / (0 + 0.5) = 2
    assert normalized_value_bias(torch.ones(2), torch.full((2,), 2.0), eps=0.5) == pytest.approx(2.0)
    assert math.isnan(normalized_value_bias(torch.zeros(0), torch.zeros(0)))


def test_advantages_asa_and_flip_by_hand():
    a_mc = mc_advantage(G)  # G - 3 = [-3, -1, 1, 3]
    a_phi = critic_advantage(G, V)  # G - V = [-2, -1, -1, 0]
    assert a_mc.tolist() == [-3.0, -1.0, 1.0, 3.0]
    assert a_phi.tolist() == [-2.0, -1.0, -1.0, 0.0]
    # signs: A_phi (-, -, -, 0) vs A_MC (-, -, +, +): agree on samples 0 and 1 -> ASA = 2 / 4; sign(0) = 0 != + flips
    assert sign_agreement(a_phi, a_mc) == 0.5
    assert flip_rate(a_phi, a_mc) == 0.5
    # one flip out of 4: ASA = 0.75, Flip = 0.25
    assert sign_agreement(torch.tensor([-1.0, -1, 1, -1]), a_mc) == 0.75
    assert flip_rate(torch.tensor([-1.0, -1, 1, -1]), a_mc) == 0.25


def test_critic_metrics_collects_them():
    m = critic_metrics(G, V)
    assert (m.ev, m.asa, m.flip, m.n) == (pytest.approx(0.9), 0.5, 0.5, 4)
    assert m.nvb == pytest.approx(1 / math.sqrt(5)) and m.nve == pytest.approx(math.sqrt(0.3))
    assert (m.g_mean, m.g_std, m.v_mean) == (3.0, pytest.approx(math.sqrt(5)), 4.0)
    empty = critic_metrics(torch.zeros(0), torch.zeros(0))
    assert empty.n == 0 and all(math.isnan(x) for x in (empty.ev, empty.nvb, empty.nve, empty.asa, empty.flip))


def _linear_log_prob(theta1, theta2):
    # log pi_j = theta1 * x_j + theta2 * y_j with x = [1, 2, -1], y = [0, 1, 1]
    x = torch.tensor([1.0, 2.0, -1.0])
    y = torch.tensor([0.0, 1.0, 1.0])
    return theta1 * x + theta2 * y


def test_policy_gradient_and_cosine_by_hand():
    theta1 = torch.tensor(0.3, requires_grad=True)
    theta2 = torch.tensor(-0.2, requires_grad=True)
    unused = torch.zeros(2, requires_grad=True)
    params = [theta1, theta2, unused]
    lp = _linear_log_prob(theta1, theta2)
    # at ratio 1: g(A) = -mean(A_j * grad log pi_j)
    # A = [1, -1, 2]:  d/dtheta1 = -(1*1 + (-1)*2 + 2*(-1)) / 3 = -(-3) / 3 = 1
    #                  d/dtheta2 = -(1*0 + (-1)*1 + 2*1) / 3 = -1/3;  unused parameters get 0
    g = policy_gradient(lp, torch.tensor([1.0, -1.0, 2.0]), params)
    assert g.tolist() == pytest.approx([1.0, -1 / 3, 0.0, 0.0])
    # A' = [1, 1, 1]: d/dtheta1 = -(1 + 2 - 1) / 3 = -2/3; d/dtheta2 = -(0 + 1 + 1) / 3 = -2/3
    g2 = policy_gradient(lp, torch.ones(3), params)
    assert g2.tolist() == pytest.approx([-2 / 3, -2 / 3, 0.0, 0.0])
    # cos = (1 * -2/3 + -1/3 * -2/3) / (sqrt(1 + 1/9) * sqrt(8/9)) = (-4/9) / (sqrt(80) / 9) = -4 / sqrt(80)
    assert cos_grad(g, g2) == pytest.approx(-4 / math.sqrt(80))
    assert cosine(torch.tensor([1.0, 0.0]), torch.tensor([0.0, 3.0])) == 0.0
    assert math.isnan(cosine(torch.zeros(3), torch.ones(3)))


def test_policy_gradient_is_the_ppo_surrogate_gradient_at_ratio_one():
    """g(A) equals the gradient of rsl-rl's clipped surrogate with pi_old = pi_theta, and -mean(A grad log pi)."""
    torch.manual_seed(0)
    net = torch.nn.Linear(5, 3)
    log_std = torch.nn.Parameter(torch.zeros(3))
    obs, act, adv = torch.randn(32, 5), torch.randn(32, 3), torch.randn(32)
    params = [*net.parameters(), log_std]

    def log_prob():
        return torch.distributions.Normal(net(obs), log_std.exp()).log_prob(act).sum(-1)

    g = policy_gradient(log_prob(), adv, params)
    reinforce = torch.autograd.grad(-(adv * log_prob()).mean(), params)
    assert torch.allclose(g, torch.cat([r.reshape(-1) for r in reinforce]), atol=1e-6)


# ---------------------------------------------------------------------------------------------- properties


def _random_case(seed: int, n: int = 257):
    gen = torch.Generator().manual_seed(seed)
    G = torch.randn(n, generator=gen, dtype=torch.float64) * 3 + 1
    V = G + torch.randn(n, generator=gen, dtype=torch.float64) * torch.rand(1, generator=gen).item() * 4 - 0.5
    return G, V


@pytest.mark.parametrize("seed", range(20))
def test_nve_bounds_abs_nvb_and_asa_plus_flip_is_one(seed):
    G, V = _random_case(seed)
    m = critic_metrics(G, V)
    assert m.nve >= abs(m.nvb) - 1e-12  # sqrt(E[x^2]) >= |E[x]| (Jensen)
    assert m.asa + m.flip == pytest.approx(1.0)
    assert m.ev <= 1.0


@pytest.mark.parametrize("seed", range(10))
def test_a_perfect_critic(seed):
    G, _ = _random_case(seed)
    m = critic_metrics(G, G.clone())
    assert m.ev == 1.0 and m.nvb == 0.0 and m.nve == 0.0


@pytest.mark.parametrize("seed", range(10))
def test_cos_grad_is_one_when_the_critic_gives_the_mc_advantage(seed):
    gen = torch.Generator().manual_seed(seed)
    G, _ = _random_case(seed, n=64)
    net = torch.nn.Linear(4, 2).double()
    obs, act = torch.randn(64, 4, generator=gen, dtype=torch.float64), torch.randn(64, 2, generator=gen).double()
    lp = torch.distributions.Normal(net(obs), 1.0).log_prob(act).sum(-1)
    V = torch.full_like(G, float(G.mean()))  # V = mean(G) -> A_phi = G - mean(G) = A_MC
    a_phi, a_mc = critic_advantage(G, V), mc_advantage(G)
    params = list(net.parameters())
    assert cos_grad(policy_gradient(lp, a_phi, params), policy_gradient(lp, a_mc, params)) == pytest.approx(1.0)
    assert flip_rate(a_phi, a_mc) == 0.0
    # CosGrad ignores the advantages' scale, not their sign
    assert cos_grad(policy_gradient(lp, 3 * a_mc, params), policy_gradient(lp, a_mc, params)) == pytest.approx(1.0)
    assert cos_grad(policy_gradient(lp, -a_mc, params), policy_gradient(lp, a_mc, params)) == pytest.approx(-1.0)


def test_metric_row_is_the_row_calibration_and_the_critic_study_share():
    from morfic_cli.diagnostics.calibration import metric_row
    from morfic_cli.diagnostics.metrics import CriticMetrics

    m = CriticMetrics(ev=0.5, nvb=-0.25, nve=1.0, asa=0.75, flip=0.25, n=8, g_mean=1.5, g_std=2.0, v_mean=2.0)
    assert metric_row(m, 0.9) == {
        "ev": 0.5,
        "nvb": -0.25,
        "abs_nvb": 0.25,  # the tables print |NVB|
        "nve": 1.0,
        "asa": 0.75,
        "flip": 0.25,
        "cos_grad": 0.9,
        "cell": "0.250/1.000/0.750",
        "n_samples": 8,
        "g_mean": 1.5,
        "g_std": 2.0,
        "v_mean": 2.0,
    }
