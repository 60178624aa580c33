"""Critic calibration metrics (paper appendix "Evaluation Metrics and Diagnostic Definitions"; docs/metrics.md).

Pure functions on 1-D tensors over the sample set I_eps (see :mod:`morfic_cli.diagnostics.returns`): ``G`` the
Monte-Carlo returns G_hat_{t,i}, ``V`` the critic's values V_phi(s_{t,i}, z_{m_i}) of the same samples. Every
expectation, mean, variance and standard deviation runs over I_eps (the paper's sets I and I_eps are one set here:
a truncated return is not a reference), population form (divide by |I_eps|), in float64.

- EV   = 1 - Var(G - V) / Var(G)                              (1 is perfect, 0 = predicting mean(G))
- NVB  = E[V - G] / (sigma_G + eps)                           eq. (nvb); > 0 overestimates, < 0 underestimates
- NVE  = sqrt(E[(V - G)^2]) / (sigma_G + eps)                 eq. (nve); NVE >= |NVB|
- A_MC = G - mean(G),  A_phi = G - V                          reference and critic-induced advantages
- ASA  = mean(1[sign A_phi == sign A_MC]),  Flip = 1 - ASA    (sign(0) = 0 is a sign of its own)
- CosGrad = cos(g(A_phi), g(A_MC)),  g(A) = grad_theta L_actor(theta; A) at ratio 1

eps (default 1e-8) only keeps the normalisation finite; it is not the truncation tolerance of I_eps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

SIGMA_EPS = 1e-8
"""eps in the denominators sigma_G + eps of NVB and NVE."""


def explained_variance(G: torch.Tensor, V: torch.Tensor) -> float:
    """EV = 1 - Var(G - V) / Var(G) (the paper's Metrics paragraph); NaN when Var(G) = 0.

    1 is a perfect critic, 0 is no better than predicting the mean of G, below 0 is worse than that. The one EV of
    morfic: the diagnostics use it on Monte-Carlo returns, training (:mod:`morfic_cli.rl.ppo`) on the rollout's raw
    GAE returns.

    Args:
        G: Returns. Shape: (n,) (any shape is flattened, e.g. (T, N, 1)).
        V: Values of the same samples. Same shape.

    Returns:
        EV as a float (in float64); NaN when Var(G) = 0 (undefined).
    """
    g = G.detach().flatten().double()
    v = V.detach().flatten().double()
    var_g = torch.var(g, correction=0)
    if var_g == 0:
        return float("nan")
    return float(1.0 - torch.var(g - v, correction=0) / var_g)


def _sigma(G: torch.Tensor) -> torch.Tensor:
    """sigma_G, the population std of G. Shape: ()."""
    return torch.std(G.double(), correction=0)


def normalized_value_bias(G: torch.Tensor, V: torch.Tensor, eps: float = SIGMA_EPS) -> float:
    """NVB = E[V - G] / (sigma_G + eps), eq. (nvb). The tables report |NVB|; NaN for no samples.

    Args:
        G: Returns. Shape: (n,).
        V: Values. Shape: (n,).
        eps: Keeps the denominator positive.
    """
    if G.numel() == 0:
        return math.nan
    return float((V.double() - G.double()).mean() / (_sigma(G) + eps))


def normalized_value_error(G: torch.Tensor, V: torch.Tensor, eps: float = SIGMA_EPS) -> float:
    """NVE = sqrt(E[(V - G)^2]) / (sigma_G + eps), eq. (nve); NaN for no samples.

    Args:
        G: Returns. Shape: (n,).
        V: Values. Shape: (n,).
        eps: Keeps the denominator positive.
    """
    if G.numel() == 0:
        return math.nan
    return float((V.double() - G.double()).pow(2).mean().sqrt() / (_sigma(G) + eps))


def mc_advantage(G: torch.Tensor) -> torch.Tensor:
    """A_MC = G - (1/|I_eps|) sum G, the Monte-Carlo reference advantage. Shape: (n,) -> (n,) float64."""
    G = G.double()
    return G - G.mean()


def critic_advantage(G: torch.Tensor, V: torch.Tensor) -> torch.Tensor:
    """A_phi = G - V, the critic-induced advantage. Shapes: (n,), (n,) -> (n,) float64."""
    return G.double() - V.double()


def sign_agreement(a_phi: torch.Tensor, a_mc: torch.Tensor) -> float:
    """ASA = (1/|I_eps|) sum 1[sign(A_phi) = sign(A_MC)]; NaN for no samples. Shapes: (n,), (n,)."""
    if a_phi.numel() == 0:
        return math.nan
    return float((torch.sign(a_phi) == torch.sign(a_mc)).double().mean())


def flip_rate(a_phi: torch.Tensor, a_mc: torch.Tensor) -> float:
    """Flip = (1/|I_eps|) sum 1[sign(A_phi) != sign(A_MC)] = 1 - ASA; NaN for no samples. Shapes: (n,), (n,)."""
    if a_phi.numel() == 0:
        return math.nan
    return float((torch.sign(a_phi) != torch.sign(a_mc)).double().mean())


def policy_gradient(
    log_prob: torch.Tensor, advantages: torch.Tensor, params: Sequence[torch.Tensor], clip_param: float = 0.2
) -> torch.Tensor:
    """g(A) = grad_theta L_actor(theta; A) at ratio 1, flattened over ``params``.

    L_actor is rsl-rl PPO's clipped surrogate, written as it is there::

        ratio = exp(log pi_theta(a|s) - log pi_old(a|s)),  log pi_old = sg(log pi_theta)  (ratio = 1)
        L = mean(max(-A * ratio, -A * clip(ratio, 1 - c, 1 + c)))

    At ratio 1 the clip is inactive, so g(A) = -mean(A * grad log pi): the policy-gradient direction that the
    advantages A would produce. The entropy bonus is left out (it does not depend on A), and A is used as given (not
    normalised: PPO's per-batch normalisation would subtract the mean advantage, which is the critic's bias).

    Args:
        log_prob: log pi_theta(a_j | s_j) of the samples, differentiable in ``params``. Shape: (n,).
        advantages: A_j, no gradient. Shape: (n,).
        params: theta, the actor's parameters.
        clip_param: PPO's clip range c (no effect at ratio 1; kept to mirror the loss).

    Returns:
        The gradient, concatenated over ``params`` (zeros for a parameter the loss does not reach). Shape: (P,).
    """
    adv = advantages.detach().to(log_prob.dtype)
    ratio = torch.exp(log_prob - log_prob.detach())
    surrogate = -adv * ratio
    surrogate_clipped = -adv * torch.clamp(ratio, 1.0 - clip_param, 1.0 + clip_param)
    loss = torch.max(surrogate, surrogate_clipped).mean()
    grads = torch.autograd.grad(loss, list(params), retain_graph=True, allow_unused=True)
    return torch.cat(
        [(torch.zeros_like(p) if g is None else g).reshape(-1) for g, p in zip(grads, params, strict=True)]
    )


def cosine(a: torch.Tensor, b: torch.Tensor) -> float:
    """a^T b / (||a||_2 ||b||_2); NaN when either vector is zero. Shapes: (P,), (P,)."""
    a, b = a.double(), b.double()
    norm = torch.linalg.vector_norm(a) * torch.linalg.vector_norm(b)
    if norm == 0:
        return math.nan
    return float(a @ b / norm)


def cos_grad(g_phi: torch.Tensor, g_mc: torch.Tensor) -> float:
    """CosGrad_phi = cos(g(A_phi), g(A_MC)) of two :func:`policy_gradient` results. Shapes: (P,), (P,)."""
    return cosine(g_phi, g_mc)


@dataclass(frozen=True)
class CriticMetrics:
    """The calibration metrics of one critic on one sample set (all over I_eps).

    Attributes:
        ev: Explained variance.
        nvb: Normalised value bias (signed; the tables print |NVB|).
        nve: Normalised value error.
        asa: Advantage sign agreement.
        flip: Sign-flip rate, 1 - ASA.
        n: |I_eps|.
        g_mean: mean(G).
        g_std: sigma_G.
        v_mean: mean(V).
    """

    ev: float
    nvb: float
    nve: float
    asa: float
    flip: float
    n: int
    g_mean: float
    g_std: float
    v_mean: float


def critic_metrics(G: torch.Tensor, V: torch.Tensor, eps: float = SIGMA_EPS) -> CriticMetrics:
    """EV, NVB, NVE, ASA and Flip of values V against returns G (both already restricted to I_eps).

    Args:
        G: Monte-Carlo returns. Shape: (n,).
        V: Critic values of the same samples. Shape: (n,).
        eps: The eps of sigma_G + eps.
    """
    G, V = G.double().reshape(-1), V.double().reshape(-1)
    a_mc, a_phi = mc_advantage(G), critic_advantage(G, V)
    empty = G.numel() == 0
    return CriticMetrics(
        ev=math.nan if empty else explained_variance(G, V),
        nvb=normalized_value_bias(G, V, eps),
        nve=normalized_value_error(G, V, eps),
        asa=sign_agreement(a_phi, a_mc),
        flip=flip_rate(a_phi, a_mc),
        n=int(G.numel()),
        g_mean=math.nan if empty else float(G.mean()),
        g_std=math.nan if empty else float(_sigma(G)),
        v_mean=math.nan if empty else float(V.mean()),
    )
