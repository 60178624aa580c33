"""The EV figure of ``morfic diagnose`` (the paper's Fig. 3 analogue): explained variance per variant and robot."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import Any

from morfic_cli.rl.variants import variant_label

EV_FLOOR = -1.0
"""Bars below this EV are drawn down to it, marked with their value (EV is unbounded below)."""


def ev_figure(rows: Sequence[dict[str, Any]]) -> tuple[bytes, bytes]:
    """Grouped bars of EV: robots on the x axis, one bar per run (labelled by variant and run name).

    Args:
        rows: Calibration rows with ``run``, ``variant``, ``robot`` and ``ev``.

    Returns:
        ``(png, pdf)`` bytes (the PDF without a creation date, so equal inputs give equal bytes).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = list(dict.fromkeys(r["robot"] for r in rows))
    runs = list(dict.fromkeys((r["run"], r["variant"]) for r in rows))
    ev = {(r["run"], r["robot"]): r["ev"] for r in rows}
    width = 0.8 / max(len(runs), 1)
    fig, ax = plt.subplots(
        figsize=(max(5.0, 1.1 * len(robots) * max(1.0, len(runs) / 3)), 3.8), constrained_layout=True
    )
    for k, (run, variant) in enumerate(runs):
        xs = [i + (k - (len(runs) - 1) / 2) * width for i in range(len(robots))]
        values = [ev.get((run, robot), math.nan) for robot in robots]
        shown = [max(v, EV_FLOOR) if not math.isnan(v) else math.nan for v in values]
        label = f"{variant_label(variant)} ({run})"
        ax.bar(xs, shown, width=width * 0.95, label=label)
        for x, v in zip(xs, values, strict=True):
            if not math.isnan(v) and v < EV_FLOOR:
                ax.annotate(f"{v:.1f}", (x, EV_FLOOR), ha="center", va="bottom", fontsize=6, rotation=90)
    ax.axhline(0.0, color="black", lw=0.8)
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xticks(range(len(robots)), robots)
    low = min([0.0, *(max(v, EV_FLOOR) for v in ev.values() if not math.isnan(v))])
    ax.set_ylim(low - 0.05, 1.05)
    ax.set_ylabel("explained variance (EV)")
    ax.set_title("Critic calibration under morphology shift (higher is better, 1 = perfect)", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    if runs:  # no diagnosis rows (a report of evals only): no bars, no legend (ncol=0 is an error)
        ax.legend(fontsize=7, ncol=min(len(runs), 4), loc="upper center", bbox_to_anchor=(0.5, -0.1), frameon=False)
    png, pdf = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=120)
    fig.savefig(pdf, format="pdf", metadata={"CreationDate": None})
    plt.close(fig)
    return png.getvalue(), pdf.getvalue()
