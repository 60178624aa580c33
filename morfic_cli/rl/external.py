"""What the external baselines' models share: the rsl-rl model interface without an MLP (docs/training.md).

The external baselines (``bot``, ``urma``; paper Table "External baselines vs. MorFiC") are token models, not
MLPs over a flat state. :class:`TokenModel` gives them what rsl-rl's PPO and morfic's evaluation call on a model
(``model(obs, stochastic_output=...)``, the output distribution's log-probability, entropy and KL, ``reset``, the
hidden state) by subclassing rsl-rl's :class:`~rsl_rl.models.MLPModel` for those methods while building none of its
MLP: a subclass builds its own network and implements :meth:`TokenModel.compute`, the action mean (N, 12) or the
value (N, 1).

They have no adaptation module and no privileged encoder (no ``estimate_privileged`` / ``encode_privileged``):
MorficPPO then runs plain rsl-rl PPO and logs the adaptation error as NaN. Their output layers compute in float32
themselves (:func:`float32_linear`), also under the ``cpu`` preset's bf16 autocast, so MorficPPO leaves them alone
(``float32_outputs``).
"""

from __future__ import annotations

import torch
import torch.nn as nn
from rsl_rl.models import MLPModel
from rsl_rl.modules import HiddenState
from rsl_rl.utils import resolve_class, unpad_trajectories
from tensordict import TensorDict


def float32_linear(layer: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """``layer(x)`` in float32, also inside a bf16 autocast region (the output layer of an action mean or value)."""
    with torch.autocast(device_type=x.device.type, enabled=False):
        return layer(x.float())


def init_transformer_weights(module: nn.Module) -> None:
    """Normal(0, 0.02) weights and zero biases for every ``nn.Linear`` and ``nn.Embedding`` of ``module``.

    BodyTransformer's initialisation of its encoder and node embeddings (GPT-2's); the attention's fused input
    projection (not an ``nn.Linear``) keeps torch's Xavier initialisation, as there.
    """
    for m in module.modules():
        if isinstance(m, (nn.Linear, nn.Embedding)):
            nn.init.normal_(m.weight, mean=0.0, std=0.02)
            if isinstance(m, nn.Linear) and m.bias is not None:
                nn.init.zeros_(m.bias)


class TokenModel(MLPModel):
    """Base of the external baselines' actors and critics: MLPModel's interface, the subclass's network.

    A subclass calls ``super().__init__(obs, obs_groups, obs_set, output_dim, distribution_cfg)`` first, then
    builds its layers, and implements :meth:`compute`. ``obs_groups[obs_set]`` lists the groups it reads.
    """

    float32_outputs: bool = True
    """Read by MorficPPO: the output layers already compute in float32 (:func:`float32_linear`)."""
    morphology_encoder: nn.Module | None = None
    """None: no descriptor input (export bakes nothing in, like ``ppo``)."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        distribution_cfg: dict | None = None,
    ) -> None:
        nn.Module.__init__(self)
        self.obs_groups = list(obs_groups[obs_set])
        for group in self.obs_groups:
            if group not in obs.keys():
                raise ValueError(f"obs_groups['{obs_set}'] names '{group}', which the env does not provide.")
        self.obs_dim = sum(obs[g][0].numel() for g in self.obs_groups)
        self.obs_normalization = False
        self.obs_normalizer = nn.Identity()
        self.output_dim = output_dim
        if distribution_cfg is not None:
            dist_class, dist_cfg = resolve_class(dict(distribution_cfg))
            self.distribution = dist_class(output_dim, **dist_cfg)
        else:
            self.distribution = None

    def compute(self, obs: TensorDict) -> torch.Tensor:
        """The action mean (N, 12) or the value (N, 1) of a batch of observations."""
        raise NotImplementedError

    def forward(
        self,
        obs: TensorDict,
        masks: torch.Tensor | None = None,
        hidden_state: HiddenState = None,
        stochastic_output: bool = False,
    ) -> torch.Tensor:
        """As MLPModel's: the mean (or value); a sample of the distribution when ``stochastic_output``."""
        obs = unpad_trajectories(obs, masks) if masks is not None else obs
        out = self.compute(obs)
        if self.distribution is not None:
            if stochastic_output:
                self.distribution.update(out)
                return self.distribution.sample()
            return self.distribution.deterministic_output(out)
        return out

    def get_latent(
        self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: HiddenState = None
    ) -> torch.Tensor:
        """Not a flat-latent model."""
        raise NotImplementedError(f"{type(self).__name__} has no flat latent; call the model.")

    def update_normalization(self, obs: TensorDict) -> None:
        """No observation normaliser (no-op)."""

    def as_jit(self) -> nn.Module:
        """Not supported by default; a subclass that can be exported overrides it."""
        raise NotImplementedError(f"{type(self).__name__} cannot be exported to TorchScript.")

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """Not supported by default; a subclass that can be exported overrides it."""
        raise NotImplementedError(f"{type(self).__name__} cannot be exported to ONNX.")
