"""``morfic critic-study``: every variant's critic fitted from scratch on frozen actors' data, scored per robot."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    FormatOpt,
    OutputFormat,
    QuietOpt,
    RobotsOpt,
    SeedOpt,
    StoreOpt,
    TrustOpt,
)
from morfic_cli.cli._progress import StepBar
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args


def _num(v: float | None) -> str:
    return "-" if v is None or v != v else f"{v:.3f}"


def _interval(row: dict) -> str:
    lo, hi = row["lo"], row["hi"]
    if lo != lo:  # NaN: one seed
        return _num(row["mean"])
    return f"{row['mean']:.2f} [{lo:.2f}, {hi:.2f}]"


def critic_study(
    actors: Annotated[
        str | None,
        typer.Option(
            "--actors",
            "--actor",
            help="Comma-separated frozen actors' runs, the unit of replication "
            "(default: runs/film-cpu-s0, -s1, -s2, runs/actor-only-cpu-s0, runs/concat-cpu-s0).",
        ),
    ] = None,
    variants: Annotated[
        str,
        typer.Option(
            "--variants",
            help="Comma-separated critics to fit, or 'all' (ppo, concat, film, film-scaled, "
            "hyper, adaln; actor-only's critic is ppo's); a user's critic as module:Class.",
        ),
    ] = "all",
    seeds: Annotated[
        int,
        typer.Option(
            "--seeds", min=1, help="Fits per variant and actor (fit seeds 0..N-1), averaged within the actor."
        ),
    ] = 1,
    command_vx: Annotated[
        str, typer.Option("--command-vx", help="Forward command(s) in m/s; one fit set over all of them.")
    ] = "1.0,2.0",
    robots: RobotsOpt = "all",
    train_envs: Annotated[
        int,
        typer.Option(
            "--train-envs",
            min=2,
            help="Envs of the training-distribution rollout per command (one sampled morphology each).",
        ),
    ] = 128,
    held_out: Annotated[
        int,
        typer.Option("--held-out", min=1, help="Of those, the last envs, never fitted on, scored as robot 'train'."),
    ] = 16,
    val_envs: Annotated[
        int,
        typer.Option(
            "--val-envs",
            min=1,
            help="The envs before those: the validation split that stops each fit and decides whether it converged.",
        ),
    ] = 16,
    target_envs: Annotated[int, typer.Option("--target-envs", min=1, help="Envs per target robot.")] = 32,
    steps: Annotated[
        int, typer.Option("--steps", min=1, help="Policy steps per rollout (must exceed H_eps, 299 at gamma 0.99).")
    ] = 800,
    max_epochs: Annotated[
        int,
        typer.Option("--max-epochs", "--epochs", min=1, help="Most passes over the fit set (early stopping's cap)."),
    ] = 100,
    patience: Annotated[
        int,
        typer.Option(
            "--patience",
            min=1,
            help="Stop a fit after this many epochs without a validation-loss improvement; keep its best epoch.",
        ),
    ] = 8,
    min_ev: Annotated[
        float,
        typer.Option(
            "--min-ev",
            help="A fit whose validation EV stays below this, or that "
            "--max-epochs cut short, is flagged unconverged and left out of the "
            "averages.",
        ),
    ] = 0.1,
    minibatch: Annotated[int, typer.Option("--minibatch", min=1, help="Samples per gradient step.")] = 256,
    stride: Annotated[int, typer.Option("--stride", min=1, help="Take every N-th step of a training env.")] = 4,
    trunc_eps: Annotated[
        float,
        typer.Option(
            "--trunc-eps", help="I_eps is the window t <= T - H_eps with gamma^H_eps <= this (docs/metrics.md)."
        ),
    ] = 0.05,
    seed: SeedOpt = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Also write critic_study.csv, summary.csv, verdicts.csv, fits.csv and critic_study.png "
            "into this directory.",
        ),
    ] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Fit every variant's critic from scratch on each frozen actor's rollouts, to convergence; score it per robot.

    Each frozen actor (--actors: the unit of replication) collects rollouts on the training morphology distribution
    (the Go2 template with sampled descriptors) and on each target robot, at each command, with sampled actions
    (stored and reused). Every critic is built fresh and regressed on the Monte-Carlo returns of that actor's
    training samples with the same optimiser and batches, --seeds times, each fit stopped early on validation envs
    (--val-envs, --patience, --max-epochs) and flagged when its validation EV stays below --min-ev or the cap
    cut it short; then scored like
    `morfic diagnose` (EV, NVB, NVE, ASA, Flip, CosGrad on the frozen actor) on held-out training envs ('train') and
    on every robot. The table is each variant's mean over actors (each actor's converged fits averaged first) with
    a 95 % t interval; the verdicts of claims (a) and (c) come from t tests over actors, paired by actor,
    Holm-corrected per claim (docs/report.md "How a verdict is read"). Stores ref diagnoses/critic-study.
    The default study (5 actors) takes about 2.5 hours on 2 cores (docs/metrics.md "Critic study").

    Example: morfic critic-study
    Example: morfic critic-study --actors runs/film-cpu-s0,runs/film-cpu-s1 --variants film,concat --robots aliengo
    """
    specs = [a.strip() for a in actors.split(",") if a.strip()] if actors else None
    check_args(
        store=store,
        out_dir=out,
        seed=seed,
        envs=target_envs,
        steps=steps,
        command_vx=command_vx,
        robots=robots,
        specs=specs,
        trust=trust_variant,
    )
    from morfic_cli.diagnostics.critic_study import (
        DEFAULT_ACTORS,
        STUDY_VARIANTS,
        StudyCfg,
        StudyProgress,
        check_cfg,
        run_study,
    )
    from morfic_cli.evaluation.protocol import parse_commands
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.rl.load import load_trained
    from morfic_cli.rl.variants import trust_variants
    from morfic_cli.store import Store

    try:
        commands = parse_commands(command_vx)
    except ValueError as exc:
        raise MorficError(
            f"--command-vx takes comma-separated numbers in m/s (e.g. 1.0,2.0), got '{command_vx}'."
        ) from exc
    names = (
        STUDY_VARIANTS
        if variants.strip().lower() == "all"
        else tuple(v.strip() for v in variants.split(",") if v.strip())
    )
    trust_variants(names)  # the critics named by --variants: the user's consent to import them
    cfg = StudyCfg(
        actors=tuple(specs or DEFAULT_ACTORS),
        variants=names,
        seeds=seeds,
        commands=commands,
        robots=tuple(parse_robot_list(robots)),
        train_envs=train_envs,
        held_out=held_out,
        val_envs=val_envs,
        target_envs=target_envs,
        steps=steps,
        seed=seed,
        stride=stride,
        max_epochs=max_epochs,
        patience=patience,
        min_ev=min_ev,
        minibatch=minibatch,
        trunc_eps=trunc_eps,
    )
    check_cfg(cfg)
    st = Store(store)
    missing = [a for a in cfg.actors if not specs and not st.has_ref(a)]
    if missing:
        raise MorficError(
            f"the default actors {', '.join(missing)} are not in store {st.root}; import their weights "
            "(`morfic store import artifacts/bundles/<run>.tar`, artifacts/README.md) or name the "
            "actors with --actors."
        )
    trained = {spec: load_trained(st, spec) for spec in cfg.actors}  # a bad checkpoint fails before any work
    with StepBar("critic-study", 0, quiet) as bar:
        result = run_study(st, cfg, actors=trained, progress=StudyProgress(phase=bar.phase, advance=bar.step))
    _write_out(out, st, result.id)
    from morfic_cli.diagnostics.study_summary import cell_summary, convergence_text, study_claims

    if not quiet:
        s = result.seconds
        n_fits = len({(r["actor"], r["variant"], r["fit_seed"]) for r in result.fits})
        info(
            f"stored diagnoses/critic-study@{result.version} ({result.id[:12]}): {n_fits} fits in {s['fits']:.0f} s "
            f"({s['fits'] / max(n_fits, 1):.0f} s a fit), rollouts {s['rollouts']:.0f} s, "
            f"scoring {s['scoring']:.0f} s; {convergence_text(result.rows)}"
        )
    summary = [r for r in cell_summary(result.rows) if r["metric"] in ("ev", "nve", "flip", "cos_grad")]
    wide: dict[tuple, dict] = {}
    for r in summary:
        row = wide.setdefault(
            (r["command_vx"], r["robot"], r["variant"]),
            {
                "command_vx": r["command_vx"],
                "robot": r["robot"],
                "variant": r["variant"],
                "n": r["n"],
                "unit": r["unit"],
                "n_fits": r["n_fits"],
                "n_flagged": r["n_flagged"],
            },
        )
        row[r["metric"]] = _interval(r)
        row[f"{r['metric']}_mean"], row[f"{r['metric']}_lo"], row[f"{r['metric']}_hi"] = r["mean"], r["lo"], r["hi"]
    emit_rows(
        list(wide.values()),
        fmt,
        columns=[
            Column("command_vx", "cmd", fmt=lambda v: f"{v:.1f}", justify="right"),
            Column("robot", "robot"),
            Column("variant", "variant"),
            Column("ev", "EV [95 %]", justify="right"),
            Column("nve", "NVE [95 %]", justify="right"),
            Column("flip", "Flip [95 %]", justify="right"),
            Column("cos_grad", "CosGrad [95 %]", justify="right"),
            Column("n", "n", justify="right"),
            Column("n_flagged", "left out", justify="right"),
        ],
        title=f"critic study ({len(cfg.actors)} actor{'s' if len(cfg.actors) > 1 else ''})",
        caption=f"mean over {'actors' if len(cfg.actors) > 1 else 'fit seeds (one actor)'} [95 % t interval], n of "
        "them; 'left out': unconverged fits; 'train' = held-out envs of the training distribution; higher is "
        "better: EV, CosGrad; lower: NVE, Flip",
    )
    if not quiet:
        for c in study_claims(result.rows):
            robots_text = ", ".join(f"{r['robot']} {r['verdict']}" for r in c["robots"])
            info(f"claim ({c['claim']}) at {c['command_vx']:g} m/s, the actor fixed: {c['verdict']} ({robots_text})")


def _write_out(out: Path | None, st, manifest_id: str) -> None:
    """``--out DIR``: the study's files; a figure a results-only bundle left out is drawn from ``summary.csv``."""
    if out is None:
        return
    out.mkdir(parents=True, exist_ok=True)
    manifest = st.read_manifest(manifest_id)
    omitted = st.omitted_files(manifest)
    for name in manifest.files:
        if name == "critic_study.png" and name in omitted and "summary.csv" in manifest.files:
            from morfic_cli.diagnostics.figures import critic_study_figure
            from morfic_cli.report.gather import read_csv_rows

            (out / name).write_bytes(critic_study_figure(read_csv_rows(st.read_file(manifest_id, "summary.csv"))))
        elif name not in omitted:
            (out / name).write_bytes(st.read_file(manifest_id, name))
