"""``morfic critic-study``: the conditioning alone, with the policy held fixed (docs/metrics.md "Critic study").

The paper's fixed-rollout analysis scores critics that were trained beside their own actors, so a critic's score
mixes its conditioning with the data its own actor produced. This study removes the actor from the comparison and
replicates over actors:

1. each of several frozen actors (:data:`DEFAULT_ACTORS`: the three ``film`` seeds and the seed-0 ``actor-only``
   and ``concat`` runs) collects, at each command, a rollout on the *training* morphology distribution (``train``
   mode: the Go2 template with a descriptor drawn from the paper's support per env, the evaluation env's settings
   otherwise) and a rollout on every target robot (descriptor mode), with sampled actions and the observation
   groups every critic reads (:mod:`~morfic_cli.diagnostics.samples`);
2. for each actor, every variant's critic is built fresh (its own morphology encoder, not shared with an actor) and
   regressed on the standardised Monte-Carlo returns G of that actor's training rollouts in I_eps (every
   ``stride``-th step, pooled over the commands), all with the same optimiser, learning rate, mini-batches and data
   order for a given fit seed, **to convergence**: after each epoch the loss on ``val_envs`` validation envs
   decides early stopping (``patience`` epochs without an improvement of ``min_delta``, at most ``max_epochs``;
   the best epoch's weights are kept, :class:`EarlyStopping`, :func:`fit_critic`); a fit whose validation EV stays
   below ``min_ev``, or that early stopping did not end, is flagged (``converged`` False) and left out of every
   average;
3. each fit is scored on its actor's samples of every robot exactly as ``morfic diagnose`` scores a run's critic:
   EV, NVB, NVE, ASA and Flip against G, and CosGrad on the frozen actor (:func:`score_fits`), per command; ``train``
   rows are the last ``held_out`` envs of the training rollout (never fitted on nor used to stop).

The unit of replication is the actor: a cell's fits are averaged within each actor first, then over actors
(:mod:`~morfic_cli.diagnostics.study_summary`). A variant's critic is the same module as in training
(:func:`~morfic_cli.rl.build.build_models`), so ``ppo``'s and ``actor-only``'s critics (both unconditioned) are one
architecture: the study fits it once, as ``ppo``.

Store: one ``diagnosis`` manifest per call (ref ``diagnoses/critic-study``, config ``layout``
:data:`STUDY_LAYOUT`) with ``critic_study.csv`` (:data:`STUDY_COLUMNS`, a row per command, robot, variant, actor
and fit seed), ``summary.csv`` (each cell's mean and interval over actors), ``verdicts.csv`` (claims (a) and (c)),
``fits.csv`` (each fit's training and validation curves) and the figure ``critic_study.png``; inputs
``actor/<run>`` and every ``rollout/<run>/<command>/<robot>``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from tensordict import TensorDict

from morfic_cli.diagnostics.calibration import check_horizon, metric_row, reference, run_label
from morfic_cli.diagnostics.metrics import cos_grad, critic_advantage, critic_metrics, mc_advantage
from morfic_cli.diagnostics.samples import DiagnoseCfg, Samples, collect_samples
from morfic_cli.diagnostics.scoring import actor_gradients, critic_values
from morfic_cli.errors import MorficError
from morfic_cli.runs import RUNS_PREFIX, run_name
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.load import TrainedModels

STUDY_REF = "diagnoses/critic-study"
TRAIN_ROBOT = "train"
"""The ``robot`` of the rows scored on held-out envs of the training distribution."""
STUDY_VARIANTS: tuple[str, ...] = ("ppo", "concat", "film", "film-scaled", "hyper", "adaln")
"""The stock critics the study fits by default: every distinct critic of the paper's seven variants (actor-only's
critic is ppo's)."""
CRITIC_ALIASES: dict[str, str] = {"actor-only": "ppo"}
"""Variants whose critic is another's (same class, same config): fitted once, under the other's name."""

STUDY_LAYOUT = 2
"""The study's store layout, in its config (``layout``): 1 (no key) = one actor, 6 fixed epochs, the fit seed as
the unit; 2 = several actors, fits to convergence with a ``converged`` flag. :func:`check_layout` refuses newer."""
ACTOR_RUNS: tuple[tuple[str, int], ...] = (("film", 0), ("film", 1), ("film", 2), ("actor-only", 0), ("concat", 0))
"""(variant, seed) of the default study's frozen actors (the unit of replication): three ``film`` seeds and two
other variants' seed-0 runs."""
DEFAULT_ACTORS: tuple[str, ...] = tuple(RUNS_PREFIX + run_name(v, s, "cpu") for v, s in ACTOR_RUNS)
"""``ACTOR_RUNS`` under the ``cpu`` preset (the shipped runs): ``runs/film-cpu-s0`` ... ``runs/concat-cpu-s0``."""

#: Columns of ``critic_study.csv``, in order.
STUDY_COLUMNS: tuple[str, ...] = (
    "command_vx",
    "robot",
    "variant",
    "fit_seed",
    "multiplicative",
    "ev",
    "nvb",
    "abs_nvb",
    "nve",
    "asa",
    "flip",
    "cos_grad",
    "cell",
    "n_samples",
    "g_mean",
    "g_std",
    "v_mean",
    "fit_loss",
    "fit_seconds",
    "epochs",
    "best_epoch",
    "val_ev",
    "converged",
    "actor",
    "rollout",
)
#: Columns of ``fits.csv`` (a row per epoch of each fit).
FIT_COLUMNS: tuple[str, ...] = (
    "actor",
    "variant",
    "fit_seed",
    "epoch",
    "loss",
    "val_loss",
    "val_ev",
    "best_epoch",
    "stopped_early",
    "converged",
    "seconds",
    "parameters",
    "n_train",
    "n_val",
)


@dataclass(frozen=True)
class StudyCfg:
    """What the critic study collects, how it fits, and what it scores (defaults: docs/metrics.md)."""

    actors: tuple[str, ...] = DEFAULT_ACTORS
    """The frozen actors' checkpoints (the unit of replication), each with its own rollouts and fits."""
    variants: tuple[str, ...] = STUDY_VARIANTS
    """Critics to fit: stock names or a user's ``module:Class``."""
    seeds: int = 1
    """Fits per variant and actor (fit seeds 0 .. seeds-1: initial weights and mini-batch order), averaged within
    the actor. One by default: the unit is the actor, and more fits only average the fit's own noise."""
    commands: tuple[float, ...] = (1.0, 2.0)
    """Forward commands (m/s); a fit is made and scored per command."""
    robots: tuple[str, ...] = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c")
    """Target robots (descriptor mode)."""
    train_envs: int = 128
    """Envs of the training-distribution rollout per command, one sampled morphology each (plus one per fall)."""
    held_out: int = 16
    """Of those, the last envs, never fitted on, scored as ``train`` (in-distribution)."""
    val_envs: int = 16
    """The envs before those: the validation split that stops the fit and decides ``converged``."""
    target_envs: int = 32
    """Envs per target robot."""
    steps: int = 800
    """Policy steps per rollout; the samples are the window t <= steps - H_eps (I_eps)."""
    seed: int = 0
    """Rollout seed (reset poses, sampled morphologies, action noise)."""
    stride: int = 4
    """Every how many policy steps of the window a training sample is taken (consecutive steps at 50 Hz are nearly
    the same state)."""
    max_epochs: int = 100
    """Most passes over the fit set (the cap of early stopping)."""
    patience: int = 8
    """Epochs without a validation improvement after which a fit stops."""
    min_delta: float = 1e-3
    """An improvement: the validation loss (in units of Var(G) of the fit set) below the best by more than this."""
    min_ev: float = 0.1
    """A fit whose validation EV at its kept epoch is below this (it learned too little of the data), or that was
    still improving at ``max_epochs``, is flagged unconverged and left out of every average."""
    minibatch: int = 256
    """Samples per gradient step."""
    learning_rate: float = 1e-3
    """Adam's learning rate (the PPO preset's)."""
    max_grad_norm: float = 1.0
    """Gradient-norm clip (the PPO preset's)."""
    trunc_eps: float = 0.05
    """eps of I_eps (docs/metrics.md)."""
    cos_stride: int = 4
    """CosGrad's actor gradients are taken over every this-many-th step of I_eps (one backward pass through the
    actor per fit and sample set: the study's dearest part); every other metric uses all of I_eps."""

    def diagnose_cfg(self, command_vx: float, train: bool) -> DiagnoseCfg:
        """The :class:`DiagnoseCfg` of the training-distribution rollout (``train``) or of the targets' one."""
        if train:  # each command's rollout draws other morphologies: the rollout seed advances with the command
            return DiagnoseCfg(
                robots=("go2",),
                mode="train",
                command_vx=command_vx,
                num_envs=self.train_envs,
                steps=self.steps,
                seed=self.seed + self.commands.index(command_vx),
                trunc_eps=self.trunc_eps,
            )
        batch = self.robots if len(self.robots) > 1 else ()
        return DiagnoseCfg(
            robots=self.robots,
            mode="descriptor",
            command_vx=command_vx,
            num_envs=self.target_envs,
            steps=self.steps,
            seed=self.seed,
            trunc_eps=self.trunc_eps,
            batch=batch,
        )


def check_cfg(cfg: StudyCfg) -> None:
    """Refuse settings that cannot give a study.

    Raises:
        MorficError: No actor, variant, robot or command, an unknown variant, an actor or command named twice,
            seeds < 1, held_out or val_envs < 1 or leaving no fit env, max_epochs, patience, minibatch or a
            stride < 1, min_delta < 0, min_ev > 1.
    """
    if not cfg.variants:
        raise MorficError("--variants is empty; give 'all' or names such as film,concat.")
    if not cfg.robots:
        raise MorficError("--robots is empty; give 'all' or names such as aliengo,b1.")
    if not cfg.commands:
        raise MorficError("--command-vx is empty; give one or more speeds such as 1.0,2.0.")
    if cfg.seeds < 1:
        raise MorficError(f"--seeds must be at least 1, got {cfg.seeds}; intervals need 2 or more.")
    if not cfg.actors:
        raise MorficError("--actors is empty; give one or more runs such as runs/film-cpu-s0,runs/film-cpu-s1.")
    if len(set(cfg.actors)) != len(cfg.actors):
        raise MorficError(f"--actors names a run twice: {', '.join(cfg.actors)}; give each once.")
    if cfg.held_out < 1 or cfg.val_envs < 1 or cfg.held_out + cfg.val_envs >= cfg.train_envs:
        raise MorficError(
            f"--held-out ({cfg.held_out}) and --val-envs ({cfg.val_envs}) must each be at least 1 and "
            f"leave fit envs: together at most --train-envs - 1 ({cfg.train_envs - 1})."
        )
    if min(cfg.max_epochs, cfg.patience, cfg.minibatch, cfg.stride, cfg.cos_stride) < 1:
        raise MorficError("--max-epochs, --patience, --minibatch and the strides must be at least 1.")
    if cfg.min_delta < 0 or not cfg.min_ev <= 1:
        raise MorficError(f"--min-delta must be >= 0 and --min-ev <= 1, got {cfg.min_delta} and {cfg.min_ev}.")
    from morfic_cli.rl.variants import resolve_variant

    for variant in cfg.variants:
        resolve_variant(variant)  # an unknown name or a user class that cannot be imported fails here
    if len(set(cfg.commands)) != len(cfg.commands):
        raise MorficError(f"--command-vx names a speed twice: {cfg.commands}; give each once.")


def canonical_variants(variants: Sequence[str]) -> list[str]:
    """The variants to fit: aliases folded into their critic (:data:`CRITIC_ALIASES`), each once, order kept."""
    out: list[str] = []
    for v in variants:
        v = CRITIC_ALIASES.get(v, v)
        if v not in out:
            out.append(v)
    return out


@dataclass
class FitData:
    """The fit set: critic inputs and Monte-Carlo returns of the training rollouts' fit envs, in I_eps.

    The critics regress the standardised return (G - g_mean) / g_std (the same affine map for every variant), and
    are scored through :class:`Denormalized`, so their values are in return units.

    Attributes:
        obs: Group -> (n, ...) float32 (``critic`` (n, 16, 48), ``privileged`` (n, 18), ``morphology`` (n, 11)).
        G: Returns. Shape: (n,) float32.
        g_mean: Mean of G.
        g_std: Population std of G.
    """

    obs: TensorDict
    G: torch.Tensor
    g_mean: float
    g_std: float

    @property
    def target(self) -> torch.Tensor:
        """(G - g_mean) / g_std. Shape: (n,)."""
        return (self.G - self.g_mean) / self.g_std

    def target_as(self, other: FitData) -> torch.Tensor:
        """G standardised with ``other``'s map (a validation set with the fit set's): (G - m) / s. Shape: (n,)."""
        return (self.G - other.g_mean) / other.g_std


class Denormalized(torch.nn.Module):
    """A critic fitted on standardised returns, in return units: V = g_mean + g_std * critic(obs). (N, 1)."""

    def __init__(self, critic: torch.nn.Module, g_mean: float, g_std: float) -> None:
        super().__init__()
        self.critic, self.g_mean, self.g_std = critic, g_mean, g_std

    def forward(self, obs: TensorDict) -> torch.Tensor:  # noqa: D102
        return self.g_mean + self.g_std * self.critic(obs)


CRITIC_GROUPS: tuple[str, ...] = ("critic", "privileged", "morphology")
"""The observation groups a critic reads."""


def split_train(samples: Samples, held_out: int, val_envs: int = 0) -> tuple[Samples, Samples, Samples]:
    """The training rollout split by env: (fit envs, the ``val_envs`` before the last, the last ``held_out``).

    Arrays (T, N, ...) -> views (T, N - val_envs - held_out, ...), (T, val_envs, ...), (T, held_out, ...).
    """
    n = samples.action.shape[1]
    cut_val, cut_held = n - held_out - val_envs, n - held_out

    def part(envs: slice) -> Samples:
        return dataclasses.replace(
            samples,
            obs={k: v[:, envs] for k, v in samples.obs.items()},
            action=samples.action[:, envs],
            reward=samples.reward[:, envs],
            value=samples.value[:, envs],
            done=samples.done[:, envs],
            time_out=samples.time_out[:, envs],
        )

    return part(slice(0, cut_val)), part(slice(cut_val, cut_held)), part(slice(cut_held, n))


def fit_data(parts: Sequence[Samples], gamma: float, cfg: DiagnoseCfg, stride: int = 1) -> FitData:
    """The samples of I_eps of every sample set, every ``stride``-th step, with their returns, pooled.

    Args:
        parts: Training rollouts (one per command), arrays (T, N, ...).
        gamma: Discount of the returns.
        cfg: For eps of I_eps.
        stride: Keep steps t with t % stride == 0.

    Raises:
        MorficError: No sample in I_eps.
    """
    obs: dict[str, list[torch.Tensor]] = {k: [] for k in CRITIC_GROUPS}
    returns = []
    for samples in parts:
        ref = reference(samples, gamma, cfg)
        mask = ref.mask.copy()
        mask[np.arange(mask.shape[0]) % stride != 0] = False
        for k in CRITIC_GROUPS:
            obs[k].append(torch.from_numpy(np.ascontiguousarray(samples.obs[k][mask])))
        returns.append(ref.G[torch.from_numpy(mask)].float())
    G = torch.cat(returns)
    if G.numel() == 0:
        raise MorficError("the training rollout has no sample in I_eps; raise --steps (see docs/metrics.md).")
    std = float(G.std(correction=0))
    return FitData(
        TensorDict({k: torch.cat(v) for k, v in obs.items()}, batch_size=[G.numel()]),
        G,
        float(G.mean()),
        std if std > 0 else 1.0,
    )


def build_critic(actor_cfg: Any, variant: str, seed: int) -> torch.nn.Module:
    """A fresh critic of ``variant`` with the frozen actor's env and PPO settings, its own morphology encoder.

    Args:
        actor_cfg: The frozen actor's TrainCfg (observation layout, sizes).
        variant: Stock name or ``module:Class``.
        seed: Seeds torch's generator before the weights are drawn.
    """
    from morfic_cli.rl.build import build_models

    cfg = dataclasses.replace(
        actor_cfg,
        variant=variant,
        model=dataclasses.replace(actor_cfg.model, shared_morphology_encoder=False, critic_hidden_dims=None),
    )
    torch.manual_seed(seed)
    _, critic = build_models(cfg)
    return critic


@dataclass
class EarlyStopping:
    """Early stopping on a validation loss: stop after ``patience`` epochs without an improvement.

    An epoch improves when its loss is below the best so far by more than ``min_delta`` (a NaN never does); the
    kept epoch is the last that improved. Epochs count from 1.
    """

    patience: int
    min_delta: float = 0.0
    best: float = math.inf
    best_epoch: int = 0
    epoch: int = 0

    def update(self, loss: float) -> bool:
        """Record the next epoch's validation loss; True when the fit should stop now."""
        self.epoch += 1
        if loss < self.best - self.min_delta:
            self.best, self.best_epoch = loss, self.epoch
        return self.epoch - self.best_epoch >= self.patience


@dataclass
class Fit:
    """One fitted critic: its actor, variant, seed, curves, kept epoch, validation EV and wall time.

    Attributes:
        losses: Mean training loss of each epoch run (units of Var(G) of the fit set).
        val_losses: Validation loss after each epoch (same units).
        val_evs: Validation EV after each epoch.
        best_epoch: The epoch whose weights the critic holds (1-based; 0 without validation).
        stopped_early: Whether early stopping ended the fit (False: it ran to ``max_epochs``).
        min_ev: The flag's threshold: ``converged`` needs val EV at ``best_epoch`` >= it.
    """

    variant: str
    seed: int
    critic: torch.nn.Module
    actor: str = ""
    losses: list[float] = field(default_factory=list)
    val_losses: list[float] = field(default_factory=list)
    val_evs: list[float] = field(default_factory=list)
    best_epoch: int = 0
    stopped_early: bool = False
    seconds: float = 0.0
    min_ev: float = -math.inf

    @property
    def parameters(self) -> int:
        """Trainable parameters of the critic."""
        return sum(p.numel() for p in self.critic.parameters() if p.requires_grad)

    @property
    def val_ev(self) -> float:
        """Validation EV of the kept weights (NaN without validation)."""
        return self.val_evs[self.best_epoch - 1] if self.best_epoch else math.nan

    @property
    def converged(self) -> bool:
        """Early stopping ended the fit and its kept weights reach ``min_ev`` on the validation envs (NaN: False)."""
        return self.stopped_early and bool(self.val_ev >= self.min_ev)


def _predict(critic: torch.nn.Module, obs: TensorDict, chunk: int = 4096) -> torch.Tensor:
    """The critic's output on every sample, without gradients, in chunks. Shape: (n,)."""
    with torch.no_grad():
        return torch.cat([critic(obs[i : i + chunk]).reshape(-1) for i in range(0, obs.batch_size[0], chunk)])


def fit_critic(
    critic: torch.nn.Module,
    data: FitData,
    cfg: StudyCfg,
    seed: int,
    val: FitData | None = None,
    on_epoch: Callable[[], None] | None = None,
) -> Fit:
    """Regress V_phi on the standardised G of the fit set (Adam, mean squared error, shuffled passes) to convergence.

    After each epoch the loss and EV on ``val`` (standardised with the fit set's map) are taken; the fit stops when
    :class:`EarlyStopping` (``cfg.patience``, ``cfg.min_delta``) says so or after ``cfg.max_epochs``, and the critic
    keeps the weights of its best validation epoch. Without ``val``, ``cfg.max_epochs`` passes and the last weights.
    The mini-batch order comes from a generator seeded with ``seed``, so two variants with the same seed see the
    same batches in the same order.

    Returns:
        The :class:`Fit` (variant and actor left empty for the caller), its critic in eval mode.
    """
    from morfic_cli.diagnostics.metrics import explained_variance

    critic.train()
    params = [p for p in critic.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(params, lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = data.G.shape[0]
    target = data.target
    val_target = val.target_as(data) if val is not None else None
    fit = Fit("", seed, critic, min_ev=cfg.min_ev)
    stopper = EarlyStopping(cfg.patience, cfg.min_delta)
    best_state: dict[str, torch.Tensor] | None = None
    start = time.perf_counter()
    for _ in range(cfg.max_epochs):
        order = torch.randperm(n, generator=gen)
        total, count = 0.0, 0
        for i in range(0, n, cfg.minibatch):
            idx = order[i : i + cfg.minibatch]
            value = critic(data.obs[idx]).reshape(-1)
            loss = torch.nn.functional.mse_loss(value, target[idx])
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
            optimizer.step()
            total += float(loss.detach()) * idx.numel()
            count += idx.numel()
        fit.losses.append(total / count)
        if on_epoch is not None:
            on_epoch()
        if val is None or val_target is None:
            continue
        critic.eval()
        pred = _predict(critic, val.obs)
        critic.train()
        fit.val_losses.append(float(torch.nn.functional.mse_loss(pred, val_target)))
        fit.val_evs.append(explained_variance(val_target, pred))
        stop = stopper.update(fit.val_losses[-1])
        if stopper.best_epoch == stopper.epoch:
            best_state = {k: v.detach().clone() for k, v in critic.state_dict().items()}
        if stop:
            fit.stopped_early = True
            break
    if best_state is not None:
        critic.load_state_dict(best_state)
    fit.best_epoch = stopper.best_epoch
    fit.seconds = time.perf_counter() - start
    critic.eval()
    return fit


def batches_per_epoch(n: int, cfg: StudyCfg) -> int:
    """Gradient steps of one epoch over ``n`` samples."""
    return math.ceil(n / cfg.minibatch)


def score_fits(
    actor: torch.nn.Module,
    fits: Sequence[Fit],
    samples: Samples,
    gamma: float,
    cfg: DiagnoseCfg,
    clip_param: float,
    cos_stride: int = 1,
) -> list[dict[str, Any]]:
    """Every fit's metrics on one sample set, CosGrad on the frozen ``actor`` (one forward pass for all fits).

    CosGrad compares g(A_phi) with g(A_MC) over the samples of I_eps at steps t % cos_stride == 0 (A_MC's mean
    taken there too); EV, NVB, NVE, ASA and Flip over all of I_eps.

    Returns:
        Per fit, in order: ``ev, nvb, abs_nvb, nve, asa, flip, cos_grad, cell, n_samples, g_mean, g_std, v_mean``.
    """
    ref = reference(samples, gamma, cfg)
    G = ref.returns
    mask_t = torch.from_numpy(ref.mask)
    values = [critic_values(f.critic, samples.obs)[mask_t].double() for f in fits]
    cos_mask = ref.mask.copy()
    cos_mask[np.arange(cos_mask.shape[0]) % cos_stride != 0] = False
    keep = torch.from_numpy(cos_mask[ref.mask])  # the strided samples among I_eps's, row-major
    G_cos = G[keep]
    grads = actor_gradients(
        actor,
        samples.obs,
        samples.action,
        cos_mask,
        [mc_advantage(G_cos), *(critic_advantage(G_cos, v[keep]) for v in values)],
        clip_param=clip_param,
    )
    return [
        metric_row(critic_metrics(G, v, cfg.sigma_eps), cos_grad(g_phi, grads[0]))
        for v, g_phi in zip(values, grads[1:], strict=True)
    ]


def study_config(cfg: StudyCfg) -> dict[str, Any]:
    """The config of a stored study: every setting (actors as given, variants as fitted) and :data:`STUDY_LAYOUT`."""
    doc = {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()}
    return {**doc, "variants": canonical_variants(cfg.variants), "layout": STUDY_LAYOUT}


def check_layout(config: dict[str, Any]) -> int:
    """The layout of a stored study's config (1 when it has none: the one-actor design).

    Raises:
        MorficError: A layout newer than :data:`STUDY_LAYOUT` (written by a newer morfic).
    """
    layout = int(config.get("layout", 1))
    if layout > STUDY_LAYOUT:
        raise MorficError(
            f"the critic study was stored with layout {layout}, newer than this morfic reads "
            f"({STUDY_LAYOUT}); upgrade morfic, or run `morfic critic-study` again."
        )
    return layout


@dataclass
class StudyResult:
    """What a study wrote: its rows, the fits' curves, the manifest id and the ref's version."""

    rows: list[dict[str, Any]]
    fits: list[dict[str, Any]]
    id: str
    version: int
    seconds: dict[str, float]


@dataclass
class StudyProgress:
    """Callbacks of a long study (all optional): a phase starts with its total, a unit of it is done."""

    phase: Callable[[str, int], None] = lambda label, total: None
    advance: Callable[[], None] = lambda: None


def _fit_rows(fit: Fit, n_train: int, n_val: int) -> list[dict[str, Any]]:
    """The rows of ``fits.csv`` of one fit: one per epoch run."""
    val = fit.val_losses + [math.nan] * (len(fit.losses) - len(fit.val_losses))
    evs = fit.val_evs + [math.nan] * (len(fit.losses) - len(fit.val_evs))
    return [
        {
            "actor": fit.actor,
            "variant": fit.variant,
            "fit_seed": fit.seed,
            "epoch": e + 1,
            "loss": loss,
            "val_loss": v,
            "val_ev": ev,
            "best_epoch": fit.best_epoch,
            "stopped_early": fit.stopped_early,
            "converged": fit.converged,
            "seconds": fit.seconds,
            "parameters": fit.parameters,
            "n_train": n_train,
            "n_val": n_val,
        }
        for e, (loss, v, ev) in enumerate(zip(fit.losses, val, evs, strict=True))
    ]


def _study_actor(
    store: Store,
    spec: str,
    trained: TrainedModels,
    cfg: StudyCfg,
    variants: Sequence[str],
    multiplicative: dict[str, bool | None],
    progress: StudyProgress,
    seconds: dict[str, float],
    inputs: dict[str, str],
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """One actor's part of the study: its rollouts, its fits, their scores. Returns (rows, fit rows)."""
    gamma, clip = trained.cfg.ppo.gamma, trained.cfg.ppo.clip_param
    check_horizon(gamma, cfg.diagnose_cfg(cfg.commands[0], True))
    label = run_label(trained, spec)
    inputs[f"actor/{label}"] = trained.checkpoint_id
    held: dict[float, Samples] = {}
    targets: dict[float, dict[str, Samples]] = {}
    fit_parts: list[Samples] = []
    val_parts: list[Samples] = []
    t0 = time.perf_counter()
    for command in cfg.commands:  # 1. the frozen actor's rollouts (reused from the store when there)
        train_cfg, target_cfg = cfg.diagnose_cfg(command, True), cfg.diagnose_cfg(command, False)
        joint = bool(target_cfg.batch)  # every target stepped as one env: one bar pass for all of them
        progress.phase(f"{label}: rollouts at {command:g} m/s", (2 if joint else 1 + len(cfg.robots)) * cfg.steps)
        step = lambda _t: progress.advance()  # noqa: E731
        train = collect_samples(store, trained, "go2", train_cfg, on_step=step)
        inputs[f"rollout/{label}/{command:g}/{TRAIN_ROBOT}"] = train.rollout_id
        fit_part, val_part, held[command] = split_train(train, cfg.held_out, cfg.val_envs)
        fit_parts.append(fit_part)
        val_parts.append(val_part)
        targets[command] = {}
        for k, robot in enumerate(cfg.robots):
            targets[command][robot] = collect_samples(
                store, trained, robot, target_cfg, on_step=step if k == 0 or not joint else None
            )
            inputs[f"rollout/{label}/{command:g}/{robot}"] = targets[command][robot].rollout_id
    seconds["rollouts"] += time.perf_counter() - t0
    diag = cfg.diagnose_cfg(cfg.commands[0], True)  # eps and sigma_eps: the same for every command
    data = fit_data(fit_parts, gamma, diag, cfg.stride)  # 2. one fit set over every command
    val = fit_data(val_parts, gamma, diag, cfg.stride)
    del fit_parts, val_parts
    fits: list[Fit] = []
    fit_rows: list[dict[str, Any]] = []
    progress.phase(
        f"{label}: fitting {len(variants)} x {cfg.seeds} critics on {data.G.shape[0]} samples "
        f"(at most {cfg.max_epochs} epochs)",
        len(variants) * cfg.seeds * cfg.max_epochs,
    )
    for variant in variants:
        for seed in range(cfg.seeds):
            fit = fit_critic(build_critic(trained.cfg, variant, seed), data, cfg, seed, val, progress.advance)
            for _ in range(cfg.max_epochs - len(fit.losses)):  # the epochs early stopping saved
                progress.advance()
            fit.variant, fit.actor = variant, label
            fit.critic = Denormalized(fit.critic, data.g_mean, data.g_std).eval()
            fits.append(fit)
            seconds["fits"] += fit.seconds
            fit_rows += _fit_rows(fit, int(data.G.shape[0]), int(val.G.shape[0]))
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    for command in cfg.commands:  # 3. every fit scored on every sample set of its actor
        sets = {TRAIN_ROBOT: held[command], **targets[command]}
        progress.phase(f"{label}: scoring {len(fits)} critics at {command:g} m/s", len(sets))
        for robot, samples in sets.items():
            scores = score_fits(trained.actor, fits, samples, gamma, diag, clip, cfg.cos_stride)
            for fit, score in zip(fits, scores, strict=True):
                rows.append(
                    {
                        "command_vx": command,
                        "robot": robot,
                        "variant": fit.variant,
                        "fit_seed": fit.seed,
                        "multiplicative": multiplicative[fit.variant],
                        **score,
                        "fit_loss": fit.losses[-1],
                        "fit_seconds": fit.seconds,
                        "epochs": len(fit.losses),
                        "best_epoch": fit.best_epoch,
                        "val_ev": fit.val_ev,
                        "converged": fit.converged,
                        "actor": label,
                        "rollout": samples.rollout_id,
                    }
                )
            progress.advance()
    seconds["scoring"] += time.perf_counter() - t0
    return rows, fit_rows


def run_study(
    store: Store,
    cfg: StudyCfg,
    *,
    actors: dict[str, TrainedModels] | None = None,
    progress: StudyProgress | None = None,
) -> StudyResult:
    """The critic study of ``cfg.actors`` (module docstring); stored as a ``diagnosis``.

    Args:
        store: Artifact store (rollouts are reused from it or written to it).
        cfg: Study settings (:func:`check_cfg` is applied).
        actors: Spec -> the checkpoint already loaded (the others are loaded here, one at a time).
        progress: Phase and step callbacks.

    Raises:
        MorficError: Bad settings, a spec that is not a checkpoint, a user variant that cannot be imported, or
            ``cfg.steps`` too short for an actor's discount.
    """
    from morfic_cli.diagnostics.figures import critic_study_figure
    from morfic_cli.diagnostics.study_summary import (
        SUMMARY_COLUMNS,
        VERDICT_COLUMNS,
        cell_summary,
        study_claims,
        verdict_rows,
    )
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.rl.load import load_trained
    from morfic_cli.rl.variants import STOCK, resolve_variant

    check_cfg(cfg)
    progress = progress or StudyProgress()
    actors = dict(actors or {})
    variants = canonical_variants(cfg.variants)
    # user classes were resolved by check_cfg (consent, import); a user's critic is neither group of claim (a) (None)
    multiplicative = {v: (resolve_variant(v).multiplicative if v in STOCK else None) for v in variants}
    rows: list[dict[str, Any]] = []
    fit_rows: list[dict[str, Any]] = []
    inputs: dict[str, str] = {}
    seconds = {"rollouts": 0.0, "fits": 0.0, "scoring": 0.0}
    labels = []
    for spec in cfg.actors:
        trained = actors.pop(spec, None) or load_trained(store, spec)
        labels.append(run_label(trained, spec))
        if labels.count(labels[-1]) > 1:
            raise MorficError(f"--actors names run {labels[-1]} twice (as {spec}); give each run once.")
        part, part_fits = _study_actor(store, spec, trained, cfg, variants, multiplicative, progress, seconds, inputs)
        rows += part
        fit_rows += part_fits
        del trained
    summary = cell_summary(rows)
    claims = verdict_rows(study_claims(rows))
    files = {
        "critic_study.csv": rows_to_csv(rows, STUDY_COLUMNS),
        "summary.csv": rows_to_csv(summary, SUMMARY_COLUMNS),
        "verdicts.csv": rows_to_csv(claims, VERDICT_COLUMNS),
        "fits.csv": rows_to_csv(fit_rows, FIT_COLUMNS),
        "critic_study.png": critic_study_figure(summary),
    }
    n_fits = len({(r["actor"], r["variant"], r["fit_seed"]) for r in fit_rows})
    n_flagged = len({(r["actor"], r["variant"], r["fit_seed"]) for r in fit_rows if not r["converged"]})
    pub = store.publish(
        "diagnosis",
        STUDY_REF,
        config=study_config(cfg),
        inputs=inputs,
        files=files,
        meta={
            "actor": ", ".join(labels),
            "actors": labels,
            "variants": variants,
            "seeds": cfg.seeds,
            "fits": n_fits,
            "unconverged": n_flagged,
            "layout": STUDY_LAYOUT,
            "seconds": {k: round(v, 1) for k, v in seconds.items()},
        },
    )
    return StudyResult(rows, fit_rows, pub.id, pub.advanced()[1], seconds)
