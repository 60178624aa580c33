"""``morfic train``: PPO training with one conditioning variant, checkpointed into the store."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    Device,
    DeviceOpt,
    FormatOpt,
    Logger,
    OutputFormat,
    Preset,
    QuietOpt,
    SeedOpt,
    StoreOpt,
    TrustOpt,
)
from morfic_cli.cli._progress import LogPace, time_left
from morfic_cli.cli._render import emit_object, info
from morfic_cli.cli.trust import remember_variants
from morfic_cli.errors import MorficError
from morfic_cli.rl.variants import help_text, trust_variants
from morfic_cli.runs import run_name
from morfic_cli.validation import check_args

if TYPE_CHECKING:
    from rich.progress import Progress


def train(
    variant: Annotated[
        str | None,
        typer.Option("--variant", help=f"{help_text()} (default film)."),
    ] = None,
    preset: Annotated[
        Preset | None, typer.Option("--preset", help="Budget: smoke (seconds), cpu (2-core machine), paper (GPU).")
    ] = None,
    seed: SeedOpt = 0,
    name: Annotated[
        str | None,
        typer.Option("--name", help="Run name: ref runs/NAME (default variant-preset-sSEED, e.g. film-smoke-s0)."),
    ] = None,
    resume: Annotated[
        str | None, typer.Option("--resume", help="Continue a run: runs/NAME (its latest checkpoint) or a checkpoint.")
    ] = None,
    device: DeviceOpt = Device.cpu,
    overrides: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="Config override key=value, repeatable (e.g. ppo.learning_rate=3e-4, "
            "env.num_envs=256, max_iterations=50). Unknown keys are an error.",
        ),
    ] = None,
    logger: Annotated[
        Logger,
        typer.Option(
            "--logger",
            help="Live curves while training: tensorboard event files, wandb "
            "(pip install 'morfic[wandb]'), or none. The store keeps the curve either way.",
        ),
    ] = Logger.tensorboard,
    log_dir: Annotated[
        Path,
        typer.Option(
            "--log-dir",
            envvar="MORFIC_LOG_DIR",
            help="Root of the run folders of --logger: <log-dir>/<run name> (env MORFIC_LOG_DIR).",
        ),
    ] = Path("logs"),
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Train a policy with one critic-conditioning variant; checkpoints go to ref runs/NAME.

    A checkpoint is written every save_interval iterations and at the end; Ctrl-C finishes the current iteration,
    writes a checkpoint and exits (press it twice to abort at once). --resume continues from the latest
    checkpoint of a run (on CPU, bit-identical to an uninterrupted run); --set max_iterations=N extends it.
    Prints the last checkpoint (ref, id, iteration, env steps, wall time) on stdout.

    --device cuda simulates with MuJoCo Warp on the GPU (pip install 'morfic[gpu]'); several GPUs:
    torchrun --nproc_per_node=G -m morfic_cli train --device cuda ... (docs/gpu.md).

    Your own critic class, by import path: --variant names it, so this command imports it, and adds it to your
    allow-list of trusted variants (`morfic trust`), so later commands on its runs import it too. --resume of a
    run with a user variant imports it only when it is on that list or named with --trust-variant.

    Example: morfic train --variant film --preset cpu --seed 0
    Your own critic: morfic train --variant my_lab.critics:GatedCritic (docs/extending.md)
    """
    started = process_start()  # the training clock counts from here: imports and the env's construction too
    check_args(store=store, name=name, seed=seed, specs=[resume] if resume is not None else None, trust=trust_variant)
    named = [variant] if variant is not None and resume is None else []
    trust_variants(named)  # --variant names it on this command line: the user's consent to import it
    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.live_log import check_logger
    from morfic_cli.rl.precision import float32_note
    from morfic_cli.rl.runner import new_run, resume_run
    from morfic_cli.store import Store

    check_logger(logger.value)
    if log_dir.exists() and not log_dir.is_dir():
        raise MorficError(f"--log-dir {log_dir} is a file; give a directory (it is created if missing).")
    live = (logger.value, log_dir)
    st = Store(store)
    if resume is not None:
        if variant is not None or preset is not None or name is not None:
            info("note: --variant/--preset/--name are taken from the checkpoint when resuming; ignored.")
        run = resume_run(st, resume, overrides, device.value, live=live)
    else:
        base = preset_cfg((preset or Preset.smoke).value, variant or "film", seed)
        cfg = apply_overrides(base, list(overrides or []))
        run = new_run(st, cfg, name or run_name(cfg.variant, cfg.seed, cfg.preset), device.value, live=live)

    run.clock_from = started
    cfg = run.cfg
    quiet = quiet or run.dist.rank != 0  # torchrun: one progress bar, rank 0's
    if named and run.dist.rank == 0:
        remember_variants(named, quiet)
    if not quiet:
        info(
            f"train: runs/{run.name} variant={cfg.variant} preset={cfg.preset} seed={cfg.seed} "
            f"envs={cfg.env.num_envs} iterations {run.iteration}->{cfg.max_iterations} "
            f"({cfg.env.num_envs * cfg.num_steps_per_env:,} transitions each) "
            f"sim={cfg.env.sim.backend} on {cfg.env.sim.device}"
            + (f" x {run.dist.world_size} processes" if run.dist.world_size > 1 else "")
        )
        note = float32_note(run.runner.alg.bf16_matmul)
        if note:
            info(note)
        if run.live is not None:
            kind, folder = run.live
            hint = f" (tensorboard --logdir {log_dir})" if kind == "tensorboard" else ""
            info(f"train: live curves ({kind}) in {folder}{hint}")

    def on_sigint(signum, frame):  # noqa: ARG001
        if run.stop_requested:
            raise KeyboardInterrupt
        run.stop_requested = True
        info("Ctrl-C: finishing this iteration and writing a checkpoint (Ctrl-C again to abort at once) ...")

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        with _progress(run, quiet):
            last = run.train()
    finally:
        signal.signal(signal.SIGINT, previous)
        run.env.close()
    if run.dist.rank != 0:  # torchrun: rank 0 wrote the checkpoints and reports them
        return
    if last is None:
        info(
            f"runs/{run.name} is already at iteration {run.iteration} of {cfg.max_iterations}; nothing to do "
            "(extend it with --set max_iterations=N)."
        )
        return
    row = run.rows[-1] if run.rows else {}
    result = {
        "ref": f"{last.ref}@{last.version}",
        "id": last.id,
        "variant": cfg.variant,
        "seed": cfg.seed,
        "iteration": last.iteration,
        "max_iterations": cfg.max_iterations,
        "env_steps": int(row.get("env_steps", 0)),
        "wall_time_s": round(run.wall_time_s, 1),  # the training clock, the last checkpoint included
        "mean_reward": row.get("mean_reward"),
        "explained_variance": row.get("explained_variance"),
        "interrupted": run.interrupted,
    }
    if not quiet and result["interrupted"]:
        info(f"stopped at iteration {last.iteration}; continue with `morfic train --resume runs/{run.name}`.")
    emit_object(result, fmt)


def process_start() -> float:
    """The ``time.perf_counter()`` reading of this process's start (Linux ``/proc``; elsewhere: now).

    The training clock starts here, so Python's start-up and the imports (seconds on a busy machine) count too.
    """
    try:
        stat = Path("/proc/self/stat").read_text()
        ticks = int(stat.rsplit(")", 1)[1].split()[19])  # field 22, starttime: clock ticks after boot
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):  # not Linux
        return time.perf_counter()
    return time.perf_counter() - max(age, 0.0)


def _num(value: float | None, digits: int = 2) -> str:
    """``0.12``, or ``-`` for a value not measured yet (None, NaN: no episode has ended)."""
    return "-" if value is None or value != value else f"{value:.{digits}f}"


def _seconds(value: float | None) -> str:
    """``12.3s``, or ``-`` before the first episode has ended (NaN)."""
    return "-" if value is None or value != value else f"{value:.1f}s"


class _progress:
    """A rich progress bar on stderr fed by the run's per-iteration rows (nothing when quiet)."""

    def __init__(self, run, quiet: bool) -> None:
        self.run, self.quiet = run, quiet
        self.bar: Progress | None = None

    def __enter__(self) -> _progress:
        if self.quiet:
            return self
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        console = Console(stderr=True, emoji=False)
        if not console.is_terminal:  # a log file: one plain line every ~1% of the run instead of a live bar
            total, first, started = self.run.cfg.max_iterations, self.run.iteration, time.monotonic()
            pace = LogPace(total, 0.01, done=first)

            def log_line(row: dict) -> None:
                it = int(row["iteration"])
                if pace.due(it):
                    elapsed = time.monotonic() - started
                    left = "" if it >= total else f"  {time_left(elapsed, it - first, total - first)} left"
                    sys.stderr.write(
                        f"it {it}/{total}  {row.get('env_steps', 0):,.0f} steps  "
                        f"{row.get('steps_per_s', 0):,.0f} steps/s  reward {_num(row.get('mean_reward'))}  "
                        f"EV {_num(row.get('explained_variance'))}  vx_err {_num(row.get('tracking.vx_error'))}  "
                        f"vx_max {row.get('curriculum.vx_max', 0):.1f}  ep {_seconds(row.get('episode_length_s'))}  "
                        f"{row.get('wall_time_s', 0):.0f}s{left}\n"
                    )
                    sys.stderr.flush()

            self.run.progress = log_line
            return self
        self.bar = Progress(
            TextColumn("[bold]train[/]"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[sps]} steps/s  reward {task.fields[reward]}  EV {task.fields[ev]}"),
            TimeRemainingColumn(),
            console=console,
            transient=False,
        )
        bar = self.bar
        bar.__enter__()
        task = bar.add_task(
            "train", total=self.run.cfg.max_iterations, completed=self.run.iteration, sps="-", reward="-", ev="-"
        )

        def update(row: dict) -> None:
            bar.update(
                task,
                completed=int(row["iteration"]),
                sps=f"{row.get('steps_per_s', 0):,.0f}",
                reward=f"{row.get('mean_reward', float('nan')):.2f}",
                ev=f"{row.get('explained_variance', float('nan')):.2f}",
            )

        self.run.progress = update
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
