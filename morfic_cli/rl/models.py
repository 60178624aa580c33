"""Actor and critic models of the MorFiC variants (docs/training.md; paper Sec. "MorFiC").

Sizes follow the paper's Tables "architecture" and "conditioning variants". Both classes subclass rsl-rl's
:class:`~rsl_rl.models.MLPModel`, so PPO, the rollout storage and the runner use them unchanged; rsl-rl resolves them
from ``class_name`` strings (``"morfic_cli.rl.models:MorficActor"``); which variant uses which configuration is
the registry's (:mod:`morfic_cli.rl.variants`). Observation groups (N = batch):

- ``history`` (N, 16, 48): noisy [h_t, o_t] = o_{t-15..t}, flattened to (N, 768) — the actor's state (15 frames,
  720, for runs recorded with ``history_includes_current``).
- ``critic`` (N, 16, 48): the same history, clean — the critic's state.
- ``privileged`` (N, 18): p_t, encoded by the critic into z_priv.
- ``morphology`` (N, 11): the normalised descriptor m, encoded into z_m = f_psi(m).

Actor (every variant): ``a = pi([h_t, dropout(z_priv_hat), z_m])`` with ``z_priv_hat = adaptation(h_t)``; ``ppo``
leaves z_m out. Critic: ``V = trunk([h_t^clean, z_priv])`` with the conditioning of the variant on z_m:

============  ===============================================================================
conditioning  per hidden layer l (pre-activation, x = layer input, h = W x + b)
============  ===============================================================================
none          h
concat        none per layer; z_m is appended to the trunk input, eq. (add)
film          h (1 + s gamma_l(z_m)) + s beta_l(z_m), eq. (film) in residual form
adaln         LN(h) (1 + s gamma_l(z_m)) + s beta_l(z_m), eq. (adaln) in residual form
hyper         W x + b + s B_l(z_m) A_l(z_m) x, rank r: the conditioning-variants table's low-rank adapter
hyper_head    hidden layers unconditioned; the head V = A_m h + c_m, (A_m, c_m) = H_eta(z_m), eq. (hyper)
============  ===============================================================================

Each modulation is followed by the trunk activation (ELU). The generators' last layers (FiLM's gamma/beta, hyper's
B, the head generator) are zero-initialised, so at initialisation every conditioned critic computes exactly its
unconditioned trunk. ``hyper_head`` is MorFiC-H (``model.hyper_conditions = "head"``); ``hyper`` is kept for runs
trained with it and as the other reading of the paper.

Encoder sharing (``model.shared_morphology_encoder``, default on): the actor owns the one morphology encoder f_psi;
the critic is built with ``shared_morphology_encoder=True`` and no encoder of its own, and
:func:`link_morphology_encoder` (called by MorficPPO and by the model loader) points it at the actor's. So the
encoder's parameters are in ``actor.parameters()`` once: one Adam update per step, clipped with the actor's
gradients, saved in the actor's state dict (export needs it there). The actor caches z_m per observation tensor, so
when PPO calls ``actor(obs)`` and ``critic(obs)`` on one mini-batch both receive the same z_m tensor object, and the
single ``loss.backward()`` of ``surrogate + c_v value_loss - c_e entropy`` sends both the policy and the value
gradients into f_psi (tested). With ``shared_morphology_encoder=False`` (runs before the option) each network owns
an encoder: the actor's trained by the policy losses only, the critic's by the value loss only.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, TypedDict

import torch
import torch.nn as nn
from rsl_rl.models import MLPModel
from rsl_rl.modules import MLP, HiddenState
from rsl_rl.utils import unpad_trajectories
from tensordict import TensorDict

from morfic_cli.errors import UnknownNameError

#: Critic conditioning kinds of :class:`MorficCritic` (a subclass may add its own by overriding ``make_modulator``).
CONDITIONINGS: tuple[str, ...] = ("none", "concat", "film", "adaln", "hyper", "hyper_head")


def flatten_groups(obs: TensorDict, groups: list[str]) -> torch.Tensor:
    """Concatenate observation groups, each flattened past the batch dimension.

    Args:
        obs: Observation groups; e.g. ``history`` of shape (N, 16, 48).
        groups: Group names, in order.

    Returns:
        Shape: (N, sum of the groups' per-sample sizes), e.g. (N, 768) for ``["history"]``.
    """
    return torch.cat([obs[g].flatten(start_dim=1) for g in groups], dim=-1)


def _state_groups(
    obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str, role_groups: list[str | None]
) -> tuple[list[str], int]:
    """Split a model's groups into the state groups (flattened, normalised) and its role groups (encoded apart).

    Returns:
        The state groups in config order and their flattened size (e.g. (["history"], 768)).
    """
    active = list(obs_groups[obs_set])
    roles = [g for g in role_groups if g is not None]
    for g in roles:
        if g not in active:
            raise ValueError(f"obs_groups['{obs_set}'] = {active} must list the group '{g}' this model encodes.")
    state = [g for g in active if g not in roles]
    if not state:
        raise ValueError(f"obs_groups['{obs_set}'] = {active} has no state group besides {roles}.")
    return state, sum(obs[g][0].numel() for g in state)


def _zero_last_linear(mlp: nn.Module) -> None:
    """Zero-initialise the weight and bias of the last ``nn.Linear`` of ``mlp`` (the generator output layer)."""
    last = [m for m in mlp.modules() if isinstance(m, nn.Linear)][-1]
    nn.init.zeros_(last.weight)
    nn.init.zeros_(last.bias)


class ModulatorCfg(TypedDict):
    """What sizes a critic's conditioning modules (``MorficCritic.modulator_cfg``)."""

    latent_dim: int
    generator_hidden_dim: int
    scale: float
    rank: int
    activation: str


class FiLM(nn.Module):
    """Residual FiLM of one hidden layer, eq. (film): ``h <- h (1 + s gamma(z_m)) + s beta(z_m)``.

    The generator is ``z_m (64) -> 128 -> 2H`` (ELU) with its last layer zero-initialised, so gamma = beta = 0 and
    the layer is unconditioned at initialisation. ``s`` is ``conditioning_scale`` (``model.film_scale``, 0.1 for
    ``film`` and ``film-scaled``, paper Table "architecture"; 1 for ``adaln``).
    """

    def __init__(
        self, latent_dim: int, hidden_dim: int, generator_hidden_dim: int, scale: float, activation: str
    ) -> None:
        super().__init__()
        self.scale = scale
        self.norm: nn.Module = nn.Identity()
        self.generator = MLP(latent_dim, 2 * hidden_dim, [generator_hidden_dim], activation)
        _zero_last_linear(self.generator)

    def forward(self, linear: nn.Linear, x: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """Modulated pre-activation of one trunk layer.

        Args:
            linear: The trunk layer (W, b).
            x: Layer input. Shape: (N, D_in).
            z_m: Morphology latent, or None for the unconditioned trunk. Shape: (N, 64).

        Returns:
            Shape: (N, H).
        """
        h = self.norm(linear(x))
        if z_m is None:
            return h
        gamma, beta = self.generator(z_m).chunk(2, dim=-1)
        return h * (1.0 + self.scale * gamma) + self.scale * beta


class AdaLN(FiLM):
    """AdaLN of one hidden layer, eq. (adaln): ``h <- LN(h)``, then residual FiLM.

    The LayerNorm keeps its own (learnable) affine; the FiLM modulation on top starts at zero like :class:`FiLM`.
    """

    def __init__(
        self, latent_dim: int, hidden_dim: int, generator_hidden_dim: int, scale: float, activation: str
    ) -> None:
        super().__init__(latent_dim, hidden_dim, generator_hidden_dim, scale, activation)
        self.norm = nn.LayerNorm(hidden_dim)


class LowRankAdapter(nn.Module):
    """Hypernetwork conditioning of one hidden layer, eq. (hyper), as a residual low-rank adapter.

    ``h <- W x + b + s B(z_m) A(z_m) x`` with ``A(z_m)`` of shape (r, D_in) and ``B(z_m)`` of shape (H, r), both
    generated per sample by ``z_m (64) -> 128 -> numel`` MLPs (ELU). B's generator ends in a zero-initialised layer,
    so the adapter is exactly zero at initialisation. Memory: the generated matrices take
    ``N * r * (D_in + H)`` floats per layer.
    """

    def __init__(
        self,
        latent_dim: int,
        in_dim: int,
        out_dim: int,
        rank: int,
        generator_hidden_dim: int,
        scale: float,
        activation: str,
    ) -> None:
        super().__init__()
        self.scale = scale
        self.generator_a = MLP(latent_dim, (rank, in_dim), [generator_hidden_dim], activation)
        self.generator_b = MLP(latent_dim, (out_dim, rank), [generator_hidden_dim], activation)
        _zero_last_linear(self.generator_b)

    def forward(self, linear: nn.Linear, x: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """Adapted pre-activation of one trunk layer.

        Args:
            linear: The trunk layer (W, b).
            x: Layer input. Shape: (N, D_in).
            z_m: Morphology latent, or None for the unconditioned trunk. Shape: (N, 64).

        Returns:
            Shape: (N, H).
        """
        h = linear(x)
        if z_m is None:
            return h
        a_z = self.generator_a(z_m)  # (N, r, D_in)
        b_z = self.generator_b(z_m)  # (N, H, r)
        u = torch.einsum("nri,ni->nr", a_z, x)
        return h + self.scale * torch.einsum("nhr,nr->nh", b_z, u)


class HyperHead(nn.Module):
    """The hypernetwork-generated value head of MorFiC-H, eq. (hyper): ``V = A_m h + c_m``, ``(A_m, c_m) = H_eta(z_m)``.

    ``A_m = A_0 + s k(z_m) U`` and ``c_m = c_0 + s k_c(z_m)``: (A_0, c_0) is the trunk's last ``nn.Linear`` (a learned
    base head), U a learned (r, H) basis, and ``[k, k_c] = G(z_m)`` a ``z_m (64) -> 128 -> O (r + 1)`` MLP (ELU)
    whose last layer is zero-initialised, so ``A_m = A_0`` and ``c_m = c_0`` at initialisation. So the head's
    weights move in a rank-r (16) subspace per morphology, scaled by s (0.1), the appendix's "low-rank, rank 16,
    scale 0.1" applied to the head. Shapes: h (N, H), z_m (N, 64) -> V (N, O), O = 1.
    """

    def __init__(
        self,
        latent_dim: int,
        in_dim: int,
        out_dim: int,
        rank: int,
        generator_hidden_dim: int,
        scale: float,
        activation: str,
    ) -> None:
        super().__init__()
        self.scale, self.rank, self.out_dim = scale, rank, out_dim
        self.basis = nn.Parameter(torch.empty(rank, in_dim))
        nn.init.orthogonal_(self.basis)
        self.generator = MLP(latent_dim, out_dim * (rank + 1), [generator_hidden_dim], activation)
        _zero_last_linear(self.generator)

    def weights(self, linear: nn.Linear, z_m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(A_m, c_m) per sample. Shapes: (N, O, H), (N, O)."""
        g = self.generator(z_m).view(-1, self.out_dim, self.rank + 1)
        a_m = linear.weight + self.scale * torch.einsum("nor,rh->noh", g[..., : self.rank], self.basis)
        return a_m, linear.bias + self.scale * g[..., self.rank]

    def forward(self, linear: nn.Linear, h: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """V = A_m h + c_m, computed without forming A_m. Shapes: (N, H), (N, 64) -> (N, O)."""
        v = linear(h)
        if z_m is None:
            return v
        g = self.generator(z_m).view(-1, self.out_dim, self.rank + 1)
        u = h @ self.basis.T  # (N, r)
        return v + self.scale * (torch.einsum("nor,nr->no", g[..., : self.rank], u) + g[..., self.rank])


class MorficActor(MLPModel):
    """Policy ``pi(a | h_t, z_priv_hat, z_m)``: an rsl-rl MLPModel whose MLP input is built from three parts.

    ``latent = [s, dropout(sg(z_priv_hat)), z_m]`` (sg = stop-gradient) with

    - ``s``: the flattened (optionally normalised) state groups, e.g. ``history`` -> (N, 768);
    - ``z_priv_hat = adaptation(s)`` (N, 16): trained only by MorficPPO's regression to the critic's z_priv, so the
      policy loss does not reach the adaptation module;
    - ``z_m = f_psi(m)`` (N, 64): the actor's own morphology encoder, left out when ``morphology_group`` is None
      (variant ``ppo``).

    The MLP head, the output distribution (``distribution_cfg``), sampling, log-probabilities, entropy and KL are
    MLPModel's, unchanged. Latent dropout (p = 0.2) acts in train mode — the runner keeps the actor in train mode
    during rollouts too, so the behaviour policy also sees dropped latents; ``eval()`` (inference, export) disables it.
    """

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        hidden_dims: tuple[int, ...] | list[int] = (512, 256, 128),
        activation: str = "elu",
        obs_normalization: bool = False,
        distribution_cfg: dict | None = None,
        morphology_group: str | None = None,
        morphology_hidden_dims: tuple[int, ...] | list[int] = (128,),
        morphology_latent_dim: int = 64,
        adaptation_hidden_dims: tuple[int, ...] | list[int] = (256, 128),
        privileged_latent_dim: int = 16,
        latent_dropout: float = 0.2,
    ) -> None:
        """Build the actor.

        Args:
            obs: Example observations (shapes only).
            obs_groups: Observation sets -> groups; ``obs_groups[obs_set]`` lists the state groups and, when used,
                ``morphology_group``.
            obs_set: This model's set (``"actor"``).
            output_dim: Number of actions (12).
            hidden_dims: Policy MLP widths.
            activation: Activation of every MLP.
            obs_normalization: Normalise the flattened state with running statistics.
            distribution_cfg: Output distribution, as for MLPModel (Gaussian, init std 1.0).
            morphology_group: Group holding m (N, 11), or None for no z_m (variant ``ppo``).
            morphology_hidden_dims: Hidden widths of the morphology encoder (11 -> 128 -> 64).
            morphology_latent_dim: Size of z_m.
            adaptation_hidden_dims: Hidden widths of the adaptation module (768 -> 256 -> 128 -> 16).
            privileged_latent_dim: Size of z_priv_hat; must equal the critic's z_priv size.
            latent_dropout: Dropout probability on z_priv_hat in the policy input during training.
        """
        # Read by the _get_obs_dim / _get_latent_dim hooks that MLPModel.__init__ calls (as rsl-rl's CNNModel does).
        self.morphology_group = morphology_group
        self.privileged_latent_dim = privileged_latent_dim
        self.morphology_latent_dim = morphology_latent_dim if morphology_group is not None else 0
        super().__init__(
            obs, obs_groups, obs_set, output_dim, hidden_dims, activation, obs_normalization, distribution_cfg
        )
        self.adaptation = MLP(self.obs_dim, privileged_latent_dim, adaptation_hidden_dims, activation)
        self.latent_dropout = nn.Dropout(latent_dropout)
        self.morphology_dim = obs[morphology_group].shape[-1] if morphology_group is not None else 0
        self.morphology_encoder: MLP | None = (
            MLP(self.morphology_dim, morphology_latent_dim, morphology_hidden_dims, activation)
            if morphology_group is not None
            else None
        )
        self._z_cache: tuple | None = None

    def get_latent(
        self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: HiddenState = None
    ) -> torch.Tensor:
        """The policy MLP input ``[s, dropout(sg(z_priv_hat)), z_m]``. Shape: (N, D_s + 16 + 64)."""
        state = self.get_state(obs)
        parts = [state, self.latent_dropout(self.adaptation(state).detach())]
        if self.morphology_encoder is not None:
            parts.append(self.encode_morphology(obs))
        return torch.cat(parts, dim=-1)

    def get_state(self, obs: TensorDict) -> torch.Tensor:
        """The flattened, optionally normalised state groups. Shape: (N, D_s), D_s = 768 for ``history``."""
        return self.obs_normalizer(flatten_groups(obs, self.obs_groups))

    def estimate_privileged(self, obs: TensorDict) -> torch.Tensor:
        """z_priv_hat = adaptation(s), with gradient, without dropout (the regression input). Shape: (N, 16)."""
        return self.adaptation(self.get_state(obs))

    def encode_morphology(self, obs: TensorDict) -> torch.Tensor:
        """z_m = f_psi(m). Shape: (N, 64).

        Called twice on the same observations (``actor(obs)`` then a sharing ``critic(obs)``), it returns the same
        tensor object: one z_m, one node of the autograd graph. The cache holds one entry, keyed by the ``m``
        tensor object and its version, the grad / inference mode and the encoder's parameter versions (an
        optimiser step invalidates it), and is dropped when a backward pass has gone through z_m (its graph is
        freed then).
        """
        if self.morphology_encoder is None:
            raise ValueError("this actor has no morphology encoder (morphology_group is None).")
        m = obs[self.morphology_group]
        key = (
            0 if m.is_inference() else m._version,
            torch.is_grad_enabled(),
            torch.is_inference_mode_enabled(),
            tuple(p._version for p in self.morphology_encoder.parameters()),
        )
        cached = self._z_cache
        if cached is not None and cached[0] is m and cached[1] == key:
            return cached[2]
        z_m = self.morphology_encoder(m)
        self._z_cache = (m, key, z_m)
        if z_m.requires_grad:
            z_m.register_hook(self._drop_z_cache)
        return z_m

    def _drop_z_cache(self, grad: torch.Tensor) -> None:
        self._z_cache = None

    def update_normalization(self, obs: TensorDict) -> None:
        """Update the state normaliser from a batch of observations (no-op without ``obs_normalization``)."""
        if self.obs_normalization:
            self.obs_normalizer.update(flatten_groups(obs, self.obs_groups))

    def export_input(self, obs: TensorDict) -> torch.Tensor:
        """The flat input of :meth:`as_jit` / :meth:`as_onnx`: ``[state groups..., m]``. Shape: (N, D_s + 11)."""
        groups = self.obs_groups + ([self.morphology_group] if self.morphology_group is not None else [])
        return flatten_groups(obs, groups)

    def as_jit(self) -> nn.Module:
        """A TorchScript-able deterministic policy on :meth:`export_input`."""
        return _ExportedActor(self)

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """An ONNX-exportable deterministic policy on :meth:`export_input`."""
        return _ExportedActor(self, verbose)

    def _get_obs_dim(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str) -> tuple[list[str], int]:
        """State groups (everything but ``morphology_group``) and their flattened size."""
        return _state_groups(obs, obs_groups, obs_set, [self.morphology_group])

    def _get_latent_dim(self) -> int:
        """D_s + |z_priv_hat| + |z_m|."""
        return self.obs_dim + self.privileged_latent_dim + self.morphology_latent_dim


class MorficCritic(MLPModel):
    """Value function ``V(h_t^clean, z_priv; z_m)``: an rsl-rl MLPModel whose trunk is conditioned on z_m.

    ``V = trunk([s, z_priv (, z_m if concat)])`` with ``s`` the flattened clean history (N, 768) and
    ``z_priv = g(p_t)`` (N, 16). The trunk is MLPModel's ``self.mlp`` (rsl-rl :class:`~rsl_rl.modules.MLP`, layers
    ``Linear, act, ..., Linear``); :meth:`trunk` runs it layer by layer and applies one modulator per hidden layer
    (:class:`FiLM`, :class:`AdaLN` or :class:`LowRankAdapter`). The critic's morphology encoder exists only when the
    conditioning uses z_m, so for ``none`` the value loss cannot depend on the morphology.
    """

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        hidden_dims: tuple[int, ...] | list[int] = (512, 256, 128),
        activation: str = "elu",
        obs_normalization: bool = False,
        privileged_group: str = "privileged",
        privileged_hidden_dims: tuple[int, ...] | list[int] = (64,),
        privileged_latent_dim: int = 16,
        morphology_group: str | None = None,
        morphology_hidden_dims: tuple[int, ...] | list[int] = (128,),
        morphology_latent_dim: int = 64,
        conditioning: str = "none",
        conditioning_scale: float = 1.0,
        hyper_rank: int = 16,
        generator_hidden_dim: int = 128,
        shared_morphology_encoder: bool = False,
    ) -> None:
        """Build the critic.

        Args:
            obs: Example observations (shapes only).
            obs_groups: Observation sets -> groups; ``obs_groups[obs_set]`` lists the state groups,
                ``privileged_group`` and, when conditioned, ``morphology_group``.
            obs_set: This model's set (``"critic"``).
            output_dim: 1 (the value).
            hidden_dims: Trunk widths ([512, 256, 128]; [1024, 512, 256] for ``film-scaled``).
            activation: Activation of every MLP.
            obs_normalization: Normalise the flattened state with running statistics.
            privileged_group: Group holding p_t (N, 18).
            privileged_hidden_dims: Hidden widths of the privileged encoder (18 -> 64 -> 16).
            privileged_latent_dim: Size of z_priv.
            morphology_group: Group holding m (N, 11); required by every conditioning but ``none``, which forbids it.
            morphology_hidden_dims: Hidden widths of the morphology encoder (11 -> 128 -> 64).
            morphology_latent_dim: Size of z_m.
            conditioning: One of :data:`CONDITIONINGS`, or a subclass's own (with its ``make_modulator``).
            conditioning_scale: s in the FiLM / AdaLN / hyper update.
            hyper_rank: Rank r of the hyper adapter / head basis.
            generator_hidden_dim: Hidden width of the FiLM / hyper generators (64 -> 128 -> ...).
            shared_morphology_encoder: Own no encoder; z_m comes from the actor's after
                :func:`link_morphology_encoder` (``morphology_hidden_dims`` / ``morphology_latent_dim`` must match
                the actor's).
        """
        if conditioning not in CONDITIONINGS and type(self).make_modulator is MorficCritic.make_modulator:
            raise UnknownNameError("conditioning", conditioning, CONDITIONINGS)
        if (conditioning == "none") != (morphology_group is None):
            raise ValueError(
                f"conditioning '{conditioning}' needs morphology_group "
                + ("None." if conditioning == "none" else "set (e.g. 'morphology').")
            )
        # Read by the _get_obs_dim / _get_latent_dim hooks that MLPModel.__init__ calls (as rsl-rl's CNNModel does).
        self.privileged_group = privileged_group
        self.morphology_group = morphology_group
        self.privileged_latent_dim = privileged_latent_dim
        self.conditioning = conditioning
        self.concat_dim = morphology_latent_dim if conditioning == "concat" else 0
        super().__init__(obs, obs_groups, obs_set, output_dim, hidden_dims, activation, obs_normalization)
        self.privileged_encoder = MLP(
            obs[privileged_group].shape[-1], privileged_latent_dim, privileged_hidden_dims, activation
        )
        self.uses_morphology = morphology_group is not None
        self.shared_morphology_encoder = shared_morphology_encoder and self.uses_morphology
        self._shared_source: tuple[MorficActor, ...] = ()  # a tuple: not a registered submodule
        self.morphology_encoder: MLP | None = (
            MLP(obs[morphology_group].shape[-1], morphology_latent_dim, morphology_hidden_dims, activation)
            if self.uses_morphology and not self.shared_morphology_encoder
            else None
        )
        self.modulator_cfg: ModulatorCfg = {
            "latent_dim": morphology_latent_dim,
            "generator_hidden_dim": generator_hidden_dim,
            "scale": conditioning_scale,
            "rank": hyper_rank,
            "activation": activation,
        }
        self.modulators: nn.ModuleList | None = None
        self.head: HyperHead | None = None
        linears = [m for m in self.mlp if isinstance(m, nn.Linear)]
        if conditioning == "hyper_head":
            c = self.modulator_cfg
            self.head = HyperHead(
                c["latent_dim"],
                linears[-1].in_features,
                linears[-1].out_features,
                c["rank"],
                c["generator_hidden_dim"],
                c["scale"],
                c["activation"],
            )
        elif conditioning not in ("none", "concat"):
            self.modulators = nn.ModuleList(self.make_modulator(lin) for lin in linears[:-1])

    def make_modulator(self, linear: nn.Linear) -> nn.Module:
        """The conditioning module of one hidden trunk layer (called once per layer, input to output).

        A user variant overrides this (docs/extending.md). The module is called as ``modulator(linear, x, z_m)``
        with x the layer input (N, D_in) and z_m (N, 64), and returns the modulated pre-activation (N, H);
        the trunk activation follows. ``self.modulator_cfg`` holds ``latent_dim``, ``generator_hidden_dim``,
        ``scale``, ``rank`` and ``activation``.

        Args:
            linear: The trunk layer (W, b); its ``in_features`` / ``out_features`` size the module.
        """
        c = self.modulator_cfg
        if self.conditioning in ("film", "adaln"):
            cls = FiLM if self.conditioning == "film" else AdaLN
            return cls(c["latent_dim"], linear.out_features, c["generator_hidden_dim"], c["scale"], c["activation"])
        if self.conditioning == "hyper":
            return LowRankAdapter(
                c["latent_dim"],
                linear.in_features,
                linear.out_features,
                c["rank"],
                c["generator_hidden_dim"],
                c["scale"],
                c["activation"],
            )
        raise ValueError(f"conditioning '{self.conditioning}' has no modulator; override make_modulator.")

    def forward(
        self,
        obs: TensorDict,
        masks: torch.Tensor | None = None,
        hidden_state: HiddenState = None,
        stochastic_output: bool = False,
    ) -> torch.Tensor:
        """The value V(s_t, z_m). Shape: (N, 1)."""
        obs = unpad_trajectories(obs, masks) if masks is not None and not self.is_recurrent else obs
        z_m = self.encode_morphology(obs) if self.uses_morphology else None
        return self.trunk(self._latent(obs, z_m), z_m)

    def trunk(self, latent: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """Run the trunk on ``latent``, modulating every hidden layer by z_m; ``z_m=None`` runs it unconditioned.

        Args:
            latent: Trunk input [s, z_priv (, z_m)]. Shape: (N, D).
            z_m: Morphology latent. Shape: (N, 64).

        Returns:
            Shape: (N, 1).
        """
        x = self.features(latent, z_m)
        last = self.mlp[-1]
        return self.head(last, x, z_m) if self.head is not None else last(x)

    def features(self, latent: torch.Tensor, z_m: torch.Tensor | None) -> torch.Tensor:
        """The last hidden layer h_t of the trunk (modulated by z_m where the conditioning does). Shape: (N, H)."""
        layers = list(self.mlp)[:-1]
        if self.modulators is None:
            x = latent
            for layer in layers:
                x = layer(x)
            return x
        x = latent
        for i, modulator in enumerate(self.modulators):
            linear, act = layers[2 * i], layers[2 * i + 1]
            x = act(modulator(linear, x, z_m))
        return x

    def get_latent(
        self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: HiddenState = None
    ) -> torch.Tensor:
        """The trunk input ``[s, z_priv (, z_m for concat)]``. Shape: (N, D_s + 16 (+ 64))."""
        z_m = self.encode_morphology(obs) if self.concat_dim else None
        return self._latent(obs, z_m)

    def get_state(self, obs: TensorDict) -> torch.Tensor:
        """The flattened, optionally normalised clean history. Shape: (N, D_s), D_s = 768."""
        return self.obs_normalizer(flatten_groups(obs, self.obs_groups))

    def encode_privileged(self, obs: TensorDict) -> torch.Tensor:
        """z_priv = g(p_t), the adaptation target. Shape: (N, 16)."""
        return self.privileged_encoder(obs[self.privileged_group])

    def encode_morphology(self, obs: TensorDict) -> torch.Tensor:
        """z_m = f_psi(m): the actor's (shared encoder, the same tensor the actor got) or the critic's own. (N, 64)."""
        if not self.uses_morphology:
            raise ValueError("this critic has no morphology encoder (conditioning 'none').")
        if self.shared_morphology_encoder:
            if not self._shared_source:
                raise ValueError(
                    "this critic shares the actor's morphology encoder; call "
                    "link_morphology_encoder(actor, critic) first."
                )
            return self._shared_source[0].encode_morphology(obs)
        return self.morphology_encoder(obs[self.morphology_group])  # type: ignore[misc]

    def update_normalization(self, obs: TensorDict) -> None:
        """Update the state normaliser from a batch of observations (no-op without ``obs_normalization``)."""
        if self.obs_normalization:
            self.obs_normalizer.update(flatten_groups(obs, self.obs_groups))

    def as_jit(self) -> nn.Module:
        """Not supported: only the policy is exported."""
        raise NotImplementedError("MorficCritic is not exported; export the actor.")

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        """Not supported: only the policy is exported."""
        raise NotImplementedError("MorficCritic is not exported; export the actor.")

    def _latent(self, obs: TensorDict, z_m: torch.Tensor | None) -> torch.Tensor:
        parts = [self.get_state(obs), self.encode_privileged(obs)]
        if self.concat_dim:
            if z_m is None:
                raise ValueError("a concat critic needs z_m (from encode_morphology).")
            parts.append(z_m)
        return torch.cat(parts, dim=-1)

    def _get_obs_dim(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str) -> tuple[list[str], int]:
        """State groups (everything but the privileged and morphology groups) and their flattened size."""
        return _state_groups(obs, obs_groups, obs_set, [self.privileged_group, self.morphology_group])

    def _get_latent_dim(self) -> int:
        """D_s + |z_priv| (+ |z_m| for concat)."""
        return self.obs_dim + self.privileged_latent_dim + self.concat_dim


def link_morphology_encoder(actor: nn.Module, critic: nn.Module) -> None:
    """Point a sharing critic (``shared_morphology_encoder=True``) at the actor's morphology encoder; else no-op.

    Raises:
        ValueError: The critic shares but the actor has no encoder, or the latent sizes differ.
    """
    if not (isinstance(critic, MorficCritic) and critic.shared_morphology_encoder):
        return
    if not isinstance(actor, MorficActor) or actor.morphology_encoder is None:
        raise ValueError("the critic shares the actor's morphology encoder, but the actor has none.")
    if critic.modulator_cfg["latent_dim"] != actor.morphology_latent_dim:
        raise ValueError(
            f"critic z_m size {critic.modulator_cfg['latent_dim']} != actor z_m size {actor.morphology_latent_dim}."
        )
    critic._shared_source = (actor,)


class ExportedPolicy(nn.Module):
    """What every exported policy module shares: one flat input ``obs``, one output ``actions``, no recurrent state.

    TorchScript, ONNX and rsl-rl's exporter read these. A subclass sets ``input_size`` and defines ``forward``.
    """

    is_recurrent: bool = False
    if TYPE_CHECKING:  # for mypy only: TorchScript cannot read this module's string annotations
        input_size: int  # width of the flat input ``obs`` (set by the subclass)
    __jit_unused_properties__ = ["input_names", "output_names"]

    @torch.jit.export
    def reset(self) -> None:
        """Reset recurrent state (no-op)."""

    def get_dummy_inputs(self) -> tuple[torch.Tensor]:
        """A zero input for ONNX tracing. Shape: (1, input_size)."""
        return (torch.zeros(1, self.input_size),)

    @property
    def input_names(self) -> list[str]:
        """ONNX input names."""
        return ["obs"]

    @property
    def output_names(self) -> list[str]:
        """ONNX output names."""
        return ["actions"]


class _ExportedActor(ExportedPolicy):
    """Deterministic policy on one flat input ``[state groups..., m]`` for TorchScript and ONNX export.

    Shape: (N, D_s + 11) -> (N, 12) (D_s + 0 for ``ppo``). No dropout (export is inference).
    """

    def __init__(self, model: MorficActor, verbose: bool = False) -> None:
        super().__init__()
        self.verbose = verbose
        self.state_dim = model.obs_dim
        self.morphology_dim = model.morphology_dim
        self.input_size = model.obs_dim + model.morphology_dim
        self.obs_normalizer = copy.deepcopy(model.obs_normalizer)
        self.adaptation = copy.deepcopy(model.adaptation)
        self.morphology_encoder = (
            copy.deepcopy(model.morphology_encoder) if model.morphology_encoder is not None else nn.Identity()
        )
        self.mlp = copy.deepcopy(model.mlp)
        self.deterministic_output = (
            model.distribution.as_deterministic_output_module() if model.distribution is not None else nn.Identity()
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Actions (distribution mean) from the flat input. Shape: (N, D_s + 11) -> (N, 12)."""
        state = self.obs_normalizer(x[:, : self.state_dim])
        parts = [state, self.adaptation(state)]
        if self.morphology_dim > 0:
            parts.append(self.morphology_encoder(x[:, self.state_dim :]))
        return self.deterministic_output(self.mlp(torch.cat(parts, dim=-1)))
