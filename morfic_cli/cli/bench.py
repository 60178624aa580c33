"""``morfic bench``: throughput against the raw-physics floor on this machine."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli import _options
from morfic_cli.cli._options import DEFAULT_STORE, Device, DeviceOpt, FormatOpt, OutputFormat, QuietOpt, StoreOpt
from morfic_cli.cli._render import Column, emit_object, emit_rows, info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args


def bench(
    what: Annotated[
        _options.Benchmark,
        typer.Argument(
            help="env (env steps/s vs the physics floor) or train (PPO iterations of a preset vs the same floor)."
        ),
    ],
    envs: Annotated[str, typer.Option("--envs", help="Comma-separated env counts, e.g. 256,1024,4096.")] = "256",
    steps: Annotated[int, typer.Option("--steps", min=1, help="Timed policy steps per measurement.")] = 50,
    backend: Annotated[
        _options.Backend,
        typer.Option(
            "--backend",
            help="Simulation backend: cpu (MuJoCo C) or warp (MuJoCo Warp; alias gpu; pip install "
            "'morfic[gpu]'); --device cuda implies warp.",
        ),
    ] = _options.Backend.cpu,
    device: DeviceOpt = Device.cpu,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the env and the random actions.")] = 0,
    preset: Annotated[_options.Preset, typer.Option("--preset", help="bench train: training preset.")] = (
        _options.Preset.cpu
    ),
    variant: Annotated[str, typer.Option("--variant", help="bench train: actor-critic variant.")] = "film",
    iterations: Annotated[int, typer.Option("--iterations", min=1, help="bench train: timed PPO iterations.")] = 5,
    repeats: Annotated[
        int,
        typer.Option(
            "--repeats", min=1, help="bench env: alternating env / floor repetitions; the result is their median."
        ),
    ] = 3,
    compare: Annotated[
        str | None,
        typer.Option(
            "--compare",
            help="bench train: also time this git commit, branch or tag, side by side in alternating runs (e.g. main).",
        ),
    ] = None,
    rounds: Annotated[int, typer.Option("--rounds", min=1, help="bench train --compare: runs per side.")] = 2,
    overrides: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="bench train: config override key=value, repeatable, as in `morfic train` (e.g. "
            "ppo.use_mixed_precision=false).",
        ),
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Measure env steps/s (or training steps/s) against the raw physics floor, in one run.

    bench train times --iterations PPO iterations of a preset (after one warm-up iteration) and replays
    their physics calls as the floor: fraction_of_floor is what training keeps of the raw simulation rate.

    The floor steps the same MuJoCo models in C with no env logic; ratio = env steps/s divided by
    the floor in env steps/s (physics steps/s / decimation). The table is stored as an artifact.
    `--format json` prints one object for a single --envs value, else a list.

    --backend warp --device cpu|cuda runs MuJoCo Warp on warp's CPU device or the GPU; bench train
    --device cuda trains as `morfic train --device cuda` does (MuJoCo Warp on the GPU).

    On a shared machine: env and floor are timed in alternation (--repeats, or every iteration for bench train) and
    the medians reported with their spread and the load average; a ratio above 1.05 (the env faster than its own
    physics) is not printed as a result: the machine was too noisy, rerun it. bench train --compare REF times the
    code of commit REF and this checkout side by side (--rounds alternating runs each) and prints the s/iteration
    ratio.

    Example: morfic bench env --envs 256,1024 --steps 50 --format json
    Example: morfic bench env --backend warp --device cuda --envs 4096,8192
    Example: morfic bench train --preset cpu --iterations 5
    Example: morfic bench train --preset cpu --iterations 3 --compare main --rounds 3
    Example: morfic bench train --preset cpu --iterations 2 --set ppo.use_mixed_precision=false
    """
    check_args(store=store, env_counts=envs if what is _options.Benchmark.env else None, steps=steps, seed=seed)
    backend_name = backend.value
    if overrides and (what is not _options.Benchmark.train or compare is not None):
        raise MorficError("--set overrides the training config of `morfic bench train` (without --compare); drop it.")
    if what is _options.Benchmark.train:
        from morfic_cli.rl.variants import trust_variants

        trust_variants([variant])  # --variant names it on this command line: the user's consent to import it
        if compare is not None:
            _compare_train(
                compare, preset.value, variant, iterations, rounds, seed, fmt, quiet, device.value, backend_name
            )
            return
        _bench_train(
            preset.value,
            variant,
            iterations,
            seed,
            fmt,
            quiet,
            store,
            device.value,
            backend_name,
            list(overrides or []),
        )
        return
    if compare is not None:
        raise MorficError("--compare times training; use it with `morfic bench train`.")
    if repeats < 1:
        raise MorficError("--repeats must be a positive integer.")
    try:
        counts = [int(x) for x in envs.split(",") if x.strip()]
    except ValueError as exc:
        raise MorficError(f"--envs must be comma-separated integers, got '{envs}'.") from exc
    if not counts or min(counts) < 1:
        raise MorficError(f"--envs must be positive integers, got '{envs}'.")
    if backend_name == "cpu" and device != Device.cpu:
        raise MorficError("the cpu backend simulates on the CPU; use --backend warp with --device cuda.")
    if device == Device.cuda:
        from morfic_cli.sim.warp import warp_device

        warp_device("cuda")  # Error: without CUDA, before any work

    from morfic_cli.benchmarks import bench_env
    from morfic_cli.recording.tables import write_bench_table

    rows = []
    for n in counts:
        if not quiet:
            info(f"bench env: {n} envs x {steps} steps on {backend_name} ({device.value}) ...")
        rows.append(
            bench_env(n, steps, backend=backend_name, seed=seed, device=device.value, repeats=repeats).as_dict()
        )
    artifact = write_bench_table(store, "env", rows)
    if fmt == OutputFormat.json and len(rows) == 1:
        emit_object(rows[0], fmt)
    else:
        emit_rows(
            rows,
            fmt,
            columns=[
                Column("num_envs", "envs", justify="right"),
                Column("env_steps_per_s", "env steps/s", fmt=lambda v: f"{v:,.0f}", justify="right"),
                Column(
                    "physics_floor_steps_per_s", "physics floor steps/s", fmt=lambda v: f"{v:,.0f}", justify="right"
                ),
                Column("floor_env_steps_per_s", "floor env steps/s", fmt=lambda v: f"{v:,.0f}", justify="right"),
                Column("ratio", justify="right", fmt=lambda v: "noisy" if v is None else f"{v:.2f}"),
                Column("ratio_spread", "ratio min-max", justify="right", fmt=lambda v: f"{v[0]:.2f}-{v[1]:.2f}"),
                Column("threads", justify="right"),
                Column("load_before", "load", justify="right", fmt=lambda v: f"{v:.1f}"),
            ],
            title=f"morfic bench env: {rows[0]['backend']} on {rows[0]['device']} ({rows[0]['cpu_model']}, "
            f"{rows[0]['cores']} cores)",
        )
    _warn_noisy([r for r in rows if r["noisy"]], "env")
    if not quiet:
        info(f"wrote table {artifact.id[:12]} (ref {artifact.ref}@{artifact.version}) to store {store}")


def _warn_noisy(rows: list[dict], what: str) -> None:
    """Say on stderr that a ratio above 1.05 was measured and not reported (always, also with --quiet)."""
    import sys

    from morfic_cli.benchmarks import MAX_CREDIBLE_RATIO

    for row in rows:
        lo, hi = row.get("ratio_spread") or row["fraction_spread"]
        sys.stderr.write(
            f"Warning: bench {what} at {row['num_envs']} envs measured the env faster than its own physics floor "
            f"(ratio {lo:.2f}-{hi:.2f} over the repetitions, above {MAX_CREDIBLE_RATIO}), so no ratio is reported: "
            f"the machine was too noisy (load average {row['load_before']:.1f} -> {row['load_after']:.1f}); rerun "
            "it when the machine is quieter.\n"
        )


def _compare_train(
    ref: str,
    preset: str,
    variant: str,
    iterations: int,
    rounds: int,
    seed: int,
    fmt: OutputFormat,
    quiet: bool,
    device: str,
    backend: str,
) -> None:
    from morfic_cli.benchmarks import compare_train

    if iterations < 1 or rounds < 1:
        raise MorficError("--iterations and --rounds must be positive integers.")
    if device != "cpu" or backend != "cpu":
        raise MorficError("--compare times the cpu backend on the CPU; drop --device/--backend.")
    result = compare_train(ref, preset, variant, iterations, rounds, seed, progress=None if quiet else info)
    if fmt == OutputFormat.json:
        emit_object(result.as_dict(), fmt)
        return
    emit_rows(
        result.summary_rows(),
        fmt,
        columns=[
            Column("code"),
            Column("s_per_iteration", "s/iter", justify="right", fmt=lambda v: f"{v:.2f}"),
            Column("collect_s_per_iteration", "collect s", justify="right", fmt=lambda v: f"{v:.2f}"),
            Column("learn_s_per_iteration", "learn s", justify="right", fmt=lambda v: f"{v:.2f}"),
            Column("train_steps_per_s", "steps/s", justify="right", fmt=lambda v: f"{v:,.0f}"),
            Column(
                "fraction_of_floor", "of floor", justify="right", fmt=lambda v: "noisy" if v is None else f"{v:.2f}"
            ),
            Column("load", "load min-max", justify="right", fmt=lambda v: f"{v[0]:.1f}-{v[1]:.1f}"),
        ],
        title=f"morfic bench train --compare {ref}: {preset} preset, {variant}, {iterations} iterations x "
        f"{result.rounds} rounds per side; s/iter ratio this / {ref} = {result.s_per_iteration_ratio:.3f} "
        f"(rounds {result.ratio_spread[0]:.3f}-{result.ratio_spread[1]:.3f})",
    )


def _bench_train(
    preset: str,
    variant: str,
    iterations: int,
    seed: int,
    fmt: OutputFormat,
    quiet: bool,
    store,
    device: str,
    backend: str,
    overrides: list[str],
) -> None:
    from morfic_cli.benchmarks import bench_train
    from morfic_cli.recording.tables import write_bench_table
    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.devices import check_device
    from morfic_cli.rl.precision import bf16_matmul, cpu_bf16_kernels, float32_note

    check_device(device)
    cfg = apply_overrides(preset_cfg(preset, variant, seed), overrides)  # unknown keys: Error before any work
    if not quiet:
        info(
            f"bench train: {preset} preset, {variant}, {device}, 1 warm-up + {iterations} timed iterations"
            + (f", {' '.join(overrides)}" if overrides else "")
            + " ..."
        )
    note = float32_note(bf16_matmul(device, cpu_bf16_kernels())) if cfg.ppo.use_mixed_precision else None
    if note and not quiet:
        info(note)
    if backend != "cpu":  # --device cuda selects warp itself
        overrides = [f"env.sim.backend={backend}", *overrides]
    row = bench_train(preset, variant, iterations, seed, overrides, device=device).as_dict()
    artifact = write_bench_table(store, "train", [row])
    if fmt == OutputFormat.csv:
        emit_rows([row], fmt)
    else:
        emit_object(row, fmt)
    _warn_noisy([row] if row["noisy"] else [], "train")
    if not quiet:
        info(f"wrote table {artifact.id[:12]} (ref {artifact.ref}@{artifact.version}) to store {store}")
