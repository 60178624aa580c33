"""``morfic distance``: normalised morphology distance to the training robot, eq. (morph_dist)."""

from __future__ import annotations

from typing import Annotated

import typer

from morfic_cli.cli._options import (
    DEFAULT_STORE,
    FormatOpt,
    Normalize,
    OutputFormat,
    QuietOpt,
    RobotsOpt,
    StoreOpt,
)
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.validation import check_args


def distance(
    robots: RobotsOpt = "all",
    reference: Annotated[str, typer.Option("--reference", help="Robot whose descriptor is m_train.")] = "go2",
    normalize: Annotated[
        Normalize,
        typer.Option(
            "--normalize",
            help="span: min/max over the support and all robots (d in [0,1]); support: the training support only.",
        ),
    ] = Normalize.span,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Normalised 11-D morphology distance of each robot to the reference, eq. (morph_dist).

    d = ||m~_target - m~_train||_2 / sqrt(11), m~ min-max normalised per dimension. The table is
    also written into the store as a CSV table artifact (ref tables/distance).

    Example: morfic distance --robots go1,a1,b1 --format json
    """
    check_args(store=store, robots=robots, reference=reference)
    from morfic_cli.morphology.distance import distance_table, parse_robot_list
    from morfic_cli.recording.tables import write_distance_table

    names = parse_robot_list(robots)
    ref_name = parse_robot_list(reference)[0]
    rows = distance_table(names, ref_name, normalize.value)
    flat = [r.as_row(ref_name, normalize.value) for r in rows]
    artifact = write_distance_table(store, flat, names, ref_name, normalize.value)
    if fmt == OutputFormat.json:  # the out-of-support dimensions as a list, not the table's joined text
        shown = [
            {**row, "outside": [{"dim": k, "side": "above" if v > 0 else "below"} for k, v in r.outside.items()]}
            for row, r in zip(flat, rows, strict=True)
        ]
    else:
        shown = flat
    emit_rows(
        shown,
        fmt,
        columns=[
            Column("robot"),
            Column("d", fmt=lambda v: f"{v:.3f}", justify="right"),
            Column("n_outside", "dims outside support", justify="right"),
            Column("outside", "outside the training support (↑ above, ↓ below)"),
        ],
        title=f"Normalised morphology distance to {ref_name} ({normalize.value})",
    )
    if not quiet:
        info(f"wrote table {artifact.id[:12]} (ref {artifact.ref}@{artifact.version}) to store {store}")
