"""``morfic critic-study``: the conditioning alone, with the policy held fixed (docs/metrics.md "Critic study").

The paper's fixed-rollout analysis scores critics that were trained beside their own actors, so a critic's score
mixes its conditioning with the data its own actor produced. This study removes the actor from the comparison:

1. one frozen actor (the seed-0 ``film`` run by default) collects, at each command, a rollout on the *training*
   morphology distribution (``train`` mode: the Go2 template with a descriptor drawn from the paper's support per
   env, the evaluation env's settings otherwise) and a rollout on every target robot (descriptor mode), with
   sampled actions and the observation groups every critic reads (:mod:`~morfic_cli.diagnostics.samples`);
2. every variant's critic is built fresh (its own morphology encoder, not shared with an actor) and regressed on
   the Monte-Carlo returns G of the training rollout's samples in I_eps, all with the same optimiser, learning
   rate, epochs, mini-batches and data order for a given seed (:func:`fit_critic`), several seeds each;
3. each fit is scored on every robot's samples exactly as ``morfic diagnose`` scores a run's critic: EV, NVB,
   NVE, ASA and Flip against G, and CosGrad on the frozen actor (:func:`score_fits`); ``train`` rows are held-out
   envs of the training distribution (in-distribution calibration).

A variant's critic is the same module as in training (:func:`~morfic_cli.rl.runner.build_models`), so ``ppo``'s and
``actor-only``'s critics (both unconditioned) are one architecture: the study fits it once, as ``ppo``.

Store: one ``diagnosis`` manifest per call (ref ``diagnoses/critic-study``) with ``critic_study.csv``
(:data:`STUDY_COLUMNS`, a row per command, robot, variant and fit seed), ``fits.csv`` (each fit's loss curve and
wall time) and the figure ``critic_study.png``; inputs ``actor`` and every ``rollout/<command>/<robot>``.
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
FIT_COLUMNS: tuple[str, ...] = ("command_vx", "variant", "fit_seed", "epoch", "loss", "seconds", "parameters",
                                "n_train")


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
    """Envs of the training-distribution rollout, one sampled morphology each (plus one per fall)."""
    held_out: int = 16
    """Of those, the last envs, kept out of the fit and scored as ``train`` (in-distribution)."""
    target_envs: int = 32
    """Envs per target robot."""
    steps: int = 800
    """Policy steps per rollout; the samples are the window t <= steps - H_eps (I_eps)."""
    seed: int = 0
    """Rollout seed (reset poses, sampled morphologies, action noise)."""
    epochs: int = 8
    """Passes over the fit set."""
    minibatch: int = 2048
    """Samples per gradient step."""
    learning_rate: float = 1e-3
    """Adam's learning rate (the PPO preset's)."""
    max_grad_norm: float = 1.0
    """Gradient-norm clip (the PPO preset's)."""
    trunc_eps: float = 0.05
    """eps of I_eps (docs/metrics.md)."""

    def diagnose_cfg(self, command_vx: float, train: bool) -> DiagnoseCfg:
        """The :class:`DiagnoseCfg` of the training-distribution rollout (``train``) or of the targets' one."""
        if train:
            return DiagnoseCfg(robots=("go2",), mode="train", command_vx=command_vx, num_envs=self.train_envs,
                               steps=self.steps, seed=self.seed, trunc_eps=self.trunc_eps)
        batch = self.robots if len(self.robots) > 1 else ()
        return DiagnoseCfg(robots=self.robots, mode="descriptor", command_vx=command_vx, num_envs=self.target_envs,
                           steps=self.steps, seed=self.seed, trunc_eps=self.trunc_eps, batch=batch)


def check_cfg(cfg: StudyCfg) -> None:
    """Refuse settings that cannot give a study.

    Raises:
        MorficError: No variant, robot or command, seeds < 1, held_out outside [1, train_envs), epochs < 1.
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
    if cfg.epochs < 1 or cfg.minibatch < 1:
        raise MorficError("--epochs and --minibatch must be at least 1.")


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
    """The fit set: critic inputs and Monte-Carlo returns of the training rollout's fit envs, in I_eps.

    Attributes:
        obs: Group -> (n, ...) float32 (``critic`` (n, 16, 48), ``privileged`` (n, 18), ``morphology`` (n, 11)).
        G: Returns. Shape: (n,) float32.
    """

    obs: TensorDict
    G: torch.Tensor


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


def fit_data(samples: Samples, gamma: float, cfg: DiagnoseCfg) -> FitData:
    """The samples of I_eps of ``samples`` with their returns, flattened row-major over (t, env)."""
    ref = reference(samples, gamma, cfg)
    mask = ref.mask
    obs = {k: torch.from_numpy(np.ascontiguousarray(samples.obs[k][mask])) for k in CRITIC_GROUPS}
    n = int(mask.sum())
    if n == 0:
        raise MorficError("the training rollout has no sample in I_eps; raise --steps (see docs/metrics.md).")
    return FitData(TensorDict(obs, batch_size=[n]), ref.returns.float())


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
    """Regress V_phi on G over the fit set: Adam, mean squared error, ``cfg.epochs`` shuffled passes.

    The mini-batch order comes from a generator seeded with ``seed``, so two variants with the same seed see the
    same batches in the same order.

    Returns:
        (mean loss of each epoch, wall seconds).
    """
    critic.train()
    params = [p for p in critic.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(params, lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = data.G.shape[0]
    losses: list[float] = []
    start = time.perf_counter()
    for _ in range(cfg.epochs):
        order = torch.randperm(n, generator=gen)
        total, count = 0.0, 0
        for i in range(0, n, cfg.minibatch):
            idx = order[i : i + cfg.minibatch]
            value = critic(data.obs[idx]).reshape(-1)
            loss = torch.nn.functional.mse_loss(value, data.G[idx])
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
               clip_param: float) -> list[dict[str, Any]]:
    """Every fit's metrics on one sample set, CosGrad on the frozen ``actor`` (one pass for all fits).

    Returns:
        Per fit, in order: ``ev, nvb, abs_nvb, nve, asa, flip, cos_grad, cell, n_samples, g_mean, g_std, v_mean``.
    """
    ref = reference(samples, gamma, cfg)
    G = ref.returns
    mask_t = torch.from_numpy(ref.mask)
    values = [critic_values(f.critic, samples.obs)[mask_t].double() for f in fits]
    grads = actor_gradients(actor, samples.obs, samples.action, ref.mask,
                            [mc_advantage(G), *(critic_advantage(G, v) for v in values)], clip_param=clip_param)
    rows = []
    for v, g_phi in zip(values, grads[1:], strict=True):
        m = critic_metrics(G, v, cfg.sigma_eps)
        rows.append({"ev": m.ev, "nvb": m.nvb, "abs_nvb": abs(m.nvb), "nve": m.nve, "asa": m.asa, "flip": m.flip,
                     "cos_grad": cos_grad(g_phi, grads[0]), "cell": paper_cell(m.nvb, m.nve, m.asa),
                     "n_samples": m.n, "g_mean": m.g_mean, "g_std": m.g_std, "v_mean": m.v_mean})
    return rows


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
    from morfic_cli.rl.variants import resolve_variant

    check_cfg(cfg)
    progress = progress or StudyProgress()
    trained = actor if actor is not None else load_trained(store, actor_spec)
    gamma, clip = trained.cfg.ppo.gamma, trained.cfg.ppo.clip_param
    variants = canonical_variants(cfg.variants)
    multiplicative = {v: resolve_variant(v).multiplicative for v in variants}  # user classes fail here, early
    check_horizon(gamma, cfg.diagnose_cfg(cfg.commands[0], True))
    label = run_label(trained, actor_spec)
    rows: list[dict[str, Any]] = []
    fit_rows: list[dict[str, Any]] = []
    inputs = {"actor": trained.checkpoint_id}
    seconds = {"rollouts": 0.0, "fits": 0.0, "scoring": 0.0}
    for command in cfg.commands:
        t0 = time.perf_counter()
        train_cfg, target_cfg = cfg.diagnose_cfg(command, True), cfg.diagnose_cfg(command, False)
        joint = bool(target_cfg.batch)  # every target stepped as one env: one bar pass for all of them
        progress.phase(f"{label}: rollouts at {command:g} m/s", (2 if joint else 1 + len(cfg.robots)) * cfg.steps)
        step = lambda _t: progress.advance()  # noqa: E731
        train = collect_samples(store, trained, "go2", train_cfg, on_step=step)
        inputs[f"rollout/{command:g}/{TRAIN_ROBOT}"] = train.rollout_id
        targets: dict[str, Samples] = {}
        for k, robot in enumerate(cfg.robots):
            targets[robot] = collect_samples(store, trained, robot, target_cfg, on_step=step if k == 0 or not joint
                                             else None)
            inputs[f"rollout/{command:g}/{robot}"] = targets[robot].rollout_id
        seconds["rollouts"] += time.perf_counter() - t0
        fit_part, held = split_train(train, cfg.held_out)
        data = fit_data(fit_part, gamma, train_cfg)
        fits: list[Fit] = []
        progress.phase(f"fitting {len(variants)} x {cfg.seeds} critics at {command:g} m/s",
                       len(variants) * cfg.seeds * batches_per_fit(data.G.shape[0], cfg))
        for variant in variants:
            for seed in range(cfg.seeds):
                critic = build_critic(trained.cfg, variant, seed)
                losses, secs = fit_critic(critic, data, cfg, seed, on_batch=progress.advance)
                fit = Fit(variant, seed, critic, losses, secs)
                fits.append(fit)
                seconds["fits"] += secs
                fit_rows += [{"command_vx": command, "variant": variant, "fit_seed": seed, "epoch": e + 1,
                              "loss": loss, "seconds": secs, "parameters": fit.parameters,
                              "n_train": int(data.G.shape[0])} for e, loss in enumerate(losses)]
        t0 = time.perf_counter()
        sets = {TRAIN_ROBOT: held, **targets}
        progress.phase(f"scoring {len(fits)} critics at {command:g} m/s", len(sets))
        for robot, samples in sets.items():
            scores = score_fits(trained.actor, fits, samples, gamma, train_cfg, clip)
            for fit, score in zip(fits, scores, strict=True):
                rows.append({"command_vx": command, "robot": robot, "variant": fit.variant, "fit_seed": fit.seed,
                             "multiplicative": multiplicative[fit.variant], **score,
                             "fit_loss": fit.losses[-1], "fit_seconds": fit.seconds, "actor": label,
                             "rollout": samples.rollout_id})
            progress.advance()
        seconds["scoring"] += time.perf_counter() - t0
    summary = cell_summary(rows)
    claims = verdict_rows(study_claims(rows))
    config = {"actor": actor_spec, **{k: list(v) if isinstance(v, tuple) else v
                                      for k, v in dataclasses.asdict(cfg).items()}, "variants": variants}
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
