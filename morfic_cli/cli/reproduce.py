"""``morfic reproduce``: the whole pipeline in one command, idempotent through the store."""

from __future__ import annotations

import signal
import sys
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    Device,
    DeviceOpt,
    FormatOpt,
    OutputFormat,
    QuietOpt,
    StoreOpt,
    TrustOpt,
)
from morfic_cli.cli._render import emit_object, info
from morfic_cli.rl.variants import REPRODUCE_VARIANTS, VARIANTS

if TYPE_CHECKING:  # rich is imported when a view opens (start-up time)
    from rich.console import Console
    from rich.live import Live
    from rich.progress import Progress, TaskID
    from rich.table import Table
from morfic_cli.validation import check_args


def _step_line(result) -> str:
    """One finished pipeline step as a console line: kind, label, status, seconds, detail, short id."""
    from morfic_cli.pipeline import NOT_RUN

    marks = {**_MARKS, NOT_RUN: "[yellow]not run[/]"}
    line = f"{result.kind} {result.label}: {marks.get(result.status, result.status)}"
    if result.status not in ("skipped", NOT_RUN):
        line += f" in {result.seconds:.1f} s"
    if result.detail:
        line += f" ({result.detail})"
    if result.id:
        line += f" [dim]{result.id[:12]}[/]"
    return line


class PipelinePreset(str, Enum):
    """``reproduce``'s presets: the training presets and ``shipped`` (the shipped trained runs)."""

    smoke = "smoke"
    cpu = "cpu"
    paper = "paper"
    shipped = "shipped"


class Executor(str, Enum):
    """Where the jobs run."""

    local = "local"
    ray = "ray"


_MARKS = {
    "done": "[green]done[/]",
    "resumed": "[green]resumed[/]",
    "skipped": "[dim]skipped (in the store)[/]",
    "interrupted": "[yellow]interrupted[/]",
}


def reproduce(
    preset: Annotated[
        PipelinePreset,
        typer.Option(
            "--preset",
            help="shipped: no training; import the trained cpu runs shipped in artifacts/bundles/ and "
            "evaluate, diagnose and report them (~10 min on 2 cores). smoke: minutes, exercises the pipeline (its "
            "numbers are not results). cpu: trains, ~1 h per run on 2 cores. paper: GPU.",
        ),
    ] = PipelinePreset.smoke,
    seeds: Annotated[int, typer.Option("--seeds", help="Seeds per variant (0..N-1).")] = 1,
    variants: Annotated[
        str,
        typer.Option(
            "--variants",
            help=f"Comma-separated variants to train, or 'all' (the paper's: "
            f"{', '.join(REPRODUCE_VARIANTS)}); a user variant by import path module:Class (named "
            "here, it is imported, and added to your allow-list of trusted variants: `morfic trust`).",
        ),
    ] = "all",
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", "-o", help="Folder for the report's files (default: reports/<preset> in the store's folder)."
        ),
    ] = None,
    overrides: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="Training config override key=value for every run (as `morfic train --set`), e.g. max_iterations=1.",
        ),
    ] = None,
    bundles: Annotated[
        Path | None,
        typer.Option(
            "--bundles",
            help="With --preset shipped: the folder of run bundles "
            "(<variant>-cpu-s0.tar; default the checkout's artifacts/bundles).",
        ),
    ] = None,
    full_protocol: Annotated[
        bool,
        typer.Option(
            "--full-protocol",
            help="With --preset shipped: evaluate and diagnose with the paper's "
            "protocol (both modes at 2.0 and 2.5 m/s, 64 envs; ~10 min per variant on 2 cores) "
            "instead of the quick one (descriptor mode at 2.0 m/s, 16 envs).",
        ),
    ] = False,
    device: DeviceOpt = Device.cpu,
    executor: Annotated[
        Executor,
        typer.Option(
            "--executor",
            help="local: every step here, one after another (default). ray: "
            "train, eval, diagnose and fixed-rollout jobs as Ray tasks, results imported into the "
            "store (pip install 'morfic[cluster]'; docs/cluster.md).",
        ),
    ] = Executor.local,
    address: Annotated[
        str | None,
        typer.Option(
            "--address",
            help="With --executor ray: the cluster's HOST:PORT (from `ray start "
            "--head`); default: start a local Ray instance on this machine.",
        ),
    ] = None,
    retries: Annotated[
        int,
        typer.Option(
            "--retries",
            help="With --executor ray: times a job is retried when its worker process "
            "dies (user errors are never retried).",
        ),
    ] = 3,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            help="Evaluations and diagnoses run side by side in this many worker processes (one keeps about one "
            "core busy); default: one per core with --preset shipped, else 1. Training always runs one run at a time.",
        ),
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Train all variants, evaluate, diagnose, compare and report: the paper's pipeline in one command.

    For each variant and seed: train (ref runs/<variant>-<preset>-s<seed>), evaluate on every robot at 2.0 and 2.5 m/s
    in both modes (issue 58's variants in actuation-matched mode too), diagnose the critic; then the fixed-rollout
    analysis on aliengo and mini_cheetah (the film actor frozen, every critic scored), the comparison tables and the
    report (LaTeX + PDF where pdflatex is installed, Markdown, figures, the paper's tables beside ours). Idempotent: a
    step whose inputs and config already have a result in the store is skipped, so a second run does nothing and a run
    after Ctrl-C (training checkpoints first) continues where it stopped. The smoke preset takes minutes on 2 cores and
    only exercises the pipeline; cpu is sized for a 2-core machine (hours per variant), paper for a GPU.

    --preset shipped trains nothing: it imports the seed-0 cpu runs shipped under artifacts/bundles/ and runs
    the paper's main zero-shot table (descriptor mode, 2.0 m/s) and the diagnostics with 16 envs per rollout
    (--full-protocol: the paper's whole protocol), so a fresh checkout shows real results in minutes.

    Example: morfic reproduce --preset shipped
    """
    check_args(store=store, out_dir=out, variants=variants, trust=trust_variant)
    _check_executor(executor, address, retries)
    _check_jobs(jobs, executor)
    _check_shipped(preset, bundles, full_protocol, executor, overrides)
    from morfic_cli.pipeline import Pipeline, reproduce_cfg
    from morfic_cli.rl.devices import check_device
    from morfic_cli.store import Store

    names = (
        REPRODUCE_VARIANTS
        if variants.strip().lower() == "all"
        else tuple(v.strip() for v in variants.split(",") if v.strip())
    )
    shipped = preset is PipelinePreset.shipped
    cfg = reproduce_cfg(
        preset.value,
        seeds=seeds,
        variants=None if shipped and names == REPRODUCE_VARIANTS else names,
        device=device.value,
        bundles=bundles,
        full_protocol=full_protocol,
    )
    if overrides:
        import dataclasses

        from morfic_cli.rl.config import apply_overrides, preset_cfg

        apply_overrides(preset_cfg(cfg.preset), list(overrides))  # unknown keys fail before anything runs
        cfg = dataclasses.replace(cfg, train_overrides=tuple(overrides))
    check_device(cfg.device)
    users = [v for v in cfg.variants if v not in VARIANTS]  # named by --variants: trusted here and from now on
    if users:
        from morfic_cli.cli.trust import remember_variants

        remember_variants(users, quiet)
    if executor is Executor.ray:
        from morfic_cli.cluster.ray_executor import import_ray

        import_ray()  # not installed: Error saying what to install, before the store is touched
    st = Store(store)
    out_dir = out if out is not None else st.root / "reports" / cfg.report_name
    view = _View(quiet) if executor is Executor.local else _RayView(quiet)
    pipeline = Pipeline(st, cfg, out=out_dir, progress=view)
    view.total = len(pipeline.plan())
    if not quiet and executor is Executor.local and pipeline.trains_in_bf16():  # ray: the workers' CPUs decide
        from morfic_cli.rl.precision import bf16_matmul, cpu_bf16_kernels, float32_note

        note = float32_note(bf16_matmul(cfg.device, cpu_bf16_kernels()))
        if note:
            info(note)
    side_by_side = _job_pool(pipeline, jobs, shipped) if executor is Executor.local else None
    if not quiet:
        where = "" if executor is Executor.local else f", executor ray ({address or 'local instance'})"
        if side_by_side is not None:
            where += f", evaluations and diagnoses {side_by_side.jobs} side by side"
        info(
            f"reproduce: preset {preset.value}, {len(cfg.variants)} variants ({', '.join(cfg.variants)}) x "
            f"{cfg.seeds} seed(s), "
            f"{len(pipeline.plan())} steps, store {st.root}{where}"
        )
    if executor is Executor.ray:
        _run_ray(pipeline, view, address, retries, quiet, fmt, out_dir)
        return

    def on_sigint(signum, frame):  # noqa: ARG001
        if pipeline.interrupt():
            info(
                "Ctrl-C: finishing this training iteration and checkpointing; run the same command again to "
                "continue (Ctrl-C again to abort at once)."
            )
            return
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        with view:
            result = pipeline.run(side_by_side)
    finally:
        signal.signal(signal.SIGINT, previous)
    if result.interrupted:
        info(
            "stopped after Ctrl-C; the checkpoint is in the store. Run the same `morfic reproduce` command again "
            "to continue where it stopped."
        )
        sys.exit(130)
    _summary(result, quiet, fmt, out_dir)


def _check_shipped(
    preset: PipelinePreset, bundles: Path | None, full_protocol: bool, executor: Executor, overrides: list[str] | None
) -> None:
    from morfic_cli.errors import MorficError

    if preset is not PipelinePreset.shipped:
        for flag, given in (("--bundles", bundles is not None), ("--full-protocol", full_protocol)):
            if given:
                raise MorficError(
                    f"{flag} is for --preset shipped (the shipped runs); the {preset.value} preset trains its own."
                )
        return
    if executor is not Executor.local:
        raise MorficError("--preset shipped trains nothing and runs here; use it without --executor ray.")
    if overrides:
        raise MorficError("--set changes training configs; --preset shipped trains nothing (leave out --set).")


def _check_jobs(jobs: int | None, executor: Executor) -> None:
    from morfic_cli.errors import MorficError

    if jobs is None:
        return
    if jobs < 1:
        raise MorficError(f"--jobs must be 1 or more, got {jobs}.")
    if executor is not Executor.local:
        raise MorficError(
            "--jobs is for --executor local; Ray places the jobs by the cluster's CPUs (leave out --jobs)."
        )


def _job_pool(pipeline, jobs: int | None, shipped: bool):
    """The worker pool of ``--jobs`` (default: one per core for the shipped preset, else none)."""
    from morfic_cli.cluster.pool import JobPool, cores

    n = jobs if jobs is not None else (cores() if shipped else 1)
    return JobPool(pipeline, n) if n > 1 else None


def _check_executor(executor: Executor, address: str | None, retries: int) -> None:
    from morfic_cli.errors import MorficError

    if address is not None and executor is not Executor.ray:
        raise MorficError("--address is the Ray cluster to run on; use it with --executor ray.")
    if address is not None and (":" not in address or not address.rsplit(":", 1)[1].isdigit()):
        if address != "auto":
            raise MorficError(
                f"--address {address!r} is not HOST:PORT (or 'auto'), e.g. --address 127.0.0.1:6379 "
                f"as printed by `ray start --head`."
            )
    if retries < 0:
        raise MorficError(f"--retries must be 0 or more, got {retries}.")


def _run_ray(pipeline, view, address: str | None, retries: int, quiet: bool, fmt, out_dir: Path) -> None:
    from morfic_cli.cluster.ray_executor import RayExecutor

    runner = RayExecutor(pipeline, address=address, retries=retries, on_update=view.update)
    with view:
        result = runner.run()
    if result.interrupted:
        info(
            "stopped after Ctrl-C: outstanding jobs were cancelled; every finished job is in the store. Run the "
            "same `morfic reproduce` command again to continue (it skips what the store holds)."
        )
        sys.exit(130)
    _summary(result, quiet, fmt, out_dir)


def _summary(result, quiet: bool, fmt, out_dir: Path) -> None:
    """The result on stdout, then the summary and the ``report:`` line on stderr, last, where the eye lands.

    The table gives the report's files as counts by type (hundreds of figure paths would push the report line off
    the screen); ``--format json`` and ``csv`` list every path.
    """
    rep = result.report
    done = result.work_done
    files = [str(p) for p in rep.out_files] if rep else []
    emit_object(
        {
            "report": rep.ref if rep else None,
            "id": rep.id if rep else None,
            "out": str(out_dir),
            "files": files_summary(rep.out_files if rep else []) if fmt == OutputFormat.table else files,
            "steps": len(result.steps),
            "work_done": done,
            "skipped": len(result.steps) - done,
            "wall_time_s": round(result.seconds, 1),
        },
        fmt,
    )
    if not quiet:
        info(f"reproduce: {done} step(s) did work, {len(result.steps) - done} skipped, {result.seconds:.1f} s")
        if rep is not None:
            if rep.pdf_error:
                info(f"note: no PDF: {rep.pdf_error.splitlines()[0]}")
            main = next(
                (p for p in rep.out_files if p.name == "report.pdf"),
                next((p for p in rep.out_files if p.name == "report.md"), out_dir),
            )
            info(f"[bold]report:[/] {main}  (folder {out_dir}; store ref {rep.ref}, id {rep.id[:12]})")


def files_summary(paths: list[Path]) -> str:
    """``219 files: 150 .png, 60 .pdf, 8 .csv, 1 .md`` (most frequent type first; ``0 files`` for none)."""
    counts: dict[str, int] = {}
    for path in paths:
        suffix = Path(path).suffix or "(no extension)"
        counts[suffix] = counts.get(suffix, 0) + 1
    kinds = ", ".join(f"{n} {suffix}" for suffix, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
    return f"{len(paths)} files" + (f": {kinds}" if kinds else "")


class _View:
    """One rich progress view on stderr: the overall steps and the current step's work; plain lines in a log."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar: Progress | None = None
        self.overall: TaskID | None = None
        self.current: TaskID | None = None
        self.console: Console | None = None
        self.done = 0
        self.total: int | None = None
        self.live = False

    def __enter__(self) -> _View:
        if self.quiet:
            return self
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.console = Console(stderr=True, emoji=False)
        self.live = self.console.is_terminal
        if self.live:
            self.bar = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[detail]}"),
                TimeElapsedColumn(),
                console=self.console,
            )
            self.bar.__enter__()
            self.overall = self.bar.add_task("[bold]reproduce[/]", total=self.total, detail="steps")
        return self

    def step_start(self, index: int, total: int, label: str, units: int, unit: str) -> None:
        if self.bar is None or self.overall is None:
            return
        self.bar.update(self.overall, total=total, completed=self.done)
        if self.current is not None:
            self.bar.remove_task(self.current)
        self.current = self.bar.add_task(f"  {label}", total=units, detail=unit)

    def step_advance(self, completed: int | None = None, advance: int = 0, detail: str = "") -> None:
        if self.bar is None or self.current is None:
            return
        kwargs: dict[str, Any] = {"detail": detail} if detail else {}  # rich.Progress.update's task fields
        if completed is not None:
            self.bar.update(self.current, completed=completed, **kwargs)
        else:
            self.bar.update(self.current, advance=advance, **kwargs)

    def step_end(self, result) -> None:
        self.done += 1
        if self.quiet:
            return
        line = _step_line(result)
        if self.bar is not None and self.overall is not None:
            if self.current is not None:
                self.bar.remove_task(self.current)
                self.current = None
            self.bar.update(self.overall, completed=self.done)
            self.bar.console.print(line)
        elif self.console is not None:
            self.console.print(line, highlight=False)

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)


class _RayView(_View):
    """The ``--executor ray`` view: a live table of jobs (queued / running / done / failed, where each ran)."""

    _STYLE = {
        "queued": "dim",
        "running": "yellow",
        "done": "green",
        "skipped": "dim",
        "failed": "red",
        "cancelled": "red",
    }

    def __init__(self, quiet: bool) -> None:
        super().__init__(quiet)
        self.live_view: Live | None = None
        self.run = None

    def __enter__(self) -> _RayView:
        if self.quiet:
            return self
        from rich.console import Console
        from rich.live import Live

        self.console = Console(stderr=True, emoji=False)
        if self.console.is_terminal:
            self.live_view = Live(console=self.console, refresh_per_second=2, transient=False)
            self.live_view.__enter__()
        return self

    def update(self, run) -> None:
        self.run = run
        if self.live_view is not None:
            self.live_view.update(self._table(run))

    def _table(self, run: Any) -> Table:
        from rich.table import Table

        counts: dict[str, int] = {}
        for js in run.jobs.values():
            counts[js.state] = counts.get(js.state, 0) + 1
        title = f"reproduce on Ray ({run.address}: {run.resources}): " + ", ".join(
            f"{n} {state}" for state, n in sorted(counts.items())
        )
        table = Table(title=title, title_justify="left")
        for col in ("job", "state", "where", "detail"):
            table.add_column(col)
        for js in run.jobs.values():
            style = self._STYLE.get(js.state, "")
            table.add_row(js.job.key, f"[{style}]{js.state}[/]" if style else js.state, js.node, js.detail[:80])
        return table

    def step_end(self, result) -> None:
        self.done += 1
        if self.quiet or self.console is None:
            return
        line = _step_line(result)
        self.console.print(line, highlight=False)

    def __exit__(self, *exc) -> None:
        if self.live_view is not None:
            self.live_view.__exit__(*exc)
        if not self.quiet and self.console is not None and self.run is not None:
            for js in self.run.jobs.values():
                if js.state in ("failed", "cancelled"):
                    self.console.print(f"{js.job.key}: [red]{js.state}[/] {js.detail}", highlight=False)
