"""MorFiC's PPO: rsl-rl PPO plus the adaptation-module regression and per-update critic metrics (docs/training.md).

PPO's loss, its mini-batch loop, the adaptive learning rate and the rollout storage are rsl-rl's, untouched.
:class:`MorficPPO` adds, per PPO mini-batch and right after PPO's optimiser step on it:

- one step of a separate optimiser on the adaptation loss
  ``L_adapt = c_adapt * || z_priv_hat(h_t) - sg(z_priv(p_t)) ||^2`` (mean over batch and latent), where z_priv comes
  from the critic's privileged encoder and sg is stop-gradient; only the actor's adaptation module moves;
- the KL and clip-fraction diagnostics of that mini-batch, read from the distribution PPO's loss just used.

It hooks in by wrapping the storage's mini-batch generator for the duration of ``update()`` (the code after each
``yield`` runs when PPO asks for the next mini-batch), so no line of PPO's loss is copied here; that wrap and the
other reaches into rsl-rl internals are in :mod:`morfic_cli.rl.rsl_rl_patches`.

Mixed precision (``use_mixed_precision``, rsl-rl's flag; the ``cpu`` preset turns it on): rsl-rl runs the update's
forward passes under bf16 autocast; MorficPPO also runs the rollout's ``act`` and the bootstrap value of
``compute_returns`` under it, so the log-probabilities of the ratio pi_theta / pi_old are computed the same way on
both sides, and keeps the two output layers (the action mean and the value) in float32, so actions, log-probabilities
and values are not rounded to bf16's 8 bits (docs/benchmarks-history.md, "The levers, each measured alone").
Weights, gradients and Adam's state stay float32. The optimiser is Adam with ``fused=True`` (one kernel over all
parameters instead of a Python loop).
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator

import torch
import torch.nn as nn
from rsl_rl.algorithms import PPO
from rsl_rl.storage import RolloutStorage
from rsl_rl.utils import reduce_gradients_in_buckets, resolve_optimizer
from tensordict import TensorDict

from morfic_cli.diagnostics.metrics import explained_variance  # the one EV; imported here for the training loss
from morfic_cli.rl.models import MorficActor, MorficCritic, link_morphology_encoder
from morfic_cli.rl.precision import bf16_matmul, cpu_bf16_kernels, matmul_region
from morfic_cli.rl.rsl_rl_patches import raw_models, tapped_mini_batches

ALGORITHM_CLASS = "morfic_cli.rl.ppo:MorficPPO"

#: Keys MorficPPO adds to rsl-rl's loss dict (logged per update as ``Loss/<key>``).
EXTRA_LOSS_KEYS: tuple[str, ...] = ("explained_variance", "value_loss", "kl", "clip_fraction", "adaptation_error")


def algorithm_cfg() -> dict:
    """The runner config's ``algorithm`` entry with the paper's PPO hyperparameters (Table "PPO hyperparameters").

    Returns:
        A fresh dict with ``class_name`` "morfic_cli.rl.ppo:MorficPPO".
    """
    return {
        "class_name": ALGORITHM_CLASS,
        "optimizer": "adam",
        "learning_rate": 1.0e-3,
        "schedule": "adaptive",
        "desired_kl": 0.01,
        "num_learning_epochs": 5,
        "num_mini_batches": 4,
        "clip_param": 0.2,
        "gamma": 0.99,
        "lam": 0.95,
        "value_loss_coef": 1.0,
        "use_clipped_value_loss": True,
        "entropy_coef": 0.01,
        "max_grad_norm": 1.0,
        "adaptation_loss_coef": 1.0,
        "adaptation_learning_rate": None,
    }


class _UpdateStats:
    """Per-mini-batch sums of the extra metrics, kept as tensors so the device syncs once per update."""

    def __init__(self) -> None:
        self.count = 0
        self.kl = torch.zeros(())
        self.clip_fraction = torch.zeros(())
        self.adaptation_error = torch.zeros(())

    def add(self, kl: torch.Tensor, clip_fraction: torch.Tensor, adaptation_error: torch.Tensor) -> None:
        self.count += 1
        self.kl = self.kl.to(kl.device) + kl.float()
        self.clip_fraction = self.clip_fraction.to(kl.device) + clip_fraction.float()
        self.adaptation_error = self.adaptation_error.to(kl.device) + adaptation_error.float()

    def means(self) -> dict[str, float]:
        n = max(self.count, 1)
        return {
            "kl": self.kl.item() / n,
            "clip_fraction": self.clip_fraction.item() / n,
            "adaptation_error": self.adaptation_error.item() / n,
        }


class _Float32Linear(nn.Linear):
    """``nn.Linear`` that always computes in float32, also inside a bf16 autocast region (same parameters)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        with torch.autocast(device_type=x.device.type, enabled=False):
            return super().forward(x.float())


def _output_layers(model: nn.Module) -> list[nn.Linear]:
    """The output layers to keep in float32: the last ``nn.Linear`` of a model's MLP head (action mean, or value).

    None for a model whose output layers compute in float32 themselves (``float32_outputs``: the external
    baselines, :mod:`morfic_cli.rl.external`).
    """
    if getattr(model, "float32_outputs", False):
        return []
    return [[m for m in model.get_submodule("mlp").modules() if isinstance(m, nn.Linear)][-1]]


class MorficPPO(PPO):
    """rsl-rl PPO with the adaptation regression and the per-update metrics of :data:`EXTRA_LOSS_KEYS`.

    Config keys (the runner config's ``algorithm`` entry): every rsl-rl PPO key, plus

    - ``adaptation_loss_coef`` (default 1.0): c_adapt; 0 stops training the adaptation module (the error is still
      logged). With Adam the coefficient mostly acts as an on/off switch; the step size is the learning rate.
    - ``adaptation_learning_rate`` (default None = PPO's initial ``learning_rate``): fixed learning rate of the
      adaptation optimiser (same optimiser type as PPO's, gradient-norm clipped to ``max_grad_norm``).

    Loss-dict entries added to rsl-rl's ``value``, ``surrogate`` and ``entropy``:

    - ``explained_variance``: :func:`explained_variance` of the rollout's raw returns vs the values stored at
      collection time (before this update).
    - ``value_loss``: PPO's value loss, the same number as ``value`` (clipped when ``use_clipped_value_loss``).
    - ``kl``: mean over mini-batches of the mean KL(pi_old || pi_theta), the analytic Gaussian KL rsl-rl's adaptive
      schedule uses, at the parameters PPO's loss saw on that mini-batch.
    - ``clip_fraction``: mean over mini-batches of the fraction of samples with ``|ratio - 1| > clip_param``.
    - ``adaptation_error``: mean over mini-batches of ``||z_priv_hat - z_priv||^2 / 16`` before each adaptation step.

    Models without an adaptation module (an actor without ``estimate_privileged`` or a critic without
    ``encode_privileged``: the external baselines) train with plain PPO; ``adaptation_error`` is then NaN.

    Only feed-forward models without symmetry augmentation are supported.
    """

    actor: MorficActor
    critic: MorficCritic
    optimizer: torch.optim.Optimizer
    adaptation_optimizer: torch.optim.Optimizer | None

    def __init__(
        self,
        actor: MorficActor,
        critic: MorficCritic,
        storage: RolloutStorage,
        adaptation_loss_coef: float = 1.0,
        adaptation_learning_rate: float | None = None,
        **kwargs,
    ) -> None:
        """Build PPO, then the adaptation optimiser.

        Args:
            actor: The policy; its adaptation module (``estimate_privileged``) is trained when it has one.
            critic: The value function; its privileged encoder (``encode_privileged``) gives the adaptation target.
            storage: rsl-rl rollout storage.
            adaptation_loss_coef: c_adapt.
            adaptation_learning_rate: Adaptation optimiser learning rate; None uses ``learning_rate``.
            **kwargs: rsl-rl PPO arguments (learning_rate, clip_param, ..., device, multi_gpu_cfg).
        """
        #: Whether the actor has an adaptation module to regress onto the critic's z_priv (not the baselines).
        self.adapts = hasattr(actor, "estimate_privileged") and hasattr(critic, "encode_privileged")
        if actor.is_recurrent or critic.is_recurrent:
            raise ValueError("MorficPPO supports feed-forward models only.")
        if kwargs.get("symmetry_cfg"):
            raise ValueError("MorficPPO does not support symmetry augmentation.")
        if self.adapts and actor.privileged_latent_dim != critic.privileged_latent_dim:
            raise ValueError(
                f"actor z_priv_hat size {actor.privileged_latent_dim} != critic z_priv size "
                f"{critic.privileged_latent_dim}."
            )
        link_morphology_encoder(actor, critic)  # one f_psi for both (model.shared_morphology_encoder)
        super().__init__(actor, critic, storage, **kwargs)
        #: How the bf16 matrix products run (morfic_cli/rl/precision.py); None without mixed precision.
        self.bf16_matmul = bf16_matmul(str(self.device), cpu_bf16_kernels()) if self.use_mixed_precision else None
        self.adaptation_loss_coef = adaptation_loss_coef
        self.adaptation_learning_rate = (
            adaptation_learning_rate if adaptation_learning_rate is not None else self.learning_rate
        )
        optimizer = resolve_optimizer(kwargs.get("optimizer", "adam"))
        fused = {"fused": True} if optimizer is torch.optim.Adam else {}
        if fused:  # rsl-rl's Adam, fused: same update, one kernel for all parameters
            self.optimizer = optimizer(self.optimizer.param_groups[0]["params"], lr=self.learning_rate, **fused)
        self.adaptation_optimizer = (
            optimizer(raw_models(self)[0].adaptation.parameters(), lr=self.adaptation_learning_rate, **fused)
            if self.adapts
            else None
        )

    @contextlib.contextmanager
    def _precision(self, autocast: bool = True) -> Iterator[None]:
        """Float32 output layers, and bf16 autocast when ``autocast``, while ``use_mixed_precision``; else nothing.

        The update passes ``autocast=False``: rsl-rl opens one autocast region per mini-batch itself, and an
        enclosing region, even a disabled one, would keep autocast's cache of bf16 weight copies alive across
        mini-batches (the cache is cleared when the outermost region exits), so every mini-batch would run on the
        weights of the first. On a CPU without bf16 kernels the region's bf16 matrix products, forward and
        backward, are computed in float32 from the bf16 operands (``bf16_matmul``, :mod:`morfic_cli.rl.precision`).
        """
        if not self.use_mixed_precision:
            yield
            return
        heads = [head for model in raw_models(self) for head in _output_layers(model)]
        classes = [type(h) for h in heads]
        for head in heads:
            head.__class__ = _Float32Linear
        try:
            region = (
                torch.autocast(device_type=torch.device(self.device).type, dtype=torch.bfloat16)
                if autocast
                else contextlib.nullcontext()
            )
            with region, matmul_region(self.bf16_matmul):
                yield
        finally:
            for head, cls in zip(heads, classes, strict=True):
                head.__class__ = cls

    def act(self, obs: TensorDict) -> torch.Tensor:
        """PPO's act (actions, values, log-probabilities of the rollout), in the update's precision."""
        with self._precision():
            return super().act(obs)

    def compute_returns(self, obs: TensorDict) -> None:
        """PPO's GAE returns; the bootstrap value in the same precision as the rollout's values."""
        with self._precision():
            super().compute_returns(obs)

    def update(self) -> dict[str, float]:
        """PPO's update (rsl-rl), with the adaptation steps and metrics interleaved per mini-batch.

        Returns:
            rsl-rl's loss dict plus :data:`EXTRA_LOSS_KEYS`.
        """
        storage = self.storage
        # Raw returns and the values stored at collection time; PPO only normalises the advantages.
        ev = explained_variance(storage.returns, storage.values)
        stats = _UpdateStats()
        with tapped_mini_batches(storage, functools.partial(self._tap_mini_batches, stats=stats)):
            with self._precision(autocast=False):  # rsl-rl autocasts each mini-batch; this adds float32 outputs
                loss_dict = super().update()
        loss_dict.update(stats.means())
        loss_dict["explained_variance"] = ev
        loss_dict["value_loss"] = loss_dict["value"]
        return loss_dict

    def save(self) -> dict:
        """PPO's checkpoint dict plus ``adaptation_optimizer_state_dict``."""
        saved = super().save()
        if self.adaptation_optimizer is not None:
            saved["adaptation_optimizer_state_dict"] = self.adaptation_optimizer.state_dict()
        return saved

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """PPO's load, plus the adaptation optimiser state when the optimiser is loaded and the checkpoint has it."""
        load_iteration = super().load(loaded_dict, load_cfg, strict)
        if (
            (load_cfg is None or load_cfg.get("optimizer"))
            and "adaptation_optimizer_state_dict" in loaded_dict
            and self.adaptation_optimizer is not None
        ):
            self.adaptation_optimizer.load_state_dict(loaded_dict["adaptation_optimizer_state_dict"])
        return load_iteration

    def _tap_mini_batches(
        self,
        generator: Callable[[int, int], Iterator[RolloutStorage.Batch]],
        num_mini_batches: int,
        num_epochs: int,
        stats: _UpdateStats,
    ) -> Iterator[RolloutStorage.Batch]:
        """Yield PPO's mini-batches; after PPO has stepped on one, record its metrics and step the adaptation loss."""
        for batch in generator(num_mini_batches, num_epochs):
            yield batch
            # PPO.update has run its loss, backward and optimiser step on `batch`; the actor's distribution is still
            # the one its loss used (PPO does no actor forward pass after the loss).
            kl, clip_fraction = self._policy_shift(batch)
            stats.add(kl, clip_fraction, self._adaptation_step(batch))

    def _policy_shift(self, batch: RolloutStorage.Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean KL(pi_old || pi_theta) and clip fraction of one mini-batch. Shapes: (), ()."""
        with torch.no_grad():
            n = batch.old_actions_log_prob.shape[0]
            new_params = tuple(p[:n] for p in self.actor.output_distribution_params)
            kl = self.actor.get_kl_divergence(batch.old_distribution_params, new_params).mean()
            log_prob = self.actor.get_output_log_prob(batch.actions)[:n]
            ratio = torch.exp(log_prob - batch.old_actions_log_prob.squeeze(-1))
            clip_fraction = ((ratio - 1.0).abs() > self.clip_param).float().mean()
        return kl, clip_fraction

    def _adaptation_step(self, batch: RolloutStorage.Batch) -> torch.Tensor:
        """One optimiser step on L_adapt for one mini-batch; returns the error before the step. Shape: ().

        NaN, and no step, for models without an adaptation module (the external baselines).
        """
        optimizer = self.adaptation_optimizer
        if not self.adapts or optimizer is None:
            return torch.full((), float("nan"))
        obs = batch.observations
        with torch.autocast(
            device_type=torch.device(self.device).type, enabled=self.use_mixed_precision, dtype=torch.bfloat16
        ):
            actor, critic = raw_models(self)
            with torch.no_grad():
                z_priv = critic.encode_privileged(obs)  # target: no gradient reaches the critic
            z_priv_hat = actor.estimate_privileged(obs)
            error = (z_priv_hat.float() - z_priv.float()).pow(2).mean()
        if self.adaptation_loss_coef > 0.0:
            params = list(actor.adaptation.parameters())
            optimizer.zero_grad()
            (self.adaptation_loss_coef * error).backward()
            if self.is_multi_gpu:
                reduce_gradients_in_buckets(params, self.gpu_world_size, self.grad_reduce_bucket_mb)
            nn.utils.clip_grad_norm_(params, self.max_grad_norm)
            optimizer.step()
            optimizer.zero_grad(set_to_none=True)
        return error.detach()
