"""Score trained models on stored samples: critic values V_phi and actor-loss gradients g(A) (docs/metrics.md).

The models get the observation groups recorded in the rollout, flattened over (T, N) into one batch, as a
TensorDict: a critic reads its own groups (``critic`` history, ``privileged``, and ``morphology`` when conditioned),
exactly the inputs it was trained on; the actor reads ``history`` (and ``morphology``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch
from tensordict import TensorDict

from morfic_cli.diagnostics.metrics import policy_gradient

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel


def batch_obs(obs: dict[str, np.ndarray], mask: np.ndarray | None = None) -> TensorDict:
    """The observation groups of the samples in ``mask`` as one batch.

    Args:
        obs: Group -> (T, N, ...).
        mask: Which samples. Shape: (T, N) bool; None = all, in (t, i) row-major order.

    Returns:
        Group -> (n, ...) float32, batch size (n,).
    """
    flat = {k: (v[mask] if mask is not None else v.reshape(-1, *v.shape[2:])) for k, v in obs.items()}
    n = next(iter(flat.values())).shape[0]
    return TensorDict({k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in flat.items()}, batch_size=[n])


def critic_values(critic: torch.nn.Module, obs: dict[str, np.ndarray], batch_size: int = 8192) -> torch.Tensor:
    """V_phi(s_t, z_m) of every sample. Shape: (T, N) float32.

    Args:
        critic: A trained critic (eval mode).
        obs: Group -> (T, N, ...).
        batch_size: Samples per forward pass.
    """
    td = batch_obs(obs)
    with torch.no_grad():
        values = [critic(td[i : i + batch_size]).reshape(-1) for i in range(0, td.batch_size[0], batch_size)]
    shape = next(iter(obs.values())).shape[:2]
    return torch.cat(values).reshape(shape)


def actor_gradients(
    actor: MLPModel,
    obs: dict[str, np.ndarray],
    actions: np.ndarray,
    mask: np.ndarray,
    advantages: Sequence[torch.Tensor],
    clip_param: float = 0.2,
    chunk: int = 4096,
) -> list[torch.Tensor]:
    """g(A) = grad_theta L_actor(theta; A) at ratio 1 for each advantage vector A (:func:`policy_gradient`).

    L_actor is a mean over the n samples of ``mask``; it is evaluated in chunks and the chunk gradients are summed
    with weights n_chunk / n, which is the gradient of the mean over all samples.

    Args:
        actor: The actor whose update direction is measured (eval mode: no latent dropout).
        obs: Group -> (T, N, ...).
        actions: The actions taken. Shape: (T, N, 12).
        mask: The samples (I_eps). Shape: (T, N) bool.
        advantages: Each A, one value per sample of ``mask`` in row-major order. Shapes: (n,).
        clip_param: PPO's clip range (inactive at ratio 1).
        chunk: Samples per forward/backward pass.

    Returns:
        One flattened gradient per advantage vector. Shapes: (P,), P = number of actor parameters.
    """
    params = [p for p in actor.parameters() if p.requires_grad]
    td = batch_obs(obs, mask)
    acts = torch.from_numpy(np.ascontiguousarray(actions[mask]))
    n = acts.shape[0]
    grads = [torch.zeros(sum(p.numel() for p in params), dtype=torch.float64) for _ in advantages]
    with torch.enable_grad():
        for start in range(0, n, chunk):
            stop = min(start + chunk, n)
            mean = actor(td[start:stop])
            actor.distribution.update(mean)
            log_prob = actor.get_output_log_prob(acts[start:stop])
            for g, adv in zip(grads, advantages, strict=True):
                g += policy_gradient(log_prob, adv[start:stop], params, clip_param).double() * ((stop - start) / n)
    return grads
