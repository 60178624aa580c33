"""``morfic reproduce``: train every variant (x seeds) -> evaluate -> diagnose -> fixed-rollout -> compare -> report.

The ``shipped`` preset trains nothing: each run is imported from its bundle (``<bundles>/<run name>.tar``, the
trained ``cpu``-preset runs shipped under ``artifacts/bundles/``), then evaluated and diagnosed with a reduced
protocol sized to finish in minutes on 2 cores (``--protocol full``: the paper's).

Every step is idempotent through the store: before it runs, it looks for a result of the same inputs and config
(:func:`~morfic_cli.store.publish.find_manifest`) and, when there is one, is skipped. Training is keyed by its run
ref ``runs/<variant>-<preset>-s<seed>``: a finished run is skipped, an interrupted one (Ctrl-C) is resumed from its
last checkpoint, a run of that name trained with another config is an error. So a second ``reproduce`` does no
work, and one after a Ctrl-C continues where the first stopped.

The pipeline reports progress through a :class:`Progress` (the CLI draws it with rich); it never prints.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from morfic_cli.errors import MorficError
from morfic_cli.report.build import ReportCfg, ReportResult, build_report
from morfic_cli.report.claims import PAPER_COMMAND
from morfic_cli.report.paper import ROBOTS
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, REPRODUCE_VARIANTS, VARIANTS, eval_modes, resolve_variant
from morfic_cli.runs import RUNS_PREFIX, run_name, run_of
from morfic_cli.store import Store
from morfic_cli.store.publish import find_manifest


@dataclass(frozen=True)
class ReproduceCfg:
    """The whole pipeline (defaults: the paper's protocol; :func:`reproduce_cfg` sizes it per preset).

    Attributes:
        preset: Training budget (smoke, cpu, paper).
        variants: Variants to train; default :data:`~morfic_cli.rl.variants.REPRODUCE_VARIANTS`, the paper's seven
            and the external baselines (``bot``, ``urma``, ``genloco``: the report's external-baselines tables;
            docs/report.md, "Which variants train by default").
        seeds: Seeds per variant (0 .. seeds-1).
        train_overrides: ``--set key=value`` items applied to every training config.
        robots: Evaluation and diagnosis targets.
        command_vx: Evaluation commands (m/s).
        modes: Evaluation modes of every run; None: each run's variant's
            (:func:`~morfic_cli.rl.variants.eval_modes`: descriptor and full, issue 58's ``actuation-matched`` too).
        eval_envs: Envs per evaluation rollout.
        eval_steps: Policy steps per evaluation rollout.
        diagnose_envs: Envs per diagnostic rollout.
        diagnose_steps: Policy steps per diagnostic rollout (must exceed H_eps).
        trunc_eps: eps of I_eps.
        batch_robots: Step the descriptor-mode rollouts of all ``robots`` as one env (each robot its slice of
            ``len(robots) x envs`` envs; :func:`~morfic_cli.evaluation.rollout.run_rollouts`) in the evaluation, the
            diagnosis and the fixed-rollout analysis: same per-robot protocol, other random start states, about half
            the CPU time. The ``shipped`` quick protocol does; ``cpu``, ``paper`` and ``--full-protocol`` do not.
        fixed_rollout_robots: Targets of the fixed-rollout analysis.
        actor_variant: Variant whose seed-0 actor is frozen for the fixed-rollout analysis.
        device: Training device.
        torch_threads: torch intra-op threads while the pipeline runs (None: leave torch's default). The smoke
            preset's batches of 2-8 envs run several times faster on one thread than on two that contend.
        bundles: Folder of run bundles (``<run name>.tar``); when set, runs are imported from it instead of
            trained (the ``shipped`` preset).
        critic_study: The critic study's settings (:class:`~morfic_cli.diagnostics.critic_study.StudyCfg` fields
            that differ from its defaults), run on the fixed-rollout actor after the fixed-rollout analysis; None: no
            study step. ``cpu`` and ``paper`` run the default study (~30 fits), ``smoke`` a tiny one; ``shipped``
            imports the study shipped with the runs (``<bundles>/results/critic-study.tar``) when there is one.
        name: The report's name (``reports/<name>``); default the preset.
    """

    preset: str = "smoke"
    variants: tuple[str, ...] = REPRODUCE_VARIANTS
    seeds: int = 1
    train_overrides: tuple[str, ...] = ()
    robots: tuple[str, ...] = ROBOTS
    command_vx: tuple[float, ...] = (2.0, 2.5)
    modes: tuple[str, ...] | None = None
    eval_envs: int = 64
    eval_steps: int = 500
    diagnose_envs: int = 64
    diagnose_steps: int = 800
    trunc_eps: float = 0.05
    batch_robots: bool = False
    fixed_rollout_robots: tuple[str, ...] = ("aliengo", "mini_cheetah")
    actor_variant: str = FIXED_ROLLOUT_ACTOR
    device: str = "cpu"
    torch_threads: int | None = None
    bundles: str | None = None
    critic_study: dict[str, Any] | None = None
    name: str | None = None

    @property
    def report_name(self) -> str:
        """``reports/<report_name>``."""
        return self.name or self.preset


#: The pipeline presets: the training presets, and ``shipped`` (import the shipped ``cpu`` runs, train nothing).
SHIPPED = "shipped"
#: The preset of the shipped runs.
SHIPPED_TRAIN_PRESET = "cpu"
#: The ``shipped`` preset's quick protocol, sized so that seven variants are evaluated, diagnosed and reported in
#: about 10 minutes on 2 cores (docs/reproducing.md): the paper's main zero-shot table only (descriptor mode,
#: 2.0 m/s) and its episode and diagnostic lengths, with 16 envs instead of 64 (at 16 envs a policy step costs
#: little more than its fixed Python overhead, so fewer steps, not fewer envs, would be the real saving), the seven
#: robots' 16 envs stepped as one batch of 112 (``batch_robots``: one policy call and one env step per step for all
#: robots, about half the CPU time of seven rollouts of 16; docs/benchmarks-history.md).
SHIPPED_PROTOCOL: dict[str, Any] = {
    "modes": ("descriptor",),
    "command_vx": (2.0,),
    "eval_envs": 16,
    "eval_steps": 500,
    "diagnose_envs": 16,
    "diagnose_steps": 800,
    "batch_robots": True,
}


SMOKE_STUDY: dict[str, Any] = {
    "seeds": 2,
    "commands": (2.0,),
    "train_envs": 4,
    "held_out": 1,
    "val_envs": 1,
    "target_envs": 2,
    "steps": 80,
    "trunc_eps": 0.5,
    "max_epochs": 2,
    "patience": 1,
    "minibatch": 64,
    "stride": 2,
}
"""The smoke preset's critic study: every stage in seconds (its numbers are not results)."""
SHIPPED_STUDY_BUNDLE = "results/critic-study.tar"
"""Where, under the bundle folder, the shipped preset finds the critic study of the shipped runs."""


def default_bundles() -> Path:
    """The repository's ``artifacts/bundles`` (where a source checkout keeps the shipped runs)."""
    return Path(__file__).resolve().parents[1] / "artifacts" / "bundles"


def bundle_path(bundles: str | Path, spec: str) -> Path:
    """The bundle of run ``spec`` (``runs/NAME``): ``<bundles>/NAME.tar``."""
    return Path(bundles) / f"{run_of(spec)}.tar"


def shipped_bundle(bundles: str | Path, variant: str, seed: int = 0) -> Path:
    """The bundle of the shipped run of ``variant``: ``<bundles>/<variant>-cpu-s<seed>.tar``."""
    return bundle_path(bundles, RUNS_PREFIX + run_name(variant, seed, SHIPPED_TRAIN_PRESET))


def shipped_variants(bundles: str | Path, seed: int = 0) -> tuple[str, ...]:
    """The stock variants (in :data:`VARIANTS` order) whose seed-``seed`` bundle is in ``bundles``."""
    return tuple(v for v in VARIANTS if shipped_bundle(bundles, v, seed).is_file())


def reproduce_cfg(
    preset: str,
    *,
    seeds: int = 1,
    variants: tuple[str, ...] | None = None,
    device: str = "cpu",
    bundles: str | Path | None = None,
    full_protocol: bool = False,
) -> ReproduceCfg:
    """The pipeline of a preset.

    ``smoke`` exercises every stage in minutes on 2 cores: 2 envs x 25 steps per evaluation rollout, 2 envs x 80
    steps per diagnostic rollout with eps = 0.5 (H_eps = 69 steps instead of 299). Its numbers are not results.
    ``cpu`` and ``paper`` use the paper's protocol: 64 envs x 500 steps, diagnostics 64 envs x 800 steps, eps 0.05.
    ``shipped`` imports the seed-0 ``cpu`` runs from ``bundles`` (default :func:`default_bundles`; every variant
    with a bundle there unless ``variants`` names some) and evaluates them with :data:`SHIPPED_PROTOCOL`, or the
    paper's protocol with ``full_protocol``.

    Raises:
        UnknownNameError: Unknown preset or variant.
        MorficError: Fewer than one seed; for ``shipped``, no bundle folder, no bundles in it, a named variant
            without a bundle, or more than one seed.
    """
    from morfic_cli.errors import UnknownNameError
    from morfic_cli.rl.config import PRESETS

    if preset not in (*PRESETS, SHIPPED):
        raise UnknownNameError("preset", preset, (*PRESETS, SHIPPED))
    for v in variants or ():
        resolve_variant(v)
    if seeds < 1:
        raise MorficError(f"--seeds must be at least 1, got {seeds}.")
    if preset == SHIPPED:
        return _shipped_cfg(seeds, variants, device, Path(bundles) if bundles else default_bundles(), full_protocol)
    base = ReproduceCfg(preset=preset, seeds=seeds, variants=tuple(variants or REPRODUCE_VARIANTS), device=device)
    if preset == "smoke":
        return dataclasses.replace(
            base,
            eval_envs=2,
            eval_steps=25,
            diagnose_envs=2,
            diagnose_steps=80,
            trunc_eps=0.5,
            torch_threads=1,
            critic_study=SMOKE_STUDY,
        )
    return dataclasses.replace(base, critic_study={})


def _shipped_cfg(
    seeds: int, variants: tuple[str, ...] | None, device: str, bundles: Path, full_protocol: bool
) -> ReproduceCfg:
    if seeds != 1:
        raise MorficError("--preset shipped has one seed per variant (seed 0); leave out --seeds.")
    if not bundles.is_dir():
        raise MorficError(
            f"no bundle folder {bundles}: run from a source checkout of morfic (it ships the trained "
            f"runs under artifacts/bundles/), or pass --bundles DIR."
        )
    if variants:
        missing = [str(shipped_bundle(bundles, v)) for v in variants if not shipped_bundle(bundles, v).is_file()]
        if missing:
            raise MorficError(
                f"no shipped bundle {', '.join(missing)}; the shipped variants are "
                f"{', '.join(shipped_variants(bundles)) or 'none'} (or train one: morfic reproduce "
                f"--preset cpu --variants ...)."
            )
    else:
        variants = shipped_variants(bundles)
        if not variants:
            raise MorficError(f"no shipped bundles (<variant>-cpu-s0.tar) in {bundles}; pass --bundles DIR.")
    base = ReproduceCfg(
        preset=SHIPPED_TRAIN_PRESET,
        seeds=1,
        variants=tuple(variants),
        device=device,
        bundles=str(bundles),
        name=SHIPPED,
    )
    return base if full_protocol else dataclasses.replace(base, **SHIPPED_PROTOCOL)


class _Stoppable(Protocol):
    """A training run as the pipeline stops it (``rl.runner.TrainingRun``)."""

    stop_requested: bool


class Progress(Protocol):
    """What the pipeline tells its user: steps starting, advancing and ending."""

    def step_start(self, index: int, total: int, label: str, units: int, unit: str) -> None:
        """Step ``index`` of ``total`` starts; it has ``units`` units of work (iterations, policy steps)."""

    def step_advance(self, completed: int | None = None, advance: int = 0, detail: str = "") -> None:
        """The current step reached ``completed`` units (or moved ``advance`` more)."""

    def step_end(self, result: StepResult) -> None:
        """The current step ended (done, resumed, skipped)."""


class _Silent:
    def step_start(self, index: int, total: int, label: str, units: int, unit: str) -> None:  # noqa: D102
        pass

    def step_advance(self, completed: int | None = None, advance: int = 0, detail: str = "") -> None:  # noqa: D102
        pass

    def step_end(self, result: StepResult) -> None:  # noqa: D102
        pass


#: A step's status when it cannot run (the fixed-rollout analysis without its actor); ``detail`` says why.
NOT_RUN = "not run"
STUDY_LABEL = "diagnoses/critic-study"
"""The critic-study step's label (its ref)."""


@dataclass
class StepResult:
    """What one step did.

    ``status`` is done, resumed (a run continued), skipped (the store had the result), interrupted (training
    stopped at a checkpoint after Ctrl-C) or not run (:data:`NOT_RUN`: it cannot run, ``detail`` says why).
    """

    kind: str
    label: str
    status: str
    id: str | None = None
    ref: str | None = None
    seconds: float = 0.0
    detail: str = ""


@dataclass
class ReproduceResult:
    """Every step's result and the report."""

    steps: list[StepResult] = field(default_factory=list)
    report: ReportResult | None = None
    interrupted: bool = False
    seconds: float = 0.0

    @property
    def work_done(self) -> int:
        """Steps that did work (not skipped)."""
        return sum(s.status not in ("skipped", NOT_RUN) for s in self.steps)


#: Step kinds that ``reproduce --jobs`` runs side by side in worker processes (:meth:`Pipeline.run`).
SIDE_BY_SIDE: tuple[str, ...] = ("eval", "diagnose")

SideBySide = Callable[[list[tuple[str, str]]], list[StepResult]]
"""Runs (kind, label) steps of :data:`SIDE_BY_SIDE` kinds together; their results in the given order."""


def _json(doc: Any) -> Any:
    return json.loads(json.dumps(doc))


#: Config fields that say where a run executed, not what it is; a finished run trained elsewhere still counts.
EXECUTION_FIELDS: tuple[str, ...] = ("env.sim.num_threads", "env.sim.device", "env.sim.backend")


def experiment_config(doc: dict[str, Any]) -> dict[str, Any]:
    """A resolved training config without :data:`EXECUTION_FIELDS` (threads default to the machine's cores)."""
    out = json.loads(json.dumps(doc))
    for dotted in EXECUTION_FIELDS:
        *parents, leaf = dotted.split(".")
        node = out
        for key in parents:
            node = node.get(key, {}) if isinstance(node, dict) else {}
        if isinstance(node, dict):
            node.pop(leaf, None)
    return out


class Pipeline:
    """The steps of one ``reproduce`` over a store. Use :meth:`run`; :meth:`interrupt` handles a Ctrl-C.

    Args:
        store: Artifact store.
        cfg: What to run.
        out: Folder the report's files are written to.
        progress: Progress sink (default: silent).
    """

    def __init__(
        self, store: Store, cfg: ReproduceCfg, out: Path | None = None, progress: Progress | None = None
    ) -> None:
        self.store, self.cfg, self.out = store, cfg, out
        self.progress = progress or _Silent()
        self._training: _Stoppable | None = None
        self._stop = False
        self.report_result: ReportResult | None = None

    # ------------------------------------------------------------------ plan
    def run_specs(self) -> list[tuple[str, int, str]]:
        """(variant, seed, ``runs/NAME``) of every training run, variant-major."""
        return [
            (v, s, RUNS_PREFIX + run_name(v, s, self.cfg.preset))
            for v in self.cfg.variants
            for s in range(self.cfg.seeds)
        ]

    def trains_in_bf16(self) -> bool:
        """True when a run this pipeline has yet to train (not finished in the store) autocasts to bf16."""
        if self.cfg.bundles:
            return False
        return any(
            self.train_cfg(v, s).ppo.use_mixed_precision
            and not (self.store.has_ref(spec) and self.store.read_manifest(spec).meta.get("finished"))
            for v, s, spec in self.run_specs()
        )

    def plan(self) -> list[tuple[str, str, Callable[[], StepResult]]]:
        """Every step as (kind, label, function), in order."""
        runs = self.run_specs()
        steps: list[tuple[str, str, Callable[[], StepResult]]] = []
        for v, s, spec in runs:
            if self.cfg.bundles:
                steps.append(("import", spec, functools.partial(self.import_run, v, spec)))
            else:
                steps.append(("train", spec, functools.partial(self.train, v, s, spec)))
        for _, _, spec in runs:
            steps.append(("eval", spec, functools.partial(self.evaluate, spec)))
        for _, _, spec in runs:
            steps.append(("diagnose", spec, functools.partial(self.diagnose, spec)))
        for robot in self.cfg.fixed_rollout_robots:
            steps.append(("fixed-rollout", robot, functools.partial(self.fixed_rollout, robot)))
        if self.cfg.critic_study is not None or self.shipped_study() is not None:
            steps.append(("critic-study", STUDY_LABEL, self.critic_study))
        steps.append(("compare", "compare-baselines", self.compare))
        steps.append(("report", f"reports/{self.cfg.report_name}", self.report))
        return steps

    # ------------------------------------------------------------------ run
    def run(self, side_by_side: SideBySide | None = None) -> ReproduceResult:
        """Run (or skip) every step in order; after a Ctrl-C (:meth:`interrupt`) stop once training checkpointed.

        Args:
            side_by_side: Runs the steps of :data:`SIDE_BY_SIDE` kinds together, when the first of them comes up,
                and returns their results in plan order (``reproduce --jobs``: :class:`~morfic_cli.cluster.pool.
                JobPool`); None runs every step here, one after another.

        Returns:
            Every step's result; ``interrupted`` when it stopped early (run it again to continue).
        """
        import torch

        result = ReproduceResult()
        start = time.perf_counter()
        threads = torch.get_num_threads()
        if self.cfg.torch_threads:
            torch.set_num_threads(self.cfg.torch_threads)
        plan = self.plan()
        batch = [(kind, label) for kind, label, _ in plan if side_by_side is not None and kind in SIDE_BY_SIDE]
        try:
            for kind, label, fn in plan:
                if (kind, label) in batch:
                    if side_by_side is not None and (kind, label) == batch[0]:
                        result.steps += side_by_side(batch)
                    continue
                t0 = time.perf_counter()
                step = fn()
                step.seconds = time.perf_counter() - t0
                result.steps.append(step)
                self.progress.step_end(step)
                if self._stop:
                    result.interrupted = True
                    break
        finally:
            torch.set_num_threads(threads)
        result.report = self.report_result
        result.seconds = time.perf_counter() - start
        return result

    def interrupt(self) -> bool:
        """Handle a Ctrl-C; True when it is handled gracefully.

        A training step finishes its iteration, checkpoints and the pipeline stops after it (True); any other step
        cannot stop cleanly mid-way (False: the caller aborts, the store stays consistent).
        """
        if self._training is not None and not self._training.stop_requested:
            self._training.stop_requested = True
            self._stop = True
            return True
        return False

    def _start(self, kind: str, label: str, units: int, unit: str) -> None:
        keys = [(k, lab) for k, lab, _ in self.plan()]
        self.progress.step_start(keys.index((kind, label)), len(keys), f"{kind} {label}", units, unit)

    # ------------------------------------------------------------------ steps
    def train_cfg(self, variant: str, seed: int):
        """The training config of a run (preset, variant, seed, then the overrides)."""
        from morfic_cli.rl.config import apply_overrides, preset_cfg

        return apply_overrides(preset_cfg(self.cfg.preset, variant, seed), list(self.cfg.train_overrides))

    def stored_train(self, variant: str, seed: int, spec: str) -> StepResult | None:
        """The skipped result when the store holds ``spec`` finished; None when it must train (or resume).

        The stored config is compared as rebuilt (``train_cfg_from_dict``): a field its morfic did not have reads
        its legacy value, or its default when that is what that morfic did (``env.rand.geometry``).

        Raises:
            MorficError: ``spec`` exists but was trained with another config.
        """
        from morfic_cli.rl.config import train_cfg_from_dict, train_cfg_to_dict

        if not self.store.has_ref(spec):
            return None
        manifest = self.store.read_manifest(spec)
        recorded = train_cfg_to_dict(train_cfg_from_dict(manifest.config))
        if experiment_config(recorded) != experiment_config(train_cfg_to_dict(self.train_cfg(variant, seed))):
            raise MorficError(
                f"{spec} exists in {self.store.root} but was trained with another config than this "
                f"reproduce asks for; use another --store, or move it aside (it stays in the store's history)."
            )
        if manifest.meta.get("finished"):
            return StepResult(
                "train",
                spec,
                "skipped",
                manifest.id,
                spec,
                detail=f"finished at iteration {manifest.meta.get('iteration')}",
            )
        return None

    def train(self, variant: str, seed: int, spec: str) -> StepResult:
        """Train ``spec`` (skip when finished, resume when interrupted)."""
        from morfic_cli.rl.runner import new_run, resume_run

        cfg = self.train_cfg(variant, seed)
        name = run_of(spec)
        self._start("train", spec, cfg.max_iterations, "it")
        status = "done"
        found = self.stored_train(variant, seed, spec)
        if found is not None:
            return found
        if self.store.has_ref(spec):
            run = resume_run(self.store, spec, device=self.cfg.device)
            status = "resumed"
        else:
            run = new_run(self.store, cfg, name, self.cfg.device)
        start_it = run.iteration
        run.progress = lambda row: self.progress.step_advance(completed=int(row["iteration"]))
        self.progress.step_advance(completed=start_it)
        self._training = run
        try:
            last = run.train()
        finally:
            self._training = None
            run.env.close()
        if last is None:  # nothing left to train: mark as skipped
            return StepResult("train", spec, "skipped", self.store.resolve(spec), spec)
        if run.interrupted:
            status = "interrupted"
        detail = f"iterations {start_it}->{last.iteration}"
        return StepResult("train", spec, status, last.id, f"{spec}@{last.version}", detail=detail)

    def import_run(self, variant: str, spec: str) -> StepResult:
        """Import the shipped run ``spec`` from its bundle (skip when the store holds it finished).

        The run is taken as shipped: its config is the one it was trained with (recorded in it), not
        re-checked against today's preset; it must be a finished run of ``variant``.

        Raises:
            MorficError: No bundle, or the bundle (or the store's ``spec``) is not a finished run of ``variant``.
            StoreError: A damaged bundle (nothing imported).
        """
        from morfic_cli.store.transfer import import_tar

        self._start("import", spec, 1, "bundle")
        path = bundle_path(self.cfg.bundles or "", spec)
        status, detail = "skipped", "in the store"
        if not self.store.has_ref(spec):
            if not path.is_file():
                raise MorficError(f"no bundle {path} for {spec}; pass --bundles DIR holding {path.name}.")
            report = import_tar(self.store, path)
            status, detail = "done", f"{path.name}: {report.objects_added} new objects"
        manifest = self.store.read_manifest(spec)
        if (
            manifest.kind != "checkpoint"
            or not manifest.meta.get("finished")
            or manifest.config.get("variant") != variant
        ):
            where = f"{path}" if status == "done" else f"{self.store.root}"
            raise MorficError(
                f"{spec} in {where} is not a finished {variant} run (kind {manifest.kind}, variant "
                f"{manifest.config.get('variant')}, finished {bool(manifest.meta.get('finished'))}); "
                f"use another --store, or re-export the bundle from a finished run."
            )
        self.progress.step_advance(completed=1)
        it = manifest.meta.get("iteration")
        return StepResult("import", spec, status, manifest.id, spec, detail=f"{detail}, iteration {it}")

    def variant_of(self, spec: str) -> str:
        """The variant of run ``spec``: this pipeline's (:meth:`run_specs`), else the one the store's run records.

        Raises:
            MorficError: ``spec`` is neither this pipeline's run nor in the store.
        """
        for variant, _, s in self.run_specs():
            if s == spec:
                return variant
        if not self.store.has_ref(spec):
            raise MorficError(f"{spec} is not a run of this reproduce and not in {self.store.root}.")
        return str(self.store.read_manifest(spec).config["variant"])

    def eval_cfg(self, spec: str):
        """The evaluation config of run ``spec``: the protocol's modes, or (``modes`` None) its variant's."""
        from morfic_cli.evaluation.protocol import EvalCfg

        c = self.cfg
        return EvalCfg(
            robots=c.robots,
            modes=c.modes if c.modes is not None else eval_modes(self.variant_of(spec)),
            command_vx=c.command_vx,
            num_envs=c.eval_envs,
            steps=c.eval_steps,
            seed=0,
            batch_robots=c.batch_robots,
        )

    def stored_eval(self, spec: str, cfg=None) -> StepResult | None:
        """The skipped result when the store holds this evaluation of ``spec``'s checkpoint, else None.

        ``cfg``: another evaluation config than :meth:`eval_cfg` (another command, say); the same by default.
        """
        if not self.store.has_ref(spec):
            return None
        from morfic_cli.evaluation.protocol import eval_config

        config = _json(eval_config(spec, cfg or self.eval_cfg(spec)))
        found = find_manifest(
            self.store, "eval", config, inputs_subset={"checkpoint": self.store.resolve(spec)}, files=("eval.csv",)
        )
        return StepResult("eval", spec, "skipped", found) if found else None

    def evaluate(self, spec: str, cfg=None) -> StepResult:
        """Evaluate a run's checkpoint on every robot, mode and command (skip when stored).

        ``cfg``: as in :meth:`stored_eval`.
        """
        from morfic_cli.evaluation.protocol import evaluate

        cfg = cfg or self.eval_cfg(spec)
        found = self.stored_eval(spec, cfg)
        if found is not None:
            return found
        units = len(cfg.robots) * len(cfg.modes) * len(cfg.command_vx) * cfg.steps
        self._start("eval", spec, units, "steps")
        res = evaluate(
            self.store,
            spec,
            cfg,
            on_rollout_start=lambda r, m, v: self.progress.step_advance(detail=f"{r} {m} {v:g}"),
            on_step=lambda _t: self.progress.step_advance(advance=1),
        )
        return StepResult("eval", spec, "done", res.id, f"{res.ref}@{res.version}")

    def diagnose_cfg(self, robots: tuple[str, ...], command_vx: float = PAPER_COMMAND):
        """The diagnosis config (the paper's: descriptor mode, 2.0 m/s; ``command_vx`` another command).

        With ``batch_robots`` every robot's rollout is its slice of one env of all ``cfg.robots``, in the
        fixed-rollout analysis too (so it reuses the diagnosis's rollouts of its actor).
        """
        from morfic_cli.diagnostics.samples import DiagnoseCfg

        c = self.cfg
        return DiagnoseCfg(
            robots=robots,
            mode="descriptor",
            command_vx=command_vx,
            num_envs=c.diagnose_envs,
            steps=c.diagnose_steps,
            seed=0,
            trunc_eps=c.trunc_eps,
            batch=c.robots if c.batch_robots else (),
        )

    def stored_diagnosis(self, spec: str, cfg=None) -> StepResult | None:
        """The skipped result when the store holds this diagnosis of ``spec``'s checkpoint, else None.

        ``cfg``: another diagnosis config than :meth:`diagnose_cfg` of every robot (another command, say).
        """
        if not self.store.has_ref(spec):
            return None
        from morfic_cli.diagnostics.samples import diagnose_config

        config = _json({"specs": [spec], **diagnose_config(cfg or self.diagnose_cfg(self.cfg.robots))})
        found = find_manifest(
            self.store,
            "diagnosis",
            config,
            inputs_subset={f"checkpoint/{spec}": self.store.resolve(spec)},
            files=("calibration.csv",),
        )
        return StepResult("diagnose", spec, "skipped", found) if found else None

    def diagnose(self, spec: str, cfg=None) -> StepResult:
        """Critic calibration of a run on every robot (skip when stored); ``cfg`` as in :meth:`stored_diagnosis`."""
        from morfic_cli.diagnostics.calibration import diagnose_runs

        cfg = cfg or self.diagnose_cfg(self.cfg.robots)
        found = self.stored_diagnosis(spec, cfg)
        if found is not None:
            return found
        self._start("diagnose", spec, len(cfg.robots) * cfg.steps, "steps")
        trained = None
        if cfg.batch and self.fixed_rollout_reads_tokens() and spec == self.fixed_rollout_models()[0]:
            from morfic_cli.diagnostics.fixed_rollout import recording_tokens
            from morfic_cli.rl.load import load_trained

            trained = [recording_tokens(load_trained(self.store, spec))]  # the fixed-rollout analysis reuses them
        res = diagnose_runs(
            self.store,
            [spec],
            cfg,
            trained=trained,
            on_rollout_start=lambda _r, robot: self.progress.step_advance(detail=robot),
            on_step=lambda _t: self.progress.step_advance(advance=1),
        )
        return StepResult("diagnose", spec, "done", res.id, f"{res.ref}@{res.version}")

    def fixed_rollout_models(self) -> tuple[str, list[str]]:
        """(actor spec, critic specs) of the fixed-rollout analysis: the seed-0 run of ``actor_variant``, always.

        Every critic is scored on that one actor's rollouts (paper Table "causal advantage"), also when
        ``actor_variant`` is not among the variants reproduced (then its run must be in the store already:
        :meth:`fixed_rollout_unavailable`); never another variant's actor in its place. The critics are every run's
        but those :meth:`fixed_rollout_left_out` names.
        """
        runs = self.run_specs()
        actor = RUNS_PREFIX + run_name(self.cfg.actor_variant, 0, self.cfg.preset)
        left_out = self.fixed_rollout_left_out()
        return actor, [spec for _, _, spec in runs if spec not in left_out]

    def fixed_rollout_left_out(self) -> dict[str, str]:
        """The runs whose critic the fixed-rollout analysis leaves out, each with why.

        A critic trained with other returns or inputs than the frozen actor's run cannot be scored on its rollouts
        (:func:`~morfic_cli.diagnostics.fixed_rollout.incompatible`, on the runs' training configs): issue 58's
        runs with the extended descriptor (``env.obs.extended_morphology``). None of the paper's variants is.
        """
        from morfic_cli.diagnostics.fixed_rollout import incompatible

        actor = self.train_cfg(self.cfg.actor_variant, 0)
        left_out: dict[str, str] = {}
        for variant, seed, spec in self.run_specs():
            differ = incompatible(actor, self.train_cfg(variant, seed))
            if differ:
                left_out[spec] = (
                    f"{spec}'s critic is left out of the fixed-rollout analysis: trained with other "
                    f"{', '.join(differ)} than the frozen actor's run, its values read other inputs or predict "
                    "other returns than that actor's rollouts record"
                )
        return left_out

    def fixed_rollout_reads_tokens(self) -> bool:
        """Whether a critic of the fixed-rollout analysis reads URMA's token groups (its actor's rollouts record them).

        Under the batched protocol (``batch_robots``) the actor's diagnosis then records them too, so the analysis
        reuses its rollouts instead of stepping all robots again (the calibration is the same: same physics and
        actor inputs, more groups kept).
        """
        left_out = self.fixed_rollout_left_out()
        return any(
            self.train_cfg(variant, seed).env.obs.body_tokens
            for variant, seed, spec in self.run_specs()
            if spec not in left_out
        )

    def fixed_rollout_unavailable(self) -> str | None:
        """Why the fixed-rollout analysis cannot run, or None.

        Its actor is neither reproduced here nor in the store, or every run's critic is left out
        (:meth:`fixed_rollout_left_out`).
        """
        actor, critics = self.fixed_rollout_models()
        if not critics:
            return "every critic is left out: " + "; ".join(self.fixed_rollout_left_out().values())
        if any(spec == actor for _, _, spec in self.run_specs()) or self.store.has_ref(actor):
            return None
        return (
            f"its frozen actor {actor} is neither reproduced here nor in the store; add "
            f"{self.cfg.actor_variant} to --variants or import its run's bundle"
        )

    def stored_fixed_rollout(self, robot: str, command_vx: float = PAPER_COMMAND) -> StepResult | None:
        """The skipped result when the store holds this fixed-rollout analysis (robot, command), else None."""
        actor, critics = self.fixed_rollout_models()
        if not all(self.store.has_ref(spec) for spec in (actor, *critics)):
            return None
        from morfic_cli.diagnostics.samples import diagnose_config

        cfg = self.diagnose_cfg((robot,), command_vx)
        config = {"robot": robot, "actor": actor, "critics": critics, **diagnose_config(cfg)}
        config.pop("robots")
        subset = {"actor": self.store.resolve(actor), **{f"critic/{c}": self.store.resolve(c) for c in critics}}
        found = find_manifest(
            self.store, "diagnosis", _json(config), inputs_subset=subset, files=("fixed_rollout.csv",)
        )
        return StepResult("fixed-rollout", robot, "skipped", found) if found else None

    def fixed_rollout(self, robot: str, *, reuse: bool = True, command_vx: float = PAPER_COMMAND) -> StepResult:
        """One frozen actor (the seed-0 run of ``actor_variant``), every run's critic, on ``robot`` at ``command_vx``.

        With ``reuse`` False the critics are scored again even where the store holds the analysis (on the rollout
        this store holds or collects, which may be other samples than the stored analysis's).
        """
        from morfic_cli.diagnostics.fixed_rollout import fixed_rollout, load_models

        actor, critics = self.fixed_rollout_models()
        cfg = self.diagnose_cfg((robot,), command_vx)
        found = self.stored_fixed_rollout(robot, command_vx) if reuse else None
        if found is not None:
            return found
        why = self.fixed_rollout_unavailable()
        if why is not None:
            return StepResult("fixed-rollout", robot, NOT_RUN, detail=why)
        self._start("fixed-rollout", robot, cfg.steps, "steps")
        models = load_models(self.store, actor, critics, cfg)
        res = fixed_rollout(self.store, robot, models, cfg, on_step=lambda _t: self.progress.step_advance(advance=1))
        left_out = self.fixed_rollout_left_out()
        detail = f"left out (other inputs or returns): {', '.join(left_out)}" if left_out else ""
        return StepResult("fixed-rollout", robot, "done", res.id, f"{res.ref}@{res.version}", detail=detail)

    def study_actors(self) -> list[str]:
        """The critic study's frozen actors, those this pipeline trains or the store holds.

        They are :data:`~morfic_cli.diagnostics.critic_study.ACTOR_RUNS` under this preset's run names.
        """
        from morfic_cli.diagnostics.critic_study import ACTOR_RUNS

        mine = {spec for _, _, spec in self.run_specs()}
        specs = [RUNS_PREFIX + run_name(v, s, self.cfg.preset) for v, s in ACTOR_RUNS]
        return [s for s in specs if s in mine or self.store.has_ref(s)]

    def study_cfg(self):
        """The critic study's :class:`~morfic_cli.diagnostics.critic_study.StudyCfg` (None: no study)."""
        from morfic_cli.diagnostics.critic_study import StudyCfg

        if self.cfg.critic_study is None:
            return None
        return StudyCfg(**{"robots": self.cfg.robots, "actors": tuple(self.study_actors()), **self.cfg.critic_study})

    def shipped_study(self) -> Path | None:
        """The shipped critic-study bundle (``shipped`` preset only), when the bundle folder has one."""
        if not self.cfg.bundles:
            return None
        path = Path(self.cfg.bundles) / SHIPPED_STUDY_BUNDLE
        return path if path.is_file() else None

    def critic_study(self) -> StepResult:
        """Every critic fitted from scratch on each study actor's data (skip when stored; shipped: import)."""
        from morfic_cli.diagnostics.critic_study import STUDY_REF, StudyProgress, run_study, study_config

        shipped = self.shipped_study()
        if shipped is not None:
            from morfic_cli.store.transfer import import_tar

            self._start("critic-study", STUDY_LABEL, 1, "bundle")
            report = import_tar(self.store, shipped)
            status = "skipped" if all(v == "unchanged" for v in report.refs.values()) else "done"  # a rerun: as held
            found = self.store.resolve(STUDY_REF) if self.store.has_ref(STUDY_REF) else None
            return StepResult("critic-study", STUDY_LABEL, status, found, STUDY_REF, detail=f"imported {shipped.name}")
        cfg = self.study_cfg()
        if not cfg.actors:
            return StepResult(
                "critic-study",
                STUDY_LABEL,
                NOT_RUN,
                detail="none of its actors (film seeds 0-2, actor-only and concat seed 0) is reproduced "
                "here or in the store",
            )
        found = find_manifest(
            self.store,
            "diagnosis",
            _json(study_config(cfg)),
            inputs_subset={f"actor/{run_of(a)}": self.store.resolve(a) for a in cfg.actors},
            files=("critic_study.csv",),
        )
        if found:
            return StepResult("critic-study", STUDY_LABEL, "skipped", found)
        self._start("critic-study", STUDY_LABEL, 1, "study")
        progress = StudyProgress(phase=lambda label, _total: self.progress.step_advance(detail=label))
        res = run_study(self.store, cfg, progress=progress)
        return StepResult("critic-study", STUDY_LABEL, "done", res.id, f"{STUDY_REF}@{res.version}")

    def compare(self) -> StepResult:
        """The comparison tables with the paper's columns (skip when the same one is stored)."""
        from morfic_cli.report.compare import compare_tables, store_comparison
        from morfic_cli.report.gather import gather, resolve_runs

        specs = [spec for _, _, spec in self.run_specs()]
        self._start("compare", "compare-baselines", 1, "table")
        data = gather(self.store, resolve_runs(self.store, specs), curves=False)
        written, reused = store_comparison(self.store, data, compare_tables(data, with_paper=True), True)
        return StepResult(
            "compare",
            "compare-baselines",
            "skipped" if reused else "done",
            written.id,
            f"{written.ref}@{written.version}",
        )

    def report(self) -> StepResult:
        """The report (LaTeX, Markdown, figures, the paper's tables beside ours), copied to ``out``."""
        specs = tuple(spec for _, _, spec in self.run_specs())
        name = self.cfg.report_name
        cfg = ReportCfg(
            runs=specs,
            latex=True,
            markdown=True,
            figures=True,
            with_paper=True,
            name=name,
            title=f"MorFiC reproduction report ({name} preset)",
        )
        self._start("report", f"reports/{name}", 1, "report")
        res = build_report(self.store, cfg, out=self.out, on_stage=lambda s: self.progress.step_advance(detail=s))
        self.report_result = res
        return StepResult("report", res.ref, "skipped" if res.reused else "done", res.id, f"{res.ref}@{res.version}")
