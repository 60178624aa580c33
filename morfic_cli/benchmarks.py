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
