"""Training runs: rsl-rl's OnPolicyRunner with checkpoints in the artifact store (docs/training.md, docs/concepts.md).

rsl-rl does the PPO loop (:class:`~rsl_rl.runners.OnPolicyRunner.learn`); morfic plugs in through its
``Logger``: :class:`CurveLogger` turns each iteration's metrics into a training-curve row and calls
:class:`TrainingRun` back, which draws the progress, writes checkpoints and honours Ctrl-C between
iterations. Store layout of a run named ``NAME``:

- ref ``runs/NAME`` -> ``checkpoint`` manifests: ``model.pt`` (actor and critic weights),
  ``curve.csv`` (the training curve so far) and, in the last checkpoint of a training (finished or Ctrl-C),
  ``curve.png`` (drawn once, off the training loop); config = the resolved :class:`TrainCfg`;
  meta = variant, seed, iteration, env steps, wall time, git commit, finished/interrupted;
  input ``trainer_state`` = a ``checkpoint`` manifest (config ``{"role": "trainer-state"}``) with
  ``trainer.json`` + ``trainer-tensors.pt`` (optimiser states, env state, RNG states, logger buffers as
  tensors + JSON, :mod:`morfic_cli.rl.trainer_state`).

A checkpoint is therefore ONE ref update: whatever instant a kill hits, ``runs/NAME`` names a
checkpoint whose trainer state is there, and ``--resume`` continues bit-exactly on CPU. The update is a
compare-and-set on the version this process last wrote (or resumed from; none for a new run), so two trainings
that write one run at once cannot interleave their checkpoints: the second to checkpoint stops with an error. Every
``torch.load`` here is ``weights_only=True``: a bundle from anyone can never run code.

Runs written before this layout kept the trainer state apart, under ref ``resume/NAME`` (``trainer.pt``,
input ``checkpoint`` = the weights); they still resume when that file holds only tensors and plain
containers, and give a clear error otherwise.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import re
import subprocess
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger
from tensordict import TensorDict

from morfic_cli import __version__
from morfic_cli.envs import observations as O
from morfic_cli.errors import ArtifactNotFoundError, MorficError
from morfic_cli.morphology.descriptor import DIM as DESCRIPTOR_DIM
from morfic_cli.morphology.extended import EXTENDED_DIM
from morfic_cli.rl import trainer_state
from morfic_cli.rl.config import TrainCfg, apply_overrides, train_cfg_from_dict, train_cfg_to_dict
from morfic_cli.rl.models import link_morphology_encoder
from morfic_cli.rl.ppo import ALGORITHM_CLASS
from morfic_cli.rl.rsl_rl_patches import raw_models, replace_logger
from morfic_cli.rl.variants import resolve_variant
from morfic_cli.runs import RESUME_PREFIX, RUNS_PREFIX, run_of
from morfic_cli.sim.args import NUM_JOINTS
from morfic_cli.store import RefMovedError, Store
from morfic_cli.store.lock import LockTimeoutError
from morfic_cli.store.refs import is_ref_name
from morfic_cli.store.shallow import TRAINER_STATE_ROLE  # defined by the store: weights-only bundles leave it out
from morfic_cli.validation import check_stored_cfg


def rsl_rl_cfg(cfg: TrainCfg) -> dict[str, Any]:
    """The rsl-rl runner config (``obs_groups``, ``algorithm``, ``actor``, ``critic``, ...) of a TrainCfg.

    Raises:
        MorficError: A user variant whose module cannot be imported (:func:`~morfic_cli.rl.variants.resolve_variant`),
            or a variant that reads observation groups the env config does not give.
    """
    variant = resolve_variant(cfg.variant)
    actor, critic, obs_groups = variant.model_cfgs()
    given = dummy_observations(cfg).keys()
    missing = [g for groups in obs_groups.values() for g in groups if g not in given]
    if missing:  # e.g. urma with --set env.obs.body_tokens=false
        raise MorficError(f"variant {cfg.variant} reads the observation groups {', '.join(dict.fromkeys(missing))}, "
                          "which this env config does not give; keep the variant's env settings (for urma "
                          "env.obs.body_tokens=true).")
    if "distribution_cfg" in actor:
        actor["distribution_cfg"]["init_std"] = cfg.model.init_std
    if not variant.own_models:  # the external baselines keep their own sizes (model.*_hidden_dims are the MLPs')
        actor["hidden_dims"] = list(cfg.model.actor_hidden_dims)
        if cfg.model.critic_hidden_dims is not None:
            critic["hidden_dims"] = list(cfg.model.critic_hidden_dims)
    if variant.stock and not variant.own_models:  # a user's class takes the config its critic_defaults give
        if critic["conditioning"] == "film":
            critic["conditioning_scale"] = cfg.model.film_scale
        if critic["conditioning"] == "hyper" and cfg.model.hyper_conditions == "head":
            critic["conditioning"] = "hyper_head"
        if cfg.model.shared_morphology_encoder and variant.actor_morphology and variant.critic_morphology:
            critic["shared_morphology_encoder"] = True
    algorithm = {"class_name": ALGORITHM_CLASS, "optimizer": "adam", **dataclasses.asdict(cfg.ppo),
                 "rnd_cfg": None, "symmetry_cfg": None}
    return {
        "obs_groups": obs_groups,
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": cfg.save_interval,
        "check_for_nan": True,
        "algorithm": algorithm,
        "actor": actor,
        "critic": critic,
        "logger": "tensorboard",
    }


def dummy_observations(cfg: TrainCfg, batch: int = 1) -> TensorDict:
    """Zero observations with the env's group shapes, to build models without an env. Batch shape: (batch,)."""
    h = O.history_frames(cfg.env.obs)
    return TensorDict(
        {
            "policy": torch.zeros(batch, O.POLICY_DIM),
            "history": torch.zeros(batch, h, O.POLICY_DIM),
            "critic": torch.zeros(batch, h, O.POLICY_DIM),
            "privileged": torch.zeros(batch, O.PRIVILEGED_DIM),
            "morphology": torch.zeros(batch, EXTENDED_DIM if cfg.env.obs.extended_morphology else DESCRIPTOR_DIM),
            **({"joint_description": torch.zeros(batch, NUM_JOINTS, O.JOINT_DESCRIPTION_DIM),
                "foot_description": torch.zeros(batch, 4, O.FOOT_DESCRIPTION_DIM),
                "foot_state": torch.zeros(batch, 4, O.FOOT_STATE_DIM)} if cfg.env.obs.body_tokens else {}),
        },
        batch_size=[batch],
    )


def build_models(cfg: TrainCfg) -> tuple[torch.nn.Module, torch.nn.Module]:
    """A fresh (actor, critic) pair of a config, on CPU, without an env."""
    from rsl_rl.utils import resolve_class
    from rsl_rl.utils.utils import resolve_obs_groups

    rcfg = rsl_rl_cfg(cfg)
    obs = dummy_observations(cfg)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the resolved groups on stdout
        groups = resolve_obs_groups(obs, rcfg["obs_groups"], ["actor", "critic"])
    actor_class, actor_kwargs = resolve_class(rcfg["actor"])
    critic_class, critic_kwargs = resolve_class(rcfg["critic"])
    actor = actor_class(obs, groups, "actor", NUM_JOINTS, **actor_kwargs)
    critic = critic_class(obs, groups, "critic", 1, **critic_kwargs)
    link_morphology_encoder(actor, critic)
    return actor, critic


@dataclasses.dataclass
class TrainedModels:
    """A checkpoint's models, ready for evaluation (eval mode, CPU)."""

    actor: torch.nn.Module
    critic: torch.nn.Module
    cfg: TrainCfg
    checkpoint_id: str
    meta: dict[str, Any]


def load_trained(store: Store, spec: str) -> TrainedModels:
    """Load a checkpoint's actor and critic (``spec``: ``runs/NAME``, ``runs/NAME@N``, id or prefix).

    Raises:
        ArtifactNotFoundError: Nothing by that name.
        UntrustedVariantError: Its user variant is neither trusted nor named on this command line (nothing of it
            is imported; :func:`~morfic_cli.rl.variants.require_trusted`).
        MorficError: It is not a training checkpoint, or its user variant cannot be imported or its weights do
            not fit that class.
    """
    manifest = store.read_manifest(spec)
    if manifest.kind != "checkpoint" or "model.pt" not in manifest.files:
        raise MorficError(f"'{spec}' is a {manifest.kind} artifact, not a training checkpoint; "
                          "pass a run ref such as runs/film-cpu-s0 (see `morfic store ls --kind checkpoint`).")
    check_weights(store, spec, manifest)
    cfg = check_stored_cfg(manifest.config, spec)  # a bundle's config: checked before anything is built
    variant = resolve_variant(cfg.variant, source=spec)  # a user variant: only with the user's consent, else Error
    actor, critic = build_models(cfg)
    state = _load_weights(store, manifest.id, "cpu")
    try:
        actor.load_state_dict(state["actor"])
        critic.load_state_dict(state["critic"])
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0]
        if variant.stock:
            raise MorficError(
                f"checkpoint '{spec}' was written by morfic {manifest.morfic_version}, and its weights do not fit "
                f"the '{cfg.variant}' models of this morfic {__version__} ({first}); evaluate it with morfic "
                f"{manifest.morfic_version}, or retrain it with this version.") from exc
        raise MorficError(f"checkpoint '{spec}' does not fit variant '{cfg.variant}' ({variant.critic_class}) as "
                          f"it is installed now ({first}); install the version of the class it was trained "
                          "with.") from exc
    actor.eval()
    critic.eval()
    return TrainedModels(actor, critic, cfg, manifest.id, dict(manifest.meta))


def variant_record(cfg: TrainCfg) -> dict[str, Any]:
    """What a checkpoint's meta records of its variant: the actor and critic configs it was built from.

    The variant itself (a stock name or a user's import path) is ``meta.variant``; ``model`` keeps the classes
    and their config as rsl-rl received them, so a reader can see what a user variant's class was given.
    """
    rcfg = rsl_rl_cfg(cfg)
    return {"model": {"actor": rcfg["actor"], "critic": rcfg["critic"], "obs_groups": rcfg["obs_groups"]}}


def git_commit() -> str | None:
    """The commit of the morfic checkout this code runs from, or None outside a git checkout."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                             text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


class _Sink:
    """Stands in for rsl-rl's log writer so its Logger keeps its episode buffers; writes nothing."""


class CurveLogger(Logger):
    """rsl-rl's Logger, but each iteration becomes a curve row handed to ``on_iteration`` (no console dump).

    Its clock (:attr:`wall_time_s`) is the wall time the user waited for: from :meth:`start_clock` (the start of
    rsl-rl's ``learn``) on, checkpoints and logging included, added to the wall time of the run before a resume.
    rsl-rl's own ``tot_time`` (collection + learning only) is kept for what rsl-rl computes from it.
    """

    def __init__(self, *args: Any, dt: float, on_iteration: Callable[[dict[str, float]], None],
                 live: tuple[str, Path] | None = None, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.dt = dt
        self.on_iteration = on_iteration
        self.wall_time_s = 0.0
        """Wall seconds of the run so far (over resumes), as of the last :meth:`clock` reading."""
        self._clock_start: float | None = None
        self._clock_base = 0.0
        self.live_cfg = live
        self.live: Any = None

    def start_clock(self, since: float | None = None) -> None:
        """Start counting wall time on top of :attr:`wall_time_s` (the time of the run before this process).

        Args:
            since: A ``time.perf_counter()`` reading to count from (``morfic train``: the command's start, so the
                imports and the env's construction count too); None: now.
        """
        self._clock_base = self.wall_time_s
        self._clock_start = time.perf_counter() if since is None else since

    def clock(self) -> float:
        """The run's wall seconds now (:attr:`wall_time_s` updated); before :meth:`start_clock`, the stored value."""
        if self._clock_start is not None:
            self.wall_time_s = self._clock_base + time.perf_counter() - self._clock_start
        return self.wall_time_s

    def stop_clock(self) -> float:
        """Read the clock a last time and stop it; returns the run's wall seconds."""
        wall = self.clock()
        self._clock_start = None
        return wall

    def init_logging_writer(self) -> None:
        """No rsl-rl writer, no git snapshot (the store keeps the run); the live writer, if one is configured."""
        self.writer = _Sink()  # type: ignore[assignment]
        if self.live_cfg is not None and self.live is None and not self.disable_logs:
            from morfic_cli.rl.live_log import open_writer

            kind, log_dir = self.live_cfg
            self.live = open_writer(kind, log_dir, self.cfg)

    def close_live(self) -> None:
        """Flush and close the live writer (reopened by the next :meth:`init_logging_writer`)."""
        if self.live is not None:
            (self.live.stop if hasattr(self.live, "stop") else self.live.close)()
            self.live = None

    def log(self, it: int, start_it: int, total_it: int, collect_time: float, learn_time: float, loss_dict: dict,
            learning_rate: float, action_std: torch.Tensor, rnd_weight: float | None, **_: Any) -> None:
        """Build the curve row of iteration ``it`` (0-based) and pass it on."""
        size = self.cfg["num_steps_per_env"] * self.num_envs
        self.tot_timesteps += size
        self.tot_time += collect_time + learn_time
        row: dict[str, float] = {
            "iteration": it + 1,
            "env_steps": self.tot_timesteps,
            "wall_time_s": self.clock(),
            "steps_per_s": size / max(collect_time + learn_time, 1e-9),
            "collect_s": collect_time,
            "learn_s": learn_time,
            "mean_reward": sum(self.rewbuffer) / len(self.rewbuffer) if self.rewbuffer else float("nan"),
            "episode_length_s": (sum(self.lenbuffer) / len(self.lenbuffer) * self.dt) if self.lenbuffer
            else float("nan"),
            "learning_rate": learning_rate,
            "action_std": float(action_std.detach().mean()),
        }
        row.update({k: float(v) for k, v in loss_dict.items()})
        by_key: dict[str, list[float]] = {}  # each log key's values over the iteration's steps
        for step_log in host_values(self.ep_extras):  # one device -> host read for the iteration's logs
            for key, value in step_log.items():
                by_key.setdefault(key, []).append(value)
        means = {key: sum(values) / len(values) for key, values in by_key.items()}
        for key, values in by_key.items():
            name = key.strip("/").replace("/", ".")
            if name.startswith("reward.") or name == "env.nonfinite_resets":
                continue  # per-step means; the episode means below are what the curve shows
            row[name] = max(values) if name == "curriculum.vx_max" else means[key]
        if self.live is not None:
            from morfic_cli.rl.live_log import write_iteration

            extras = means
            # before the first episode ends: the mean return and length so far of the episodes under way
            reward = (sum(self.rewbuffer) / len(self.rewbuffer) if self.rewbuffer
                      else float(self.cur_reward_sum.float().mean()))
            length = (sum(self.lenbuffer) / len(self.lenbuffer) if self.lenbuffer
                      else float(self.cur_episode_length.float().mean()))
            wall = None if self.live_cfg is not None and self.live_cfg[0] == "wandb" else self.wall_time_s  # as rsl-rl
            write_iteration(self.live, it, size, collect_time, learn_time, {k: float(v) for k, v in loss_dict.items()},
                            learning_rate, float(action_std.detach().mean()), extras, reward, length, wall)
        self.ep_extras.clear()
        self.on_iteration(row)

    def state_dict(self) -> dict[str, Any]:
        """The episode buffers and counters, for exact curves after a resume."""
        return {"rewbuffer": list(self.rewbuffer), "lenbuffer": list(self.lenbuffer),
                "cur_reward_sum": self.cur_reward_sum.clone(), "cur_episode_length": self.cur_episode_length.clone(),
                "tot_timesteps": self.tot_timesteps, "tot_time": self.tot_time, "wall_time_s": self.clock()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.rewbuffer = deque(state["rewbuffer"], maxlen=100)
        self.lenbuffer = deque(state["lenbuffer"], maxlen=100)
        self.cur_reward_sum.copy_(state["cur_reward_sum"])
        self.cur_episode_length.copy_(state["cur_episode_length"])
        self.tot_timesteps, self.tot_time = state["tot_timesteps"], state["tot_time"]
        self.wall_time_s = state["wall_time_s"]


def host_values(logs: list[dict[str, Any]]) -> list[dict[str, float]]:
    """Each step's log dict as floats, the tensors among them (0-d, on the env's device) read back in one transfer.

    The warp backend keeps its logs on the device (docs/gpu.md, "Device-resident step"); reading them one
    ``float()`` at a time would wait for the device once per value, about 60 x 24 times per iteration.
    """
    out: list[dict[str, float]] = [{} for _ in logs]
    tensors = []
    for i, log in enumerate(logs):
        for key, value in log.items():
            if isinstance(value, torch.Tensor):
                tensors.append((i, key, value.detach().reshape(()).to(torch.float64)))
            else:
                out[i][key] = float(value)
    if tensors:
        for (i, key, _), value in zip(tensors, torch.stack([t for _, _, t in tensors]).tolist(), strict=True):
            out[i][key] = value
    return out


class _StoreRunner(OnPolicyRunner):
    """OnPolicyRunner whose own file checkpoints are switched off: :class:`TrainingRun` writes to the store."""

    def save(self, path: str, infos: dict | None = None) -> None:  # noqa: ARG002
        """No files: checkpoints go to the artifact store."""


class _Stop(Exception):
    """Raised from the iteration hook to leave rsl-rl's loop after a Ctrl-C checkpoint."""


@dataclasses.dataclass
class Checkpoint:
    """A checkpoint written to the store."""

    id: str
    ref: str
    version: int
    iteration: int


class TrainingRun:
    """One training run: env + rsl-rl runner + store checkpoints. Use :func:`new_run` or :func:`resume_run`."""

    def __init__(self, store: Store, cfg: TrainCfg, name: str, device: str = "cpu",
                 live: tuple[str, Path] | None = None) -> None:
        from morfic_cli.envs.locomotion import LocomotionEnv
        from morfic_cli.rl.live_log import run_log_dir

        self.dist = distributed_info()
        self.live = (live[0], run_log_dir(live[1], name)) if live is not None and live[0] != "none" else None
        """(logger, run folder) of the live curves, or None."""
        cfg = for_device(cfg, device)
        self.store, self.cfg, self.name, self.device = store, cfg, name, torch_device(device)
        self.git_commit = git_commit()  # the code this process runs (HEAD may move while it trains)
        torch.manual_seed(cfg.seed)
        # under torchrun every rank simulates its own envs: seed + rank (rank 0 = a single-process run)
        self.env = LocomotionEnv(cfg.env, mode="train", seed=cfg.seed + self.dist.rank)
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the models on stdout
            self.runner = _StoreRunner(self.env, rsl_rl_cfg(cfg), log_dir=None, device=self.device)
        replace_logger(self.runner, lambda old: CurveLogger(
            log_dir="", cfg=old.cfg, env_cfg=old.env_cfg, num_envs=old.num_envs,
            is_distributed=self.runner.is_distributed, gpu_world_size=self.runner.gpu_world_size,
            gpu_global_rank=self.runner.gpu_global_rank, device=old.device, dt=self.env.dt,
            on_iteration=self._on_iteration, live=self.live,
        ))
        self.rows: list[dict[str, float]] = []
        self.iteration = 0
        self.parent: str | None = None
        self.head: str | None = None
        """The id ``runs/NAME`` must point at when the next checkpoint is written (None: no ref yet)."""
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
        logger: CurveLogger = self.runner.logger  # type: ignore[assignment]
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
        return self.runner.logger.clock()  # type: ignore[attr-defined]

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
        model = _to_bytes({"actor": actor.state_dict(), "critic": critic.state_dict()})
        curves = {"curve.csv": curve_csv(self.rows)}
        if finished or interrupted:
            curves["curve.png"] = curve_png(self.rows)
        logger: CurveLogger = self.runner.logger  # type: ignore[assignment]
        wall = logger.clock()  # after the drawing: the stored time misses only the write below
        saved = alg.save()
        saved.pop("actor_state_dict"), saved.pop("critic_state_dict")
        trainer = trainer_state.encode({
            "iteration": self.iteration,
            "alg": saved,
            "learning_rate": alg.learning_rate,
            "env": self.env.state_dict(),
            "logger": self.runner.logger.state_dict(),
            "torch_rng": torch.get_rng_state(),
        })
        meta = {
            "variant": self.cfg.variant, "seed": self.cfg.seed, "preset": self.cfg.preset, "iteration": self.iteration,
            "max_iterations": self.cfg.max_iterations, "env_steps": logger.tot_timesteps,
            "wall_time_s": round(wall, 3), "git_commit": self.git_commit, "finished": finished,
            "interrupted": interrupted, "parent": self.parent, "device": self.device, "run": self.name,
            "vx_max": float(self.env.command_ranges.vx[1]), **variant_record(self.cfg),
            **({"bf16_matmul": alg.bf16_matmul} if getattr(alg, "bf16_matmul", None) else {}),
        }
        with self._stopped_on_lock_timeout(), self.store.writing():
            state = self.store.put_manifest("checkpoint", config={"role": "trainer-state"}, files=trainer,
                                            meta={"iteration": self.iteration, "run": self.name,
                                                  "format": trainer_state.FORMAT})
            ckpt = self.store.put_manifest(
                "checkpoint", config=train_cfg_to_dict(self.cfg), meta=meta, inputs={TRAINER_STATE_ROLE: state},
                files={"model.pt": model, **curves},
            )
            try:  # the one visible step, unless another process wrote this run meanwhile
                version = self.store.set_ref(RUNS_PREFIX + self.name, ckpt, expect=self.head)
            except RefMovedError as exc:
                raise MorficError(self._moved_message(exc)) from exc
        self.parent = self.head = ckpt
        out = Checkpoint(ckpt, RUNS_PREFIX + self.name, version, self.iteration)
        self.checkpoints.append(out)
        return out

    def _moved_message(self, exc: RefMovedError) -> str:
        """What a training whose run another process wrote meanwhile says as it stops (it lost the race)."""
        ref = RUNS_PREFIX + self.name
        if exc.current is None:
            now = "was removed"
        else:
            try:
                other = self.store.read_manifest(exc.current.id).meta.get("iteration")
            except MorficError:
                other = None
            at = f" at iteration {other}" if other is not None else ""
            now = (f"was created by another process ({exc.current.id[:12]}{at})" if self.head is None else
                   f"was advanced by another process (version {exc.current.version} is {exc.current.id[:12]}{at}, "
                   f"not this training's last checkpoint {self.head[:12]})")
        return (f"run '{ref}' {now} while this training ran: two trainings cannot write one run, so this one "
                f"stops without recording its checkpoint at iteration {self.iteration} (gc removes it); the ref keeps "
                f"the other training's checkpoints (`morfic store show {ref} --history`). Give each training its own "
                f"--name; `morfic train --resume {ref}` continues from the ref's current version.")

    @contextlib.contextmanager
    def _stopped_on_lock_timeout(self):
        """Turn a store lock that stayed busy (a long gc) during a checkpoint into an error that says how to go on."""
        try:
            yield
        except LockTimeoutError as exc:
            ref = RUNS_PREFIX + self.name
            last = (f"`morfic train --resume {ref}` continues from its last checkpoint" if self.head is not None else
                    f"it has no checkpoint yet: start it again with `morfic train --name {self.name}` (and its "
                    "--variant, --preset, --seed and --set)")
            raise MorficError(f"{exc} This training stopped at iteration {self.iteration} without writing that "
                              f"checkpoint; {last}.") from exc

    def _restore(self, ckpt_id: str, trainer: dict[str, Any], rows: list[dict[str, float]]) -> None:
        alg = self.runner.alg
        model = _load_weights(self.store, ckpt_id, self.device)
        loaded = dict(trainer["alg"], actor_state_dict=model["actor"], critic_state_dict=model["critic"])
        alg.load(loaded, None, True)
        alg.learning_rate = trainer["learning_rate"]
        self.env.load_state_dict(trainer["env"])
        self.runner.logger.load_state_dict(trainer["logger"])  # type: ignore[attr-defined]
        torch.set_rng_state(trainer["torch_rng"])
        self.iteration = int(trainer["iteration"])
        self.rows = rows
        self.parent = ckpt_id
        self._fresh = False


def check_weights(store: Store, spec: str, manifest: Any) -> None:
    """Raise when the checkpoint's weights were left out (a run imported from a results-only bundle).

    Raises:
        MorficError: ``model.pt`` of ``manifest`` is recorded as left out (``shallow/``); names the bundle to import.
    """
    if store.weights_omitted(manifest):
        name = run_of(spec, manifest.meta)
        raise MorficError(f"{spec} was imported from a results-only bundle: its weights (model.pt) and trainer state "
                          "were left out, so it cannot be evaluated, played, exported, diagnosed or resumed (its "
                          "tables, curves and config are here, for `morfic report`). Import a bundle with its weights "
                          f"first: its weights-only bundle (made by `morfic store export {RUNS_PREFIX}{name} --latest "
                          "--without-trainer-state` in the store that trained it; shipped ones are under "
                          "artifacts/bundles/), or its full bundle to resume it.")


def _load_weights(store: Store, ckpt_id: str, device: str) -> dict[str, Any]:
    """``model.pt`` of a checkpoint: ``{"actor": state dict, "critic": state dict}``, loaded as tensors only."""
    state = trainer_state.load_tensors(store.read_file(ckpt_id, "model.pt"), f"model.pt of checkpoint {ckpt_id[:12]}",
                                       map_location=device)
    if not (isinstance(state, dict) and isinstance(state.get("actor"), dict) and isinstance(state.get("critic"), dict)):
        raise MorficError(f"model.pt of checkpoint {ckpt_id[:12]} is not {{'actor': ..., 'critic': ...}} weights; "
                          "use a checkpoint written by `morfic train`.")
    return state


def _to_bytes(obj: Any) -> bytes:
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def check_device(device: str) -> None:
    """Raise MorficError when ``device`` cannot train here.

    ``cuda`` needs a CUDA build of torch that sees a GPU and the optional warp backend
    (``pip install 'morfic[gpu]'``); under torchrun with more than one process it is the only choice
    (rsl-rl's distributed training uses NCCL).
    """
    dist = distributed_info()
    if device == "cpu":
        if dist.world_size > 1:
            raise MorficError(f"distributed training (torchrun, WORLD_SIZE={dist.world_size}) needs --device cuda: "
                              "rsl-rl reduces gradients with NCCL; run a single process for --device cpu.")
        return
    if device == "cuda":
        if not torch.cuda.is_available():
            raise MorficError("--device cuda: no CUDA device is available on this machine (or torch is a CPU "
                              "build); train with --device cpu, or on a GPU machine with a CUDA build of torch and "
                              "`pip install 'morfic[gpu]'`.")
        from morfic_cli.sim.warp import import_warp

        import_warp()  # MorficError with the install hint when mujoco_warp is missing
        return
    raise MorficError(f"unknown device '{device}'; valid devices are: cpu, cuda.")


@dataclasses.dataclass(frozen=True)
class DistributedInfo:
    """This process's place in a torchrun job (world size 1, rank 0 outside torchrun).

    Attributes:
        world_size: Processes in the job (``WORLD_SIZE``).
        rank: Global rank (``RANK``); only rank 0 writes to the store.
        local_rank: Rank on this node (``LOCAL_RANK``); the GPU ``cuda:LOCAL_RANK`` is this process's.
    """

    world_size: int
    rank: int
    local_rank: int


def distributed_info() -> DistributedInfo:
    """Read torchrun's environment variables (the ones rsl-rl's OnPolicyRunner reads too)."""
    return DistributedInfo(int(os.environ.get("WORLD_SIZE", "1")), int(os.environ.get("RANK", "0")),
                           int(os.environ.get("LOCAL_RANK", "0")))


def torch_device(device: str) -> str:
    """The torch device of this process: ``cuda`` becomes ``cuda:LOCAL_RANK`` (what rsl-rl expects under torchrun)."""
    return f"cuda:{distributed_info().local_rank}" if device == "cuda" else device


def for_device(cfg: TrainCfg, device: str) -> TrainCfg:
    """Place the simulation on ``device``.

    ``cuda`` selects the warp backend (MuJoCo Warp) on this process's GPU, so that simulation,
    observations and the policy share the device; ``cpu`` keeps the configured backend and puts its
    tensors on the CPU (``--set env.sim.backend=warp`` runs MuJoCo Warp on warp's CPU device).
    """
    if device == "cuda":
        return apply_overrides(cfg, ["env.sim.backend=warp", f"env.sim.device={torch_device(device)}"])
    return apply_overrides(cfg, ["env.sim.device=cpu"])


def new_run(store: Store, cfg: TrainCfg, name: str, device: str = "cpu",
            live: tuple[str, Path] | None = None) -> TrainingRun:
    """A fresh run under ``runs/NAME``.

    ``live`` = (logger, log root) writes live curves into ``<log root>/NAME`` (:mod:`morfic_cli.rl.live_log`).

    Raises:
        MorficError: ``runs/NAME`` already exists (resume it or pick another --name).
    """
    check_device(device)
    if store.has_ref(RUNS_PREFIX + name):
        raise MorficError(f"run '{RUNS_PREFIX}{name}' already exists in {store.root}; continue it with "
                          f"`--resume {RUNS_PREFIX}{name}` or choose another --name.")
    return TrainingRun(store, cfg, name, device, live)


def resume_run(store: Store, spec: str, overrides: list[str] | None = None, device: str = "cpu",
               live: tuple[str, Path] | None = None) -> TrainingRun:
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
    run = TrainingRun(store, cfg, point.name, device, live)
    run._restore(point.manifest.id, point.trainer, point.rows)
    ref = RUNS_PREFIX + point.name
    if "@" not in spec and spec in (ref, point.name):  # the ref's current version, as read: no re-read race
        run.head = point.manifest.id
    else:  # an older version or an id: its checkpoints go on after the ref's current version (a fork)
        run.head = store.resolve(ref) if store.has_ref(ref) else None
    return run


@dataclasses.dataclass
class ResumePoint:
    """What ``--resume`` continues from: the checkpoint, its run name, trainer state and curve so far."""

    manifest: Any
    name: str
    trainer: dict[str, Any]
    rows: list[dict[str, float]]


def load_resume_point(store: Store, spec: str) -> ResumePoint:
    """The checkpoint ``spec`` names with its trainer state, loaded without building an env (see :func:`resume_run`)."""
    from morfic_cli.recording.curves import read_curve_csv

    try:
        manifest = store.read_manifest(spec)
    except ArtifactNotFoundError as exc:
        if not spec.startswith(RUNS_PREFIX) and store.has_ref(RUNS_PREFIX + spec):
            manifest = store.read_manifest(RUNS_PREFIX + spec)
        elif "@" not in spec and is_ref_name(spec) and not store.has_ref(spec) and not _HEX.fullmatch(spec):
            name = spec.removeprefix(RUNS_PREFIX)
            raise ArtifactNotFoundError(
                f"{exc} A run killed before its first checkpoint (written every save_interval iterations) leaves "
                f"nothing to resume: start it afresh with `morfic train --name {name}` and its --variant, --preset, "
                "--seed and --set.") from exc
        else:
            raise
    if manifest.kind != "checkpoint" or "model.pt" not in manifest.files:
        raise MorficError(f"--resume '{spec}' is not a training checkpoint; pass a run ref like runs/film-cpu-s0.")
    name = run_of(spec, manifest.meta)
    resolve_variant(check_stored_cfg(manifest.config, spec).variant, source=spec)  # checked, then consent
    check_weights(store, spec, manifest)
    state_id = manifest.inputs.get(TRAINER_STATE_ROLE)
    if state_id is not None and store.is_omitted(state_id):
        raise MorficError(f"{spec} was imported without its trainer state (a weights-only bundle); it evaluates and "
                          "exports, but cannot be resumed. Import the full bundle (made by `morfic store export "
                          f"{RUNS_PREFIX}{name} --latest`, without --without-trainer-state, in the store that trained "
                          "it) to resume it, or start a new run with `morfic train`.")
    if state_id is not None:
        state = store.read_manifest(state_id)
        trainer = trainer_state.decode(store.read_file(state.id, trainer_state.JSON_FILE),
                                       store.read_file(state.id, trainer_state.TENSORS_FILE), f"checkpoint '{spec}'")
    else:
        trainer = _legacy_trainer_state(store, spec, manifest.id, name)
    trainer_state.check_trainer_state(trainer, f"checkpoint '{spec}'", TRAINER_KEYS)  # keys, types, sizes
    rows = read_curve_csv(store.read_file(manifest.id, "curve.csv"))
    return ResumePoint(manifest, name, trainer, rows)


_HEX = re.compile(r"[0-9a-f]{4,64}")

#: Keys every trainer state holds.
TRAINER_KEYS = frozenset({"iteration", "alg", "learning_rate", "env", "logger", "torch_rng"})


def _legacy_trainer_state(store: Store, spec: str, ckpt_id: str, name: str) -> dict[str, Any]:
    """The ``resume/NAME`` trainer state of a checkpoint written before the one-ref layout (tensors only)."""
    legacy = RESUME_PREFIX + name
    states = {}
    if store.has_ref(legacy):
        for entry in store.ref_history(legacy):
            states[store.read_manifest(entry.id).inputs.get("checkpoint")] = entry.id
    if ckpt_id not in states:
        older = [e for e in store.ref_history(RUNS_PREFIX + name) if e.id in states] \
            if store.has_ref(RUNS_PREFIX + name) else []
        hint = (f" Its last resumable checkpoint is {RUNS_PREFIX}{name}@{older[-1].version}: `morfic train --resume "
                f"{RUNS_PREFIX}{name}@{older[-1].version}`." if older else " Start a new run with `morfic train`.")
        raise MorficError(f"checkpoint '{spec}' has no trainer state in {store.root} (policy bundles of older morfic "
                          f"versions carry weights only, as does a checkpoint cut short by a kill), so it cannot be "
                          f"resumed.{hint}")
    return trainer_state.load_tensors(store.read_file(states[ckpt_id], "trainer.pt"),
                                      f"the trainer state (trainer.pt, an older format) of checkpoint '{spec}'")
