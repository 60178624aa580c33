"""Throughput benchmarks: the env against the raw-physics floor on the same models, in one run."""

from __future__ import annotations

import os
import platform
import time
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class EnvBenchResult:
    """One ``morfic bench env`` measurement.

    Attributes:
        num_envs: Parallel envs N.
        steps: Policy steps timed (after warm-up).
        backend: Simulation backend.
        threads: Worker threads of the backend.
        env_steps_per_s: Policy (env) steps per second through ``LocomotionEnv.step`` with random
            actions: N * steps / wall time.
        physics_floor_steps_per_s: Physics steps per second when exactly the env's own stepping calls
            (same models, states, controls) are replayed in C with no env logic: the raw floor of the
            very same workload.
        floor_env_steps_per_s: The floor in env steps: physics floor / decimation.
        ratio: env_steps_per_s / floor_env_steps_per_s (1 = the env adds no overhead).
        cpu_model: The machine's CPU.
        cores: Logical cores.
    """

    num_envs: int
    steps: int
    backend: str
    threads: int
    env_steps_per_s: float
    physics_floor_steps_per_s: float
    floor_env_steps_per_s: float
    ratio: float
    cpu_model: str
    cores: int

    def as_dict(self) -> dict:
        """Plain dict for JSON/CSV."""
        return asdict(self)


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (or platform as a fallback)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def bench_env(num_envs: int, steps: int, backend: str = "cpu", seed: int = 0, warmup: int = 5) -> EnvBenchResult:
    """Measure env steps/s with random actions and the physics floor on the same models.

    Args:
        num_envs: Parallel envs.
        steps: Timed policy steps.
        backend: "cpu" (or "gpu" when available).
        seed: Seed of the env and the random actions.
        warmup: Untimed policy steps first.

    Returns:
        The measurement.
    """
    import dataclasses

    import torch

    from morfic_cli.config import EnvCfg, SimCfg
    from morfic_cli.envs.locomotion import LocomotionEnv
    from morfic_cli.sim.floor import StepRecorder, replay_floor

    cfg = EnvCfg(num_envs=num_envs, sim=dataclasses.replace(SimCfg(), backend=backend))
    env = LocomotionEnv(cfg, mode="train", seed=seed)
    gen = torch.Generator().manual_seed(seed)
    try:
        for _ in range(warmup):
            env.step(torch.rand((num_envs, 12), generator=gen) * 2 - 1)
        actions = [torch.rand((num_envs, 12), generator=gen) * 2 - 1 for _ in range(steps)]
        recorder = StepRecorder(env.backend.stepper)
        t0 = time.perf_counter()
        for a in actions:
            env.step(a)
        wall = time.perf_counter() - t0
        recorder.stop()
        env_sps = num_envs * steps / wall
        # best of two replays: the floor is the fastest the same physics can run, so the ratio is conservative
        floor = max(replay_floor(env.backend.models, recorder.calls, cfg.sim.num_threads) for _ in range(2))
    finally:
        env.close()
    floor_env = floor / cfg.decimation
    return EnvBenchResult(
        num_envs=num_envs,
        steps=steps,
        backend=backend,
        threads=cfg.sim.num_threads,
        env_steps_per_s=round(env_sps, 1),
        physics_floor_steps_per_s=round(floor, 1),
        floor_env_steps_per_s=round(floor_env, 1),
        ratio=round(env_sps / floor_env, 4),
        cpu_model=cpu_model(),
        cores=os.cpu_count() or 1,
    )


@dataclass(frozen=True)
class TrainBenchResult:
    """One ``morfic bench train`` measurement: PPO iterations of a preset against the physics floor.

    Attributes:
        preset: Training preset measured.
        variant: Actor-critic variant.
        num_envs: Parallel envs N.
        iterations: Timed PPO iterations (after one untimed warm-up iteration).
        transitions: Transitions collected in the timed iterations.
        s_per_iteration: Wall seconds per iteration (collection + update).
        collect_s_per_iteration: Of which rollout collection (env + policy inference).
        learn_s_per_iteration: Of which the PPO update.
        train_steps_per_s: Transitions per second including learning.
        floor_env_steps_per_s: The same physics calls replayed in C with no env or learning, in env steps/s.
        fraction_of_floor: train_steps_per_s / floor_env_steps_per_s.
        torch_threads: torch intra-op threads.
        cpu_model: The machine's CPU.
        cores: Logical cores.
    """

    preset: str
    variant: str
    num_envs: int
    iterations: int
    transitions: int
    s_per_iteration: float
    collect_s_per_iteration: float
    learn_s_per_iteration: float
    train_steps_per_s: float
    floor_env_steps_per_s: float
    fraction_of_floor: float
    torch_threads: int
    cpu_model: str
    cores: int

    def as_dict(self) -> dict:
        """Plain dict for JSON/CSV."""
        return asdict(self)


def bench_train(preset: str = "cpu", variant: str = "film", iterations: int = 5, seed: int = 0,
                overrides: list[str] | None = None) -> TrainBenchResult:
    """Time ``iterations`` PPO iterations of a preset (after one warm-up) and replay their physics as the floor.

    The run goes to a temporary store that is deleted afterwards.
    """
    import tempfile

    import torch

    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.runner import new_run
    from morfic_cli.sim.floor import StepRecorder, replay_floor
    from morfic_cli.store import Store

    cfg = apply_overrides(preset_cfg(preset, variant, seed),
                          [f"max_iterations={iterations + 1}", f"save_interval={iterations + 10}", *(overrides or [])])
    with tempfile.TemporaryDirectory(prefix="morfic-bench-") as tmp:
        run = new_run(Store(tmp), cfg, "bench")
        rows: list[dict] = []
        recorder: list[StepRecorder] = []

        def on_row(row: dict) -> None:
            rows.append(row)
            if len(rows) == 1:  # warm-up done: record the physics of the timed iterations
                recorder.append(StepRecorder(run.env.backend.stepper))

        run.progress = on_row
        try:
            run.train()
            recorder[0].stop()
            floor = max(replay_floor(run.env.backend.models, recorder[0].calls, cfg.env.sim.num_threads)
                        for _ in range(2))
        finally:
            run.env.close()
    timed = rows[1:]
    collect = sum(r["collect_s"] for r in timed) / len(timed)
    learn = sum(r["learn_s"] for r in timed) / len(timed)
    transitions = cfg.env.num_envs * cfg.num_steps_per_env * len(timed)
    sps = transitions / sum(r["collect_s"] + r["learn_s"] for r in timed)
    floor_env = floor / cfg.env.decimation
    return TrainBenchResult(
        preset=preset, variant=variant, num_envs=cfg.env.num_envs, iterations=len(timed), transitions=transitions,
        s_per_iteration=round(collect + learn, 3), collect_s_per_iteration=round(collect, 3),
        learn_s_per_iteration=round(learn, 3), train_steps_per_s=round(sps, 1),
        floor_env_steps_per_s=round(floor_env, 1), fraction_of_floor=round(sps / floor_env, 4),
        torch_threads=torch.get_num_threads(), cpu_model=cpu_model(), cores=os.cpu_count() or 1,
    )
