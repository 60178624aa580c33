"""``morfic report``: the paper's tables and figures from what the store holds, as a ``report`` artifact.

The report reads only the store (:func:`~morfic_cli.report.gather.gather`): runs, their evaluations and diagnoses,
the morphology-support table; it stores the comparison it builds on (``tables/compare-baselines``) and then itself
(ref ``reports/<name>``), with every artifact it read as an input and listed in its Provenance section. Files of the
report artifact: ``report.json`` (every table with values and bold marks, and the provenance) and
``provenance.csv`` always; ``report.md`` with ``markdown``; ``report.tex`` (standalone, booktabs) and, where
pdflatex is installed, ``report.pdf`` with ``latex``; ``figures/*.png|pdf`` with ``figures``.

The same runs, results and options give the same inputs and config: the stored report is then found and reused
instead of being built again. The config carries :data:`REPORT_LAYOUT`, so a morfic that lays the report out
differently builds it anew instead of finding the old one.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from morfic_cli import __version__
from morfic_cli.report import paper
from morfic_cli.report import tables as T
from morfic_cli.report.claims import PAPER_COMMAND, Claim, at_command, check_claims, row_command
from morfic_cli.report.compare import (
    COMPARE_REF,
    EXTERNAL_TABLE_VARIANTS,
    claim_rows,
    compare_tables,
    store_comparison,
    without_external,
)
from morfic_cli.report.gather import Provenance, StoreData, filter_presets, gather, read_csv_rows, resolve_runs
from morfic_cli.report.model import Table
from morfic_cli.rl.variants import STOCK
from morfic_cli.store import Store
from morfic_cli.store.publish import find_manifest

REPORTS_PREFIX = "reports/"

FIGURES: dict[str, str] = {
    "ev": "Explained variance of the critic of each of the paper's variants per robot (higher is better, 1 = "
    "perfect); the axis is logarithmic below -1, so no bar is cut.",
    "ev-external": "Explained variance of the external baselines' critics and MorFiC-F's per robot, as trained here "
    '(the paper\'s Fig. "Critic calibration under morphology shift", right).',
    "distance": "Forward velocity at 2.0 m/s (error bars: std over envs) against the normalised morphology "
    "distance to Go2, one point per robot.",
    "compute": "Training device-hours normalised to 400M transitions, per run (and the paper's methods).",
    "curves": "Training curves: mean episode return and the critic's explained variance.",
}

#: The text above the claims (docs/results.md reads them with the reasons behind each).
CLAIMS_INTRO = (
    "Each of the paper's five claims checked against the results below (morfic_cli/report/claims.py), "
    "at 2.0 m/s and, where the store has evaluations there, at 1.0 m/s. Each claim names its primary "
    "comparisons; each is tested over training seeds (Welch's t, a t-contrast, an equivalence test or "
    "Spearman's rho over the robots), the p-values are Holm-corrected together, and the verdict counts "
    "the significant ones: holds (all in the claimed direction), holds partly (some, none against), "
    "mixed, partly reversed, does not hold (all against), or cannot tell (none significant; one seed "
    "per variant gives no test). Under each comparison that is not significant: the seeds per side "
    'that would detect its effect with 80 % power (docs/report.md "How a verdict is read").'
)

SPEED_PREFIX = "speed-"
"""Figure names ``speed-<run>-<robot>``: the eval figure of that run on that robot (descriptor mode, 2.0 m/s)."""

SPEED_PER_FIGURE = 6
"""Eval figures per LaTeX figure (three rows of two fit a page at a legible size)."""

SPEED_CAPTION = (
    "Forward speed over time of {run} on each robot at a commanded 2.0 m/s (descriptor mode), as "
    "`morfic eval` drew it: the mean over alive envs, the 10-90th percentile band, the command dashed "
    "and falls as red ticks (their count in the legend); below, the percentage of envs alive. A run "
    "imported from a results-only bundle, which leaves the time series out, has each drawn from its "
    "eval table instead: v_x and its best 1 s (mean and std), S and the share of valid envs."
)


def ev_external_figure(calibration: list[dict[str, Any]]) -> dict[str, tuple[bytes, bytes]]:
    """``{"ev-external": (png, pdf)}``: the EV of the external baselines and MorFiC-F from their diagnoses.

    The paper's Fig. "Critic calibration under morphology shift", right panel; empty without an external baseline's
    diagnosis.
    """
    from morfic_cli.report import figures as F

    rows = [r for r in calibration if r["variant"] in EXTERNAL_TABLE_VARIANTS]
    if not any(r["variant"] != "film" for r in rows):
        return {}
    return {"ev-external": F.ev_figure(rows)}


def eval_figures(store: Store, evals: list[dict[str, Any]]) -> dict[str, tuple[bytes, bytes]]:
    """The eval figures of the main protocol (descriptor mode, 2.0 m/s), ``speed-<run>-<robot>``.

    The stored ones, or, for a rollout a results-only bundle left without its figure, one drawn from the eval row
    (:func:`~morfic_cli.evaluation.figures.figure_or_table`).
    """
    from morfic_cli.evaluation.figures import figure_or_table
    from morfic_cli.evaluation.names import rollout_role

    out: dict[str, tuple[bytes, bytes]] = {}
    for row in sorted(
        evals,
        key=lambda r: (r["run"], paper.ROBOTS.index(r["robot"]) if r["robot"] in paper.ROBOTS else len(paper.ROBOTS)),
    ):
        if row["mode"] != "descriptor" or abs(float(row["command_vx"]) - 2.0) > 1e-9:
            continue
        rid = store.read_manifest(row["artifact"]).inputs.get(rollout_role(row["robot"], "descriptor", 2.0))
        if rid is None:
            continue
        figure = figure_or_table(store, rid, row, f"{row['run']} on {row['robot']}, descriptor mode, command 2 m/s")
        if figure is not None:
            out[f"{SPEED_PREFIX}{row['run']}-{row['robot']}"] = figure
    return out


def _speed_groups(names: list[str], runs: list[str]) -> dict[str, list[str]]:
    """Speed figure names grouped by run (the longest run name that prefixes the figure name)."""
    groups: dict[str, list[str]] = {}
    for n in names:
        rest = n.removeprefix(SPEED_PREFIX)
        run = max((r for r in runs if rest.startswith(r + "-")), key=len, default=rest.rsplit("-", 1)[0])
        groups.setdefault(run, []).append(n)
    return groups


@dataclass(frozen=True)
class ReportCfg:
    """What a report contains.

    Attributes:
        runs: Run specs (``runs/film-cpu-s0``); empty = every run in the store.
        presets: Keep only the runs trained with one of these presets (``cpu``); empty = every preset.
        latex: Write ``report.tex`` (and ``report.pdf`` where pdflatex is installed).
        markdown: Write ``report.md``.
        figures: Draw the figures.
        with_paper: Put the paper's published tables after ours.
        name: The report's ref is ``reports/<name>``.
        title: Document title.
    """

    runs: tuple[str, ...] = ()
    presets: tuple[str, ...] = ()
    latex: bool = False
    markdown: bool = True
    figures: bool = False
    with_paper: bool = False
    name: str = "latest"
    title: str = "MorFiC reproduction report"


@dataclass
class ReportResult:
    """A stored report: id, ref, version, its file names, whether it was reused, where --out files went."""

    id: str
    ref: str
    version: int
    files: list[str]
    reused: bool
    tables: int
    provenance: list[Provenance]
    out_files: list[Path] = field(default_factory=list)
    pdf_error: str | None = None


def _other_commands(rows: Sequence[dict[str, Any]]) -> list[float]:
    """The commands (m/s) of ``rows`` other than the paper's, ascending: each gets its own tables after the paper's."""
    return sorted({round(row_command(r), 6) for r in rows} - {PAPER_COMMAND})


@dataclass
class _Section:
    heading: str
    tables: list[Table] = field(default_factory=list)
    text: str = ""
    claims: list[Claim] = field(default_factory=list)


def _sections(
    data: StoreData, tables: dict[str, list[dict[str, Any]]], support: list[dict[str, Any]], with_paper: bool
) -> list[_Section]:
    transfer, calib = tables.get("transfer", []), tables.get("calibration", [])
    fixed, compute = tables.get("fixed_rollout", []), tables.get("compute", [])
    P = (lambda *ts: [T.paper_table(t) for t in ts]) if with_paper else (lambda *ts: [])  # noqa: E731
    out: list[_Section] = [_Section("The paper's claims", text=CLAIMS_INTRO, claims=check_claims(*claim_rows(data)))]

    main = T.transfer_table(
        transfer,
        key="zero_shot_transfer",
        title="Zero-shot cross-morphology transfer",
        command_vx=2.0,
        mode="descriptor",
        variants=T.MAIN_VARIANTS,
    )
    # The paper splits its variants over two tables (main, ablation); with runs outside the main table's four, one
    # more table puts every variant side by side, in our order.
    every = (
        T.transfer_table(
            transfer,
            key="zero_shot_transfer_every",
            title="Zero-shot transfer, every variant",
            command_vx=2.0,
            mode="descriptor",
            min_columns=2,
        )
        if any(r["variant"] not in T.MAIN_VARIANTS for r in transfer)
        else None
    )
    sec = _Section("Zero-shot transfer", [t for t in [main, every] if t] + P(paper.ZERO_SHOT_TRANSFER))
    if not main:
        sec.text = (
            "No descriptor-mode evaluation at 2.0 m/s of ppo / actor-only / concat / film runs in the store "
            "(`morfic eval RUN --command-vx 2.0`)."
        )
    out.append(sec)

    has_ablation = any(r["variant"] in T.ABLATION_VARIANTS[1:] for r in transfer)
    abl = (
        T.transfer_table(
            transfer,
            key="critic_conditioning_ablation",
            title="Ablation: multiplicative critics",
            command_vx=2.0,
            mode="descriptor",
            variants=T.ABLATION_VARIANTS,
        )
        if has_ablation
        else None
    )
    sec = _Section(
        "Ablation", [t for t in [abl] if t] + P(paper.CRITIC_CONDITIONING_ABLATION, paper.FILM_MORPH_RANGE_ABLATION)
    )
    if not abl:
        sec.text = f"No evaluated {' / '.join(T.ABLATION_VARIANTS[1:])} runs in the store."
    out.append(sec)

    fast = T.transfer_table(
        transfer,
        key="transfer_25",
        title="Transfer at a higher commanded speed",
        command_vx=2.5,
        mode="descriptor",
        use_max=True,
    )
    out.append(
        _Section(
            "Transfer at 2.5 m/s",
            [t for t in [fast] if t],
            "" if fast else "No descriptor-mode evaluation at 2.5 m/s in the store.",
        )
    )

    full = [
        t
        for t in (
            T.transfer_table(
                transfer,
                key=f"transfer_full_{v:g}".replace(".", "_"),
                title=f"Transfer with the targets' own models at {v:g} m/s",
                command_vx=v,
                mode="full",
            )
            for v in (2.0, 2.5)
        )
        if t
    ]
    if full:
        out.append(
            _Section(
                "Transfer with the targets' own models (morfic extension)",
                full,
                "The paper applies each target's 11-D descriptor to the Go2 template (descriptor mode); "
                "here the policy runs on the target's own MJCF model (full mode).",
            )
        )

    matched = [
        t
        for t in (
            T.transfer_table(
                transfer,
                key=f"transfer_matched_{v:g}".replace(".", "_"),
                title=f"Transfer with actuation matched to mass at {v:g} m/s",
                command_vx=v,
                mode="actuation-matched",
            )
            for v in (2.0, 2.5)
        )
        if t
    ]
    if matched:
        out.append(
            _Section(
                "Transfer with actuation matched to mass (morfic extension)",
                matched,
                "Descriptor mode with the target's Kp, Kd and torque limits set as a deployer sets them "
                "for its mass: Go2's x the target's total mass / Go2's (docs/eval.md).",
            )
        )

    goal = goal_section(data)
    if goal is not None:
        out.append(goal)

    out.append(_external_section(tables, with_paper))

    # ours at the paper's command, the paper's, then ours at each other command (a run's diagnoses at 2.0 and 1.0 m/s
    # are separate rows, never two seeds of one); the external baselines' are in their own section
    calib = without_external(calib)
    crit = [t for t in (T.ev_table(calib), T.critic_table(calib)) if t]
    crit_other = [
        t
        for c in _other_commands(calib)
        for t in (T.ev_table(calib, command_vx=c), T.critic_table(calib, command_vx=c))
        if t
    ]
    out.append(
        _Section(
            "Critic diagnostics",
            crit + P(paper.CRITIC_METRICS_VARIANTS) + crit_other,
            "" if crit or crit_other else "No calibration diagnoses of these runs in the store (`morfic diagnose`).",
        )
    )
    fx = [t for t in [T.fixed_rollout_table(fixed)] if t]
    fx_other = [t for t in (T.fixed_rollout_table(fixed, command_vx=c) for c in _other_commands(fixed)) if t]
    out.append(
        _Section(
            "Fixed-rollout diagnostic",
            fx + P(paper.CAUSAL_ADV_ALL) + fx_other,
            ""
            if fx or fx_other
            else "No fixed-rollout diagnoses with these runs' critics in the store "
            "(`morfic diagnose --fixed-rollout aliengo`).",
        )
    )
    if data.study:
        from morfic_cli.report.study import study_tables, study_text

        out.append(
            _Section(
                "Critic study: the conditioning alone, the actor fixed",
                study_tables(data.study),
                study_text(
                    data.study,
                    str(data.study_meta.get("actor", "?")),
                    data.study[0]["artifact"],
                    data.study_meta.get("seconds", {}),
                ),
            )
        )
    comp = T.compute_table(compute)
    out.append(
        _Section("Training compute", [t for t in [comp] if t] + ([T.paper_compute_table()] if with_paper else []))
    )
    sup = T.support_table(support)
    out.append(_Section("Morphology support", [t for t in [sup] if t] + P(paper.MORPHOLOGY_SUPPORT)))
    return out


EXTERNAL_TEXT = (
    "The paper compares MorFiC with four cross-morphology methods using their released weights in "
    "their own simulators (its rows below, marked paper). Ours re-implement BodyTransformer (bot), URMA "
    "(urma) and GenLoco (genloco) in morfic's pipeline and train them on the Go2 template with "
    "MorFiC-F's rewards, curriculum and budget (docs/training.md, \"External baselines\"); GenLoco's "
    "motion-imitation reward is not reproduced. They are evaluated and diagnosed as every variant."
)


def _external_section(tables: dict[str, list[dict[str, Any]]], with_paper: bool) -> _Section:
    """The external baselines' section: the paper's rows and ours, in transfer, critic metrics and compute.

    Transfer at 2.0 and 2.5 m/s (the paper's rows and ours), ours on the targets' own models, our critics' EV and
    metrics (the paper's with ``with_paper``), and the compute of both.
    """
    ext, compute = tables.get("external", []), tables.get("compute", [])
    calib = [r for r in tables.get("calibration", []) if r["variant"] in EXTERNAL_TABLE_VARIANTS]
    calib = calib if any(r["variant"] != "film" for r in calib) else []
    found = [T.external_table(ext, c) for c in (2.0, 2.5)]
    found += [T.external_table(ext, c, mode="full") for c in (2.0, 2.5)]
    found += [
        T.ev_table(calib, key="critic_ev_external", title="Explained variance of the external baselines' critics"),
        T.critic_table(calib, key="critic_metrics_external", title="Critic calibration of the external baselines"),
    ]
    found += [T.paper_table(paper.CRITIC_METRICS_EXTERNAL)] if with_paper else []
    return _Section("External baselines", [t for t in found if t] + [T.external_compute_table(compute)], EXTERNAL_TEXT)


GOAL_HEADING = "One policy for seven robots (beyond the paper)"


def goal_section(data: StoreData) -> _Section | None:
    """Issue 58's goal section: today's film and each actuation variant against :data:`~morfic_cli.report.goal.GOAL`.

    Present only when a run of a table-``actuation`` variant (``film-act``, ``ppo-act``, ...) is among the runs.
    Full mode at each goal command, then descriptor and actuation-matched mode against the same bars
    (:func:`~morfic_cli.report.goal.goal_table`); the text says the goal, and per column the robots that meet it
    at both commands (k of 7) and, for an actuation variant, Go2, Go1 and A1 against film of the same preset. Then,
    where the evals recorded termination counts, what ended the failed episodes in full mode at each goal command
    (:func:`~morfic_cli.report.goal.ended_by_table`).
    """
    from morfic_cli.report import goal as G
    from morfic_cli.rl.variants import table_variants

    actuation = table_variants("actuation")
    if not any(r.variant in actuation for r in data.runs):
        return None
    order = (G.GOAL.reference, *actuation)
    rows = [r for r in data.evals if r["variant"] in order]
    keys = sorted({(str(r["preset"]), str(r["variant"])) for r in rows}, key=lambda k: (k[0], order.index(k[1])))
    multi = len({p for p, _ in keys}) > 1

    def column(r: Mapping[str, Any]) -> str:
        return f"{r['preset']}/{r['variant']}"

    def header(preset: str, variant: str) -> str:
        n = len({r["seed"] for r in rows if (r["preset"], r["variant"]) == (preset, variant)})
        return f"{T.method_label(variant, preset, multi)}, {n} seed{'s' if n != 1 else ''}"

    columns = [(f"{p}/{v}", header(p, v)) for p, v in keys]
    found = [
        G.goal_table(rows, mode, c, columns, column)
        for mode in (G.GOAL.mode, "descriptor", "actuation-matched")
        for c in G.GOAL.commands
    ]
    ended = [r for r in data.terminations if r["variant"] in order]
    found += [G.ended_by_table(ended, rows, G.GOAL.mode, c, columns, column) for c in G.GOAL.commands]
    lines = [f"Issue 58's goal: {G.GOAL.text()}. The goal's bars are morfic_cli/report/goal.py's GOAL."]
    for key, head in columns:
        met, missing = G.robots_meeting(rows, key, column)
        line = f"{head}: robots meeting the goal (both commands, every seed): {len(met)} of {len(G.ROBOTS)}"
        line += f" ({', '.join(T.robot_label(r) for r in met)})" if met else ""
        if missing:
            line += f"; no {G.GOAL.mode}-mode rows at {' and '.join(f'{c:.1f}' for c in missing)} m/s"
        preset, variant = key.split("/", 1)
        if variant != G.GOAL.reference:
            ref = f"{preset}/{G.GOAL.reference}"
            vs = G.reference_text(G.reference_effects(rows, key, column, ref), G.GOAL.reference)
            line += f". Go2, Go1 and A1 against {G.GOAL.reference}: {vs}" if vs else ""
        lines.append(line + ".")
    return _Section(GOAL_HEADING, [t for t in found if t], "\n\n".join(lines))


def seeds_note(data: StoreData) -> str:
    """The report's first lines when a variant has one seed: why its claims read "cannot tell", and the full answer.

    Empty when every variant has two seeds or more (or there are no runs).
    """
    seeds: dict[str, set[int]] = {}
    for r in data.runs:
        seeds.setdefault(r.variant, set()).add(r.seed)
    single = sorted(v for v, s in seeds.items() if len(s) < 2)
    if not single:
        return ""
    how = (
        "The experiment's answer (the README's findings: 3 seeds a variant) is in the shipped results bundles: "
        "`morfic store import --append artifacts/bundles/results/*.tar`, then `morfic report` "
        "(docs/reproducing.md)."
    )
    if len(single) == len(seeds):
        return (
            "Read this first: this store has one training seed per variant, so no claim can be tested here "
            '(a test compares seeds): every verdict below reads "cannot tell", which is not a finding. ' + how
        )
    return (
        f"Read this first: {', '.join(single)} {'has' if len(single) == 1 else 'have'} one training seed here, "
        'so the comparisons that need them cannot be tested ("cannot tell" is then not a finding). ' + how
    )


def _intro(data: StoreData, with_paper: bool) -> str:
    presets = sorted({r.preset for r in data.runs})
    unfinished = [r.name for r in data.runs if not r.finished]
    note = seeds_note(data)  # first: a one-seed store's verdicts differ from the README's, and why
    text = (f"{note}\n\n" if note else "") + (
        f"Built by morfic {__version__} from {len(data.runs)} training run(s) ({', '.join(presets)} preset) and "
        f"the results stored for them; every number traces to an artifact id listed under Provenance "
        f"(`morfic store show ID`). Variant names follow the paper: "
        + ", ".join(f"{v.label} = {name}" for name, v in STOCK.items())
        + "."
    )
    if "smoke" in presets:
        text += " The smoke preset trains for seconds to exercise the pipeline: its numbers are not results."
    if unfinished:
        text += f" Runs not trained to the end: {', '.join(unfinished)}."
    if with_paper:
        text += " Tables marked (paper) are the paper's published numbers, with its bold marks."
    return text


def _provenance_rows(prov: list[Provenance]) -> list[dict[str, Any]]:
    return [{"kind": p.kind, "ref": p.ref or "", "id": p.id, "role": p.role} for p in prov]


def _paper_title(t: Table) -> Table:
    from dataclasses import replace

    return replace(t, title=f"{t.title} (paper)") if t.source == "paper" else t


def render(
    cfg: ReportCfg,
    data: StoreData,
    sections: list[_Section],
    prov: list[Provenance],
    figures: dict[str, tuple[bytes, bytes]],
) -> dict[str, bytes]:
    """The report's files (name -> bytes), see the module docstring."""
    from morfic_cli.recording.tables import rows_to_csv

    prov_rows = _provenance_rows(prov)
    run_names = [r.name for r in data.runs]
    files: dict[str, bytes] = {}
    doc = {
        "title": cfg.title,
        "morfic_version": __version__,
        "runs": [asdict(r) for r in data.runs],
        "sections": [
            {
                "heading": s.heading,
                "text": s.text,
                "tables": [t.to_dict() for t in s.tables],
                **({"claims": [asdict(c) for c in s.claims]} if s.claims else {}),
            }
            for s in sections
        ],
        "figures": sorted(figures),
        "provenance": prov_rows,
    }
    files["report.json"] = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False, default=str).encode()
    files["provenance.csv"] = rows_to_csv(prov_rows, ("kind", "ref", "id", "role"))
    for name, (png, pdf) in figures.items():
        files[f"figures/{name}.png"] = png
        files[f"figures/{name}.pdf"] = pdf
    intro = _intro(data, cfg.with_paper)
    if cfg.markdown:
        from morfic_cli.report.markdown import claims_markdown, document_markdown, table_markdown

        md = []
        for s in sections:
            body = "\n\n".join(
                x
                for x in [s.text, claims_markdown(s.claims), *(table_markdown(_paper_title(t)) for t in s.tables)]
                if x
            )
            md.append((s.heading, body))
        if figures:
            fixed = [n for n in figures if not n.startswith(SPEED_PREFIX)]
            shown = [f"![{FIGURES[n]}](figures/{n}.png)\n\n*{FIGURES[n]}*\n" for n in fixed]
            for run, names in _speed_groups([n for n in figures if n.startswith(SPEED_PREFIX)], run_names).items():
                shown.append(
                    " ".join(f"![{n}](figures/{n}.png)" for n in names) + f"\n\n*{SPEED_CAPTION.format(run=run)}*\n"
                )
            md.append(("Figures", "\n".join(shown)))
        table = ["| kind | ref | id | role |", "|---|---|---|---|"]
        table += [f"| {p['kind']} | {p['ref'] or '-'} | `{p['id']}` | {p['role']} |" for p in prov_rows]
        md.append(("Provenance", "Every artifact this report was built from:\n\n" + "\n".join(table)))
        files["report.md"] = document_markdown(cfg.title, md, intro=intro).encode()
    if cfg.latex:
        from morfic_cli.report.latex import (
            claims_latex,
            document_latex,
            escape,
            figure_grid_latex,
            figure_latex,
            longtable_latex,
            table_latex,
        )

        tex = []
        for s in sections:
            body = "\n\n".join(
                x
                for x in [
                    escape(s.text) if s.text else "",
                    claims_latex(s.claims),
                    *(table_latex(_paper_title(t)) for t in s.tables),
                ]
                if x
            )
            tex.append((s.heading, body or escape("Nothing in the store for this section.")))
        if figures:
            fixed = [figure_latex(f"figures/{n}.pdf", FIGURES[n]) for n in figures if not n.startswith(SPEED_PREFIX)]
            grids = []
            for run, names in _speed_groups([n for n in figures if n.startswith(SPEED_PREFIX)], run_names).items():
                chunks = [names[i : i + SPEED_PER_FIGURE] for i in range(0, len(names), SPEED_PER_FIGURE)]
                for k, chunk in enumerate(chunks):
                    part = f" (part {k + 1} of {len(chunks)})" if len(chunks) > 1 else ""
                    grids.append(
                        figure_grid_latex(
                            [f"figures/{n}.pdf" for n in chunk], SPEED_CAPTION.format(run=run) + part, per_row=2
                        )
                    )
            tex.append(("Figures", "\n\n".join(fixed + grids)))
        tex.append(
            (
                "Provenance",
                escape("Every artifact this report was built from (`morfic store show ID`):")
                + "\n\n"
                + longtable_latex(
                    ("kind", "ref", "id", "role"),
                    [(p["kind"], p["ref"] or "-", p["id"], p["role"]) for p in prov_rows],
                    "llp{0.5\\linewidth}l",
                ),
            )
        )
        files["report.tex"] = document_latex(cfg.title, tex, preamble_note=intro).encode()
    return files


REPORT_LAYOUT = 10
"""The report's layout (tables, sections, wording); bump it with any change to what a report of the same results
shows. 2: the every-variant zero-shot table; fixed-rollout rows per frozen actor. 3: training curves as the mean
and min-max band over seeds, legends off the data. 4: the critic-study section. 5: a run's diagnoses at two
commands are separate rows, never two seeds (the critic and fixed-rollout tables at 2.0 m/s, then at 1.0 m/s).
6: the claims' verdicts from Holm-corrected t tests, with the seeds each undecided comparison would need.
7: the external baselines' section (the paper's rows and ours, their EV figure and compute); the paper's own
variants' tables and claims without them. 8: issue 58's goal section (with runs of the actuation variants).
9: the goal section's "what ended the failed episodes" tables (where the evals recorded termination counts).
10: the goal tables' intervals of S clipped to [0, 1]."""


def report_config(cfg: ReportCfg, data: StoreData) -> dict[str, Any]:
    """The config of a stored report: options, runs (not the name of its ref) and :data:`REPORT_LAYOUT`."""
    doc = asdict(cfg)
    doc.pop("name")
    if not doc["presets"]:  # the runs list says which runs; an unfiltered report keeps its earlier config
        doc.pop("presets")
    doc["runs"] = sorted(r.spec for r in data.runs)
    doc["layout"] = REPORT_LAYOUT
    return json.loads(json.dumps({"report": "morfic", **doc}))


def build_report(
    store: Store, cfg: ReportCfg, *, out: Path | None = None, on_stage: Callable[[str], None] | None = None
) -> ReportResult:
    """Build (or find) the report of ``cfg`` and store it; with ``out``, also write its files there.

    Raises:
        MorficError: No runs in the store, or a spec that is not a run.
    """
    from morfic_cli.report.support import SUPPORT_REF, ensure_support_table

    stage = on_stage or (lambda _s: None)
    runs = filter_presets(resolve_runs(store, cfg.runs), cfg.presets)  # bad specs fail before any message
    stage(f"reading the results of {len(runs)} runs")
    data = gather(store, runs)
    support_id, _ = ensure_support_table(store)
    tables = compare_tables(data, with_paper=cfg.with_paper)
    compare, _ = store_comparison(store, data, tables, with_paper=cfg.with_paper)
    prov = [
        *data.provenance,
        Provenance(support_id, "table", SUPPORT_REF, "table/morphology-support"),
        Provenance(compare.id, "table", COMPARE_REF, "table/compare-baselines"),
    ]
    config = report_config(cfg, data)
    inputs = {p.role: p.id for p in prov}
    ref = REPORTS_PREFIX + cfg.name
    existing = find_manifest(store, "report", config, inputs)
    pdf_error = None
    if existing is None:
        support = read_csv_rows(store.read_file(support_id, "support.csv"))
        sections = _sections(data, tables, support, cfg.with_paper)
        figures = {}
        if cfg.figures:
            stage("drawing figures")
            from morfic_cli.report import figures as F

            figures = {
                "ev": F.ev_figure(without_external(at_command(tables.get("calibration", []), PAPER_COMMAND))),
                **ev_external_figure(at_command(tables.get("calibration", []), PAPER_COMMAND)),
                "distance": F.distance_figure(tables.get("transfer", []), with_paper=cfg.with_paper),
                "compute": F.compute_figure(tables.get("compute", []), with_paper=cfg.with_paper),
                "curves": F.curves_figure(
                    data.curves, {r.name: r.variant for r in runs}, {r.name: r.preset for r in runs}
                ),
                **eval_figures(store, data.evals),
            }
        stage("writing the report")
        files = render(cfg, data, sections, prov, figures)
        if cfg.latex:
            from morfic_cli.report.latex import NO_PDF_ENV, compile_pdf, pdf_skipped, pdflatex

            if pdf_skipped():
                pdf_error = f"{NO_PDF_ENV} is set; report.tex is written, report.pdf is not"
            elif pdflatex() is not None:
                stage("compiling the PDF")
                try:
                    files["report.pdf"] = compile_pdf(
                        files["report.tex"].decode(), {k: v for k, v in files.items() if k.startswith("figures/")}
                    )
                except RuntimeError as exc:
                    pdf_error = str(exc)
            else:
                pdf_error = "pdflatex is not installed; report.tex is written, report.pdf is not"
        n_tables = sum(len(s.tables) for s in sections)
        pub = store.publish(
            "report",
            ref,
            config=config,
            inputs=inputs,
            files=files,
            meta={"tables": n_tables, "runs": [r.name for r in runs], "pdf_error": pdf_error},
        )
    else:
        pub = store.publish("report", ref, config=config, inputs=inputs, reuse=True)
    existing, version, reused = pub.id, pub.advanced()[1], pub.reused
    manifest = store.read_manifest(existing)
    result = ReportResult(
        existing,
        ref,
        version,
        sorted(manifest.files),
        reused,
        int(manifest.meta.get("tables", 0)),
        prov,
        pdf_error=manifest.meta.get("pdf_error"),
    )
    if out is not None:
        result.out_files = write_out(store, existing, out)
    return result


def write_out(store: Store, report_id: str, out: Path) -> list[Path]:
    """Copy every file of a stored report into the folder ``out`` (created); returns the paths written.

    Raises:
        StoreError: A file name that would leave ``out`` (a report imported from an untrusted bundle).
    """
    from morfic_cli.store.manifest import safe_join

    manifest = store.read_manifest(report_id)
    Path(out).mkdir(parents=True, exist_ok=True)
    paths = []
    for name in sorted(manifest.files):
        path = safe_join(Path(out), name)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(store.read_file(report_id, name))
        paths.append(path)
    return paths
