"""``morfic store``: inspect and maintain the artifact store (thin: the logic is in morfic_cli.store)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich.markup import escape

from morfic_cli.cli._options import DEFAULT_STORE, FormatOpt, OutputFormat, StoreOpt
from morfic_cli.cli._render import Column, emit_object, emit_rows, err_console, info
from morfic_cli.errors import MorficError, StoreError, printable
from morfic_cli.store import MANIFEST_KINDS, Store
from morfic_cli.store.transfer import appends_results, export_path
from morfic_cli.validation import check_args

app = typer.Typer(
    help=(
        "Inspect and maintain the artifact store: list and show artifacts, verify hashes, collect "
        "garbage, move artifacts between machines.\n\nExample: morfic store ls --format json"
    ),
    no_args_is_help=True,
)


def human_size(size: Any) -> str:
    """Bytes as a short human string (``1.5 MiB``); ``-`` for ``None``."""
    if size is None:
        return "-"
    value = float(size)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{int(value)} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{value:.1f} GiB"


def _left_out(omitted: Any, files: Any = ()) -> str:
    """The note on what a weights-only or results-only export left out (``omitted``, ``files``: their ids)."""
    if files:
        return (
            f"{len(omitted)} trainer state(s) and {len(files)} weight, rollout-log, curve and figure file(s) left "
            "out (results only: `morfic report` reads it and draws the figures; it cannot evaluate, diagnose or "
            "resume)"
        )
    return f"{len(omitted)} trainer state(s) left out (weights only: evaluates and exports, cannot be resumed)"


def _short_id(oid: Any) -> str:
    return str(oid)[:12] if oid else "-"


def _short_time(time: Any) -> str:
    return str(time)[:19].replace("T", " ") if time else "-"


_LS_COLUMNS = [
    Column("ref"),
    Column("id", fmt=_short_id),
    Column("kind"),
    Column("created", header="created (UTC)", fmt=_short_time, drop=2),
    Column("files", justify="right", drop=3),
    Column("size", fmt=human_size, justify="right", no_wrap=True, drop=1),
]


def _emit(rows: list[dict[str, Any]], fmt: OutputFormat, columns: list[Column], title: str) -> None:
    """emit_rows, plus a header line for an empty CSV so scripts still see the column names."""
    if not rows and fmt == OutputFormat.csv:
        sys.stdout.write(",".join(c.key for c in columns) + "\n")
        return
    emit_rows(rows, fmt, columns, title=title)


@app.command("ls")
def ls(
    kind: Annotated[Optional[str], typer.Option("--kind", help=f"Only this kind: {', '.join(MANIFEST_KINDS)}.")] = None,
    all_: Annotated[
        bool,
        typer.Option(
            "--all",
            help="Also list unnamed artifacts (the inputs refs point to: trainer states, "
            "rollouts, ...) and old ref versions (shown as name@N).",
        ),
    ] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """List the artifacts (manifests) a ref names, oldest first; --all lists every one.

    Unnamed artifacts (a run's trainer states, an eval's rollouts, ...) are counted on stderr, not listed: a store
    with the results bundles imported holds a thousand of them.

    Example: morfic store ls --kind run --format json
    """
    rows = Store(store).ls(kind, include_superseded=all_)
    unnamed = [] if all_ else [r for r in rows if r["ref"] is None]
    rows = rows if all_ else [r for r in rows if r["ref"] is not None]
    if not rows and not unnamed:
        info(f"no artifacts{f' of kind {kind}' if kind else ''} in store {escape(str(store))}")
    _emit(rows, fmt, _LS_COLUMNS, title=f"artifacts in {store}")
    if unnamed:
        size = human_size(sum(r["size"] or 0 for r in unnamed))
        info(
            f"{len(unnamed)} unnamed artifact(s) not listed ({size} held here; the inputs of the refs above, such as "
            "trainer states and rollouts); --all lists them and the old ref versions."
        )


@app.command("show")
def show(
    spec: Annotated[str, typer.Argument(help="Ref (runs/film-cpu-s0), ref@N, id or unique id prefix.")],
    history: Annotated[bool, typer.Option("--history", help="List every version of the ref instead.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Print one manifest (or, with --history, every version of a ref).

    Example: morfic store show runs/film-cpu-s0@1
    """
    st = Store(store)
    if not history:
        emit_object(st.describe(spec), fmt)
        return
    entries = st.ref_history(spec)
    rows = [{"version": e.version, "id": e.id, "time": e.time, "current": e.version == len(entries)} for e in entries]
    columns = [
        Column("version", justify="right"),
        Column("id", fmt=_short_id),
        Column("time", header="time (UTC)", fmt=_short_time),
        Column("current"),
    ]
    _emit(rows, fmt, columns, title=f"history of {spec}")


@app.command("get")
def get(
    spec: Annotated[str, typer.Argument(help="Ref (runs/film-cpu-s0), ref@N, id or unique id prefix.")],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Directory to write the files into (created if missing); each file's path is printed."
        ),
    ],
    files: Annotated[
        Optional[list[str]], typer.Option("--file", help="Only this file of the artifact (repeatable).")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace files that exist in DIR.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Copy an artifact's files out of the store into DIR, byte for byte, under readable names; print their paths.

    Files keep their names in the artifact (model.pt, eval.csv, table.csv, policy.onnx); a rollout's
    rollout.mcap is named after its robot, mode and command (go1-descriptor-vx2.0.mcap). A file that exists in DIR
    is kept (nothing is written) unless --force. Only plain names are written (no hidden part such as .config/, no
    .py or .pth; docs/concepts.md), and never two files to one path, so no artifact can plant configuration or
    code, whatever DIR is.

    Example: morfic store get runs/film-cpu-s0 --file model.pt --out ckpt/
    """
    from morfic_cli.store.get import get_files

    got = get_files(Store(store), spec, out, files, force=force)
    rows = [{"file": g.name, "path": str(g.path), "id": g.id, "size": g.size} for g in got]
    columns = [
        Column("file"),
        Column("path", overflow="fold"),
        Column("id", fmt=_short_id),
        Column("size", fmt=human_size, justify="right"),
    ]
    _emit(rows, fmt, columns, title=f"files of {spec}")


@app.command("verify")
def verify(store: StoreOpt = DEFAULT_STORE) -> None:
    """Rehash every object and check the manifest index and refs; exit 1 if anything is wrong.

    Example: morfic store verify --store artifacts
    """
    report = Store(store).verify()
    for problem in report.problems:
        err_console.print(f"  {printable(problem)}", markup=False, highlight=False, soft_wrap=True)
    if not report.ok:
        raise StoreError(
            f"{len(report.problems)} problem(s) found in store {store} (listed above); restore "
            "damaged objects from an export (`morfic store import`) or drop what no longer "
            "matters and run `morfic store gc`."
        )
    leftovers = (
        f"; {report.temp_files} leftover temp file(s), `morfic store gc --yes` removes them"
        if report.temp_files
        else ""
    )
    omitted = f"; {report.omitted} trainer state(s) left out by a weights-only import" if report.omitted else ""
    if report.omitted_files:
        omitted = (
            f"; {report.omitted} trainer state(s) and {report.omitted_files} weight, rollout-log, curve and "
            "figure file(s) left out by a results-only import"
        )
    info(
        f"store {escape(str(store))} OK: {report.objects} objects ({human_size(report.bytes)}), "
        f"{report.manifests} manifests, {report.refs} refs checked{leftovers}{omitted}"
    )


@app.command("gc")
def gc(
    yes: Annotated[bool, typer.Option("--yes", "-y", help="Really delete; without it gc only reports.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Remove objects that no version of any ref reaches (a dry run unless --yes).

    Example: morfic store gc --yes
    """
    report = Store(store).gc(dry_run=not yes)
    rows = [{"id": i.id, "kind": i.kind, "size": i.size} for i in report.removed]
    if rows or fmt != OutputFormat.table:
        columns = [Column("id"), Column("kind"), Column("size", fmt=human_size, justify="right")]
        _emit(rows, fmt, columns, title="unreachable objects")
    what = (
        f"{len(rows)} unreachable object(s) ({human_size(report.removed_bytes)}) and "
        f"{report.temp_files} leftover temp file(s); {report.reachable} reachable object(s) kept"
    )
    if report.dry_run:
        hint = "; run `morfic store gc --yes` to delete them" if rows or report.temp_files else ""
        info(f"dry run: would remove {what}{hint}")
    else:
        info(f"removed {what}")


@app.command("export")
def export(
    refs: Annotated[list[str], typer.Argument(help="Ref names to export, with every version.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Directory to write the tar into (created if missing).")],
    name: Annotated[
        Optional[str],
        typer.Option(
            "--name",
            help="The tar's file name, NAME.tar (default: one ref's last part, e.g. "
            "film-cpu-s0.tar; several refs' last parts joined by '+').",
        ),
    ] = None,
    latest: Annotated[
        bool,
        typer.Option(
            "--latest",
            help="Only each ref's current version (a small snapshot, "
            "e.g. a trained policy without its earlier checkpoints).",
        ),
    ] = False,
    without_trainer_state: Annotated[
        bool,
        typer.Option(
            "--without-trainer-state",
            help="A weights-only bundle: leave out the runs' trainer states (optimiser, env "
            "state, RNG; most of a run's size); it evaluates and exports, but cannot be resumed.",
        ),
    ] = False,
    results_only: Annotated[
        bool,
        typer.Option(
            "--results-only",
            help="A results-only bundle of the named runs (runs/NAME; other refs are an error): each "
            "run's current checkpoint (config, curve table) and every eval, diagnosis and check made from it (tables), "
            "without weights, trainer states, rollout logs, rendered figures or other runs' curves. `morfic report` "
            "reads it and draws its figures from the tables; it cannot evaluate, diagnose or resume.",
        ),
    ] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite the tar if it exists.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Write the named refs and everything they reach into one tar file, DIR/NAME.tar; print its path.

    The tar is named after the refs unless --name says otherwise: runs/film-cpu-s0 -> film-cpu-s0.tar;
    runs/film-cpu-s0 runs/film-cpu-s1 -> film-cpu-s0+film-cpu-s1.tar; five refs -> film-cpu-s0+4-more.tar. An existing
    tar is kept unless --force. With --latest only the current version of each ref goes in; it arrives as version
    1 of that ref. With --results-only the refs are runs: each goes in as with --latest, together with the refs
    of their evals and diagnoses (evals/NAME, diagnoses/...) up to the run's last result (docs/concepts.md).

    Example: morfic store export runs/film-cpu-s0 runs/film-cpu-s1 --out bundles/ --name film
    """
    check_args(store=store, out_dir=out, specs=refs)
    path = export_path(out, refs, name, force=force)
    report = Store(store).export_tar(
        refs, path, latest=latest, without_trainer_state=without_trainer_state, results_only=results_only
    )
    info(
        f"exported {len(report.refs)} ref(s), {report.objects} objects ({human_size(report.bytes)}) "
        f"to {escape(str(report.path))}"
    )
    if report.omitted or report.omitted_files:
        info(_left_out(report.omitted, report.omitted_files))
    if fmt == OutputFormat.table:  # the path alone, whole (a table would fold a long one), for `$(...)`
        sys.stdout.write(f"{report.path}\n")
        return
    emit_object(
        {
            "path": str(report.path),
            "refs": report.refs,
            "objects": report.objects,
            "bytes": report.bytes,
            "omitted": sorted(report.omitted),
            "omitted_files": sorted(report.omitted_files),
        },
        fmt,
    )


def _say_user_variants(bundle: str, named: dict[str, list[str]]) -> None:
    """A line per user variant (not stock) an imported bundle's runs name: its refs, and whether this user trusts it."""
    from morfic_cli.rl.variants import STOCK, is_trusted

    for variant, refs in named.items():
        if variant in STOCK:
            continue
        shown = escape(", ".join(refs[:5])) + (f" and {len(refs) - 5} more" if len(refs) > 5 else "")
        how = (
            "trusted here"
            if is_trusted(variant)
            else f"NOT trusted here: commands on them import it only with --trust-variant {variant}, or after "
            f"`morfic trust {variant}`"
        )
        info(
            f"{escape(bundle)}: needs the user variant {variant} (code morfic imports to rebuild the models) for "
            f"{shown}; {how}"
        )


@app.command("import")
def import_(
    paths: Annotated[list[Path], typer.Argument(help="Tar files made by `morfic store export`, one or more.")],
    append: Annotated[
        bool,
        typer.Option(
            "--append",
            help="A result ref this store holds with another history (a shared log such as "
            "diagnoses/calibration, from bundles of different stores) gets the import's versions it "
            "never pointed at appended after its own, instead of being refused as diverged. A run's "
            "ref (runs/NAME) is never appended to: a diverged one is another run of that name.",
        ),
    ] = False,
    fmt: FormatOpt = OutputFormat.table,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Import export tars, one after the other (rehashes every object; safe to run twice).

    Prints a row per ref of each tar (bundle, ref, status) and, on stderr, a line per tar. A tar that cannot be
    imported gets its own `Error:` line and leaves the store as it was; the others are imported all the same,
    and the command exits 1 at the end.

    Nothing in a bundle is executed. A line on stderr names each user variant (module.path:Class) its runs need,
    with their refs and whether you trust it (`morfic trust`); commands import it only with your consent. A
    bundle naming a variant that is not a well-formed name is refused.

    Bundles of one store merge in any order. Bundles of different stores (the shipped results bundles come
    from several) can each hold their own history of a shared ref such as diagnoses/calibration; a history that is
    not a prefix of the store's is refused as diverged unless --append adds its versions after the store's
    (results are found by their manifests, so only the version numbers differ with the import order; reports cite ids).

    Example: morfic store import artifacts/bundles/*.tar --store artifacts
    """
    import os

    st = Store(store)
    rows: list[dict[str, Any]] = []
    failed: list[str] = []
    for path in paths:
        try:
            report = st.import_tar(path, append=appends_results if append else False)
        except MorficError as exc:
            if len(paths) == 1 or os.environ.get("MORFIC_DEBUG", "") not in ("", "0"):
                raise
            err_console.print(f"Error: {printable(exc, keep=chr(10))}", markup=False, highlight=False, soft_wrap=True)
            failed.append(path.name)
            continue
        rows += [{"bundle": path.name, "ref": name, "status": status} for name, status in report.refs.items()]
        repaired = f", {report.objects_repaired} corrupt here and repaired" if report.objects_repaired else ""
        left_out = (
            f"; {_left_out(report.omitted, report.omitted_files)}" if report.omitted or report.omitted_files else ""
        )
        filled = f"; {len(report.filled)} left-out object(s) filled in" if report.filled else ""
        info(
            f"{escape(path.name)}: imported {report.objects_added} new object(s) ({report.objects_present} already "
            f"present{repaired}), {len(report.refs)} ref(s) into {escape(str(store))}{left_out}{filled}"
        )
        _say_user_variants(path.name, report.variants)
    if rows or not failed:
        title = f"refs imported from {paths[0].name}" if len(paths) == 1 else f"refs imported from {len(paths)} tars"
        _emit(rows, fmt, [Column("bundle"), Column("ref"), Column("status")], title=title)
    if failed:
        done = f"; the other {len(paths) - len(failed)} were imported" if len(failed) < len(paths) else ""
        raise StoreError(
            f"{len(failed)} of {len(paths)} tar(s) not imported ({', '.join(failed)}; why above){done}. "
            "Fix or replace those and import them again (importing a tar twice is safe)."
        )
