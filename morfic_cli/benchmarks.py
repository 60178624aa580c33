"""Throughput benchmarks: the env against the raw-physics floor on the same models, in one run.

Robustness on a shared machine (docs/benchmarks.md, "How `morfic bench` measures"): the env (or a training
iteration) and its physics floor are timed in alternation, repetition by repetition, so a burst of load from another
process hits both sides of a ratio rather than one; results are medians over the repetitions with their spread
(min, max), and the 1-minute load average before and after is part of every result. A ratio above
:data:`MAX_CREDIBLE_RATIO` (the env faster than its own physics, which it cannot be) is not reported: ``ratio`` is
None, ``noisy`` is True and the CLI says to rerun on a quieter machine. :func:`compare_train` times two commits side
by side, in alternating subprocesses.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

MAX_CREDIBLE_RATIO = 1.05
"""The largest env/floor ratio reported as a result; above it the measurement was disturbed (timing noise)."""


def load_average() -> float:
    """The 1-minute load average (runnable processes; a 2-core machine is saturated at 2.0), or NaN."""
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:  # pragma: no cover - platforms without getloadavg
        return float("nan")


def credible(ratio: float) -> float | None:
    """``ratio`` rounded, or None when it exceeds :data:`MAX_CREDIBLE_RATIO` (see the module docstring)."""
    return round(ratio, 4) if ratio <= MAX_CREDIBLE_RATIO else None


def _spread(values: list[float], digits: int = 4) -> list[float]:
    return [round(min(values), digits), round(max(values), digits)]


@dataclass(frozen=True)
class EnvBenchResult:
    """One ``morfic bench env`` measurement: medians over ``repeats`` alternating env / floor repetitions.

    Attributes:
        num_envs: Parallel envs N.
        steps: Policy steps timed per repetition (after warm-up).
        backend: Simulation backend.
        device: Where the backend simulates: "cpu", or the GPU ("cuda:0 (NVIDIA ...)").
        threads: Worker threads of the backend (the CPU backend's; warp uses its device).
        env_steps_per_s: Policy (env) steps per second through ``LocomotionEnv.step`` with random
            actions: N * steps / wall time.
        physics_floor_steps_per_s: Physics steps per second when exactly the env's own stepping calls
            (same models, states, controls) are replayed in C with no env logic: the raw floor of the
            very same workload.
        floor_env_steps_per_s: The floor in env steps: physics floor / decimation.
        ratio: Median over repetitions of env steps/s / floor env steps/s (1 = the env adds no overhead); None
            when above :data:`MAX_CREDIBLE_RATIO` (``noisy``).
        cpu_model: The machine's CPU.
        cores: Logical cores.
        repeats: Env / floor repetitions, alternating.
        ratio_spread: [min, max] of the per-repetition ratios.
        env_steps_per_s_spread: [min, max] of the per-repetition env steps/s.
        noisy: True when the median ratio exceeded :data:`MAX_CREDIBLE_RATIO`: rerun on a quieter machine.
        load_before: 1-minute load average when the measurement started.
        load_after: 1-minute load average when it ended.
    """

    num_envs: int
    steps: int
    backend: str
    device: str
    threads: int
    env_steps_per_s: float
    physics_floor_steps_per_s: float
    floor_env_steps_per_s: float
    ratio: float | None
    cpu_model: str
    cores: int
    repeats: int = 1
    ratio_spread: list[float] = field(default_factory=list)
    env_steps_per_s_spread: list[float] = field(default_factory=list)
    noisy: bool = False
    load_before: float = float("nan")
    load_after: float = float("nan")

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

    def floor(self, num_threads: int, replays: int = 2) -> float:
        """Physics steps per second of the recorded calls with no env logic: best of ``replays`` replays."""
        from morfic_cli.sim.floor import replay_floor

        if self._cpu:
            return max(replay_floor(self.backend.models, self._recorder.calls, num_threads) for _ in range(replays))
        nsteps = self.calls[0][1]
        best = 0.0
        for _ in range(replays):
            self.backend.load_state_dict(self.start)
            best = max(best, self.backend.physics_floor([t for t, _ in self.calls], nsteps))
        return best


def bench_env(
    num_envs: int,
    steps: int,
    backend: str = "cpu",
    seed: int = 0,
    warmup: int = 5,
    device: str = "cpu",
    repeats: int = 3,
) -> EnvBenchResult:
    """Measure env steps/s with random actions and the physics floor on the same models, in alternation.

    Each repetition times ``steps`` env steps (recording their stepping calls), then replays exactly those calls as
    the floor (best of two replays); the result holds the medians over ``repeats`` repetitions.

    Args:
        num_envs: Parallel envs.
        steps: Timed policy steps per repetition.
        backend: "cpu" or "warp" (alias "gpu").
        seed: Seed of the env and the random actions.
        warmup: Untimed policy steps first (the warp backend compiles its kernels, or captures its
            graphs, in the first one).
        device: Where the warp backend simulates: "cpu" or "cuda" (the CPU backend: "cpu" only).
        repeats: Alternating env / floor repetitions (>= 1).

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
    load_before = load_average()
    env = LocomotionEnv(cfg, mode="train", seed=seed)
    gen = torch.Generator().manual_seed(seed)
    env_sps: list[float] = []
    floors: list[float] = []
    try:
        for _ in range(warmup):
            env.step(torch.rand((num_envs, 12), generator=gen) * 2 - 1)
        for _ in range(max(1, int(repeats))):
            actions = [torch.rand((num_envs, 12), generator=gen) * 2 - 1 for _ in range(steps)]
            recorder = PhysicsRecorder(env.backend)
            t0 = time.perf_counter()
            for a in actions:
                env.step(a)
            wall = time.perf_counter() - t0
            recorder.stop()
            env_sps.append(num_envs * steps / wall)
            # best of two replays: the floor is the fastest the same physics can run, so the ratio is conservative
            floors.append(recorder.floor(cfg.sim.num_threads))
    finally:
        env.close()
    ratios = [e / (f / cfg.decimation) for e, f in zip(env_sps, floors, strict=True)]
    ratio = statistics.median(ratios)
    floor = statistics.median(floors)
    return EnvBenchResult(
        num_envs=num_envs,
        steps=steps,
        backend=backend,
        device=device_name(device),
        threads=cfg.sim.num_threads,
        env_steps_per_s=round(statistics.median(env_sps), 1),
        physics_floor_steps_per_s=round(floor, 1),
        floor_env_steps_per_s=round(floor / cfg.decimation, 1),
        ratio=credible(ratio),
        cpu_model=cpu_model(),
        cores=os.cpu_count() or 1,
        repeats=len(ratios),
        ratio_spread=_spread(ratios),
        env_steps_per_s_spread=_spread(env_sps, 1),
        noisy=ratio > MAX_CREDIBLE_RATIO,
        load_before=load_before,
        load_after=load_average(),
    )


@dataclass(frozen=True)
class TrainBenchResult:
    """One ``morfic bench train`` measurement: PPO iterations of a preset against the physics floor.

    Every timed iteration is followed by the replay of its own physics calls (its floor); the figures are medians
    over the timed iterations.

    Attributes:
        preset: Training preset measured.
        variant: Actor-critic variant.
        backend: Simulation backend.
        device: Training device: "cpu", or the GPU ("cuda:0 (NVIDIA ...)").
        num_envs: Parallel envs N.
        iterations: Timed PPO iterations (after one untimed warm-up iteration).
        transitions: Transitions collected in the timed iterations.
        s_per_iteration: Wall seconds per iteration (collection + update), median.
        collect_s_per_iteration: Of which rollout collection (env + policy inference).
        learn_s_per_iteration: Of which the PPO update.
        train_steps_per_s: Transitions per second including learning.
        floor_env_steps_per_s: The same physics calls replayed in C with no env or learning, in env steps/s.
        fraction_of_floor: Median over iterations of train steps/s / floor env steps/s; None when above
            :data:`MAX_CREDIBLE_RATIO` (``noisy``).
        torch_threads: torch intra-op threads.
        cpu_model: The machine's CPU.
        cores: Logical cores.
        s_per_iteration_spread: [min, max] over the timed iterations.
        fraction_spread: [min, max] of the per-iteration fractions of floor.
        noisy: True when the median fraction exceeded :data:`MAX_CREDIBLE_RATIO`: rerun on a quieter machine.
        load_before: 1-minute load average when the measurement started.
        load_after: 1-minute load average when it ended.
        omp_wait_policy: ``OMP_WAIT_POLICY`` of the process (morfic_cli/threads.py).
        mixed_precision: The preset's ``ppo.use_mixed_precision`` (bf16 autocast).
        bf16_kernels: Whether this CPU has fast bf16 matrix kernels (None: unknown).
        bf16_matmul: How the run's bf16 matrix products ran: "native", "float32" (a CPU without bf16 kernels,
            morfic_cli/rl/precision.py), or None without mixed precision.
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
    fraction_of_floor: float | None
    torch_threads: int
    cpu_model: str
    cores: int
    s_per_iteration_spread: list[float] = field(default_factory=list)
    fraction_spread: list[float] = field(default_factory=list)
    noisy: bool = False
    load_before: float = float("nan")
    load_after: float = float("nan")
    omp_wait_policy: str = ""
    mixed_precision: bool = False
    bf16_kernels: bool | None = None
    bf16_matmul: str | None = None

    def as_dict(self) -> dict:
        """Plain dict for JSON/CSV."""
        return asdict(self)


def bench_train(
    preset: str = "cpu",
    variant: str = "film",
    iterations: int = 5,
    seed: int = 0,
    overrides: list[str] | None = None,
    device: str = "cpu",
) -> TrainBenchResult:
    """Time ``iterations`` PPO iterations of a preset (after one warm-up) and replay their physics as the floor.

    The run goes to a temporary store that is deleted afterwards. ``device="cuda"`` trains as
    ``morfic train --device cuda`` does (the warp backend on the GPU).
    """
    import tempfile

    import torch

    from morfic_cli.rl.config import apply_overrides, preset_cfg
    from morfic_cli.rl.precision import cpu_bf16_kernels
    from morfic_cli.rl.runner import new_run
    from morfic_cli.store import Store

    cfg = apply_overrides(
        preset_cfg(preset, variant, seed),
        [f"max_iterations={iterations + 1}", f"save_interval={iterations + 10}", *(overrides or [])],
    )
    load_before = load_average()
    with tempfile.TemporaryDirectory(prefix="morfic-bench-") as tmp:
        run = new_run(Store(tmp), cfg, "bench", device)
        matmul = run.runner.alg.bf16_matmul
        cfg = run.cfg
        rows: list[dict] = []
        floors: list[float] = []
        recorder: list[PhysicsRecorder] = []

        def on_row(row: dict) -> None:
            rows.append(row)
            if recorder:  # a timed iteration ended: replay its physics now, before the next one (alternation)
                recorder[0].stop()
                floors.append(recorder.pop().floor(cfg.env.sim.num_threads, replays=1))
            if len(rows) <= iterations:  # the warm-up or a timed iteration done: record the next one
                recorder.append(PhysicsRecorder(run.env.backend))

        run.progress = on_row
        try:
            run.train()
        finally:
            run.env.close()
    timed = rows[1:]
    per_iter = [r["collect_s"] + r["learn_s"] for r in timed]
    transitions = cfg.env.num_envs * cfg.num_steps_per_env
    fractions = [transitions / s / (f / cfg.env.decimation) for s, f in zip(per_iter, floors, strict=True)]
    fraction = statistics.median(fractions)
    med = statistics.median
    return TrainBenchResult(
        preset=preset,
        variant=variant,
        backend=cfg.env.sim.backend,
        device=device_name(cfg.env.sim.device),
        num_envs=cfg.env.num_envs,
        iterations=len(timed),
        transitions=transitions * len(timed),
        s_per_iteration=round(med(per_iter), 3),
        collect_s_per_iteration=round(med(r["collect_s"] for r in timed), 3),
        learn_s_per_iteration=round(med(r["learn_s"] for r in timed), 3),
        train_steps_per_s=round(transitions / med(per_iter), 1),
        floor_env_steps_per_s=round(med(floors) / cfg.env.decimation, 1),
        fraction_of_floor=credible(fraction),
        torch_threads=torch.get_num_threads(),
        cpu_model=cpu_model(),
        cores=os.cpu_count() or 1,
        s_per_iteration_spread=_spread(per_iter, 3),
        fraction_spread=_spread(fractions),
        noisy=fraction > MAX_CREDIBLE_RATIO,
        load_before=load_before,
        load_after=load_average(),
        omp_wait_policy=os.environ.get("OMP_WAIT_POLICY", ""),
        mixed_precision=cfg.ppo.use_mixed_precision,
        bf16_kernels=cpu_bf16_kernels(),
        bf16_matmul=matmul,
    )


@dataclass(frozen=True)
class TrainComparison:
    """``morfic bench train --compare REF``: this checkout and commit REF timed side by side, in alternation.

    Attributes:
        ref: The commit-ish compared against, as given.
        ref_commit: Its full commit hash.
        this: What "this" is: the working tree of this checkout (its HEAD commit, "+ changes" when dirty).
        rounds: Rounds; each runs both sides once, in alternating order (this, ref; then ref, this; ...).
        this_runs: This side's :class:`TrainBenchResult` dicts, one per round.
        ref_runs: REF's ``bench train`` JSON objects, one per round (REF's own keys).
        s_per_iteration_ratio: Median over rounds of this s/iteration / REF's s/iteration (0.5 = twice as fast).
        ratio_spread: [min, max] of the per-round ratios.
    """

    ref: str
    ref_commit: str
    this: str
    rounds: int
    this_runs: list[dict]
    ref_runs: list[dict]
    s_per_iteration_ratio: float
    ratio_spread: list[float]

    def as_dict(self) -> dict:
        """Plain dict for JSON."""
        return asdict(self)

    def summary_rows(self) -> list[dict]:
        """One row per side: medians over rounds of the keys both sides report."""
        keys = (
            "s_per_iteration",
            "collect_s_per_iteration",
            "learn_s_per_iteration",
            "train_steps_per_s",
            "floor_env_steps_per_s",
            "fraction_of_floor",
        )
        out = []
        for side, runs in ((self.this, self.this_runs), (f"{self.ref} ({self.ref_commit[:10]})", self.ref_runs)):
            row: dict = {"code": side}
            for k in keys:
                vals = [r[k] for r in runs if r.get(k) is not None]
                row[k] = round(statistics.median(vals), 4) if vals else None
            row["load"] = _spread([r["load_before"] for r in runs], 2)
            out.append(row)
        return out


def _checkout_root() -> Path:
    import morfic_cli

    return Path(morfic_cli.__file__).resolve().parents[1]


def _git(root: Path, *args: str) -> str:
    import subprocess

    from morfic_cli.errors import MorficError

    proc = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise MorficError(
            f"git {' '.join(args)} failed in {root}: {proc.stderr.strip() or proc.stdout.strip()}; "
            "--compare needs a git checkout of morfic and a commit, branch or tag it knows."
        )
    return proc.stdout.strip()


def _bench_subprocess(root: Path, argv: list[str], env: dict[str, str]) -> dict:
    """Run ``python -m morfic_cli bench train ... --format json`` with ``root``'s code; its JSON object."""
    import json
    import subprocess
    import sys

    from morfic_cli.errors import MorficError

    proc = subprocess.run(
        [sys.executable, "-m", "morfic_cli", "bench", "train", *argv], cwd=root, env=env, capture_output=True, text=True
    )
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise MorficError(f"bench train with the code in {root} failed (exit {proc.returncode}): {' '.join(tail)}")
    return json.loads(proc.stdout)


def compare_train(
    ref: str,
    preset: str = "cpu",
    variant: str = "film",
    iterations: int = 3,
    rounds: int = 2,
    seed: int = 0,
    progress=None,
) -> TrainComparison:
    """Time ``bench train`` of this checkout and of commit ``ref`` side by side, in alternating subprocesses.

    REF's tree is exported with ``git archive`` into a temporary directory (no worktree is registered) and run with
    the same Python and packages; each side runs through its own ``morfic`` entry point, so each gets the thread
    settings its own code chooses (an ``OMP_WAIT_POLICY`` set by this process is not passed on; one the user set is).

    Args:
        ref: A commit, branch or tag of this checkout's repository.
        preset: Training preset, both sides.
        variant: Actor-critic variant, both sides.
        iterations: Timed iterations per run.
        rounds: Runs per side; the order alternates between rounds.
        seed: Seed, both sides.
        progress: Called with a line of text before each run (or None).

    Returns:
        Both sides' results and the median s/iteration ratio (this / REF).
    """
    import io
    import subprocess
    import tarfile
    import tempfile

    from morfic_cli.threads import user_environment

    root = _checkout_root()
    ref_commit = _git(root, "rev-parse", "--verify", f"{ref}^{{commit}}")
    head = _git(root, "rev-parse", "HEAD")
    dirty = bool(_git(root, "status", "--porcelain", "--untracked-files=no"))
    this = f"this checkout ({head[:10]}{' + changes' if dirty else ''})"
    argv = [
        "--preset",
        preset,
        "--variant",
        variant,
        "--iterations",
        str(iterations),
        "--seed",
        str(seed),
        "--format",
        "json",
        "-q",
    ]
    env = user_environment()
    this_runs: list[dict] = []
    ref_runs: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="morfic-compare-") as tmp:
        ref_root = Path(tmp) / "ref"
        ref_root.mkdir()
        archive = subprocess.run(["git", "-C", str(root), "archive", ref_commit], capture_output=True, check=True)
        with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
            tar.extractall(ref_root, filter="data")
        sides = {"this": (root, this_runs), "ref": (ref_root, ref_runs)}
        for r in range(max(1, int(rounds))):
            for name in ("this", "ref") if r % 2 == 0 else ("ref", "this"):
                side_root, runs = sides[name]
                if progress is not None:
                    progress(f"round {r + 1}/{rounds}: {this if name == 'this' else ref} ...")
                side_env = dict(env, PYTHONPATH=str(side_root))
                store = Path(tmp) / f"store-{name}"
                load = load_average()
                out = _bench_subprocess(side_root, [*argv, "--store", str(store)], side_env)
                out.setdefault("load_before", load)  # older code does not report it
                out.setdefault("load_after", load_average())
                runs.append(out)
    ratios = [a["s_per_iteration"] / b["s_per_iteration"] for a, b in zip(this_runs, ref_runs, strict=True)]
    return TrainComparison(
        ref=ref,
        ref_commit=ref_commit,
        this=this,
        rounds=len(ratios),
        this_runs=this_runs,
        ref_runs=ref_runs,
        s_per_iteration_ratio=round(statistics.median(ratios), 4),
        ratio_spread=_spread(ratios),
    )
