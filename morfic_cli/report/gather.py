"""Read what the store holds for a set of runs: checkpoints, evaluations, diagnoses, curves; with provenance.

Nothing here trains or simulates. A run is a ref ``runs/NAME`` (or a checkpoint id) and stands for its checkpoint;
the results of that checkpoint are found by content, not by name: every ``eval`` manifest whose input
``checkpoint`` is it, every ``diagnosis`` whose ``calibration.csv`` rows or fixed-rollout critics name it. Where
several artifacts hold the same row (the same robot, mode and command of a checkpoint; of a fixed-rollout row, the
same robot, frozen actor, critic, mode and command), the one measured on the most samples (envs x steps) wins, and
among equals the newest: a quick ``morfic eval --envs 2`` never hides the protocol's 64 x 500, and a run's diagnosis
at 1.0 m/s never hides its diagnosis at 2.0 m/s (a row that records no command is at the paper's 2.0 m/s,
:func:`~morfic_cli.report.claims.row_command`). Each artifact a row came from is recorded in
:attr:`StoreData.provenance`.
"""

from __future__ import annotations

import io
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from morfic_cli.errors import MorficError
from morfic_cli.report.claims import row_command
from morfic_cli.runs import RUNS_PREFIX, run_of
from morfic_cli.store import Store


@dataclass(frozen=True)
class RunInfo:
    """A training run as the store records it (the checkpoint manifest's meta and config).

    Attributes:
        spec: How it was named (``runs/film-cpu-s0``, or an id).
        name: Run name (``film-cpu-s0``).
        checkpoint: Checkpoint manifest id.
        variant: Conditioning variant.
        seed: Training seed.
        preset: Budget preset.
        iteration: PPO iterations done.
        max_iterations: Iterations asked for.
        env_steps: Transitions collected.
        wall_time_s: Training wall time (s).
        device: cpu or cuda.
        finished: Reached max_iterations.
        created: Manifest creation time.
        machine: The machine it trained on, where the checkpoint's meta records one (``machine`` or ``host``), else
            "".
    """

    spec: str
    name: str
    checkpoint: str
    variant: str
    seed: int
    preset: str
    iteration: int
    max_iterations: int
    env_steps: int
    wall_time_s: float
    device: str
    finished: bool
    created: str
    machine: str = ""


@dataclass(frozen=True)
class Provenance:
    """One artifact a report or table was built from: id, kind, a ref naming it (if any) and what it gave."""

    id: str
    kind: str
    ref: str | None
    role: str


@dataclass
class StoreData:
    """Everything a comparison or report reads, for a set of runs.

    Attributes:
        runs: The runs, in the order given (or by name).
        evals: eval.csv rows (+ ``run``, ``variant``, ``seed``, ``preset``, ``checkpoint``, ``artifact``).
        terminations: The termination counts of the kept eval rows, from the same artifacts: ``terminations.csv``
            lines (``robot``, ``mode``, ``command_vx``, ``term``, ``envs``) with the same added keys; none for a row
            whose eval predates the counts (:func:`~morfic_cli.evaluation.terminations.read_terminations`).
        calibration: calibration.csv rows (+ the same keys).
        fixed: fixed_rollout.csv rows of critics among the runs and their MC reference rows (+ ``artifact``).
        study: critic_study.csv rows of the newest critic study one of whose frozen actors is one of the runs
            (+ ``artifact``); ``study_meta`` is that manifest's meta (actor, seconds).
        curves: Run name -> training-curve rows of its checkpoint.
        params: Checkpoint id -> (actor, critic) parameter counts, ``sum(p.numel())`` of the models its stored config
            builds (:func:`parameter_counts`; stock variants only).
        provenance: Every artifact used.
    """

    runs: list[RunInfo]
    evals: list[dict[str, Any]] = field(default_factory=list)
    terminations: list[dict[str, Any]] = field(default_factory=list)
    calibration: list[dict[str, Any]] = field(default_factory=list)
    fixed: list[dict[str, Any]] = field(default_factory=list)
    study: list[dict[str, Any]] = field(default_factory=list)
    study_meta: dict[str, Any] = field(default_factory=dict)
    curves: dict[str, list[dict[str, float]]] = field(default_factory=dict)
    params: dict[str, tuple[int, int]] = field(default_factory=dict)
    provenance: list[Provenance] = field(default_factory=list)

    def input_ids(self) -> dict[str, str]:
        """Provenance as manifest ``inputs``: role -> id."""
        return {p.role: p.id for p in self.provenance}


def run_info(store: Store, spec: str) -> RunInfo:
    """The run a spec names (``runs/NAME`` = its current checkpoint; ``NAME`` alone is tried as ``runs/NAME``).

    Raises:
        ArtifactNotFoundError: Nothing by that name.
        MorficError: It is not a training checkpoint.
    """
    if not spec.startswith(RUNS_PREFIX) and "@" not in spec and store.has_ref(RUNS_PREFIX + spec):
        spec = RUNS_PREFIX + spec
    manifest = store.read_manifest(spec)
    if manifest.kind != "checkpoint" or "model.pt" not in manifest.files:
        raise MorficError(
            f"'{spec}' is a {manifest.kind} artifact, not a training run; pass run refs such as "
            "runs/film-cpu-s0 (see `morfic store ls --kind checkpoint`)."
        )
    meta, cfg = manifest.meta, manifest.config
    name = run_of(spec, meta)
    return RunInfo(
        spec=spec,
        name=str(name),
        checkpoint=manifest.id,
        variant=str(meta.get("variant") or cfg.get("variant")),
        seed=int(meta.get("seed", cfg.get("seed", 0))),
        preset=str(meta.get("preset") or cfg.get("preset") or "?"),
        iteration=int(meta.get("iteration", 0)),
        max_iterations=int(meta.get("max_iterations", 0)),
        env_steps=int(meta.get("env_steps", 0)),
        wall_time_s=float(meta.get("wall_time_s", 0.0)),
        device=str(meta.get("device", "cpu")),
        finished=bool(meta.get("finished", False)),
        created=manifest.created,
        machine=str(meta.get("machine") or meta.get("host") or ""),
    )


def all_runs(store: Store) -> list[str]:
    """Every ``runs/NAME`` ref whose current version is a training checkpoint, sorted."""
    out = []
    for name in store.list_refs():
        if not name.startswith(RUNS_PREFIX):
            continue
        manifest = store.read_manifest(name)
        if manifest.kind == "checkpoint" and "model.pt" in manifest.files:
            out.append(name)
    return out


def resolve_runs(store: Store, specs: Sequence[str] | None) -> list[RunInfo]:
    """The runs named (none: every run in the store), each checkpoint once.

    Raises:
        MorficError: No runs at all, or a spec that is not a run.
    """
    names = list(specs) if specs else all_runs(store)
    if not names:
        raise MorficError(
            f"no training runs in store {store.root}; train some (`morfic train`, or `morfic reproduce "
            "--preset smoke`) or pass --store."
        )
    runs, seen = [], set()
    for spec in names:
        info = run_info(store, spec)
        if info.checkpoint not in seen:
            seen.add(info.checkpoint)
            runs.append(info)
    return runs


def filter_presets(runs: Sequence[RunInfo], presets: Sequence[str]) -> list[RunInfo]:
    """The runs trained with one of ``presets`` (the preset in each checkpoint's meta / config); none: all.

    Raises:
        MorficError: No run has any of the presets (the message lists the presets the runs have).
    """
    if not presets:
        return list(runs)
    kept = [r for r in runs if r.preset in presets]
    if not kept:
        have = ", ".join(
            f"{p} ({n} run{'s' if n != 1 else ''})" for p, n in sorted(Counter(r.preset for r in runs).items())
        )
        raise MorficError(
            f"no run has preset {' or '.join(presets)}; the runs here have: {have}. Pass one of "
            "those to --preset, or leave --preset out for every run."
        )
    return kept


def read_csv_rows(data: bytes) -> list[dict[str, Any]]:
    """CSV bytes -> rows (pandas; empty cells become None)."""
    import pandas as pd

    if not data.strip():
        return []
    frame = pd.read_csv(io.BytesIO(data))
    rows = frame.to_dict("records")
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()} for r in rows]


def ref_labels(store: Store) -> dict[str, str]:
    """Manifest id -> a ref naming it, for provenance listings: a current ref first, else ``name@N``."""
    current: dict[str, str] = {}
    old: dict[str, str] = {}
    for name in store.list_refs():
        try:
            history = store.ref_history(name)
        except MorficError:
            continue
        if history:
            current.setdefault(history[-1].id, name)
        for entry in reversed(history[:-1]):
            old.setdefault(entry.id, f"{name}@{entry.version}")
    return {**old, **current}


def _keep(table: dict[tuple, dict[str, Any]], key: tuple, row: dict[str, Any]) -> None:
    """Put ``row`` under ``key`` unless a row measured on more samples is there (rows come oldest first)."""

    def size(r: dict[str, Any]) -> float:
        try:
            return float(r.get("num_envs") or 0) * float(r.get("steps") or 0)
        except (TypeError, ValueError):
            return 0.0

    if key not in table or size(row) >= size(table[key]):
        table[key] = row


def _run_keys(run: RunInfo) -> dict[str, Any]:
    return {
        "run": run.name,
        "variant": run.variant,
        "seed": run.seed,
        "preset": run.preset,
        "checkpoint": run.checkpoint,
    }


def parameter_counts(store: Store, runs: Sequence[RunInfo]) -> dict[str, tuple[int, int]]:
    """Checkpoint id -> (actor, critic) parameter counts of each run of a stock variant.

    Each count is ``sum(p.numel() for p in model.parameters())`` of the model its stored config builds
    (:func:`~morfic_cli.rl.build.build_models`; a parameter the two share, e.g. the morphology encoder, counts in
    both). A user variant's run is left out (counting would import its code), as is a run whose stored config this
    morfic cannot read. One build per distinct config: the seeds of a variant share it.
    """
    import json

    from morfic_cli.rl.variants import STOCK

    stock = [r for r in runs if r.variant in STOCK]
    if not stock:
        return {}
    from morfic_cli.rl.build import build_models
    from morfic_cli.validation import check_stored_cfg

    out: dict[str, tuple[int, int]] = {}
    built: dict[str, tuple[int, int]] = {}
    for run in stock:
        doc = store.read_manifest(run.checkpoint).config
        key = json.dumps({k: doc.get(k) for k in ("variant", "model", "env")}, sort_keys=True, default=str)
        if key not in built:
            try:
                actor, critic = build_models(check_stored_cfg(doc, run.spec))
            except MorficError:
                continue
            built[key] = (sum(p.numel() for p in actor.parameters()), sum(p.numel() for p in critic.parameters()))
        out[run.checkpoint] = built[key]
    return out


def gather(store: Store, runs: Sequence[RunInfo], *, curves: bool = True) -> StoreData:
    """Collect every stored result of ``runs`` (see the module docstring for the rules)."""
    from morfic_cli.evaluation.terminations import read_terminations

    data = StoreData(runs=list(runs))
    by_ckpt = {r.checkpoint: r for r in runs}
    labels = ref_labels(store)
    used: dict[str, Provenance] = {}

    def use(oid: str, kind: str, role: str) -> None:
        used.setdefault(oid, Provenance(oid, kind, labels.get(oid), role))

    for run in runs:
        use(run.checkpoint, "checkpoint", f"checkpoint/{run.name}")

    evals: dict[tuple, dict[str, Any]] = {}
    ended: dict[tuple, dict[str, int]] = {}  # (eval artifact, robot, mode, command) -> term -> envs
    calib: dict[tuple, dict[str, Any]] = {}
    fixed: dict[tuple, dict[str, Any]] = {}
    for kind in ("eval", "diagnosis"):
        for item in store.ls(kind):  # oldest first: newer rows overwrite older ones
            manifest = store.read_manifest(item["id"])
            if kind == "eval" and "eval.csv" in manifest.files:
                owner = by_ckpt.get(manifest.inputs.get("checkpoint", ""))
                if owner is None:
                    continue
                for line in read_terminations(store, manifest.id):
                    where = (manifest.id, line["robot"], line["mode"], line["command_vx"])
                    ended.setdefault(where, {})[line["term"]] = line["envs"]
                for row in read_csv_rows(store.read_file(manifest.id, "eval.csv")):
                    key = (owner.checkpoint, row["robot"], row["mode"], float(row["command_vx"]))
                    _keep(evals, key, {**row, **_run_keys(owner), "artifact": manifest.id})
            elif kind == "diagnosis" and "calibration.csv" in manifest.files:
                for row in read_csv_rows(store.read_file(manifest.id, "calibration.csv")):
                    owner = by_ckpt.get(str(row.get("checkpoint")))
                    if owner is None:
                        continue
                    key = (owner.checkpoint, row["robot"], row["mode"], row_command(row))
                    _keep(calib, key, {**row, **_run_keys(owner), "artifact": manifest.id})
            elif kind == "diagnosis" and "critic_study.csv" in manifest.files:
                actors = [v for k, v in manifest.inputs.items() if k == "actor" or k.startswith("actor/")]
                if any(a in by_ckpt for a in actors):  # oldest first: the newest study wins
                    from morfic_cli.diagnostics.critic_study import check_layout

                    check_layout(manifest.config)  # a study laid out by a newer morfic is refused, not misread
                    data.study = [
                        {**row, "artifact": manifest.id}
                        for row in read_csv_rows(store.read_file(manifest.id, "critic_study.csv"))
                    ]
                    data.study_meta = dict(manifest.meta)
            elif kind == "diagnosis" and "fixed_rollout.csv" in manifest.files:
                rows = read_csv_rows(store.read_file(manifest.id, "fixed_rollout.csv"))
                actor = manifest.inputs.get("actor")
                mine = [r for r in rows if str(r.get("checkpoint")) in by_ckpt]
                if not mine and actor not in by_ckpt:
                    continue
                for row in rows:
                    critic = str(row.get("checkpoint")) if row.get("checkpoint") else "mc"
                    if critic != "mc" and critic not in by_ckpt:
                        continue
                    fixed_key = (row["robot"], actor, critic, row["mode"], row_command(row))
                    extra = _run_keys(by_ckpt[critic]) if critic != "mc" else {"run": "MC", "variant": "mc"}
                    _keep(fixed, fixed_key, {**row, **extra, "actor_checkpoint": actor, "artifact": manifest.id})

    for kept, kind, role in (
        (evals, "eval", "eval"),
        (calib, "diagnosis", "calibration"),
        (fixed, "diagnosis", "fixed-rollout"),
    ):
        for row in kept.values():
            use(row["artifact"], kind, f"{role}/{row['artifact'][:12]}")
    if data.study:
        use(data.study[0]["artifact"], "diagnosis", f"critic-study/{data.study[0]['artifact'][:12]}")
    data.evals = list(evals.values())
    for row in data.evals:  # the counts of the kept rows only, from the artifact each row came from
        where = (row["artifact"], row["robot"], row["mode"], float(row["command_vx"]))
        keys = {k: row[k] for k in ("run", "variant", "seed", "preset", "checkpoint", "artifact")}
        data.terminations += [
            {**keys, "robot": where[1], "mode": where[2], "command_vx": where[3], "term": term, "envs": n}
            for term, n in ended.get(where, {}).items()
        ]
    data.calibration = list(calib.values())
    data.fixed = list(fixed.values())
    if curves:
        from morfic_cli.recording.curves import read_curve_csv

        for run in runs:
            manifest = store.read_manifest(run.checkpoint)
            if "curve.csv" in manifest.files and "curve.csv" not in store.omitted_files(manifest):
                data.curves[run.name] = read_curve_csv(store.read_file(run.checkpoint, "curve.csv"))
    data.params = parameter_counts(store, runs)
    data.provenance = list(used.values())
    return data
