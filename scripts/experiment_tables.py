"""Copy one experiment run's result tables out of the store into docs/results/, with the ids they come from.

Writes, for run RUN (its results as `morfic reproduce --preset cpu` stored them, found as the pipeline finds them,
so a table is never another run's):

- ``<out>/RUN-eval.csv`` and ``<out>/RUN-calibration.csv``: the eval's and the diagnosis's files, verbatim;
- ``<out>/RUN-eval-1.0.csv``: the eval at 1.0 m/s, the trained regime (:func:`trained_regime_cfg`: 64 envs x 500
  steps, as :func:`trained_regime_command`), verbatim;
- ``<out>/RUN-terminations.csv`` and ``<out>/RUN-terminations-1.0.csv``: the two evals' termination counts (their
  ``terminations.csv``, verbatim: docs/eval.md, "Termination counts"), where the eval recorded them
  (:func:`write_terminations`; an eval made before the counts were gives no file);
- ``<out>/RUN-eval-1.0-full.csv`` and ``<out>/RUN-terminations-1.0-full.csv``: for a run of issue 58's reference
  variant (film), the goal's extra eval (:func:`goal_eval_cfg`: every robot in full mode at 1.0 m/s, 64 envs x 500
  steps, the eval ``morfic eval RUN --command-vx 1.0 --mode full`` makes), so Go2, Go1 and A1 can be compared with
  film in the goal's mode (``morfic_cli.report.goal.goal_evals`` says which a variant needs; its other evals, and
  so their ids, are unchanged); left out, with a note, when the store lacks it (``--run-missing`` or
  ``--goal-evals-only`` makes it from the run's weights);
- ``<out>/RUN-calibration-1.0.csv``: the critic's diagnosis at 1.0 m/s (:func:`trained_regime_diagnosis`: the
  paper's protocol at that command), verbatim, when the store holds it or the run's weights to make it (a run
  imported from a results-only bundle has none: the file is left out, with a note);
- ``<out>/fixed-rollout-<robot>.csv``: RUN's critic row (and the MC reference row) of the fixed-rollout analysis
  on each robot, the frozen film actor's rollout, merged with the rows of the critics scored before, each row with
  the content id of the samples it was scored on (``samples``). The first samples are the reference
  (``<out>/fixed-rollout-<robot>.json``); a store that lacks them (a results-only bundle leaves rollout logs out, and
  another CPU does not reproduce them bit for bit) scores on a new rollout, whose rows go in beside the reference
  rows (:func:`merge_fixed_rows`). A critic that reads other inputs than the frozen actor's run (issue 58's extended
  descriptor) is left out, with a note (``Pipeline.fixed_rollout_left_out``), at both commands;
- ``<out>/fixed-rollout-1.0-<robot>.csv``: the same at 1.0 m/s (:func:`fixed_rollout_path`: the frozen film actor's
  rollout at the trained regime's command), when the store holds that analysis or both runs' weights to make it (a
  run imported from a results-only bundle has none: left out, with a note);
- ``<out>/RUN-curve.csv``: the training curve's main columns (:data:`CURVE_COLUMNS`);
- ``<out>/RUN-artifacts.json``: the ids of the checkpoint, eval, 1.0 m/s eval (``eval-1.0``), the goal's extra eval
  (``eval-1.0-full``, film only), diagnosis, 1.0 m/s diagnosis (``diagnosis-1.0``) and fixed-rollout analyses
  (``fixed_rollout``, at 1.0 m/s ``fixed_rollout-1.0``).

Each eval holds the modes of RUN's variant (:func:`morfic_cli.rl.variants.eval_modes`; its ``mode`` column tells
them apart): the paper's variants descriptor and full mode, at 1.0 m/s descriptor mode alone; the external baselines
both modes at 1.0 m/s too; issue 58's variants (table ``actuation``) descriptor, full and actuation-matched mode at
every command.

With ``--run-missing`` the run is first evaluated (at 2.0/2.5 and at 1.0 m/s), diagnosed (at 2.0 and 1.0 m/s) and
its critic scored in the fixed-rollout analysis (at 2.0 and, with both runs' weights at hand, 1.0 m/s), each step
with the paper's protocol (``morfic reproduce --preset cpu``'s configs) and skipped when the store holds it: the
experiment queue's evaluation of a run, without re-evaluating the variant's other seeds. With
``--fixed-rollout-only`` only the fixed-rollout rows are written (the analysis run first when the store lacks it);
with ``--diagnosis-1.0-only`` only the 1.0 m/s diagnosis (run first when the store lacks it and holds the weights),
with ``--goal-evals-only`` only the goal's extra evals (likewise; an Error for a variant that needs none),
with ``--fixed-rollout-1.0-only`` only the 1.0 m/s fixed-rollout rows (likewise), for a run whose other tables are
in ``--out`` already.
When RUN's critic had to be scored on other samples than the reference (:func:`merge_fixed_rows`), ``--run-missing``
also scores every seed-0 critic whose weights the store holds on those samples (:func:`seed0_to_rescore`), which
measures what the other samples change.

Usage: python scripts/experiment_tables.py RUN_NAME [--out docs/results] [--store STORE] [--run-missing]
       [--fixed-rollout-only [--rescore] | --fixed-rollout-1.0-only [--rescore] | --diagnosis-1.0-only
        | --goal-evals-only]
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
import time
from pathlib import Path

from morfic_cli.report.claims import PAPER_COMMAND, TRAINED_COMMAND, command_suffix


def fixed_rollout_path(out: Path, robot: str, command_vx: float = PAPER_COMMAND) -> Path:
    """``out/fixed-rollout-<robot>.csv`` (the paper's 2.0 m/s), ``out/fixed-rollout-1.0-<robot>.csv`` at 1.0 m/s."""
    return out / f"fixed-rollout{command_suffix(command_vx)}-{robot}.csv"


def fixed_rollout_key(command_vx: float = PAPER_COMMAND) -> str:
    """The ``<run>-artifacts.json`` key of its fixed-rollout analyses: ``fixed_rollout``, ``fixed_rollout-1.0``."""
    return f"fixed_rollout{command_suffix(command_vx)}"


def merge_fixed_rows(
    path: Path,
    new_rows: list[dict[str, str]],
    columns: list[str],
    samples: str,
    same_weights: frozenset[str] = frozenset(),
) -> list[dict[str, str]]:
    """``path``'s rows with ``new_rows`` merged in, one row per (critic, samples); MC rows first.

    ``samples`` is the content id of the new rows' rollout samples (its ``obs.npz``). A rollout's manifest id (the
    ``rollout`` column) differs between stores (it hashes its creation time), its samples' content id does not when
    the frozen actor's rollout is collected again on the same kind of CPU; another CPU's float rounding gives other
    samples. The first samples of ``path`` are the reference (the sidecar ``<path>.json``: ``samples``, and the
    rollout manifests that held them); rows on other samples are kept beside them (``other_samples``), so a critic
    scored on both measures what the samples change, and ``results_tables.load_fixed`` reads one row per critic,
    the reference row where there is one. A critic's new row on the same samples replaces its old one.

    A run retrained under its old name (its weights lost) is another critic unless its weights are the same bytes:
    a critic's old rows whose ``checkpoint`` is neither a new row's nor in ``same_weights`` (checkpoint ids known to
    hold the new checkpoint's weights) are dropped, on every samples, so no table reads a lost run's row as the
    retrained run's.
    """
    side = path.with_suffix(".json")
    old = list(csv.DictReader(path.open())) if path.is_file() else []
    known = json.loads(side.read_text()) if side.is_file() else {"samples": samples, "rollouts": []}
    for r in old:  # rows written before the samples column: the reference samples
        r["samples"] = r.get("samples") or known["samples"]
    new_rows = [{**r, "samples": samples} for r in new_rows]
    if samples == known["samples"]:
        known["rollouts"] = sorted({*known["rollouts"], *(r["rollout"] for r in new_rows)})
    else:
        others = known.setdefault("other_samples", {})
        others[samples] = sorted({*others.get(samples, []), *(r["rollout"] for r in new_rows)})
    side.write_text(json.dumps(known, indent=1) + "\n")
    kept = {r["critic"]: {r.get("checkpoint", ""), *same_weights} for r in new_rows if r["critic"] != "MC"}
    old = [r for r in old if r["critic"] not in kept or r.get("checkpoint", "") in kept[r["critic"]]]
    merged = {(r["critic"], r["samples"]): r for r in old}
    merged.update({(r["critic"], r["samples"]): r for r in new_rows})
    order = [known["samples"], *known.get("other_samples", {})]
    rows = sorted(merged.values(), key=lambda r: (order.index(r["samples"]), r["critic"] != "MC"))
    return [{c: r.get(c, "") for c in columns} for r in rows]


#: The training-curve columns kept in ``<run>-curve.csv`` (the store's curve.csv has ~80 columns, 1.2 MB a run).
CURVE_COLUMNS = [
    "iteration",
    "env_steps",
    "wall_time_s",
    "mean_reward",
    "episode_length_s",
    "explained_variance",
    "tracking.vx_error",
    "curriculum.vx_max",
    "action_std",
]


def curve_rows(curve_csv: str) -> list[dict[str, str]]:
    """The :data:`CURVE_COLUMNS` of a run's curve.csv, numbers to 5 significant digits."""

    def short(v: str) -> str:
        try:
            return f"{float(v):.5g}"
        except ValueError:
            return v

    return [{c: short(r.get(c, "")) for c in CURVE_COLUMNS} for r in csv.DictReader(io.StringIO(curve_csv))]


def write_csv(path: Path, rows: list[dict[str, str]], columns: list[str]) -> None:
    """``rows`` as CSV with ``columns``."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.write_text(buf.getvalue())


def terminations_path(out: Path, run: str, command_vx: float = PAPER_COMMAND) -> Path:
    """``out/RUN-terminations.csv`` (the 2.0/2.5 m/s eval), ``out/RUN-terminations-1.0.csv`` (the 1.0 m/s eval)."""
    return out / f"{run}-terminations{command_suffix(command_vx)}.csv"


def write_terminations(store, eval_id: str, path: Path) -> bool:
    """Write the eval's ``terminations.csv`` verbatim to ``path`` when it records counts; whether it did.

    An eval made before the counts were recorded (or imported without the file) writes nothing and removes a
    ``path`` left from another eval, so no run's counts are another eval's.
    """
    from morfic_cli.evaluation.terminations import TERMINATIONS_CSV, read_terminations

    if not read_terminations(store, eval_id):
        path.unlink(missing_ok=True)
        return False
    path.write_bytes(store.read_file(eval_id, TERMINATIONS_CSV))
    print(f"{path} (termination counts, artifact {eval_id[:12]})")
    return True


def one_run_pipeline(store, variant: str, seed: int, spec: str):
    """``morfic reproduce --preset cpu``'s pipeline restricted to the one run ``spec`` (its steps' configs unchanged).

    Its fixed-rollout analysis scores this run's critic alone on the frozen film actor's rollouts (reused from the
    store, so every critic of a robot's table is scored on the same samples).
    """
    from morfic_cli.pipeline import Pipeline, reproduce_cfg

    class OneRun(Pipeline):
        def run_specs(self) -> list[tuple[str, int, str]]:
            return [(variant, seed, spec)]

    return OneRun(store, reproduce_cfg("cpu", variants=(variant,), seeds=seed + 1))


def trained_regime_cfg(variant: str):
    """The 1.0 m/s evaluation of a run of ``variant`` (``morfic eval RUN --command-vx 1.0 [--mode ...]``).

    The paper's 64 envs x 500 steps, every robot in the CLI's order (``--robots all``), not batched, in the variant's
    modes at 1.0 m/s (:func:`~morfic_cli.rl.variants.eval_modes`): for the paper's variants descriptor mode alone,
    the config (and so the content address) the seed-0 runs' ``eval-1.0`` ids were made with.
    """
    from morfic_cli.evaluation.protocol import EvalCfg
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.rl.variants import eval_modes

    return EvalCfg(
        robots=tuple(parse_robot_list("all")),
        modes=eval_modes(variant, trained_regime=True),
        command_vx=(TRAINED_COMMAND,),
    )


def trained_regime_command(spec: str, modes: tuple[str, ...]) -> str | None:
    """The ``morfic eval`` command that makes :func:`trained_regime_cfg`'s eval of ``spec`` in ``modes``.

    None for modes that no one ``--mode`` choice runs (all three: only ``--run-missing`` makes that eval).
    """
    flag = {("descriptor",): "", ("descriptor", "full"): " --mode both"}.get(modes)
    if flag is None and len(modes) == 1:
        flag = f" --mode {modes[0]}"
    return None if flag is None else f"morfic eval {spec} --command-vx 1.0{flag}"


def trained_regime_eval(pipe, spec: str, run_missing: bool) -> str | None:
    """The id of the stored 1.0 m/s eval of ``spec``'s checkpoint (:func:`trained_regime_cfg` of its variant).

    Run first when ``run_missing`` and the store lacks it; None when it lacks it otherwise.
    """
    cfg = trained_regime_cfg(pipe.variant_of(spec))
    step = pipe.stored_eval(spec, cfg)
    if step is None and run_missing:
        start = time.monotonic()
        step = pipe.evaluate(spec, cfg)
        print(f"eval {spec} at 1.0 m/s: done in {time.monotonic() - start:.0f} s", file=sys.stderr)
    return step.id if step else None


def goal_eval_cfg(command_vx: float):
    """The goal's extra eval of a run at ``command_vx`` (:func:`morfic_cli.report.goal.goal_evals`).

    Every robot in the CLI's order, the goal's mode alone, the paper's 64 envs x 500 steps, not batched: the config
    (and so the content address) of ``morfic eval RUN --command-vx 1.0 --mode full`` (:func:`goal_eval_command`).
    """
    from morfic_cli.evaluation.protocol import EvalCfg
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.report.goal import GOAL

    return EvalCfg(robots=tuple(parse_robot_list("all")), modes=(GOAL.mode,), command_vx=(command_vx,))


def goal_eval_command(spec: str, command_vx: float) -> str:
    """The ``morfic eval`` command that makes :func:`goal_eval_cfg`'s eval of ``spec`` at ``command_vx``."""
    from morfic_cli.report.goal import GOAL

    return f"morfic eval {spec} --command-vx {command_vx:.1f} --mode {GOAL.mode}"


def write_goal_evals(store, pipe, spec: str, run: str, out: Path, ids: dict, run_missing: bool) -> list[float]:
    """Write the goal's extra evals of ``spec`` (:func:`morfic_cli.report.goal.goal_evals` of its variant).

    Each is the store's, or run first when ``run_missing`` and the store holds the run's weights; written to
    ``out/RUN-<name>.csv`` (``name`` :func:`~morfic_cli.report.goal.goal_eval_name`: ``eval-1.0-full``), its
    termination counts beside it (``RUN-terminations-1.0-full.csv``), its id under ``name`` in ``ids``. Returns the
    commands left out (a note on stderr says how to make each).
    """
    from morfic_cli.report.goal import goal_eval_name, goal_evals

    left_out = []
    for command in goal_evals(pipe.variant_of(spec)):
        cfg = goal_eval_cfg(command)
        step = pipe.stored_eval(spec, cfg)
        if step is None and run_missing and has_weights(store, spec):
            start = time.monotonic()
            step = pipe.evaluate(spec, cfg)
            print(
                f"eval {spec} for the goal at {command:.1f} m/s: done in {time.monotonic() - start:.0f} s",
                file=sys.stderr,
            )
        if step is None:
            print(
                f"note: no {cfg.modes[0]}-mode eval of {spec} at {command:.1f} m/s in {store.root} (issue 58's goal "
                f"compares with it): `{goal_eval_command(spec, command)}`, or rerun with --goal-evals-only (both need "
                "the run's weights)",
                file=sys.stderr,
            )
            left_out.append(command)
            continue
        name = goal_eval_name(command)
        path = out / f"{run}-{name}.csv"
        path.write_bytes(store.read_file(step.id, "eval.csv"))
        ids[name] = step.id
        print(f"{path} (artifact {step.id[:12]})")
        write_terminations(store, step.id, out / f"{run}-{goal_eval_name(command, 'terminations')}.csv")
    return left_out


def trained_regime_diagnose_cfg(pipe):
    """``pipe``'s diagnosis config (the paper's: every robot, descriptor mode, 64 envs x 800 steps) at 1.0 m/s."""
    return pipe.diagnose_cfg(pipe.cfg.robots, TRAINED_COMMAND)


def has_weights(store, spec: str) -> bool:
    """Whether ``store`` holds ``spec``'s weights (a run imported from a results-only bundle does not)."""
    return not store.weights_omitted(store.read_manifest(spec))


def trained_regime_diagnosis(store, pipe, spec: str, run_missing: bool) -> str | None:
    """The id of the stored 1.0 m/s diagnosis of ``spec``'s checkpoint: ``pipe``'s (the paper's protocol) at 1.0 m/s.

    Run first when ``run_missing``, the store lacks it and holds the run's weights; None when it lacks it otherwise.
    """
    cfg = trained_regime_diagnose_cfg(pipe)
    step = pipe.stored_diagnosis(spec, cfg)
    if step is None and run_missing and has_weights(store, spec):
        start = time.monotonic()
        step = pipe.diagnose(spec, cfg)
        print(f"diagnose {spec} at 1.0 m/s: done in {time.monotonic() - start:.0f} s", file=sys.stderr)
    return step.id if step else None


def write_trained_regime_diagnosis(store, pipe, spec: str, run: str, out: Path, ids: dict, run_missing: bool) -> None:
    """Write ``out/RUN-calibration-1.0.csv`` and its id (``diagnosis-1.0``), or say on stderr why it is left out."""
    found = trained_regime_diagnosis(store, pipe, spec, run_missing)
    if found is None:
        print(
            f"note: no 1.0 m/s diagnosis of {spec} in {store.root} (it needs the run's weights: import its bundle "
            "and its weights bundle, then rerun with --run-missing or --diagnosis-1.0-only); claim (a) at 1.0 m/s "
            "reads the runs that have one",
            file=sys.stderr,
        )
        return
    path = out / f"{run}-calibration-1.0.csv"
    path.write_bytes(store.read_file(found, "calibration.csv"))
    ids["diagnosis-1.0"] = found
    print(f"{path} (artifact {found[:12]})")


def write_fixed_rollout(
    store,
    pipe,
    spec: str,
    out: Path,
    ids: dict,
    same_weights: frozenset[str],
    command_vx: float,
    *,
    run_it: bool,
    rescore: bool,
) -> dict[str, str] | str:
    """Write RUN's rows of the fixed-rollout analysis at ``command_vx`` into :func:`fixed_rollout_path` per robot.

    Each robot's analysis is the store's, or run first when ``run_it`` (``rescore``: run again on the rollout this
    store holds or collects even where it holds one); its id goes under :func:`fixed_rollout_key` in ``ids``.
    Returns robot -> the samples RUN's critic was scored on (for :func:`seed0_to_rescore`), or why a robot has none.
    """
    from morfic_cli.diagnostics.fixed_rollout import FIXED_ROLLOUT_COLUMNS

    run = spec.removeprefix("runs/")
    key = fixed_rollout_key(command_vx)
    used: dict[str, str] = {}  # robot -> the samples RUN's critic was scored on here
    for robot in pipe.cfg.fixed_rollout_robots:
        step = None if rescore else pipe.stored_fixed_rollout(robot, command_vx)
        if step is None and (run_it or rescore):
            step = pipe.fixed_rollout(robot, reuse=not rescore, command_vx=command_vx)
        if step is None or step.id is None:
            why = pipe.fixed_rollout_unavailable()
            return f"no fixed-rollout analysis at {command_vx:.1f} m/s of {spec}'s critic on {robot}" + (
                f": {why}" if why else ""
            )
        rows = list(csv.DictReader(io.StringIO(store.read_file(step.id, "fixed_rollout.csv").decode())))
        mine = [r for r in rows if r["critic"] in ("MC", run)]
        samples = store.read_manifest(mine[0]["rollout"]).files["obs.npz"].id
        path = fixed_rollout_path(out, robot, command_vx)
        columns = [*FIXED_ROLLOUT_COLUMNS, "samples"]
        merged = merge_fixed_rows(path, mine, columns, samples, same_weights)
        write_csv(path, merged, columns)
        used[robot] = samples
        reference = json.loads(path.with_suffix(".json").read_text())["samples"]
        if samples == reference or not any(r["critic"] == run and r["samples"] == reference for r in merged):
            ids.setdefault(key, {})[robot] = step.id  # the analysis of the row the claims read
        else:  # this run has a row on the reference samples: its analysis on these is kept aside
            ids.setdefault(f"{key}_other_samples", {}).setdefault(robot, {})[samples[:12]] = step.id
        print(f"{path}: {run}'s critic (artifact {step.id[:12]})")
    return used


def main(argv: list[str] | None = None) -> int:
    """Write the tables; 1 with ``Error:`` when the store has no paper-protocol result of the run."""
    from morfic_cli.rl.variants import eval_modes
    from morfic_cli.store import Store

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="run name, e.g. concat-cpu-s0")
    p.add_argument("--out", type=Path, default=Path("docs/results"))
    p.add_argument("--store", default=os.environ.get("MORFIC_STORE", "artifacts"))
    p.add_argument(
        "--run-missing",
        action="store_true",
        help="first evaluate, diagnose and score the run's critic on the film actor's rollouts (each "
        "with the paper's protocol, skipped when the store holds it)",
    )
    only = p.add_mutually_exclusive_group()
    only.add_argument(
        "--fixed-rollout-only",
        action="store_true",
        help="only the fixed-rollout rows; run the analysis (film actor frozen) if the store lacks it",
    )
    only.add_argument(
        "--fixed-rollout-1.0-only",
        dest="fixed_1_0_only",
        action="store_true",
        help="only the fixed-rollout rows at 1.0 m/s; run the analysis if the store lacks it (it "
        "needs the run's and the frozen actor's weights)",
    )
    only.add_argument(
        "--diagnosis-1.0-only",
        dest="diagnosis_only",
        action="store_true",
        help="only the 1.0 m/s diagnosis (run if the store lacks it and holds the run's weights)",
    )
    only.add_argument(
        "--goal-evals-only",
        dest="goal_only",
        action="store_true",
        help="only the evals issue 58's goal needs beyond the run's own (film: full mode at 1.0 m/s); run "
        "each the store lacks (it needs the run's weights)",
    )
    p.add_argument(
        "--rescore",
        action="store_true",
        help="with --fixed-rollout-only or --fixed-rollout-1.0-only: score the critic again on the film "
        "actor's rollout this store holds or collects, even where it holds the analysis (on other "
        "samples)",
    )
    args = p.parse_args(argv)
    if args.rescore and not (args.fixed_rollout_only or args.fixed_1_0_only):
        p.error("--rescore goes with --fixed-rollout-only or --fixed-rollout-1.0-only")
    only_fixed = args.fixed_rollout_only or args.fixed_1_0_only
    store = Store(args.store)
    spec = f"runs/{args.run}"
    manifest = store.read_manifest(spec)
    variant = manifest.config["variant"]
    pipe = one_run_pipeline(store, variant, int(manifest.config["seed"]), spec)
    args.out.mkdir(parents=True, exist_ok=True)
    ids_path = args.out / f"{args.run}-artifacts.json"
    ids = json.loads(ids_path.read_text()) if ids_path.is_file() else {"run": args.run}
    weights = manifest.files["model.pt"].id if "model.pt" in manifest.files else None
    # the checkpoint these tables had (a run retrained under its name keeps its rows only if its weights are the same)
    same_weights = frozenset(
        {ids["checkpoint"]} if ids.get("checkpoint") and weights and ids.get("weights") == weights else ()
    )
    ids["checkpoint"] = manifest.id
    if weights:
        ids["weights"] = weights
    if "curve.csv" in manifest.files:
        curve = args.out / f"{args.run}-curve.csv"
        write_csv(curve, curve_rows(store.read_file(manifest.id, "curve.csv").decode()), CURVE_COLUMNS)
        print(f"{curve} (training curve, {len(CURVE_COLUMNS)} columns)")
    if args.diagnosis_only:
        write_trained_regime_diagnosis(store, pipe, spec, args.run, args.out, ids, run_missing=True)
        ids_path.write_text(json.dumps(ids, indent=1) + "\n")
        return 0
    if args.goal_only:
        from morfic_cli.report.goal import GOAL, goal_evals

        if not goal_evals(variant):
            print(
                f"Error: {args.run} is a run of {variant}; issue 58's goal needs extra evals of {GOAL.reference}'s "
                "runs only (morfic_cli/report/goal.py, goal_evals); give one of those.",
                file=sys.stderr,
            )
            return 1
        left_out = write_goal_evals(store, pipe, spec, args.run, args.out, ids, run_missing=True)
        ids_path.write_text(json.dumps(ids, indent=1) + "\n")
        if left_out:
            print(f"Error: {store.root} lacks {spec}'s weights; import its weights bundle first.", file=sys.stderr)
        return 1 if left_out else 0
    if args.run_missing and not only_fixed:
        for step in (pipe.evaluate, pipe.diagnose):
            start = time.monotonic()
            result = step(spec)
            print(f"{result.kind} {spec}: {result.status} in {time.monotonic() - start:.0f} s", file=sys.stderr)
    if not only_fixed:
        found = {
            "eval": (pipe.stored_eval(spec), "eval.csv"),
            "diagnosis": (pipe.stored_diagnosis(spec), "calibration.csv"),
        }
        for what, (step, file) in found.items():
            if step is None:
                print(
                    f"Error: no {what} of {spec} with the paper's protocol in {store.root}; rerun with "
                    "--run-missing (or `morfic reproduce --preset cpu` for the run) first.",
                    file=sys.stderr,
                )
                return 1
            path = args.out / f"{args.run}-{file}"
            path.write_bytes(store.read_file(step.id, file))
            ids[what] = step.id
            print(f"{path} (artifact {step.id[:12]})")
            if what == "eval":
                write_terminations(store, step.id, terminations_path(args.out, args.run))
        slow = trained_regime_eval(pipe, spec, args.run_missing)
        if slow is None:
            command = trained_regime_command(spec, eval_modes(variant, trained_regime=True))
            print(
                f"Error: no 1.0 m/s eval of {spec} in {store.root}; rerun with --run-missing"
                + (f" (or `{command}`)" if command else "")
                + " first.",
                file=sys.stderr,
            )
            return 1
        path = args.out / f"{args.run}-eval-1.0.csv"
        path.write_bytes(store.read_file(slow, "eval.csv"))
        ids["eval-1.0"] = slow
        print(f"{path} (artifact {slow[:12]})")
        write_terminations(store, slow, terminations_path(args.out, args.run, TRAINED_COMMAND))
        write_trained_regime_diagnosis(store, pipe, spec, args.run, args.out, ids, args.run_missing)
        write_goal_evals(store, pipe, spec, args.run, args.out, ids, args.run_missing)
    refused = pipe.fixed_rollout_left_out().get(spec)
    if refused is not None:
        print(f"{'Error' if only_fixed else 'note'}: {refused}", file=sys.stderr)
        ids_path.write_text(json.dumps(ids, indent=1) + "\n")
        return 1 if only_fixed else 0
    rescore: dict[float, dict[str, str]] = {}  # command -> robot -> the samples RUN's critic was scored on
    if not args.fixed_1_0_only:
        used = write_fixed_rollout(
            store,
            pipe,
            spec,
            args.out,
            ids,
            same_weights,
            PAPER_COMMAND,
            run_it=args.fixed_rollout_only or args.run_missing,
            rescore=args.rescore,
        )
        if isinstance(used, str):
            print(f"Error: {used} in {store.root}; rerun with --run-missing or --fixed-rollout-only.", file=sys.stderr)
            return 1
        rescore[PAPER_COMMAND] = used
    if not args.fixed_rollout_only:
        # At 1.0 m/s the analysis is new (the bundles shipped before it lack it): it needs the frozen actor's and
        # RUN's weights, which a results-only bundle leaves out, so there it is a note, not an error.
        actor, _ = pipe.fixed_rollout_models()
        at_hand = all(store.has_ref(s) and has_weights(store, s) for s in (actor, spec))
        hint = (
            f"it needs {spec}'s and {actor}'s weights (import their bundles and weights bundles), then "
            "--run-missing or --fixed-rollout-1.0-only"
        )
        if args.fixed_1_0_only and not at_hand:
            print(
                f"Error: {store.root} lacks {spec}'s or {actor}'s weights for the fixed-rollout analysis at 1.0 "
                f"m/s; {hint}.",
                file=sys.stderr,
            )
            return 1
        slow = write_fixed_rollout(
            store,
            pipe,
            spec,
            args.out,
            ids,
            same_weights,
            TRAINED_COMMAND,
            run_it=at_hand and (args.fixed_1_0_only or args.run_missing),
            rescore=args.rescore,
        )
        if isinstance(slow, str) and args.fixed_1_0_only:
            print(f"Error: {slow} in {store.root}.", file=sys.stderr)
            return 1
        if isinstance(slow, str):
            print(
                f"note: {slow} in {store.root} ({hint}); claim (c) at 1.0 m/s reads the critics that have one",
                file=sys.stderr,
            )
        else:
            rescore[TRAINED_COMMAND] = slow
    ids_path.write_text(json.dumps(ids, indent=1) + "\n")
    if args.run_missing:
        for command_vx, used in rescore.items():
            flag = "--fixed-rollout-only" if command_vx == PAPER_COMMAND else "--fixed-rollout-1.0-only"
            for run in seed0_to_rescore(store, args.out, used, command_vx):
                print(
                    f"{run}: rescored on the new samples at {command_vx:.1f} m/s (what they change, beside the "
                    "reference rows)"
                )
                main([run, flag, "--rescore", "--out", str(args.out), "--store", str(args.store)])
    return 0


def seed0_to_rescore(store, out: Path, used: dict[str, str], command_vx: float = PAPER_COMMAND) -> list[str]:
    """The seed-0 runs to score on the fixed rollout's other samples, so that what those change is measured.

    ``used`` maps each robot to the samples a critic was just scored on at ``command_vx`` (the rollout ``store``
    holds). Where those are not the reference samples of :func:`fixed_rollout_path`: every seed-0 run with results in
    ``out`` (``<run>-artifacts.json``) that has a reference row, no row on those samples, and its weights in ``store``.
    """
    from morfic_cli.errors import MorficError

    todo: list[str] = []
    seed0 = sorted(p.name[: -len("-artifacts.json")] for p in out.glob("*-cpu-s0-artifacts.json"))
    for robot, samples in used.items():
        path = fixed_rollout_path(out, robot, command_vx)
        reference = json.loads(path.with_suffix(".json").read_text())["samples"]
        if samples == reference:
            continue
        scored = {(r["critic"], r.get("samples") or reference) for r in csv.DictReader(path.open())}
        for run in seed0:
            if (run, reference) not in scored or (run, samples) in scored or run in todo:
                continue
            try:
                if has_weights(store, f"runs/{run}"):
                    todo.append(run)
            except MorficError:
                continue
    return todo


if __name__ == "__main__":
    sys.exit(main())
