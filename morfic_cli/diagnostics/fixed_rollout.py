"""``morfic diagnose --fixed-rollout ROBOT``: one frozen actor, many critics, the same samples (paper Table "causal").

The paper's causality analysis: freeze one actor (MorFiC's by default), collect its rollouts on the target once,
then score each critic on exactly those samples against the Monte-Carlo reference: the sign-flip rate of its
advantages and the cosine between the actor gradient its advantages would produce and the MC one (both gradients of
the *frozen* actor). The MC row is the reference scored against itself (V = mean(G): Flip 0, Cos 1).

Every critic must predict the same returns from the same inputs as the actor's run defines them: same discount,
reward terms, observation layout and control step; otherwise it is refused (:func:`check_compatible`).

Store: one ``diagnosis`` manifest per call (ref ``diagnoses/fixed-rollout/<robot>``) with ``fixed_rollout.csv``
(:data:`FIXED_ROLLOUT_COLUMNS`, the MC row first); inputs ``actor``, ``critic/<spec>`` and ``rollout``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch

from morfic_cli.config import eval_env_cfg
from morfic_cli.diagnostics.calibration import DiagnosisResult, check_horizon, reference, run_label, score_critics
from morfic_cli.diagnostics.samples import DiagnoseCfg, collect_samples, diagnose_config
from morfic_cli.errors import MorficError
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.config import TrainCfg
    from morfic_cli.rl.load import TrainedModels

FIXED_ROLLOUT_PREFIX = "diagnoses/fixed-rollout/"

#: Columns of ``fixed_rollout.csv``, in order.
FIXED_ROLLOUT_COLUMNS: tuple[str, ...] = (
    "critic",
    "variant",
    "robot",
    "flip",
    "cos_grad",
    "asa",
    "ev",
    "nvb",
    "abs_nvb",
    "nve",
    "n_samples",
    "coverage",
    "checkpoint",
    "actor",
    "actor_variant",
    "mode",
    "gamma",
    "trunc_eps",
    "h_eps",
    "num_envs",
    "steps",
    "seed",
    "command_vx",
    "rollout",
)

DEFAULT_ACTOR_VARIANT = FIXED_ROLLOUT_ACTOR


class _MeanCritic(torch.nn.Module):
    """The MC reference as a 'critic': V = mean(G) over I_eps for every sample, so A_phi = A_MC."""

    def __init__(self, value: float) -> None:
        super().__init__()
        self.value = value

    def forward(self, obs) -> torch.Tensor:  # noqa: D102
        return torch.full((obs.batch_size[0], 1), self.value, dtype=torch.float64)


def unusable_run(manifest: Any) -> str | None:
    """Why a run's checkpoint cannot be a default pick, or None; nothing is imported.

    Its stored config is invalid (:func:`~morfic_cli.validation.stored_cfg_problem`), or it needs a user variant that
    is not well-formed or not trusted here (:mod:`morfic_cli.rl.variants`).
    """
    from morfic_cli.errors import printable
    from morfic_cli.rl.variants import check_variant_name, is_trusted
    from morfic_cli.validation import stored_cfg_problem

    problem = stored_cfg_problem(manifest.config)
    if problem is not None:
        return f"its stored config is invalid ({printable(problem)})"
    variant = manifest.config.get("variant", "film")
    try:
        check_variant_name(variant)
    except MorficError as exc:
        return printable(str(exc).rstrip("."))
    if not is_trusted(variant):
        return f"it needs the user variant {variant}, not trusted here (--trust-variant {variant} names it)"
    return None


def newest_runs(store: Store, on_skip: Callable[[str, str], None] | None = None) -> dict[str, str]:
    """Variant -> ref (``runs/NAME``) of the newest usable checkpoint of that variant in the store.

    A run :func:`unusable_run` refuses is left out, and ``on_skip(ref, why)`` told: one bad run (a hand-made
    bundle's) does not break every command's default choice.
    """
    from morfic_cli.runs import RUNS_PREFIX

    newest: dict[str, tuple[str, str]] = {}
    for name in store.list_refs():
        if not name.startswith(RUNS_PREFIX):
            continue
        manifest = store.read_manifest(name)
        variant = manifest.meta.get("variant")
        if manifest.kind != "checkpoint" or "model.pt" not in manifest.files or not isinstance(variant, str):
            continue
        why = unusable_run(manifest)
        if why is not None:
            if on_skip is not None:
                on_skip(name, why)
            continue
        if variant not in newest or manifest.created > newest[variant][0]:
            newest[variant] = (manifest.created, name)
    return {v: ref for v, (_, ref) in newest.items()}


def default_actor(store: Store, on_skip: Callable[[str, str], None] | None = None) -> str:
    """The newest usable ``film`` run (``on_skip``: see :func:`newest_runs`).

    Raises:
        MorficError: The store has none.
    """
    runs = newest_runs(store, on_skip)
    if DEFAULT_ACTOR_VARIANT not in runs:
        have = ", ".join(sorted(runs)) or "none"
        raise MorficError(
            f"--fixed-rollout needs an actor: no '{DEFAULT_ACTOR_VARIANT}' run in store {store.root} "
            f"(variants present: {have}); pass --actor runs/NAME or train one with "
            f"`morfic train --variant {DEFAULT_ACTOR_VARIANT}`."
        )
    return runs[DEFAULT_ACTOR_VARIANT]


def default_critics(store: Store, on_skip: Callable[[str, str], None] | None = None) -> list[str]:
    """The newest usable run of each variant, in the paper's variant order (``on_skip``: see :func:`newest_runs`)."""
    from morfic_cli.rl.variants import VARIANTS

    runs = newest_runs(store, on_skip)
    return [runs[v] for v in VARIANTS if v in runs] + [r for v, r in sorted(runs.items()) if v not in VARIANTS]


def incompatible(actor: TrainCfg, critic: TrainCfg) -> list[str]:
    """The settings in which ``critic``'s training config differs from ``actor``'s (empty: it can be scored).

    A critic that differs predicts other returns or reads other inputs than the actor's rollouts record. Compared: the
    discount, the reward config, the (noise-free) observation config, and the control step. Whether the env also gives
    URMA's token groups (``env.obs.body_tokens``) does not count: :func:`load_models` has the actor's rollout record
    them when a critic reads them.
    """
    pairs = {
        "ppo.gamma": (actor.ppo.gamma, critic.ppo.gamma),
        "env.rewards": (actor.env.rewards, critic.env.rewards),
        "env.obs": tuple(dataclasses.replace(eval_env_cfg(x.env).obs, body_tokens=False) for x in (actor, critic)),
        "env.decimation": (actor.env.decimation, critic.env.decimation),
        "env.sim.physics_dt": (actor.env.sim.physics_dt, critic.env.sim.physics_dt),
    }
    return [k for k, (x, y) in pairs.items() if x != y]


def check_compatible(actor: TrainedModels, critic: TrainedModels, label: str) -> None:
    """Refuse a critic that was trained on other returns or other inputs than the actor's run (:func:`incompatible`).

    Raises:
        MorficError: They differ; the message names what.
    """
    differ = incompatible(actor.cfg, critic.cfg)
    if differ:
        raise MorficError(
            f"critic {label} was trained with other {', '.join(differ)} than the actor's run, so its "
            "values predict other returns or read other inputs; pass critics trained with the same "
            "settings (--critics runs/A,runs/B)."
        )


@dataclass
class FixedRolloutModels:
    """The frozen actor and the critics of a fixed-rollout analysis, loaded and checked (:func:`load_models`)."""

    actor_spec: str
    actor: TrainedModels
    critic_specs: list[str]
    critics: list[TrainedModels]


def recording_tokens(trained: TrainedModels) -> TrainedModels:
    """``trained`` whose rollouts also record URMA's token groups, which a urma critic reads.

    Same physics, same actor inputs, more groups kept (:func:`~morfic_cli.diagnostics.samples.kept_groups`).
    """
    env = trained.cfg.env
    if env.obs.body_tokens:
        return trained
    obs = dataclasses.replace(env.obs, body_tokens=True)
    return dataclasses.replace(trained, cfg=dataclasses.replace(trained.cfg, env=dataclasses.replace(env, obs=obs)))


def load_models(
    store: Store,
    actor_spec: str | None,
    critic_specs: Sequence[str] | None,
    cfg: DiagnoseCfg,
    on_skip: Callable[[str, str], None] | None = None,
) -> FixedRolloutModels:
    """Resolve the defaults, load the actor and the critics, and check them against each other and ``cfg``.

    Args:
        store: Artifact store.
        actor_spec: The actor's checkpoint; None = the newest ``film`` run.
        critic_specs: The critics' checkpoints; None or empty = the newest run of each variant.
        cfg: Rollout and metric settings (its steps are checked against the actor's discount).
        on_skip: Told ``(ref, why)`` of each run a default choice left out (:func:`newest_runs`; with the default
            critics also those :func:`incompatible` with the actor, which named critics make an error).

    Raises:
        MorficError: No default actor, a critic named twice, a spec that is not a checkpoint, an incompatible
            critic, or ``cfg.steps`` too short.
    """
    from morfic_cli.rl.load import load_trained

    skipped: dict[str, str] = {}
    actor_spec = actor_spec or default_actor(store, skipped.__setitem__)
    specs = list(critic_specs or default_critics(store, skipped.__setitem__))
    for ref, why in skipped.items():  # each bad run once, though both defaults saw it
        if on_skip is not None:
            on_skip(ref, why)
    if len(set(specs)) != len(specs):
        raise MorficError(f"--critics names a run twice: {','.join(specs)}; give each critic once.")
    actor = load_trained(store, actor_spec)
    critics = [load_trained(store, s) for s in specs]
    if not critic_specs:  # the default choice leaves out a critic the actor's rollouts cannot feed, and says so
        keep = [not incompatible(actor.cfg, c.cfg) for c in critics]
        for spec, critic, k in zip(specs, critics, keep, strict=True):
            if not k and on_skip is not None:
                on_skip(spec, f"trained with other {', '.join(incompatible(actor.cfg, critic.cfg))} than the actor")
        specs = [s for s, k in zip(specs, keep, strict=True) if k]
        critics = [c for c, k in zip(critics, keep, strict=True) if k]
        if not critics:
            raise MorficError(
                f"no run in {store.root} has a critic that {actor_spec}'s rollouts can feed (same discount, rewards, "
                "observations and control step); name critics with --critics runs/A,runs/B."
            )
    for spec, critic in zip(specs, critics, strict=True):
        check_compatible(actor, critic, spec)
    if any(c.cfg.env.obs.body_tokens for c in critics):
        actor = recording_tokens(actor)
    check_horizon(actor.cfg.ppo.gamma, cfg)
    return FixedRolloutModels(actor_spec, actor, specs, critics)


def fixed_rollout(
    store: Store,
    robot: str,
    models: FixedRolloutModels,
    cfg: DiagnoseCfg,
    *,
    on_rollout_start: Callable[[str, str], None] | None = None,
    on_step: Callable[[int], None] | None = None,
) -> DiagnosisResult:
    """Score every critic on the frozen actor's rollout of ``robot``: Flip and CosGrad against MC.

    Args:
        store: Artifact store.
        robot: Target robot (its rollout is collected once, or reused from the store).
        models: The actor and critics (:func:`load_models`).
        cfg: Rollout and metric settings (``cfg.robots`` is ignored).
        on_rollout_start: Called with (actor label, robot) before the rollout.
        on_step: Progress per policy step.

    Returns:
        The rows (the MC reference first, then one per critic in the given order) and the stored diagnosis.
    """
    from morfic_cli.recording.tables import rows_to_csv

    actor, actor_spec = models.actor, models.actor_spec
    critic_specs, critics = models.critic_specs, models.critics
    gamma = actor.cfg.ppo.gamma
    actor_label = run_label(actor, actor_spec)
    if on_rollout_start is not None:
        on_rollout_start(actor_label, robot)
    samples = collect_samples(store, actor, robot, cfg, on_step=on_step)
    ref = reference(samples, gamma, cfg)
    mc = _MeanCritic(float(ref.returns.mean()) if ref.returns.numel() else 0.0)
    scores = score_critics(actor.actor, [mc, *(c.critic for c in critics)], samples, ref, cfg, actor.cfg.ppo.clip_param)
    common = {
        "robot": robot,
        "actor": actor_label,
        "actor_variant": actor.cfg.variant,
        "mode": cfg.mode,
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
    rows = [{"critic": "MC", "variant": "mc", "checkpoint": None, **scores[0], **common}]
    for spec, critic, score in zip(critic_specs, critics, scores[1:], strict=True):
        rows.append(
            {
                "critic": run_label(critic, spec),
                "variant": critic.cfg.variant,
                "checkpoint": critic.checkpoint_id,
                **score,
                **common,
            }
        )
    rows = [{**{k: row[k] for k in FIXED_ROLLOUT_COLUMNS}, "reused": row["reused"]} for row in rows]
    inputs = {
        "actor": actor.checkpoint_id,
        "rollout": samples.rollout_id,
        **{f"critic/{s}": c.checkpoint_id for s, c in zip(critic_specs, critics, strict=True)},
    }
    config = {"robot": robot, "actor": actor_spec, "critics": critic_specs, **diagnose_config(cfg)}
    config.pop("robots")
    ref_name = FIXED_ROLLOUT_PREFIX + robot
    pub = store.publish(
        "diagnosis",
        ref_name,
        config=config,
        inputs=inputs,
        files={"fixed_rollout.csv": rows_to_csv(rows, FIXED_ROLLOUT_COLUMNS)},
        meta={"actor": actor_label, "critics": [r["critic"] for r in rows[1:]]},
    )
    return DiagnosisResult(rows, pub.id, *pub.advanced())
