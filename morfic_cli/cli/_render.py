"""Rendering of command output: data rows to stdout (table/json/csv), messages to stderr."""

from __future__ import annotations

import json
import math
import sys
import unicodedata
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from morfic_cli.cli._options import OutputFormat
from morfic_cli.errors import UNPRINTABLE, printable

#: Human messages (progress, "wrote artifact ...") go here, never to stdout. Not hard-wrapped (the terminal wraps
#: them); no emoji codes: a name such as ``evil.mod:X`` beside a colon would print as an emoji.
err_console = Console(stderr=True, soft_wrap=True, emoji=False)
out_console = Console(emoji=False)


@dataclass(frozen=True)
class Column:
    """One column of a printed table.

    Attributes:
        key: Row dict key.
        header: Header shown in the rich table (defaults to ``key``).
        fmt: Formatter for the rich table cell; json/csv always get the raw value.
        justify: rich justification ("left", "right", "center").
        no_wrap: Keep the cell on one line (rich shrinks other columns first).
        overflow: What a cell too long for its column does: "fold" (wrap at any character, nothing lost) or
            "ellipsis" (cut).
        whole: Never cut, fold or drop this column: what a user copies (refs, ids, runs, robots, modes). None:
            whole if ``key`` is one of :data:`WHOLE_KEYS`.
        drop: In a terminal too narrow for the table, columns with ``drop > 0`` are left out, highest first,
            until the rest fits (the caption names them; json/csv keep every column). 0: never left out.
    """

    key: str
    header: str | None = None
    fmt: Callable[[Any], str] | None = None
    justify: str = "left"
    no_wrap: bool = False
    overflow: str = "fold"
    whole: bool | None = None
    drop: int = 0

    @property
    def is_whole(self) -> bool:
        """Whether the column is shown whole (:attr:`whole`, else its key is one of :data:`WHOLE_KEYS`)."""
        return self.key in WHOLE_KEYS if self.whole is None else self.whole


#: Keys of columns a user copies into the next command; never cut (``Column.whole``).
WHOLE_KEYS = frozenset(
    {
        "ref",
        "id",
        "run",
        "name",
        "robot",
        "mode",
        "variant",
        "critic",
        "preset",
        "kind",
        "file",
        "path",
        "version",
        "bundle",
    }
)


def _cell(value: Any, col: Column) -> str:
    """A table cell's text; control characters escaped (:func:`~morfic_cli.errors.printable`: a bundle's meta)."""
    if col.fmt is not None:
        return printable(col.fmt(value))
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}" if math.isfinite(value) else str(value)
    return printable(value)


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
        text = json.dumps(json_safe(list(rows)), indent=2, default=str, ensure_ascii=False)
        sys.stdout.write(_json_text(text) + "\n")
        return
    if fmt == OutputFormat.csv:
        import pandas as pd

        frame = pd.DataFrame(rows, columns=list(rows[0].keys()) if rows else None)
        frame.to_csv(sys.stdout, index=False)
        return
    cols = list(columns) if columns else [Column(k) for k in (rows[0].keys() if rows else [])]
    cells = [[_cell(row.get(col.key), col) for col in cols] for row in rows]
    keep, widths = fit_columns(cols, cells, out_console.width)
    left_out = [col.header or col.key for i, col in enumerate(cols) if i not in keep]
    if left_out:
        note = f"left out at this terminal width: {', '.join(left_out)} (--format json or csv has every column)"
        caption = f"{caption}\n{note}" if caption else note
    table = Table(title=title, caption=caption)
    for i in keep:
        col = cols[i]
        folded = widths is not None and widths[i] < max((len(row[i]) for row in cells), default=0)
        table.add_column(
            col.header or col.key,
            justify=col.justify,  # type: ignore[arg-type]
            no_wrap=(col.no_wrap or col.is_whole) and not folded,
            overflow="fold" if col.is_whole else col.overflow,  # type: ignore[arg-type]
            width=None if widths is None else widths[i],
        )
    for row in cells:
        table.add_row(*(Text(row[i]) for i in keep))  # Text: no markup in cells
    out_console.print(table)


FOLD_FLOOR = 12
"""A whole column (a run name, a ref) folds down to this width before any other column folds."""


def _longest_word(text: str) -> int:
    return max((len(word) for word in text.split()), default=0)


def fit_columns(
    cols: Sequence[Column],
    cells: Sequence[Sequence[str]],
    width: int,
) -> tuple[list[int], list[int] | None]:
    """Which columns a rich table of ``width`` characters shows, and how wide, so that no whole column is cut.

    While the columns at their longest cells are wider than ``width``, the column with the highest ``drop`` is
    left out (rows stay one line). If the rest is still too wide, the widest wrapping columns give up characters,
    never below their longest word; whole and ``no_wrap`` columns keep their longest cell. When nothing else is
    left to shrink, the whole columns fold (wrap at any character, nothing lost), widest first, down to
    :data:`FOLD_FLOOR` characters: a long run name takes two lines and the numbers keep their width. Only then do
    the other columns fold, and last the whole ones below the floor.

    Args:
        cols: The columns, n of them.
        cells: The formatted cells, one list of n strings per row.
        width: The console's width in characters.

    Returns:
        The indices of the columns shown, in order, and the content width of each column (a list of n, entries of
        left-out columns unused), or None where every column fits at its longest cell (rich lays them out).
    """
    n = len(cols)
    heads = [col.header or col.key for col in cols]
    longest = [
        max([len(line) for text in [heads[i], *(row[i] for row in cells)] for line in text.splitlines()] or [0])
        for i in range(n)
    ]
    rigid = [cols[i].is_whole or cols[i].no_wrap for i in range(n)]
    least = [
        longest[i] if rigid[i] else max(_longest_word(heads[i]), *(_longest_word(row[i]) for row in cells), 1)
        for i in range(n)
    ]
    keep = list(range(n))

    def room(shown: list[int]) -> int:  # content width left: each column has 2 of padding and 1 of border, + 1
        return width - 3 * len(shown) - 1

    while sum(longest[i] for i in keep) > room(keep):  # one line per row where leaving out columns gets there
        droppable = [i for i in keep if cols[i].drop > 0]
        if not droppable:
            break
        keep.remove(max(droppable, key=lambda i: (cols[i].drop, i)))
    if sum(longest[i] for i in keep) <= room(keep):
        return keep, None
    widths = list(longest)
    excess = sum(widths[i] for i in keep) - room(keep)
    while excess > 0:
        shrinkable = [i for i in keep if widths[i] > least[i]]
        if not shrinkable:  # even at their least the columns do not fit: the whole ones fold (nothing is lost) down
            # to FOLD_FLOOR, widest first, so numbers keep their width; then the lesser ones; then the whole ones
            shrinkable = (
                [i for i in keep if widths[i] > FOLD_FLOOR and cols[i].is_whole]
                or [i for i in keep if widths[i] > 1 and not cols[i].is_whole]
                or [i for i in keep if widths[i] > 1]
            )
            if not shrinkable:
                break
        widest = max(shrinkable, key=lambda i: (widths[i], -i))
        widths[widest] -= 1
        excess -= 1
    return keep, widths


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


def _json_text(text: str) -> str:
    r"""JSON text with each character that :func:`~morfic_cli.errors.printable` escapes written as ``\uXXXX``.

    The same data once parsed (such characters occur only inside strings), and nothing a terminal acts on.
    """
    return "".join(json.dumps(c)[1:-1] if c != "\n" and unicodedata.category(c) in UNPRINTABLE else c for c in text)


def emit_object(obj: Any, fmt: OutputFormat, title: str | None = None) -> None:
    """Print one object: JSON for json, a key/value table for table (never JSON), key,value CSV for csv.

    The table and CSV flatten nested dicts into dotted keys (:func:`flatten`).
    """
    obj = json_safe(obj)
    if fmt == OutputFormat.csv and isinstance(obj, dict):
        emit_rows(
            [{"key": k, "value": json.dumps(v) if isinstance(v, dict | list) else v} for k, v in obj.items()], fmt
        )
        return
    if fmt == OutputFormat.table:
        table = Table(title=title, show_header=False)
        table.add_column("key", style="bold")
        table.add_column("value", overflow="fold")
        for key, value in flatten(obj):
            table.add_row(Text(printable(key)), Text(printable(_plain(value))))
        out_console.print(table)
        return
    sys.stdout.write(json.dumps(obj, indent=2, default=str) + "\n")


def info(message: str) -> None:
    """A human message on stderr (control characters but newlines escaped: :func:`~morfic_cli.errors.printable`)."""
    err_console.print(printable(message, keep="\n"))
