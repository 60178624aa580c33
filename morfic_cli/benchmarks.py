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
        device: Where the backend simulates: "cpu", or the GPU ("cuda:0 (NVIDIA ...)").
        threads: Worker threads of the backend (the CPU backend's; warp uses its device).
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
    device: str
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


def device_name(device: str) -> str:
    """``cpu``, or a CUDA device with its name, e.g. ``cuda:0 (NVIDIA H100 80GB HBM3)``."""
    import torch

    if not device.startswith("cuda"):
        return "cpu"
    dev = torch.device(device)
    index = dev.index or 0
    return f"cuda:{index} ({torch.cuda.get_device_name(index)})"


class PhysicsRecorder:
    """Record a backend's stepping calls during a timed window, then time the same physics alone (the floor).

    CPU backend: :class:`morfic_cli.sim.floor.StepRecorder` + :func:`~morfic_cli.sim.floor.replay_floor`
    (every call replayed from its recorded state on a fresh stepper). Warp backend: the recorded
    joint targets are replayed by :meth:`morfic_cli.sim.warp.WarpBackend.physics_floor` from the state
    at the start of the window, without resets (the worlds continue from their own results).

    Args:
        backend: The env's backend; recording starts now.
    """

    def __init__(self, backend) -> None:
        from morfic_cli.sim.floor import StepRecorder

        self.backend = backend
        self._cpu = hasattr(backend, "stepper")
        if self._cpu:
            self._recorder = StepRecorder(backend.stepper)
            return
        self.start = backend.state_dict()
        self.calls: list[tuple[object, int]] = []
        self._inner = backend.step

        def _recording_step(joint_targets, nsteps):
            self.calls.append((joint_targets.detach().clone(), int(nsteps)))
            return self._inner(joint_targets, nsteps)

        backend.step = _recording_step

    def stop(self) -> None:
        """Stop recording."""
        if self._cpu:
            self._recorder.stop()
        else:
            self.backend.step = self._inner

    def floor(self, num_threads: int) -> float:
        """Physics steps per second of the recorded calls with no env logic: best of two replays."""
        from morfic_cli.sim.floor import replay_floor

        if self._cpu:
            return max(replay_floor(self.backend.models, self._recorder.calls, num_threads) for _ in range(2))
        nsteps = self.calls[0][1]
        best = 0.0
        for _ in range(2):
            self.backend.load_state_dict(self.start)
            best = max(best, self.backend.physics_floor([t for t, _ in self.calls], nsteps))
        return best


def bench_env(num_envs: int, steps: int, backend: str = "cpu", seed: int = 0, warmup: int = 5,
              device: str = "cpu") -> EnvBenchResult:
    """Measure env steps/s with random actions and the physics floor on the same models.

    Args:
        num_envs: Parallel envs.
        steps: Timed policy steps.
        backend: "cpu" or "warp" (alias "gpu").
        seed: Seed of the env and the random actions.
        warmup: Untimed policy steps first (the warp backend compiles its kernels, or captures its
            graphs, in the first one).
        device: Where the warp backend simulates: "cpu" or "cuda" (the CPU backend: "cpu" only).

    Returns:
        The measurement.
    """
    import dataclasses

    import torch

    from morfic_cli.config import EnvCfg, SimCfg
    from morfic_cli.envs.locomotion import LocomotionEnv

    if backend == "cpu" and device != "cpu":
        from morfic_cli.errors import MorficError

        raise MorficError(f"the cpu backend simulates on the CPU; use --backend warp for --device {device}.")
    if device == "cuda":
        from morfic_cli.sim.warp import warp_device

        device = warp_device(device)
    cfg = EnvCfg(num_envs=num_envs, sim=dataclasses.replace(SimCfg(), backend=backend, device=device))
    env = LocomotionEnv(cfg, mode="train", seed=seed)
    gen = torch.Generator().manual_seed(seed)
    try:
        for _ in range(warmup):
            env.step(torch.rand((num_envs, 12), generator=gen) * 2 - 1)
        actions = [torch.rand((num_envs, 12), generator=gen) * 2 - 1 for _ in range(steps)]
        recorder = PhysicsRecorder(env.backend)
        t0 = time.perf_counter()
        for a in actions:
            env.step(a)
        wall = time.perf_counter() - t0
        recorder.stop()
        env_sps = num_envs * steps / wall
        # best of two replays: the floor is the fastest the same physics can run, so the ratio is conservative
        floor = recorder.floor(cfg.sim.num_threads)
    finally:
        env.close()
    floor_env = floor / cfg.decimation
    return EnvBenchResult(
        num_envs=num_envs,
        steps=steps,
        backend=backend,
        device=device_name(device),
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
        backend: Simulation backend.
        device: Training device: "cpu", or the GPU ("cuda:0 (NVIDIA ...)").
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
    backend: str
    device: str
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
                overrides: list[str] | None = None, device: str = "cpu") -> TrainBenchResult:
    """Time ``iterations`` PPO iterations of a preset (after one warm-up) and replay their physics as the floor.

    The run goes to a temporary store that is deleted afterwards. ``device="cuda"`` trains as
    ``morfic train --device cuda`` does (the warp backend on the GPU).
    """
    import tempfile

    import torch

    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.runner import new_run
    from morfic_cli.store import Store

    cfg = apply_overrides(preset_cfg(preset, variant, seed),
                          [f"max_iterations={iterations + 1}", f"save_interval={iterations + 10}", *(overrides or [])])
    with tempfile.TemporaryDirectory(prefix="morfic-bench-") as tmp:
        run = new_run(Store(tmp), cfg, "bench", device)
        cfg = run.cfg
        rows: list[dict] = []
        recorder: list[PhysicsRecorder] = []

        def on_row(row: dict) -> None:
            rows.append(row)
            if len(rows) == 1:  # warm-up done: record the physics of the timed iterations
                recorder.append(PhysicsRecorder(run.env.backend))

        run.progress = on_row
        try:
            run.train()
            recorder[0].stop()
            floor = recorder[0].floor(cfg.env.sim.num_threads)
        finally:
            run.env.close()
    timed = rows[1:]
    collect = sum(r["collect_s"] for r in timed) / len(timed)
    learn = sum(r["learn_s"] for r in timed) / len(timed)
    transitions = cfg.env.num_envs * cfg.num_steps_per_env * len(timed)
    sps = transitions / sum(r["collect_s"] + r["learn_s"] for r in timed)
    floor_env = floor / cfg.env.decimation
    return TrainBenchResult(
        preset=preset, variant=variant, backend=cfg.env.sim.backend, device=device_name(cfg.env.sim.device),
        num_envs=cfg.env.num_envs, iterations=len(timed), transitions=transitions,
        s_per_iteration=round(collect + learn, 3), collect_s_per_iteration=round(collect, 3),
        learn_s_per_iteration=round(learn, 3), train_steps_per_s=round(sps, 1),
        floor_env_steps_per_s=round(floor_env, 1), fraction_of_floor=round(sps / floor_env, 4),
        torch_threads=torch.get_num_threads(), cpu_model=cpu_model(), cores=os.cpu_count() or 1,
    )
