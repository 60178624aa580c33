"""Markdown output: GitHub-flavoured tables (bold with ``**``) and a document for a README or an issue.

Tables are written here, not with ``DataFrame.to_markdown``: that needs ``tabulate`` (a dependency morfic does not
otherwise have), pads every cell to its column's width (each generated table in docs/ and every report would change
whitespace only and grow wider), and escapes no ``|`` in cells, which :func:`table_markdown` must do anyway.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from morfic_cli.report.model import Part, Table, number_text

if TYPE_CHECKING:
    from morfic_cli.report.claims import Claim

_ARROWS = {"up": "↑", "down": "↓"}


def _escape(text: str) -> str:
    return text.replace("|", "\\|")


def part_markdown(part: Part) -> str:
    """One part: ``2.04 ± 0.37``, bold as ``**...**``, "-" when missing."""
    if part.text is not None:
        body = _escape(part.text)
    else:
        body = number_text(part.value, part.decimals)
        if part.std is not None and body != "-":
            body += f" ± {number_text(part.std, part.decimals)}"
    if part.bold and body != "-":
        body = f"**{body}**"
    return body + _ARROWS.get(part.mark, "")


def table_markdown(table: Table) -> str:
    """The table as Markdown: a bold caption line, the table, its notes."""
    header = [table.corner, *table.columns]
    if table.groups:
        names = [g for g, span in table.groups for _ in range(span)]
        header = [table.corner] + [f"{g} {c}" for g, c in zip(names, table.columns, strict=True)]
    lines = [
        f"**{table.title}.** {table.caption}".rstrip(),
        "",
        "| " + " | ".join(_escape(h) for h in header) + " |",
        "|" + "---|" + "---:|" * len(table.columns),
    ]
    for row in table.rows:
        if not row.cells:
            lines.append(f"| *{_escape(row.label)}* |" + " |" * len(table.columns))
            continue
        cells = [" / ".join(part_markdown(p) for p in cell) for cell in row.cells]
        lines.append("| " + " | ".join([_escape(row.label), *cells]) + " |")
    lines += [f"\n{n}" for n in table.notes]
    return "\n".join(lines) + "\n"


def document_markdown(title: str, sections: Sequence[tuple[str, str]], *, intro: str = "") -> str:
    """A Markdown document: a title, an intro paragraph, then (heading, body) sections."""
    out = [f"# {title}", ""]
    if intro:
        out += [intro, ""]
    for heading, body in sections:
        out += [f"## {heading}", "", body.rstrip(), ""]
    return "\n".join(out)


def claims_markdown(claims: Sequence[Claim]) -> str:
    """The paper's claims as a list: each claim with its verdict, then its parts (:func:`claim_parts`)."""
    from morfic_cli.report.claims import claim_parts

    out = []
    for c in claims:
        parts = "".join(
            f"\n  - {label}: {text if label == 'From' else _escape(text)}" for label, text in claim_parts(c)
        )
        out.append(f"- **({c.key}) {_escape(c.claim)}** Verdict: **{c.verdict}**.{parts}")
    return "\n".join(out)
