"""``morfic critic-study``: every variant's critic fitted from scratch on one frozen actor's data, scored per robot."""

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
from morfic_cli.cli.trust import note_skipped
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
    actor: Annotated[
        str | None,
        typer.Option("--actor", help="The frozen actor's run (default: the newest film run, e.g. runs/film-cpu-s0)."),
    ] = None,
    variants: Annotated[
        str,
        typer.Option("--variants", help="Comma-separated critics to fit, or 'all' (ppo, concat, film, film-scaled, "
                     "hyper, adaln; actor-only's critic is ppo's); a user's critic as module:Class."),
    ] = "all",
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="Fits per variant (fit seeds 0..N-1).")] = 5,
    command_vx: Annotated[
        str, typer.Option("--command-vx", help="Forward command(s) in m/s; one fit set over all of them.")
    ] = "1.0,2.0",
    robots: RobotsOpt = "all",
    train_envs: Annotated[int, typer.Option("--train-envs", min=2, help="Envs of the training-distribution "
                                            "rollout per command (one sampled morphology each).")] = 128,
    held_out: Annotated[int, typer.Option("--held-out", min=1, help="Of those, envs kept out of the fit and scored "
                                          "as robot 'train'.")] = 16,
    target_envs: Annotated[int, typer.Option("--target-envs", min=1, help="Envs per target robot.")] = 32,
    steps: Annotated[int, typer.Option("--steps", min=1, help="Policy steps per rollout (must exceed H_eps, 299 at "
                                       "gamma 0.99).")] = 800,
    epochs: Annotated[int, typer.Option("--epochs", min=1, help="Passes over the fit set.")] = 6,
    minibatch: Annotated[int, typer.Option("--minibatch", min=1, help="Samples per gradient step.")] = 256,
    stride: Annotated[int, typer.Option("--stride", min=1, help="Take every N-th step of a training env.")] = 4,
    trunc_eps: Annotated[float, typer.Option("--trunc-eps", help="I_eps is the window t <= T - H_eps with "
                                             "gamma^H_eps <= this (docs/metrics.md).")] = 0.05,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Also write critic_study.csv, summary.csv, verdicts.csv, fits.csv and critic_study.png "
        "into this directory.")] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Fit every variant's critic from scratch on one frozen actor's rollouts and score it on every robot.

    The frozen actor collects rollouts on the training morphology distribution (the Go2 template with sampled
    descriptors) and on each target robot, at each command, with sampled actions (stored and reused). Every
    critic is built fresh and regressed on the Monte-Carlo returns of the training samples with the same optimiser,
    epochs and batches, --seeds times, then scored like `morfic diagnose` (EV, |NVB|, NVE, ASA, Flip, CosGrad on
    the frozen actor) on held-out training envs ('train') and on every robot. The table is each variant's mean
    with a 95 % t interval over its fits; the verdicts of claims (a) and (c) come from Welch and t-contrast tests,
    Holm-corrected per claim (docs/report.md "How a verdict is read"). Stores ref diagnoses/critic-study.

    Example: morfic critic-study --actor runs/film-cpu-s0 --seeds 5
    Example: morfic critic-study --variants film,concat --seeds 2 --robots aliengo --command-vx 1.0 --epochs 2
    """
    check_args(store=store, out_dir=out, seed=seed, envs=target_envs, steps=steps, command_vx=command_vx,
               robots=robots, specs=[actor] if actor else None, trust=trust_variant)
    from morfic_cli.diagnostics.critic_study import STUDY_VARIANTS, StudyCfg, StudyProgress, check_cfg, run_study
    from morfic_cli.diagnostics.fixed_rollout import default_actor
    from morfic_cli.evaluation.protocol import parse_commands
    from morfic_cli.morphology.distance import parse_robot_list
    from morfic_cli.rl.runner import load_trained
    from morfic_cli.rl.variants import trust_variants
    from morfic_cli.store import Store

    try:
        commands = parse_commands(command_vx)
    except ValueError as exc:
        raise MorficError(f"--command-vx takes comma-separated numbers in m/s (e.g. 1.0,2.0), got '{command_vx}'.") \
            from exc
    names = STUDY_VARIANTS if variants.strip().lower() == "all" else tuple(
        v.strip() for v in variants.split(",") if v.strip())
    trust_variants(names)  # the critics named by --variants: the user's consent to import them
    cfg = StudyCfg(variants=names, seeds=seeds, commands=commands, robots=tuple(parse_robot_list(robots)),
                   train_envs=train_envs, held_out=held_out, target_envs=target_envs, steps=steps, seed=seed,
                   stride=stride, epochs=epochs, minibatch=minibatch, trunc_eps=trunc_eps)
    check_cfg(cfg)
    st = Store(store)
    spec = actor or default_actor(st, note_skipped)
    trained = load_trained(st, spec)  # a bad ref fails here, before any work
    with StepBar("critic-study", 0, quiet) as bar:
        result = run_study(st, spec, cfg, actor=trained, progress=StudyProgress(phase=bar.phase, advance=bar.step))
    _write_out(out, st, result.id)
    if not quiet:
        s = result.seconds
        n_fits = len({(r["variant"], r["fit_seed"]) for r in result.fits})
        info(f"stored diagnoses/critic-study@{result.version} ({result.id[:12]}): {n_fits} fits in {s['fits']:.0f} s "
             f"({s['fits'] / max(n_fits, 1):.0f} s a fit), rollouts {s['rollouts']:.0f} s, "
             f"scoring {s['scoring']:.0f} s")
    from morfic_cli.diagnostics.study_summary import cell_summary, study_claims

    summary = [r for r in cell_summary(result.rows) if r["metric"] in ("ev", "flip", "cos_grad")]
    wide: dict[tuple, dict] = {}
    for r in summary:
        row = wide.setdefault((r["command_vx"], r["robot"], r["variant"]),
                              {"command_vx": r["command_vx"], "robot": r["robot"], "variant": r["variant"],
                               "n": r["n"]})
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
            Column("flip", "Flip [95 %]", justify="right"),
            Column("cos_grad", "CosGrad [95 %]", justify="right"),
            Column("n", "fits", justify="right"),
        ],
        title=f"critic study (actor {result.rows[0]['actor'] if result.rows else spec})",
        caption="mean over fit seeds [95 % t interval]; 'train' = held-out envs of the training "
        "distribution; higher is better: EV, CosGrad; lower: Flip",
    )
    if not quiet:
        for c in study_claims(result.rows):
            robots_text = ", ".join(f"{r['robot']} {r['verdict']}" for r in c["robots"])
            info(f"claim ({c['claim']}) at {c['command_vx']:g} m/s, the actor fixed: {c['verdict']} ({robots_text})")


def _write_out(out: Path | None, st, manifest_id: str) -> None:
    """``--out DIR``: the study's files."""
    if out is None:
        return
    out.mkdir(parents=True, exist_ok=True)
    manifest = st.read_manifest(manifest_id)
    for name in manifest.files:
        (out / name).write_bytes(st.read_file(manifest_id, name))
