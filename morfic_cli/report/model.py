"""The report's table model: what a LaTeX or Markdown table is made of, independent of either.

A :class:`Table` has a header row (optionally grouped, as the paper's fixed-rollout table groups Flip and Cos. under
each robot) and rows of cells; a cell is one or more :class:`Part` joined by ``/`` (the paper's
``v ± σ / S`` is two parts), each part possibly bold or carrying an out-of-support mark. :func:`bold_best` marks the
best value(s) of a row or column the way the paper does (ties all bold, missing values never).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace


@dataclass(frozen=True)
class Part:
    """One part of a cell.

    Attributes:
        value: The number, or None (rendered as "-": missing, never zero).
        std: A ± term, or None.
        decimals: Decimals to print.
        bold: Set in bold.
        mark: "up" / "down" (out-of-support arrows of the morphology table), else "".
        text: Verbatim text instead of a number (e.g. "400M", "1.98--2.70").
    """

    value: float | None
    std: float | None = None
    decimals: int = 2
    bold: bool = False
    mark: str = ""
    text: str | None = None

    @property
    def missing(self) -> bool:
        """No number and no text."""
        return self.text is None and (self.value is None or not math.isfinite(self.value))


Cell = tuple[Part, ...]


@dataclass(frozen=True)
class Row:
    """A table row: its label and cells; a row with no cells is a section heading spanning the table."""

    label: str
    cells: tuple[Cell, ...] = ()


@dataclass(frozen=True)
class Table:
    """A table of the report.

    Attributes:
        key: Identifier (``zero_shot_transfer``); the LaTeX label is ``tab:<key>`` (``tab:paper-<key>`` for the
            paper's own numbers).
        title: Caption title.
        caption: What a cell holds.
        corner: Header of the label column ("Target", "Src.", "Parameter", "Method").
        columns: Header of each data column.
        rows: The rows.
        groups: Optional header groups above the columns: (label, number of columns spanned).
        math: Numbers in math mode as the paper sets its result cells (text mode otherwise).
        source: "store" (built from artifacts) or "paper" (published numbers).
        notes: Lines printed under the table (e.g. what the seeds are).
    """

    key: str
    title: str
    caption: str
    corner: str
    columns: tuple[str, ...]
    rows: tuple[Row, ...]
    groups: tuple[tuple[str, int], ...] = ()
    math: bool = True
    source: str = "store"
    notes: tuple[str, ...] = field(default=())

    def with_notes(self, *notes: str) -> Table:
        """A copy with more notes."""
        return replace(self, notes=(*self.notes, *notes))

    def to_dict(self) -> dict:
        """JSON-ready form (``report.json``): every part with its value, std and bold flag."""
        return {
            "key": self.key,
            "title": self.title,
            "caption": self.caption,
            "corner": self.corner,
            "columns": list(self.columns),
            "groups": [list(g) for g in self.groups],
            "source": self.source,
            "notes": list(self.notes),
            "rows": [
                {"label": r.label, "cells": [[_part_dict(p) for p in cell] for cell in r.cells]} for r in self.rows
            ],
        }


def _part_dict(p: Part) -> dict:
    value = None if p.value is None or not math.isfinite(p.value) else p.value
    std = None if p.std is None or not math.isfinite(p.std) else p.std
    out: dict = {"value": value, "std": std, "bold": p.bold}
    if p.mark:
        out["mark"] = p.mark
    if p.text is not None:
        out["text"] = p.text
    return out


def bold_best(values: Sequence[float | None], higher_is_better: bool, tol: float = 1e-12) -> list[bool]:
    """Which entries are the best (ties all best); None / NaN entries never are.

    Nothing is best without at least two values to compare, so a one-method table is not bold everywhere.

    >>> bold_best([0.2, None, 0.5, 0.5], True)
    [False, False, True, True]
    >>> bold_best([0.2, None], True)
    [False, False]
    """
    finite = [v for v in values if v is not None and math.isfinite(v)]
    if len(finite) < 2:
        return [False] * len(values)
    best = max(finite) if higher_is_better else min(finite)
    return [v is not None and math.isfinite(v) and abs(v - best) <= tol for v in values]


def number_text(value: float | None, decimals: int) -> str:
    """``value`` with ``decimals`` decimals, or "-" when missing."""
    if value is None or not math.isfinite(value):
        return "-"
    text = f"{value:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text
