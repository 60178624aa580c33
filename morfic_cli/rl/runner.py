"""Training runs: rsl-rl's OnPolicyRunner with checkpoints handed to a sink (docs/training.md, docs/concepts.md).

rsl-rl does the PPO loop (:class:`~rsl_rl.runners.OnPolicyRunner.learn`); morfic plugs in through its
``Logger``: :class:`~morfic_cli.rl.curve_logger.CurveLogger` turns each iteration's metrics into a training-curve
row and calls :class:`TrainingRun` back, which draws the progress, writes checkpoints and honours Ctrl-C between
iterations. The other concerns live beside it: model building (:mod:`morfic_cli.rl.build`), loading trained runs
(:mod:`morfic_cli.rl.load`), checkpoints (:mod:`morfic_cli.rl.checkpoint`), devices (:mod:`morfic_cli.rl.devices`)
and resume with its legacy formats (:mod:`morfic_cli.rl.resume`). Store layout of a run named ``NAME``:

- ref ``runs/NAME`` -> ``checkpoint`` manifests: ``model.pt`` (actor and critic weights),
  ``curve.csv`` (the training curve so far) and, in the last checkpoint of a training (finished or Ctrl-C),
  ``curve.png`` (drawn once, off the training loop); config = the resolved :class:`TrainCfg`;
  meta = variant, seed, iteration, env steps, wall time, git commit, finished/interrupted;
  input ``trainer_state`` = a ``checkpoint`` manifest (config ``{"role": "trainer-state"}``) with
  ``trainer.json`` + ``trainer-tensors.pt`` (optimiser states, env state, RNG states, logger buffers as
  tensors + JSON, :mod:`morfic_cli.rl.trainer_state`).

A checkpoint is therefore ONE ref update (:class:`morfic_cli.store.run_sink.RunSink`, which :func:`new_run` and
:func:`resume_run` wire): whatever instant a kill hits, ``runs/NAME`` names a checkpoint whose trainer state is
there, and ``--resume`` continues bit-exactly on CPU.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from rsl_rl.runners import OnPolicyRunner

from morfic_cli.errors import MorficError
from morfic_cli.rl import trainer_state
from morfic_cli.rl.build import rsl_rl_cfg, variant_record
from morfic_cli.rl.checkpoint import Checkpoint, CheckpointSink, to_bytes
from morfic_cli.rl.config import TrainCfg, apply_overrides, train_cfg_from_dict, train_cfg_to_dict
from morfic_cli.rl.curve_logger import CurveLogger
from morfic_cli.rl.devices import check_device, distributed_info, for_device, torch_device
from morfic_cli.rl.load import load_weights
from morfic_cli.rl.resume import load_resume_point
from morfic_cli.rl.rsl_rl_patches import raw_models, replace_logger
from morfic_cli.runs import RUNS_PREFIX
from morfic_cli.store.run_sink import RunSink
from morfic_cli.store.shallow import TRAINER_STATE_ROLE  # defined by the store: weights-only bundles leave it out

if TYPE_CHECKING:
    from morfic_cli.store import Store


def git_commit() -> str | None:
    """The commit of the morfic checkout this code runs from, or None outside a git checkout."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


class _SinkRunner(OnPolicyRunner):
    """OnPolicyRunner whose own file checkpoints are off: :class:`TrainingRun` hands checkpoints to its sink."""

    def save(self, path: str, infos: dict | None = None) -> None:  # noqa: ARG002
        """No files: checkpoints go to the run's sink."""


class _Stop(Exception):
    """Raised from the iteration hook to leave rsl-rl's loop after a Ctrl-C checkpoint."""


class TrainingRun:
    """One training run: env + rsl-rl runner + checkpoints into a sink. Use :func:`new_run` or :func:`resume_run`."""

    def __init__(
        self, sink: CheckpointSink, cfg: TrainCfg, name: str, device: str = "cpu", live: tuple[str, Path] | None = None
    ) -> None:
        from morfic_cli.envs.locomotion import LocomotionEnv
        from morfic_cli.rl.live_log import run_log_dir

        self.dist = distributed_info()
        self.live = (live[0], run_log_dir(live[1], name)) if live is not None and live[0] != "none" else None
        """(logger, run folder) of the live curves, or None."""
        cfg = for_device(cfg, device)
        self.sink, self.cfg, self.name, self.device = sink, cfg, name, torch_device(device)
        self.git_commit = git_commit()  # the code this process runs (HEAD may move while it trains)
        torch.manual_seed(cfg.seed)
        # under torchrun every rank simulates its own envs: seed + rank (rank 0 = a single-process run)
        self.env = LocomotionEnv(cfg.env, mode="train", seed=cfg.seed + self.dist.rank)
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the models on stdout
            self.runner = _SinkRunner(self.env, rsl_rl_cfg(cfg), log_dir=None, device=self.device)
        replace_logger(
            self.runner,
            lambda old: CurveLogger(
                log_dir="",
                cfg=old.cfg,
                env_cfg=old.env_cfg,
                num_envs=old.num_envs,
                is_distributed=self.runner.is_distributed,
                gpu_world_size=self.runner.gpu_world_size,
                gpu_global_rank=self.runner.gpu_global_rank,
                device=old.device,
                dt=self.env.dt,
                on_iteration=self._on_iteration,
                live=self.live,
            ),
        )
        self.rows: list[dict[str, float]] = []
        self.iteration = 0
        self.parent: str | None = None
        self.stop_requested = False
        self.interrupted = False
        self.progress: Callable[[dict[str, float]], None] | None = None
        self.checkpoints: list[Checkpoint] = []
        self.clock_from: float | None = None
        """A ``time.perf_counter()`` reading the next :meth:`train` counts the wall time from; None: its start."""
        self._fresh = True

    # ------------------------------------------------------------------ the loop
    def train(self) -> Checkpoint | None:
        """Run to ``cfg.max_iterations`` (or until Ctrl-C), checkpointing on the way; returns the last checkpoint."""
        remaining = self.cfg.max_iterations - self.iteration
        if remaining <= 0:
            return self.checkpoints[-1] if self.checkpoints else None
        self.runner.current_learning_iteration = self.iteration
        logger: CurveLogger = self.runner.logger
        logger.start_clock(self.clock_from)
        self.clock_from = None
        try:
            self.runner.learn(remaining, init_at_random_ep_len=self._fresh and self.cfg.init_at_random_ep_len)
        except _Stop:
            pass
        finally:
            logger.close_live()
            logger.stop_clock()
        return self.checkpoints[-1] if self.checkpoints else None

    @property
    def wall_time_s(self) -> float:
        """Wall seconds of the run, over resumes, checkpoints included.

        Counted from :attr:`clock_from` (or the start of rsl-rl's ``learn``) to now, or to the end of :meth:`train`.
        """
        return self.runner.logger.clock()

    def _on_iteration(self, row: dict[str, float]) -> None:
        self.iteration = int(row["iteration"])
        self.rows.append(row)
        if self.progress is not None:
            self.progress(row)
        last = self.iteration >= self.cfg.max_iterations
        stop = self.stop_requested and not last  # read once: a Ctrl-C during the save counts for the next iteration
        if self.dist.rank == 0 and (stop or last or self.iteration % self.cfg.save_interval == 0):
            self.save_checkpoint(finished=last, interrupted=stop)  # the other ranks hold the same weights
        if stop:
            self.interrupted = True
            raise _Stop

    # ------------------------------------------------------------------ checkpoints
    def save_checkpoint(self, *, finished: bool, interrupted: bool = False) -> Checkpoint:
        """Write the trainer state and the weights manifest naming it, then advance ``runs/NAME`` (one ref update).

        ``curve.png`` is drawn only for the last checkpoint of this training (``finished`` or ``interrupted``): at
        1-2 s a drawing, once per checkpoint it cost more than a smoke iteration; every checkpoint has ``curve.csv``.
        """
        from morfic_cli.recording.curves import curve_csv, curve_png

        alg = self.runner.alg
        actor, critic = raw_models(alg)
        model = to_bytes({"actor": actor.state_dict(), "critic": critic.state_dict()})
        curves = {"curve.csv": curve_csv(self.rows)}
        if finished or interrupted:
            curves["curve.png"] = curve_png(self.rows)
        logger: CurveLogger = self.runner.logger
        wall = logger.clock()  # after the drawing: the stored time misses only the write below
        saved = alg.save()
        saved.pop("actor_state_dict"), saved.pop("critic_state_dict")
        trainer = trainer_state.encode(
            {
                "iteration": self.iteration,
                "alg": saved,
                "learning_rate": alg.learning_rate,
                "env": self.env.state_dict(),
                "logger": self.runner.logger.state_dict(),
                "torch_rng": torch.get_rng_state(),
            }
        )
        meta = {
            "variant": self.cfg.variant,
            "seed": self.cfg.seed,
            "preset": self.cfg.preset,
            "iteration": self.iteration,
            "max_iterations": self.cfg.max_iterations,
            "env_steps": logger.tot_timesteps,
            "wall_time_s": round(wall, 3),
            "git_commit": self.git_commit,
            "finished": finished,
            "interrupted": interrupted,
            "parent": self.parent,
            "device": self.device,
            "run": self.name,
            "vx_max": float(self.env.command_ranges.vx[1]),
            **variant_record(self.cfg),
            **({"bf16_matmul": alg.bf16_matmul} if getattr(alg, "bf16_matmul", None) else {}),
        }
        ckpt, version = self.sink.write(
            {"model.pt": model, **curves},
            train_cfg_to_dict(self.cfg),
            meta,
            {
                TRAINER_STATE_ROLE: (
                    trainer,
                    {"role": "trainer-state"},
                    {"iteration": self.iteration, "run": self.name, "format": trainer_state.FORMAT},
                )
            },
        )
        self.parent = ckpt
        out = Checkpoint(ckpt, self.sink.ref, version, self.iteration)
        self.checkpoints.append(out)
        return out

    @property
    def head(self) -> str | None:
        """The id ``runs/NAME`` must point at when the next checkpoint is written (None: no ref yet)."""
        return self.sink.head

    @head.setter
    def head(self, ckpt_id: str | None) -> None:
        self.sink.head = ckpt_id

    def _restore(
        self, ckpt_id: str, model: dict[str, Any], trainer: dict[str, Any], rows: list[dict[str, float]]
    ) -> None:
        alg = self.runner.alg
        loaded = dict(trainer["alg"], actor_state_dict=model["actor"], critic_state_dict=model["critic"])
        alg.load(loaded, None, True)
        alg.learning_rate = trainer["learning_rate"]
        self.env.load_state_dict(trainer["env"])
        self.runner.logger.load_state_dict(trainer["logger"])
        torch.set_rng_state(trainer["torch_rng"])
        self.iteration = int(trainer["iteration"])
        self.rows = rows
        self.parent = ckpt_id
        self._fresh = False


def new_run(
    store: Store, cfg: TrainCfg, name: str, device: str = "cpu", live: tuple[str, Path] | None = None
) -> TrainingRun:
    """A fresh run under ``runs/NAME``.

    ``live`` = (logger, log root) writes live curves into ``<log root>/NAME`` (:mod:`morfic_cli.rl.live_log`).

    Raises:
        MorficError: ``runs/NAME`` already exists (resume it or pick another --name).
    """
    check_device(device)
    if store.has_ref(RUNS_PREFIX + name):
        raise MorficError(
            f"run '{RUNS_PREFIX}{name}' already exists in {store.root}; continue it with "
            f"`--resume {RUNS_PREFIX}{name}` or choose another --name."
        )
    return TrainingRun(RunSink(store, name), cfg, name, device, live)


def resume_run(
    store: Store,
    spec: str,
    overrides: list[str] | None = None,
    device: str = "cpu",
    live: tuple[str, Path] | None = None,
) -> TrainingRun:
    """Continue the run whose checkpoint ``spec`` names (``runs/NAME`` = its latest checkpoint).

    ``overrides`` may change e.g. ``max_iterations``; the config otherwise is the checkpoint's.

    Raises:
        ArtifactNotFoundError: No such checkpoint.
        UntrustedVariantError: Its user variant is neither trusted nor named on this command line.
        MorficError: Not a checkpoint, or its trainer state is missing (a weights-only bundle, or a policy bundle
            of an older morfic) or cannot be loaded as tensors.
    """
    check_device(device)
    point = load_resume_point(store, spec)
    cfg = apply_overrides(train_cfg_from_dict(point.manifest.config), list(overrides or []))
    run = TrainingRun(RunSink(store, point.name), cfg, point.name, device, live)
    run._restore(point.manifest.id, load_weights(store, point.manifest.id, run.device), point.trainer, point.rows)
    ref = RUNS_PREFIX + point.name
    if "@" not in spec and spec in (ref, point.name):  # the ref's current version, as read: no re-read race
        run.head = point.manifest.id
    else:  # an older version or an id: its checkpoints go on after the ref's current version (a fork)
        run.head = store.resolve(ref) if store.has_ref(ref) else None
    return run
