"""``morfic diagnose RUN...``: critic calibration of each run on each robot (paper Fig. 3 and Table "critic metrics").

For each run and robot: the run's actor collects a diagnostic rollout (:mod:`~morfic_cli.diagnostics.samples`),
its Monte-Carlo returns and I_eps are computed (:mod:`~morfic_cli.diagnostics.returns`), the run's critic is scored
on exactly those samples and the metrics of :mod:`~morfic_cli.diagnostics.metrics` are taken over I_eps; CosGrad is
measured on the run's own actor.

Store: one ``diagnosis`` manifest per call (ref ``diagnoses/calibration``, a new version each time) with
``calibration.csv`` (:data:`CALIBRATION_COLUMNS`, a row per run and robot) and the EV figure ``ev.png`` / ``ev.pdf``;
inputs ``checkpoint/<spec>`` and ``rollout/<spec>/<robot>``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from morfic_cli.diagnostics.metrics import CriticMetrics, cos_grad, critic_advantage, critic_metrics, mc_advantage
from morfic_cli.diagnostics.returns import mc_returns, min_horizon
from morfic_cli.diagnostics.samples import (
    DiagnoseCfg,
    Samples,
    batched,
    collect_batch,
    collect_samples,
    diagnose_config,
)
from morfic_cli.diagnostics.scoring import actor_gradients, critic_values
from morfic_cli.errors import MorficError
from morfic_cli.runs import run_of
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.load import TrainedModels

CALIBRATION_REF = "diagnoses/calibration"

#: Columns of ``calibration.csv``, in order.
CALIBRATION_COLUMNS: tuple[str, ...] = (
    "run",
    "variant",
    "checkpoint",
    "robot",
    "mode",
    "d",
    "ev",
    "nvb",
    "abs_nvb",
    "nve",
    "asa",
    "flip",
    "cos_grad",
    "cell",
    "n_samples",
    "coverage",
    "g_mean",
    "g_std",
    "v_mean",
    "gamma",
    "trunc_eps",
    "h_eps",
    "num_envs",
    "steps",
    "seed",
    "command_vx",
    "rollout",
)


@dataclass
class DiagnosisResult:
    """What a diagnosis wrote: the table rows, the manifest id, its ref and the ref's version."""

    rows: list[dict[str, Any]]
    id: str
    ref: str
    version: int


@dataclass
class Reference:
    """The Monte-Carlo reference of a sample set.

    Attributes:
        G: Discounted returns G_hat, float64. Shape: (T, N).
        mask: I_eps. Shape: (T, N) bool (numpy, to index the recorded arrays).
        gamma: Discount.
        h_eps: The minimum remaining horizon of a truncated sample in I_eps.
    """

    G: torch.Tensor
    mask: np.ndarray
    gamma: float
    h_eps: int

    @property
    def returns(self) -> torch.Tensor:
        """G over I_eps, row-major. Shape: (n,) float64."""
        return self.G[torch.from_numpy(self.mask)]


def check_horizon(gamma: float, cfg: DiagnoseCfg) -> int:
    """H_eps for (gamma, cfg.trunc_eps), after checking that ``cfg.steps`` leaves samples beyond it.

    Raises:
        MorficError: eps outside (0, 1), or steps <= H_eps (only samples of falling episodes would count).
    """
    if not 0.0 < cfg.trunc_eps < 1.0:
        raise MorficError(f"--trunc-eps must be in (0, 1), got {cfg.trunc_eps}; the default is 0.05.")
    h = min_horizon(gamma, cfg.trunc_eps)
    if cfg.steps <= h:
        raise MorficError(
            f"--steps {cfg.steps} is too short for Monte-Carlo returns: with gamma {gamma:g} and --trunc-eps "
            f"{cfg.trunc_eps:g} a sample counts only with at least {h} steps left before the rollout ends, so give "
            f"--steps above {h} (e.g. {h + 500}) or a larger --trunc-eps (see docs/metrics.md)."
        )
    return h


def reference(samples: Samples, gamma: float, cfg: DiagnoseCfg) -> Reference:
    """G_hat and I_eps of a sample set."""
    G, mask = mc_returns(
        torch.from_numpy(samples.reward),
        torch.from_numpy(samples.done),
        torch.from_numpy(samples.time_out),
        gamma,
        cfg.trunc_eps,
    )
    return Reference(G, mask.numpy(), gamma, min_horizon(gamma, cfg.trunc_eps))


def score_critics(
    actor: torch.nn.Module,
    critics: Sequence[torch.nn.Module],
    samples: Samples,
    ref: Reference,
    cfg: DiagnoseCfg,
    clip_param: float = 0.2,
) -> list[dict[str, Any]]:
    """Each critic's metrics on the samples, with CosGrad measured on ``actor``.

    Args:
        actor: The actor whose PPO gradient CosGrad compares (the one that collected the samples).
        critics: The critics to score.
        samples: The diagnostic rollout.
        ref: Its Monte-Carlo reference.
        cfg: For sigma_eps.
        clip_param: PPO clip range of the actor's run.

    Returns:
        Per critic: ``ev, nvb, abs_nvb, nve, asa, flip, cos_grad, cell, n_samples, coverage, g_mean, g_std, v_mean``.
    """
    G = ref.returns
    mask_t = torch.from_numpy(ref.mask)
    values = [critic_values(c, samples.obs)[mask_t].double() for c in critics]
    a_mc = mc_advantage(G)
    grads = actor_gradients(
        actor,
        samples.obs,
        samples.action,
        ref.mask,
        [a_mc, *(critic_advantage(G, v) for v in values)],
        clip_param=clip_param,
    )
    coverage = float(ref.mask.mean())
    return [
        {**metric_row(critic_metrics(G, v, cfg.sigma_eps), cos_grad(g_phi, grads[0])), "coverage": coverage}
        for v, g_phi in zip(values, grads[1:], strict=True)
    ]


def metric_row(m: CriticMetrics, cos: float) -> dict[str, Any]:
    """One critic's scores as a table row, the columns calibration.csv and critic_study.csv share.

    Args:
        m: Its metrics on one sample set.
        cos: Its CosGrad on that set.

    Returns:
        ``ev, nvb, abs_nvb, nve, asa, flip, cos_grad, cell, n_samples, g_mean, g_std, v_mean``.
    """
    return {
        "ev": m.ev,
        "nvb": m.nvb,
        "abs_nvb": abs(m.nvb),
        "nve": m.nve,
        "asa": m.asa,
        "flip": m.flip,
        "cos_grad": cos,
        "cell": paper_cell(m.nvb, m.nve, m.asa),
        "n_samples": m.n,
        "g_mean": m.g_mean,
        "g_std": m.g_std,
        "v_mean": m.v_mean,
    }


def paper_cell(nvb: float, nve: float, asa: float) -> str:
    """The paper's table cell ``|NVB|/NVE/ASA``, e.g. ``0.412/1.038/0.611``."""
    return "/".join("nan" if math.isnan(x) else f"{x:.3f}" for x in (abs(nvb), nve, asa))


def run_label(trained: TrainedModels, spec: str) -> str:
    """The run name of a checkpoint (its ``run`` meta, else the spec minus ``runs/``), plus the spec's ``@N``."""
    name = run_of(spec, trained.meta)
    return f"{name}@{spec.split('@', 1)[1]}" if "@" in spec else name


def _times(on_step: Callable[[int], None], n: int) -> Callable[[int], None]:
    """``on_step`` called ``n`` times per step: a batch of n robots' progress, one step each."""

    def each(t: int) -> None:
        for _ in range(n):
            on_step(t)

    return each


def diagnose_runs(
    store: Store,
    specs: Sequence[str],
    cfg: DiagnoseCfg,
    *,
    trained: Sequence[TrainedModels] | None = None,
    on_rollout_start: Callable[[str, str], None] | None = None,
    on_step: Callable[[int], None] | None = None,
) -> DiagnosisResult:
    """Calibration metrics of every run in ``specs`` on every robot of ``cfg``; stored as a ``diagnosis``.

    Args:
        store: Artifact store.
        specs: Checkpoint specs (``runs/film-s0``, ``runs/film-s0@3``, id), distinct.
        cfg: Rollout and metric settings.
        trained: The checkpoints already loaded, in the order of ``specs`` (else loaded here).
        on_rollout_start: Called with (run label, robot) before each rollout.
        on_step: Progress per policy step.

    Raises:
        MorficError: A spec is not a checkpoint, or ``cfg.steps`` is too short for its discount.
    """
    from morfic_cli.diagnostics.figures import ev_figure
    from morfic_cli.morphology.distance import distance_table
    from morfic_cli.morphology.robots import list_robots
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.rl.load import load_trained

    models = list(trained) if trained is not None else [load_trained(store, s) for s in specs]
    for m in models:
        check_horizon(m.cfg.ppo.gamma, cfg)
    distances = {r.robot: r.d for r in distance_table(list_robots())}
    rows: list[dict[str, Any]] = []
    inputs: dict[str, str] = {}
    labels = [run_label(m, s) for s, m in zip(specs, models, strict=True)]
    for spec, model, label in zip(specs, models, labels, strict=True):
        inputs[f"checkpoint/{spec}"] = model.checkpoint_id
        gamma = model.cfg.ppo.gamma
        joint: dict[str, Samples] | None = None  # the batched robots' samples (cfg.batch), collected at once
        for robot in cfg.robots:
            if batched(robot, cfg):
                if joint is None:
                    if on_rollout_start is not None:
                        on_rollout_start(label, "+".join(cfg.batch))
                    each = None if on_step is None else _times(on_step, len(cfg.batch))
                    joint = collect_batch(store, model, cfg, on_step=each)
                samples = joint.pop(robot)
            else:
                if on_rollout_start is not None:
                    on_rollout_start(label, robot)
                samples = collect_samples(store, model, robot, cfg, on_step=on_step)
            inputs[f"rollout/{spec}/{robot}"] = samples.rollout_id
            ref = reference(samples, gamma, cfg)
            (scores,) = score_critics(model.actor, [model.critic], samples, ref, cfg, model.cfg.ppo.clip_param)
            rows.append(
                {
                    "run": label,
                    "variant": model.cfg.variant,
                    "checkpoint": model.checkpoint_id,
                    "robot": robot,
                    "mode": cfg.mode,
                    "d": distances.get(robot),
                    **scores,
                    "gamma": gamma,
                    "trunc_eps": cfg.trunc_eps,
                    "h_eps": ref.h_eps,
                    "num_envs": cfg.num_envs,
                    "steps": cfg.steps,
                    "seed": cfg.seed,
                    "command_vx": float(cfg.command_vx),
                    "rollout": samples.rollout_id,
                    "reused": samples.reused,
                }
            )
    rows = [{**{k: row[k] for k in CALIBRATION_COLUMNS}, "reused": row["reused"]} for row in rows]
    png, pdf = ev_figure(rows)
    config = {"specs": list(specs), **diagnose_config(cfg)}
    pub = store.publish(
        "diagnosis",
        CALIBRATION_REF,
        config=config,
        inputs=inputs,
        meta={"runs": labels},
        files={"calibration.csv": rows_to_csv(rows, CALIBRATION_COLUMNS), "ev.png": png, "ev.pdf": pdf},
    )
    return DiagnosisResult(rows, pub.id, *pub.advanced())
