"""``morfic report``: the paper's tables and figures from what the store holds."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, QuietOpt, StoreOpt
from morfic_cli.cli._render import emit_object, info
from morfic_cli.validation import check_args


def report(
    runs: Annotated[
        list[str] | None, typer.Argument(help="Run refs or checkpoint ids to report on; none: every run in the store.")
    ] = None,
    preset: Annotated[
        str | None,
        typer.Option(
            "--preset",
            help="Only the runs trained with this preset (smoke, "
            "cpu, paper; comma-separated for several), so smoke runs do not sit "
            "beside cpu runs.",
        ),
    ] = None,
    latex: Annotated[
        bool,
        typer.Option(
            "--latex", help="Write a standalone report.tex (booktabs), and report.pdf where pdflatex is installed."
        ),
    ] = False,
    markdown: Annotated[
        bool,
        typer.Option("--markdown", help="Write report.md (the default when neither --latex nor --markdown is given)."),
    ] = False,
    figures: Annotated[bool, typer.Option("--figures", help="Draw the figures (PNG and PDF).")] = False,
    with_paper: Annotated[
        bool, typer.Option("--with-paper", help="Put the paper's published tables after ours.")
    ] = False,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Also write the report's files into this directory.")
    ] = None,
    name: Annotated[str, typer.Option("--name", help="The report's ref is reports/NAME.")] = "latest",
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Build the paper's tables and figures from what is in the store, as a report artifact.

    Tables (for what the store holds): zero-shot transfer ("v ± σ / S", best per robot in bold), ablation,
    transfer at 2.5 m/s, critic diagnostics (EV, |NVB|/NVE/ASA), fixed-rollout (Flip/Cos.), training compute and
    morphology support; figures: EV per variant and robot, v_x against morphology distance, compute against
    transitions, training curves. A Provenance section lists every artifact id the numbers come from. The same
    store content and options find the stored report again instead of rebuilding it. Prints the report's ref,
    id and files on stdout.

    Example: morfic report --preset cpu --latex --markdown --figures --out report/
    """
    check_args(store=store, out_dir=out, report_name=name, specs=runs)
    from morfic_cli.report.build import ReportCfg, build_report
    from morfic_cli.store import Store

    presets = tuple(p.strip() for p in (preset or "").split(",") if p.strip())
    cfg = ReportCfg(
        runs=tuple(runs or ()),
        presets=presets,
        latex=latex,
        markdown=markdown or not latex,
        figures=figures,
        with_paper=with_paper,
        name=name,
    )
    st = Store(store)
    result = build_report(st, cfg, out=out, on_stage=None if quiet else (lambda s: info(f"report: {s} ...")))
    if not quiet:
        how = "found" if result.reused else "stored"
        info(
            f"{how} {result.ref}@{result.version} ({result.id[:12]}): {result.tables} tables, "
            f"{len(result.provenance)} artifacts in its provenance"
        )
        if latex and result.pdf_error:
            info(f"note: no PDF: {result.pdf_error.splitlines()[0]}")
        if out is not None:
            info(f"wrote {len(result.out_files)} files to {out}")
        if not presets:
            from morfic_cli.report.gather import resolve_runs

            mixed = sorted({r.preset for r in resolve_runs(st, cfg.runs)})
            if len(mixed) > 1:
                info(
                    f"note: the report mixes runs of presets {', '.join(mixed)}; --preset {mixed[0]} (or another) "
                    "reports one"
                )
    emit_object(
        {
            "ref": f"{result.ref}@{result.version}",
            "id": result.id,
            "reused": result.reused,
            "files": result.files,
            "out": str(out) if out is not None else None,
            "provenance": len(result.provenance),
        },
        fmt,
    )
