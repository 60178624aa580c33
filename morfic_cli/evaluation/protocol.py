"""The paper's zero-shot protocol over robots x commands, with MCAP logs and a table in the store.

One evaluation = one ``eval`` manifest (ref ``evals/<run name>``) holding ``eval.csv`` (a row per robot and command)
and ``terminations.csv`` (per row, the envs each termination term ended, :mod:`morfic_cli.evaluation.terminations`),
with inputs ``checkpoint`` (the evaluated weights) and ``rollout/<robot>/<mode>/vx<cmd>`` (one ``rollout`` manifest
per robot and command, holding that rollout's MCAP log, see docs/mcap.md, and its figure ``speed.png`` /
``speed.pdf``, forward speed and survival over time, see :mod:`morfic_cli.evaluation.figures`).
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from morfic_cli import __version__
from morfic_cli.evaluation.metric_terms import RolloutData, metric_terms, metric_values
from morfic_cli.evaluation.names import FIGURE_PDF, FIGURE_PNG, rollout_role
from morfic_cli.evaluation.rollout import Rollout, run_rollout, run_rollouts
from morfic_cli.runs import run_of
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.rl.load import TrainedModels


def eval_columns() -> tuple[str, ...]:
    """Columns of the eval table (``eval.csv``), in order: the row's keys, the registered metrics between them.

    ``robot, mode, command_vx, d``, each metric of :data:`~morfic_cli.evaluation.metric_terms.METRICS`, then
    ``num_envs, steps``.
    """
    return ("robot", "mode", "command_vx", "d", *(t.name for t in metric_terms()), "num_envs", "steps")


EVALS_PREFIX = "evals/"


@dataclass(frozen=True)
class EvalCfg:
    """An evaluation (defaults: the paper's protocol, docs/eval.md)."""

    robots: tuple[str, ...]
    modes: tuple[str, ...] = ("descriptor",)
    command_vx: tuple[float, ...] = (2.0,)
    num_envs: int = 64
    steps: int = 500
    seed: int = 0
    scene_envs: int = 4
    """How many envs (the first ones) carry a 3D scene (geoms and body frames) in each MCAP log."""
    batch_robots: bool = False
    """Step the descriptor-mode rollouts of all ``robots`` (per command) as one env of ``len(robots) * num_envs``
    envs, each robot its slice (:func:`~morfic_cli.evaluation.rollout.run_rollouts`): the same per-robot protocol
    and metrics, other random start states, half the CPU time for seven robots. Full mode runs each robot alone."""


def eval_config(spec: str, cfg: EvalCfg) -> dict[str, Any]:
    """The config of the ``eval`` manifest of ``spec`` under ``cfg``.

    ``batch_robots`` is in it only when set, so an unbatched evaluation keeps the config (and so the content
    address) it always had.
    """
    config = {"spec": spec, **dataclasses.asdict(cfg)}
    if not cfg.batch_robots:
        config.pop("batch_robots")
    return config


def batched(cfg: EvalCfg, mode: str) -> bool:
    """Whether ``cfg``'s rollouts in ``mode`` share one env (:attr:`EvalCfg.batch_robots`)."""
    return cfg.batch_robots and mode != "full" and len(cfg.robots) > 1


@dataclass
class EvalResult:
    """What :func:`evaluate` wrote: the table rows, the eval manifest id and its ref."""

    rows: list[dict[str, Any]]
    id: str
    ref: str
    version: int
    rollouts: dict[str, Rollout]


def metrics_row(rollout: Rollout, distance: float | None) -> dict[str, Any]:
    """One row of the eval table (:func:`eval_columns`): every registered metric of ``rollout``.

    Plus ``terminations`` (term -> envs whose first episode it ended, :meth:`Rollout.termination_counts`), which
    ``morfic eval --format json`` prints and ``terminations.csv`` stores; ``eval.csv`` keeps its columns.
    """
    return {
        "robot": rollout.robot,
        "mode": rollout.mode,
        "command_vx": rollout.command_vx,
        "d": distance,
        **metric_values(RolloutData(rollout.arrays, rollout.command_vx, rollout.dt)),
        "num_envs": int(rollout.arrays["done"].shape[1]),
        "steps": int(rollout.arrays["done"].shape[0]),
        "terminations": rollout.termination_counts(),
    }


def write_rollout_log(path: Path, rollout: Rollout, metadata: dict[str, Any], scene_envs: int = 0) -> None:
    """The rollout as an MCAP log (docs/mcap.md), with a 3D scene of its first ``scene_envs`` envs (kept models)."""
    from morfic_cli.recording.rollout_log import RolloutLogWriter
    from morfic_cli.recording.scene import RolloutScene

    n = min(scene_envs, len(rollout.models))
    scene = (
        RolloutScene(rollout.models[:n], range(n), rollout.qpos_adr) if n > 0 and rollout.qpos_adr is not None else None
    )
    a = rollout.arrays
    fields = (
        "base_pos",
        "base_quat",
        "base_lin_vel",
        "base_ang_vel",
        "command",
        "joint_pos",
        "joint_vel",
        "action",
        "reward",
        "reward_terms",
        "value",
        "done",
        "time_out",
    )
    num_steps, num_envs = a["done"].shape
    with RolloutLogWriter(
        path, num_envs=num_envs, term_names=rollout.term_names, metadata=metadata, scene=scene
    ) as log:
        for t in range(num_steps):
            log.write_step(t, (t + 1) * rollout.dt, {k: a[k][t] for k in fields})


def _times(on_step: Callable[[int], None], n: int) -> Callable[[int], None]:
    """``on_step`` called ``n`` times per step: a batch of n robots' progress, one step each."""

    def each(t: int) -> None:
        for _ in range(n):
            on_step(t)

    return each


def evaluate(
    store: Store,
    spec: str,
    cfg: EvalCfg,
    *,
    on_rollout_start: Callable[[str, str, float], None] | None = None,
    on_step: Callable[[int], None] | None = None,
    keep_models: int = 0,
    trained: TrainedModels | None = None,
) -> EvalResult:
    """Evaluate checkpoint ``spec`` on every robot x mode x command of ``cfg`` and store the results.

    ``keep_models`` > 0 keeps that many envs' MjModels in each returned rollout (for ``--video``; at least
    ``cfg.scene_envs`` are kept, for the logs' 3D scene). ``trained``:
    the checkpoint already loaded with :func:`~morfic_cli.rl.load.load_trained` (else it is loaded here).

    Raises:
        ArtifactNotFoundError / MorficError: ``spec`` is not a training checkpoint.
    """
    from morfic_cli.evaluation.figures import rollout_figure
    from morfic_cli.evaluation.terminations import TERMINATION_COLUMNS, TERMINATIONS_CSV, termination_lines
    from morfic_cli.morphology.distance import distance_table
    from morfic_cli.morphology.robots import list_robots
    from morfic_cli.recording.tables import rows_to_csv
    from morfic_cli.rl.load import load_trained

    if trained is None:
        trained = load_trained(store, spec)
    distances = {r.robot: r.d for r in distance_table(list_robots())}  # span over the whole library, as `distance`
    run_name = run_of(spec, trained.meta)
    rows, rollouts, inputs = [], {}, {"checkpoint": trained.checkpoint_id}
    keep = max(keep_models, cfg.scene_envs)
    joint: dict[tuple[str, float], dict[str, Rollout]] = {}  # (mode, vx) -> the batched rollouts, robot -> rollout

    def rollout_of(robot: str, mode: str, vx: float) -> Rollout:
        if not batched(cfg, mode):
            if on_rollout_start is not None:
                on_rollout_start(robot, mode, vx)
            return run_rollout(
                trained.actor,
                trained.critic,
                trained.cfg.env,
                robot=robot,
                mode=mode,
                command_vx=vx,
                num_envs=cfg.num_envs,
                steps=cfg.steps,
                seed=cfg.seed,
                on_step=on_step,
                keep_models=keep,
            )
        if (mode, vx) not in joint:
            if on_rollout_start is not None:
                on_rollout_start("+".join(cfg.robots), mode, vx)
            each = None if on_step is None else _times(on_step, len(cfg.robots))
            joint[(mode, vx)] = run_rollouts(
                trained.actor,
                trained.critic,
                trained.cfg.env,
                robots=cfg.robots,
                mode=mode,
                command_vx=vx,
                num_envs=cfg.num_envs,
                steps=cfg.steps,
                seed=cfg.seed,
                on_step=each,
                keep_models=keep,
            )
        return joint[(mode, vx)].pop(robot)

    with tempfile.TemporaryDirectory(prefix="morfic-eval-") as tmp:
        for robot in cfg.robots:
            for mode in cfg.modes:
                for vx in cfg.command_vx:
                    rollout = rollout_of(robot, mode, vx)
                    role = rollout_role(robot, mode, vx)
                    rollouts[role] = rollout
                    rows.append(metrics_row(rollout, distances.get(robot)))
                    meta = {
                        "run": run_name,
                        "checkpoint": trained.checkpoint_id,
                        "robot": robot,
                        "descriptor": [float(x) for x in rollout.descriptor],
                        "mode": mode,
                        "command": [vx, 0.0, 0.0],
                        "seed": cfg.seed,
                        "morfic_version": __version__,
                        "term_names": rollout.term_names,
                    }
                    path = Path(tmp) / f"{robot}-{mode}-vx{vx:g}.mcap"
                    write_rollout_log(path, rollout, meta, cfg.scene_envs)
                    png, pdf = rollout_figure(
                        rollout.arrays["base_lin_vel"][..., 0],
                        rollout.terminated,
                        rollout.dt,
                        vx,
                        f"{robot}, {mode} mode, command {vx:g} m/s",
                        foot_slip=rollout.arrays["foot_slip"],
                        outcomes=rollout.outcomes(),
                        verdict=rows[-1]["verdict"],
                        terminations=rows[-1]["terminations"],
                    )
                    config = {
                        "robot": robot,
                        "mode": mode,
                        "command_vx": vx,
                        "num_envs": cfg.num_envs,
                        "steps": cfg.steps,
                        "seed": cfg.seed,
                    }
                    if batched(cfg, mode):
                        config["batch"] = list(cfg.robots)  # stepped as its slice of one env of these robots
                    inputs[role] = store.publish(
                        "rollout",
                        config=config,
                        inputs={"checkpoint": trained.checkpoint_id},
                        files={"rollout.mcap": path, FIGURE_PNG: png, FIGURE_PDF: pdf},
                        meta={k: v for k, v in meta.items() if k != "term_names"},
                    ).id
        pub = store.publish(
            "eval",
            EVALS_PREFIX + run_name,
            config=eval_config(spec, cfg),
            inputs=inputs,
            files={
                "eval.csv": rows_to_csv(rows, eval_columns()),
                TERMINATIONS_CSV: rows_to_csv(termination_lines(rows), TERMINATION_COLUMNS),
            },
            meta={"run": run_name, "iteration": trained.meta.get("iteration")},
        )
    return EvalResult(rows, pub.id, *pub.advanced(), rollouts)


def parse_commands(text: str) -> tuple[float, ...]:
    """``"2.0,2.5"`` -> (2.0, 2.5). Raises ValueError on anything else."""
    values = tuple(float(x) for x in text.split(",") if x.strip())
    if not values:
        raise ValueError(text)
    return values
