"""``morfic robots``: the robot library, its 11-D descriptors and the generated MJCF."""

from __future__ import annotations

import sys
from typing import Annotated, Any

import typer

from morfic_cli.cli._options import FormatOpt, OutputFormat
from morfic_cli.cli._render import Column, emit_object, emit_rows

app = typer.Typer(
    no_args_is_help=True,
    help=(
        "The robot library (robots/<name>.toml, env MORFIC_ROBOTS_DIR): facts with units and sources, "
        "the paper's 11-D morphology descriptor, and the MuJoCo model built from them.\n\n"
        "Example: morfic robots show go1 --xml"
    ),
)


def _mark_cell(value: Any) -> str:
    return str(value) if value else ""


@app.command("ls")
def ls(fmt: FormatOpt = OutputFormat.table) -> None:
    """List the robots: masses, standing height, template flag, descriptor dims outside the support.

    Example: morfic robots ls --format json
    """
    from morfic_cli.morphology.builder import nominal_height
    from morfic_cli.morphology.robots import iter_robots

    rows = []
    for spec in iter_robots():
        flags = spec.support_flags()
        rows.append(
            {
                "robot": spec.name,
                "display_name": spec.display_name,
                "total_mass_kg": round(spec.total_mass, 4),
                "base_mass_kg": round(spec.base_mass, 4),
                "nominal_height_m": round(nominal_height(spec), 4),
                "template": spec.is_template,
                "n_outside_support": int((flags != 0).sum()),
            }
        )
    emit_rows(
        rows,
        fmt,
        columns=[
            Column("robot"),
            Column("display_name", "name"),
            Column("total_mass_kg", "total mass (kg)", justify="right"),
            Column("base_mass_kg", "base mass (kg)", justify="right"),
            Column("nominal_height_m", "nominal height (m)", justify="right"),
            Column("template", fmt=lambda v: "yes" if v else "", justify="center"),
            Column("n_outside_support", "dims outside support", justify="right"),
        ],
        title="Robot library",
    )


@app.command("show")
def show(
    name: Annotated[str, typer.Argument(help="Robot name (see `morfic robots ls`).")],
    xml: Annotated[bool, typer.Option("--xml", help="Print the generated MJCF instead of the facts.")] = False,
    fmt: FormatOpt = OutputFormat.table,
) -> None:
    """Show one robot's facts (value, unit, source), its descriptor with out-of-support marks, and conflicts.

    Example: morfic robots show anymal_c --format json
    """
    from morfic_cli.morphology.builder import nominal_height, to_xml
    from morfic_cli.morphology.robots import conflict_rows, descriptor_rows, fact_rows, load_robot

    spec = load_robot(name)
    if xml:
        sys.stdout.write(to_xml(spec))
        return
    facts, descriptor, conflicts = fact_rows(spec), descriptor_rows(spec), conflict_rows(spec)
    summary = {
        "robot": spec.name,
        "display_name": spec.display_name,
        "template": spec.is_template,
        "source_path": str(spec.source_path),
        "total_mass_kg": round(spec.total_mass, 4),
        "public_total_mass_kg": spec.public_total_mass,
        "nominal_height_m": round(nominal_height(spec), 4),
    }
    if fmt == OutputFormat.json:  # values as numbers and lists, not the table's text
        emit_object(
            {
                **summary,
                "facts": fact_rows(spec, raw=True),
                "descriptor": descriptor,
                "descriptor_source": spec.descriptor_source,
                "conflicts": conflict_rows(spec, raw=True),
            },
            fmt,
        )
        return
    if fmt == OutputFormat.csv:
        rows = [{"section": "summary", "field": k, "value": v, "unit": "", "source": ""} for k, v in summary.items()]
        rows += [{"section": "fact", **r} for r in facts]
        rows += [
            {
                "section": "descriptor",
                "field": r["name"],
                "value": r["value"],
                "unit": r["unit"],
                "source": spec.descriptor_source,
                "mark": r["mark"],
            }
            for r in descriptor
        ]
        emit_rows(rows, fmt)
        return
    emit_rows([{"field": k, "value": v} for k, v in summary.items()], fmt, title=f"{spec.display_name} ({spec.name})")
    emit_rows(facts, fmt, columns=[Column("field"), Column("value"), Column("unit"), Column("source")], title="Facts")
    emit_rows(
        descriptor,
        fmt,
        columns=[
            Column("name"),
            Column("value", justify="right"),
            Column("unit"),
            Column("train_min", "train min", justify="right"),
            Column("train_max", "train max", justify="right"),
            Column("mark", "support", fmt=_mark_cell, justify="center"),
        ],
        title="11-D descriptor (paper); ↑/↓ = above/below the training support",
        caption=spec.descriptor_source,
    )
    if conflicts:
        emit_rows(conflicts, fmt, title="Conflicts with public sources")
