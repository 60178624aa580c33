"""``morfic critic-study``: the conditioning alone, with the policy held fixed (docs/metrics.md "Critic study").

The paper's fixed-rollout analysis scores critics that were trained beside their own actors, so a critic's score
mixes its conditioning with the data its own actor produced. This study removes the actor from the comparison:

1. one frozen actor (the seed-0 ``film`` run by default) collects, at each command, a rollout on the *training*
   morphology distribution (``train`` mode: the Go2 template with a descriptor drawn from the paper's support per
   env, the evaluation env's settings otherwise) and a rollout on every target robot (descriptor mode), with
   sampled actions and the observation groups every critic reads (:mod:`~morfic_cli.diagnostics.samples`);
2. every variant's critic is built fresh (its own morphology encoder, not shared with an actor) and regressed on
   the standardised Monte-Carlo returns G of the training rollouts' samples in I_eps (every ``stride``-th step,
   pooled over the commands, the last ``held_out`` envs left out), all with the same optimiser, learning rate,
   epochs, mini-batches and data order for a given seed (:func:`fit_critic`), several seeds each;
3. each fit is scored on every robot's samples exactly as ``morfic diagnose`` scores a run's critic: EV, NVB,
   NVE, ASA and Flip against G, and CosGrad on the frozen actor (:func:`score_fits`), per command; ``train`` rows
   are the held-out envs of the training distribution (in-distribution calibration).

A variant's critic is the same module as in training (:func:`~morfic_cli.rl.runner.build_models`), so ``ppo``'s and
``actor-only``'s critics (both unconditioned) are one architecture: the study fits it once, as ``ppo``.

Store: one ``diagnosis`` manifest per call (ref ``diagnoses/critic-study``) with ``critic_study.csv``
(:data:`STUDY_COLUMNS`, a row per command, robot, variant and fit seed), ``summary.csv`` (each cell's mean and
interval), ``verdicts.csv`` (claims (a) and (c)), ``fits.csv`` (each fit's loss curve and wall time) and the
figure ``critic_study.png``; inputs ``actor`` and every ``rollout/<command>/<robot>``.
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

from morfic_cli.diagnostics.calibration import check_horizon, paper_cell, reference, run_label
from morfic_cli.diagnostics.metrics import cos_grad, critic_advantage, critic_metrics, mc_advantage
from morfic_cli.diagnostics.samples import DiagnoseCfg, Samples, collect_samples
from morfic_cli.diagnostics.scoring import actor_gradients, critic_values
from morfic_cli.errors import MorficError
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.runner import TrainedModels

STUDY_REF = "diagnoses/critic-study"
TRAIN_ROBOT = "train"
"""The ``robot`` of the rows scored on held-out envs of the training distribution."""
STUDY_VARIANTS: tuple[str, ...] = ("ppo", "concat", "film", "film-scaled", "hyper", "adaln")
"""The stock critics the study fits by default: every distinct critic of the paper's seven variants (actor-only's
critic is ppo's)."""
CRITIC_ALIASES: dict[str, str] = {"actor-only": "ppo"}
"""Variants whose critic is another's (same class, same config): fitted once, under the other's name."""

#: Columns of ``critic_study.csv``, in order.
STUDY_COLUMNS: tuple[str, ...] = (
    "command_vx", "robot", "variant", "fit_seed", "multiplicative", "ev", "nvb", "abs_nvb", "nve", "asa", "flip",
    "cos_grad", "cell", "n_samples", "g_mean", "g_std", "v_mean", "fit_loss", "fit_seconds", "actor", "rollout",
)
#: Columns of ``fits.csv``.
FIT_COLUMNS: tuple[str, ...] = ("variant", "fit_seed", "epoch", "loss", "seconds", "parameters", "n_train")


@dataclass(frozen=True)
class StudyCfg:
    """What the critic study collects, how it fits, and what it scores (defaults: docs/metrics.md)."""

    variants: tuple[str, ...] = STUDY_VARIANTS
    """Critics to fit: stock names or a user's ``module:Class``."""
    seeds: int = 5
    """Fits per variant (fit seeds 0 .. seeds-1: initial weights and mini-batch order)."""
    commands: tuple[float, ...] = (1.0, 2.0)
    """Forward commands (m/s); a fit is made and scored per command."""
    robots: tuple[str, ...] = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c")
    """Target robots (descriptor mode)."""
    train_envs: int = 128
    """Envs of the training-distribution rollout per command, one sampled morphology each (plus one per fall)."""
    held_out: int = 16
    """Of those, the last envs, kept out of the fit and scored as ``train`` (in-distribution)."""
    target_envs: int = 32
    """Envs per target robot."""
    steps: int = 800
    """Policy steps per rollout; the samples are the window t <= steps - H_eps (I_eps)."""
    seed: int = 0
    """Rollout seed (reset poses, sampled morphologies, action noise)."""
    stride: int = 4
    """Every how many policy steps of the window a training sample is taken (consecutive steps at 50 Hz are nearly
    the same state)."""
    epochs: int = 6
    """Passes over the fit set."""
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
            return DiagnoseCfg(robots=("go2",), mode="train", command_vx=command_vx, num_envs=self.train_envs,
                               steps=self.steps, seed=self.seed + self.commands.index(command_vx),
                               trunc_eps=self.trunc_eps)
        batch = self.robots if len(self.robots) > 1 else ()
        return DiagnoseCfg(robots=self.robots, mode="descriptor", command_vx=command_vx, num_envs=self.target_envs,
                           steps=self.steps, seed=self.seed, trunc_eps=self.trunc_eps, batch=batch)


def check_cfg(cfg: StudyCfg) -> None:
    """Refuse settings that cannot give a study.

    Raises:
        MorficError: No variant, robot or command, an unknown variant, a command named twice, seeds < 1,
            held_out outside [1, train_envs), epochs, minibatch or a stride < 1.
    """
    if not cfg.variants:
        raise MorficError("--variants is empty; give 'all' or names such as film,concat.")
    if not cfg.robots:
        raise MorficError("--robots is empty; give 'all' or names such as aliengo,b1.")
    if not cfg.commands:
        raise MorficError("--command-vx is empty; give one or more speeds such as 1.0,2.0.")
    if cfg.seeds < 1:
        raise MorficError(f"--seeds must be at least 1, got {cfg.seeds}; intervals need 2 or more.")
    if not 1 <= cfg.held_out < cfg.train_envs:
        raise MorficError(f"--held-out must be between 1 and --train-envs - 1 ({cfg.train_envs - 1}), got "
                          f"{cfg.held_out}.")
    if min(cfg.epochs, cfg.minibatch, cfg.stride, cfg.cos_stride) < 1:
        raise MorficError("--epochs, --minibatch and the strides must be at least 1.")
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


class Denormalized(torch.nn.Module):
    """A critic fitted on standardised returns, in return units: V = g_mean + g_std * critic(obs). (N, 1)."""

    def __init__(self, critic: torch.nn.Module, g_mean: float, g_std: float) -> None:
        super().__init__()
        self.critic, self.g_mean, self.g_std = critic, g_mean, g_std

    def forward(self, obs: TensorDict) -> torch.Tensor:  # noqa: D102
        return self.g_mean + self.g_std * self.critic(obs)


CRITIC_GROUPS: tuple[str, ...] = ("critic", "privileged", "morphology")
"""The observation groups a critic reads."""


def split_train(samples: Samples, held_out: int) -> tuple[Samples, Samples]:
    """The training rollout split by env: (fit envs, the last ``held_out`` envs). Arrays (T, N, ...) -> views."""
    n = samples.action.shape[1]
    fit, out = slice(0, n - held_out), slice(n - held_out, n)

    def part(envs: slice) -> Samples:
        return dataclasses.replace(
            samples, obs={k: v[:, envs] for k, v in samples.obs.items()}, action=samples.action[:, envs],
            reward=samples.reward[:, envs], value=samples.value[:, envs], done=samples.done[:, envs],
            time_out=samples.time_out[:, envs])

    return part(fit), part(out)


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
    return FitData(TensorDict({k: torch.cat(v) for k, v in obs.items()}, batch_size=[G.numel()]), G,
                   float(G.mean()), std if std > 0 else 1.0)


def build_critic(actor_cfg: Any, variant: str, seed: int) -> torch.nn.Module:
    """A fresh critic of ``variant`` with the frozen actor's env and PPO settings, its own morphology encoder.

    Args:
        actor_cfg: The frozen actor's TrainCfg (observation layout, sizes).
        variant: Stock name or ``module:Class``.
        seed: Seeds torch's generator before the weights are drawn.
    """
    from morfic_cli.rl.runner import build_models

    cfg = dataclasses.replace(actor_cfg, variant=variant,
                              model=dataclasses.replace(actor_cfg.model, shared_morphology_encoder=False,
                                                        critic_hidden_dims=None))
    torch.manual_seed(seed)
    _, critic = build_models(cfg)
    return critic


@dataclass
class Fit:
    """One fitted critic: its variant, seed, loss per epoch and wall time."""

    variant: str
    seed: int
    critic: torch.nn.Module
    losses: list[float] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def parameters(self) -> int:
        """Trainable parameters of the critic."""
        return sum(p.numel() for p in self.critic.parameters() if p.requires_grad)


def fit_critic(critic: torch.nn.Module, data: FitData, cfg: StudyCfg, seed: int,
               on_batch: Callable[[], None] | None = None) -> tuple[list[float], float]:
    """Regress V_phi on the standardised G of the fit set: Adam, mean squared error, ``cfg.epochs`` shuffled passes.

    The mini-batch order comes from a generator seeded with ``seed``, so two variants with the same seed see the
    same batches in the same order.

    Returns:
        (mean loss of each epoch, in units of Var(G), wall seconds).
    """
    critic.train()
    params = [p for p in critic.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(params, lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = data.G.shape[0]
    target = data.target
    losses: list[float] = []
    start = time.perf_counter()
    for _ in range(cfg.epochs):
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
            if on_batch is not None:
                on_batch()
        losses.append(total / count)
    critic.eval()
    return losses, time.perf_counter() - start


def batches_per_fit(n: int, cfg: StudyCfg) -> int:
    """Gradient steps of one fit of ``n`` samples."""
    return cfg.epochs * math.ceil(n / cfg.minibatch)


def score_fits(actor: torch.nn.Module, fits: Sequence[Fit], samples: Samples, gamma: float, cfg: DiagnoseCfg,
               clip_param: float, cos_stride: int = 1) -> list[dict[str, Any]]:
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
    grads = actor_gradients(actor, samples.obs, samples.action, cos_mask,
                            [mc_advantage(G_cos), *(critic_advantage(G_cos, v[keep]) for v in values)],
                            clip_param=clip_param)
    rows = []
    for v, g_phi in zip(values, grads[1:], strict=True):
        m = critic_metrics(G, v, cfg.sigma_eps)
        rows.append({"ev": m.ev, "nvb": m.nvb, "abs_nvb": abs(m.nvb), "nve": m.nve, "asa": m.asa, "flip": m.flip,
                     "cos_grad": cos_grad(g_phi, grads[0]), "cell": paper_cell(m.nvb, m.nve, m.asa),
                     "n_samples": m.n, "g_mean": m.g_mean, "g_std": m.g_std, "v_mean": m.v_mean})
    return rows


def study_config(actor_spec: str, cfg: StudyCfg) -> dict[str, Any]:
    """The config of a stored study: the actor's spec and every setting (variants as fitted, aliases folded)."""
    doc = {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()}
    return {"actor": actor_spec, **doc, "variants": canonical_variants(cfg.variants)}


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


def run_study(store: Store, actor_spec: str, cfg: StudyCfg, *, actor: TrainedModels | None = None,
              progress: StudyProgress | None = None) -> StudyResult:
    """The critic study of ``actor_spec``'s frozen actor (module docstring); stored as a ``diagnosis``.

    Args:
        store: Artifact store (rollouts are reused from it or written to it).
        actor_spec: The frozen actor's checkpoint (``runs/film-cpu-s0``).
        cfg: Study settings (:func:`check_cfg` is applied).
        actor: The checkpoint already loaded (else loaded here).
        progress: Phase and step callbacks.

    Raises:
        MorficError: Bad settings, a spec that is not a checkpoint, a user variant that cannot be imported, or
            ``cfg.steps`` too short for the actor's discount.
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
    from morfic_cli.rl.runner import load_trained
    from morfic_cli.rl.variants import STOCK, resolve_variant

    check_cfg(cfg)
    progress = progress or StudyProgress()
    trained = actor if actor is not None else load_trained(store, actor_spec)
    gamma, clip = trained.cfg.ppo.gamma, trained.cfg.ppo.clip_param
    variants = canonical_variants(cfg.variants)
    # user classes were resolved by check_cfg (consent, import); a user's critic is neither group of claim (a) (None)
    multiplicative = {v: (resolve_variant(v).multiplicative if v in STOCK else None) for v in variants}
    check_horizon(gamma, cfg.diagnose_cfg(cfg.commands[0], True))
    label = run_label(trained, actor_spec)
    rows: list[dict[str, Any]] = []
    fit_rows: list[dict[str, Any]] = []
    inputs = {"actor": trained.checkpoint_id}
    seconds = {"rollouts": 0.0, "fits": 0.0, "scoring": 0.0}
    held: dict[float, Samples] = {}
    targets: dict[float, dict[str, Samples]] = {}
    fit_parts: list[Samples] = []
    t0 = time.perf_counter()
    for command in cfg.commands:  # 1. the frozen actor's rollouts (reused from the store when there)
        train_cfg, target_cfg = cfg.diagnose_cfg(command, True), cfg.diagnose_cfg(command, False)
        joint = bool(target_cfg.batch)  # every target stepped as one env: one bar pass for all of them
        progress.phase(f"{label}: rollouts at {command:g} m/s", (2 if joint else 1 + len(cfg.robots)) * cfg.steps)
        step = lambda _t: progress.advance()  # noqa: E731
        train = collect_samples(store, trained, "go2", train_cfg, on_step=step)
        inputs[f"rollout/{command:g}/{TRAIN_ROBOT}"] = train.rollout_id
        fit_part, held[command] = split_train(train, cfg.held_out)
        fit_parts.append(fit_part)
        targets[command] = {}
        for k, robot in enumerate(cfg.robots):
            targets[command][robot] = collect_samples(store, trained, robot, target_cfg,
                                                      on_step=step if k == 0 or not joint else None)
            inputs[f"rollout/{command:g}/{robot}"] = targets[command][robot].rollout_id
    seconds["rollouts"] = time.perf_counter() - t0
    diag = cfg.diagnose_cfg(cfg.commands[0], True)  # eps and sigma_eps: the same for every command
    data = fit_data(fit_parts, gamma, diag, cfg.stride)  # 2. one fit set over every command
    del fit_parts
    fits: list[Fit] = []
    progress.phase(f"fitting {len(variants)} x {cfg.seeds} critics on {data.G.shape[0]} samples",
                   len(variants) * cfg.seeds * batches_per_fit(data.G.shape[0], cfg))
    for variant in variants:
        for seed in range(cfg.seeds):
            critic = build_critic(trained.cfg, variant, seed)
            losses, secs = fit_critic(critic, data, cfg, seed, on_batch=progress.advance)
            fit = Fit(variant, seed, Denormalized(critic, data.g_mean, data.g_std).eval(), losses, secs)
            fits.append(fit)
            seconds["fits"] += secs
            fit_rows += [{"variant": variant, "fit_seed": seed, "epoch": e + 1, "loss": loss, "seconds": secs,
                          "parameters": fit.parameters, "n_train": int(data.G.shape[0])}
                         for e, loss in enumerate(losses)]
    t0 = time.perf_counter()
    for command in cfg.commands:  # 3. every fit scored on every sample set
        sets = {TRAIN_ROBOT: held[command], **targets[command]}
        progress.phase(f"scoring {len(fits)} critics at {command:g} m/s", len(sets))
        for robot, samples in sets.items():
            scores = score_fits(trained.actor, fits, samples, gamma, diag, clip, cfg.cos_stride)
            for fit, score in zip(fits, scores, strict=True):
                rows.append({"command_vx": command, "robot": robot, "variant": fit.variant, "fit_seed": fit.seed,
                             "multiplicative": multiplicative[fit.variant], **score,
                             "fit_loss": fit.losses[-1], "fit_seconds": fit.seconds, "actor": label,
                             "rollout": samples.rollout_id})
            progress.advance()
    seconds["scoring"] = time.perf_counter() - t0
    summary = cell_summary(rows)
    claims = verdict_rows(study_claims(rows))
    config = study_config(actor_spec, cfg)
    files = {
        "critic_study.csv": rows_to_csv(rows, STUDY_COLUMNS),
        "summary.csv": rows_to_csv(summary, SUMMARY_COLUMNS),
        "verdicts.csv": rows_to_csv(claims, VERDICT_COLUMNS),
        "fits.csv": rows_to_csv(fit_rows, FIT_COLUMNS),
        "critic_study.png": critic_study_figure(summary),
    }
    pub = store.publish("diagnosis", STUDY_REF, config=config, inputs=inputs, files=files,
                        meta={"actor": label, "variants": variants, "seeds": cfg.seeds,
                              "seconds": {k: round(v, 1) for k, v in seconds.items()}})
    return StudyResult(rows, fit_rows, pub.id, pub.version, seconds)
