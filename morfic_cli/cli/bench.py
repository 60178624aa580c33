"""``morfic bench``: throughput against the raw-physics floor on this machine."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, Device, DeviceOpt, FormatOpt, OutputFormat, QuietOpt, StoreOpt
from morfic_cli.cli._render import Column, emit_object, emit_rows, info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args


def bench(
    what: Annotated[str, typer.Argument(help="env (env steps/s vs the physics floor) or train (PPO iterations of "
                                        "a preset vs the same floor).")],
    envs: Annotated[str, typer.Option("--envs", help="Comma-separated env counts, e.g. 256,1024,4096.")] = "256",
    steps: Annotated[int, typer.Option("--steps", help="Timed policy steps per measurement.")] = 50,
    backend: Annotated[str, typer.Option("--backend", help="Simulation backend: cpu (MuJoCo C) or warp (MuJoCo Warp; "
                                         "pip install 'morfic[gpu]'); --device cuda implies warp.")] = "cpu",
    device: DeviceOpt = Device.cpu,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the env and the random actions.")] = 0,
    preset: Annotated[str, typer.Option("--preset", help="bench train: training preset (smoke, cpu, paper).")] = "cpu",
    variant: Annotated[str, typer.Option("--variant", help="bench train: actor-critic variant.")] = "film",
    iterations: Annotated[int, typer.Option("--iterations", help="bench train: timed PPO iterations.")] = 5,
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

    Examples: morfic bench env --envs 256,1024 --steps 50 --format json;
    morfic bench env --backend warp --device cuda --envs 4096,8192;
    morfic bench train --preset cpu --iterations 5
    """
    check_args(store=store, env_counts=envs if what == "env" else None, steps=steps, seed=seed)
    if what not in ("env", "train"):
        raise MorficError(f"unknown benchmark '{what}'; valid benchmarks are: env, train.")
    if backend not in ("cpu", "warp", "gpu"):
        raise MorficError(f"unknown simulation backend '{backend}'; valid backends are: cpu, warp.")
    if what == "train":
        _bench_train(preset, variant, iterations, seed, fmt, quiet, store, device.value, backend)
        return
    try:
        counts = [int(x) for x in envs.split(",") if x.strip()]
    except ValueError as exc:
        raise MorficError(f"--envs must be comma-separated integers, got '{envs}'.") from exc
    if not counts or min(counts) < 1 or steps < 1:
        raise MorficError("--envs and --steps must be positive integers.")
    if backend == "cpu" and device != Device.cpu:
        raise MorficError("the cpu backend simulates on the CPU; use --backend warp with --device cuda.")
    if device == Device.cuda:
        from morfic_cli.sim.warp import warp_device

        warp_device("cuda")  # Error: without CUDA, before any work

    from morfic_cli.benchmarks import bench_env
    from morfic_cli.recording.tables import write_bench_table

    rows = []
    for n in counts:
        if not quiet:
            info(f"bench env: {n} envs x {steps} steps on {backend} ({device.value}) ...")
        rows.append(bench_env(n, steps, backend=backend, seed=seed, device=device.value).as_dict())
    artifact = write_bench_table(store, rows)
    if fmt == OutputFormat.json and len(rows) == 1:
        emit_object(rows[0], fmt)
    else:
        emit_rows(
            rows,
            fmt,
            columns=[
                Column("num_envs", "envs", justify="right"),
                Column("env_steps_per_s", "env steps/s", fmt=lambda v: f"{v:,.0f}", justify="right"),
                Column("physics_floor_steps_per_s", "physics floor steps/s", fmt=lambda v: f"{v:,.0f}",
                       justify="right"),
                Column("floor_env_steps_per_s", "floor env steps/s", fmt=lambda v: f"{v:,.0f}", justify="right"),
                Column("ratio", justify="right", fmt=lambda v: f"{v:.2f}"),
                Column("threads", justify="right"),
            ],
            title=f"morfic bench env: {rows[0]['backend']} on {rows[0]['device']} ({rows[0]['cpu_model']}, "
                  f"{rows[0]['cores']} cores)",
        )
    if not quiet:
        info(f"wrote table {artifact.id[:12]} (ref {artifact.ref}@{artifact.version}) to store {store}")


def _bench_train(preset: str, variant: str, iterations: int, seed: int, fmt: OutputFormat, quiet: bool,
                 store, device: str, backend: str) -> None:
    from morfic_cli.benchmarks import bench_train
    from morfic_cli.recording.tables import write_bench_train_table
    from morfic_cli.rl.runner import check_device

    if iterations < 1:
        raise MorficError("--iterations must be a positive integer.")
    check_device(device)
    if not quiet:
        info(f"bench train: {preset} preset, {variant}, {device}, 1 warm-up + {iterations} timed iterations ...")
    overrides = [] if backend == "cpu" else [f"env.sim.backend={backend}"]  # --device cuda selects warp itself
    row = bench_train(preset, variant, iterations, seed, overrides, device=device).as_dict()
    artifact = write_bench_train_table(store, [row])
    if fmt == OutputFormat.csv:
        emit_rows([row], fmt)
    else:
        emit_object(row, fmt)
    if not quiet:
        info(f"wrote table {artifact.id[:12]} (ref {artifact.ref}@{artifact.version}) to store {store}")
