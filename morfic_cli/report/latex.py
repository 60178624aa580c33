r"""LaTeX output: booktabs tables in the paper's cell style and a standalone document that pdflatex compiles.

A result cell is set as the paper sets it, in math mode with bold parts: ``$\mathbf{2.04{\pm}0.37}/0.984$``.
The document needs only packages of a basic TeX Live (``texlive-latex-base`` + ``texlive-latex-recommended``):
geometry, booktabs, graphicx, longtable, array, float. Tables and figures are placed where they are written
(``[H]``), so every table sits under its section heading.

The provenance list is pandas' ``Styler.to_latex`` (:func:`longtable_latex`). The result tables
(:func:`table_latex`) are written here: they need four things ``Styler.to_latex`` does not write (a
``\cmidrule`` under each column group, section rows spanning the table, notes inside the float after the
``tabular``, and the shrink-to-fit wrapper), so it would only be a skeleton edited as text in four places.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from morfic_cli.report.model import Part, Table, number_text
from morfic_cli.store.manifest import safe_join

if TYPE_CHECKING:
    from morfic_cli.report.claims import Claim

_ESCAPES = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "±": r"$\pm$",
    "σ": r"$\sigma$",
    "↑": r"$\uparrow$",
    "↓": r"$\downarrow$",
    "≥": r"$\geq$",
    "≤": r"$\leq$",
    "×": r"$\times$",
    "–": "--",
    "—": "---",
    "|": r"$|$",
    "†": r"$^\dagger$",
}


def escape(text: str) -> str:
    """Plain text made safe for LaTeX (special characters escaped, a few symbols as math, `code` as typewriter)."""
    chunks = text.split("`")
    if len(chunks) % 2 == 0:  # an unpaired backtick stays a quote mark
        chunks = ["'".join(chunks)]
    out = []
    for i, chunk in enumerate(chunks):
        body = "".join(_ESCAPES.get(ch, ch) for ch in chunk)
        out.append(rf"\texttt{{{body}}}" if i % 2 else body)
    return "".join(out)


def part_latex(part: Part, math: bool) -> str:
    r"""One part: ``2.04{\pm}0.37`` in math mode (bold: ``\mathbf{...}``), or text mode with ``\textbf``."""
    if part.text is not None:
        body = escape(part.text)
        return rf"\textbf{{{body}}}" if part.bold else body
    body = number_text(part.value, part.decimals)
    if part.std is not None and body != "-":
        body += (r"{\pm}" if math else r"$\pm$") + number_text(part.std, part.decimals)
    if part.bold and body != "-":
        body = rf"\mathbf{{{body}}}" if math else rf"\textbf{{{body}}}"
    if part.mark:
        arrow = r"\uparrow" if part.mark == "up" else r"\downarrow"
        body += arrow if math else f"${arrow}$"
    return body


def cell_latex(cell: Sequence[Part], math: bool) -> str:
    """A cell: its parts joined by ``/``, wrapped in ``$...$`` in math mode."""
    body = "/".join(part_latex(p, math) for p in cell)
    return f"${body}$" if math else body


def table_latex(table: Table, *, float_env: bool = True) -> str:
    """A booktabs ``table`` (caption, label, ``tabular``), placed where it is written.

    ``[H]`` (float package) keeps it under its section heading; a table wider than the text is shrunk to the line
    width, never enlarged.
    """
    n = len(table.columns)
    lines = [r"\begin{tabular}{l" + "c" * n + "}", r"\toprule"]
    if table.groups:
        heads, rules, col = [""], [], 2
        for label, span in table.groups:
            heads.append(rf"\multicolumn{{{span}}}{{c}}{{\textbf{{{escape(label)}}}}}")
            rules.append(rf"\cmidrule(lr){{{col}-{col + span - 1}}}")
            col += span
        lines.append(" & ".join(heads) + r" \\")
        lines.append("".join(rules))
    header = [rf"\textbf{{{escape(table.corner)}}}"] + [rf"\textbf{{{escape(c)}}}" for c in table.columns]
    lines.append(" & ".join(header) + r" \\")
    lines.append(r"\midrule")
    for row in table.rows:
        if not row.cells:
            lines.append(r"\midrule")
            lines.append(rf"\multicolumn{{{n + 1}}}{{l}}{{\textit{{{escape(row.label)}}}}} \\")
            continue
        cells = [escape(row.label)] + [cell_latex(c, table.math) for c in row.cells]
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    body = "\n".join(lines)
    if n >= 5:  # shrink a table wider than the text to fit; never enlarge one
        body = "\\resizebox{\\ifdim\\width>\\linewidth\\linewidth\\else\\width\\fi}{!}{%\n" + body + "}"
    if not float_env:
        return body
    label = f"tab:paper-{table.key}" if table.source == "paper" else f"tab:{table.key}"
    caption = rf"\textbf{{{escape(table.title)}.}} {_caption_text(table.caption)}"
    notes = "".join(rf"\\[2pt]{{\footnotesize {escape(n)}}}" for n in table.notes)
    return "\n".join(
        [
            r"\begin{table}[H]",
            r"\centering",
            r"\small",
            rf"\caption{{{caption}}}",
            rf"\label{{{label}}}",
            body + notes,
            r"\end{table}",
        ]
    )


def _caption_text(caption: str) -> str:
    """Captions may carry inline math (``$...$``) written for LaTeX: escape only the text between."""
    out = []
    for i, chunk in enumerate(caption.split("$")):
        out.append(f"${chunk}$" if i % 2 else escape(chunk))
    return "".join(out)


NEED_SPACE = r"\par\vspace{0pt plus 0.2\textheight}\penalty-250\vspace{0pt plus -0.2\textheight}"
"""A conditional page break (what the needspace package does): a new page when less than about a fifth of the
page is left, so a section heading is never stranded at the foot of a page."""


def document_latex(title: str, sections: Sequence[tuple[str, str]], *, preamble_note: str = "") -> str:
    """A standalone article: ``sections`` are (heading, LaTeX body) pairs."""
    parts = [
        r"\documentclass[10pt]{article}",
        r"\usepackage[margin=1.8cm]{geometry}",
        r"\usepackage[T1]{fontenc}",
        r"\usepackage{booktabs}",
        r"\usepackage{graphicx}",
        r"\usepackage{longtable}",
        r"\usepackage{array}",
        r"\usepackage{float}",
        r"\setlength{\tabcolsep}{4pt}",
        rf"\title{{{escape(title)}}}",
        r"\date{}",
        r"\begin{document}",
        r"\maketitle",
    ]
    if preamble_note:
        parts.append(escape(preamble_note))
    for heading, body in sections:
        parts.append(NEED_SPACE)  # a heading never ends a page: break first when little room is left
        parts.append(rf"\section*{{{escape(heading)}}}")
        parts.append(body)
    parts.append(r"\end{document}")
    return "\n\n".join(parts) + "\n"


def figure_latex(path: str, caption: str) -> str:
    """A figure float including ``path`` (relative to the .tex)."""
    return "\n".join(
        [
            r"\begin{figure}[H]",
            r"\centering",
            rf"\includegraphics[width=0.9\linewidth,height=0.4\textheight,keepaspectratio]{{{path}}}",
            rf"\caption{{{escape(caption)}}}",
            r"\end{figure}",
        ]
    )


def figure_grid_latex(paths: Sequence[str], caption: str, per_row: int = 3) -> str:
    """One figure float with ``paths`` side by side, ``per_row`` to a row (e.g. one eval figure per robot)."""
    width = 0.97 / per_row
    cells = [rf"\includegraphics[width={width:.3f}\linewidth]{{{p}}}" for p in paths]
    rows = ["\n".join(cells[i : i + per_row]) for i in range(0, len(cells), per_row)]
    return "\n".join(
        [
            r"\begin{figure}[H]",
            r"\centering",
            "\\\\[4pt]\n".join(rows),
            rf"\caption{{{escape(caption)}}}",
            r"\end{figure}",
        ]
    )


def longtable_latex(header: Sequence[str], rows: Sequence[Sequence[str]], spec: str) -> str:
    """A booktabs ``longtable`` (breaks across pages, the header again on each) of plain-text cells.

    pandas' ``Styler.to_latex(environment="longtable")`` writes it (header on every page, "Continued on next page"
    at each break); the cells are escaped here first (:func:`escape`), as Styler leaves them as they are. E.g. the
    provenance list.
    """
    import pandas as pd

    frame = pd.DataFrame(
        [[escape(str(c)) for c in row] for row in rows] or [["-"] * len(header)],  # never empty
        columns=[rf"\textbf{{{escape(h)}}}" for h in header],
    )
    body = frame.style.hide(axis="index").to_latex(environment="longtable", hrules=True, column_format=spec)
    return "{\\scriptsize\n" + body.rstrip("\n") + "}"


NO_PDF_ENV = "MORFIC_NO_PDF"
"""Set (to anything but ``0``) to write ``report.tex`` without compiling ``report.pdf``, pdflatex or not (the tests
set it: each report compile costs 5-10 s on 2 cores; the one LaTeX test unsets it)."""


def pdflatex() -> str | None:
    """Path of ``pdflatex``, or None when it is not installed."""
    return shutil.which("pdflatex")


def pdf_skipped() -> bool:
    """Whether :data:`NO_PDF_ENV` asks for no PDF."""
    return os.environ.get(NO_PDF_ENV, "") not in ("", "0")


def compile_pdf(tex: str, files: Mapping[str, bytes] | None = None, *, timeout_s: float = 120.0) -> bytes:
    """Compile a standalone .tex with pdflatex in a temporary folder (``files``: name -> bytes beside it).

    Runs pdflatex twice (longtable widths settle on the second run).

    Raises:
        RuntimeError: pdflatex is missing or fails; the message ends with the log's last lines.
    """
    exe = pdflatex()
    if exe is None:
        raise RuntimeError("pdflatex is not installed (apt-get install texlive-latex-base texlive-latex-recommended)")
    with tempfile.TemporaryDirectory(prefix="morfic-tex-") as tmp:
        root = Path(tmp)
        for name, data in (files or {}).items():
            path = safe_join(root, name)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        (root / "report.tex").write_text(tex, encoding="utf-8")
        for _ in range(2):
            proc = subprocess.run(
                [exe, "-interaction=nonstopmode", "-halt-on-error", "report.tex"],
                cwd=root,
                capture_output=True,
                text=True,
                timeout=timeout_s,
                check=False,
            )
            if proc.returncode != 0:
                tail = "\n".join(proc.stdout.splitlines()[-25:])
                raise RuntimeError(f"pdflatex failed (exit {proc.returncode}):\n{tail}")
        return (root / "report.pdf").read_bytes()


def claims_latex(claims: Sequence[Claim]) -> str:
    """The paper's claims as an itemize list (see :func:`~morfic_cli.report.markdown.claims_markdown`)."""
    from morfic_cli.report.claims import claim_parts

    if not claims:
        return ""
    items = [
        rf"\item \textbf{{({c.key}) {escape(c.claim)}}} Verdict: \textbf{{{escape(c.verdict)}}}. "
        + " ".join(f"{label}: {escape(text)}." for label, text in claim_parts(c))
        for c in claims
    ]
    return "\\begin{itemize}\n" + "\n".join(items) + "\n\\end{itemize}"
