"""Rendering of command output: data rows to stdout (table/json/csv), messages to stderr."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from morfic_cli.cli._options import OutputFormat

#: Human messages (progress, "wrote artifact ...") go here, never to stdout.
err_console = Console(stderr=True, soft_wrap=True)  # messages are not hard-wrapped; the terminal wraps them
out_console = Console()


@dataclass(frozen=True)
class Column:
    """One column of a printed table.

    Attributes:
        key: Row dict key.
        header: Header shown in the rich table (defaults to ``key``).
        fmt: Formatter for the rich table cell; json/csv always get the raw value.
        justify: rich justification ("left", "right", "center").
        no_wrap: Keep the cell on one line (rich shrinks other columns first).
        overflow: What a cell too long for its column does: "ellipsis" (cut, rich's default) or "fold" (wrap
            at any character, nothing lost: paths a user copies).
    """

    key: str
    header: str | None = None
    fmt: Callable[[Any], str] | None = None
    justify: str = "left"
    no_wrap: bool = False
    overflow: str = "ellipsis"


def _cell(value: Any, col: Column) -> str:
    if col.fmt is not None:
        return col.fmt(value)
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}" if math.isfinite(value) else str(value)
    return str(value)


def emit_rows(
    rows: Sequence[dict[str, Any]],
    fmt: OutputFormat,
    columns: Sequence[Column] | None = None,
    title: str | None = None,
    caption: str | None = None,
) -> None:
    """Print ``rows`` on stdout in the requested format.

    Args:
        rows: One dict per row. json/csv print every key; the table prints ``columns``.
        fmt: table (rich), json (a list of objects) or csv (pandas, header line first).
        columns: Columns of the rich table; default every key of the first row.
        title: Title of the rich table.
        caption: Caption under the rich table.
    """
    rows = list(rows)
    if fmt == OutputFormat.json:
        sys.stdout.write(json.dumps(json_safe(list(rows)), indent=2, default=str, ensure_ascii=False) + "\n")
        return
    if fmt == OutputFormat.csv:
        import pandas as pd

        frame = pd.DataFrame(rows, columns=list(rows[0].keys()) if rows else None)
        frame.to_csv(sys.stdout, index=False)
        return
    cols = list(columns) if columns else [Column(k) for k in (rows[0].keys() if rows else [])]
    table = Table(title=title, caption=caption)
    for col in cols:
        table.add_column(col.header or col.key, justify=col.justify, no_wrap=col.no_wrap,  # type: ignore[arg-type]
                         overflow=col.overflow)  # type: ignore[arg-type]
    for row in rows:
        table.add_row(*(Text(_cell(row.get(col.key), col)) for col in cols))  # Text: no markup in cells
    out_console.print(table)


def json_safe(obj: Any) -> Any:
    """``obj`` with non-finite floats (NaN, inf) replaced by None, so the JSON printed is valid JSON."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    return obj


def flatten(obj: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """``(dotted key, leaf value)`` pairs of nested dicts; lists of plain values stay one leaf.

    Example: ``{"a": {"b": 1}, "c": [1, 2]}`` -> ``[("a.b", 1), ("c", [1, 2])]``.
    """
    if isinstance(obj, dict) and obj:
        return [pair for k, v in obj.items() for pair in flatten(v, f"{prefix}.{k}" if prefix else str(k))]
    if isinstance(obj, list | tuple) and any(isinstance(v, dict) for v in obj):
        return [pair for i, v in enumerate(obj) for pair in flatten(v, f"{prefix}[{i}]")]
    return [(prefix or "value", obj)]


def _plain(value: Any) -> str:
    """A leaf value as table text: lists comma-separated, None as '-', floats to 6 significant digits."""
    if isinstance(value, list | tuple):
        return ", ".join(_plain(v) for v in value) if value else "-"
    if isinstance(value, dict):
        return "-"  # an empty dict
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def emit_object(obj: Any, fmt: OutputFormat, title: str | None = None) -> None:
    """Print one object: JSON for json, a key/value table for table (never JSON), key,value CSV for csv.

    The table and CSV flatten nested dicts into dotted keys (:func:`flatten`).
    """
    obj = json_safe(obj)
    if fmt == OutputFormat.csv and isinstance(obj, dict):
        emit_rows([{"key": k, "value": json.dumps(v) if isinstance(v, dict | list) else v}
                   for k, v in obj.items()], fmt)
        return
    if fmt == OutputFormat.table:
        table = Table(title=title, show_header=False)
        table.add_column("key", style="bold")
        table.add_column("value", overflow="fold")
        for key, value in flatten(obj):
            table.add_row(Text(key), Text(_plain(value)))
        out_console.print(table)
        return
    sys.stdout.write(json.dumps(obj, indent=2, default=str) + "\n")


def info(message: str) -> None:
    """A human message on stderr."""
    err_console.print(message)
