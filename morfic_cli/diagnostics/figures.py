"""The EV figure of ``morfic diagnose`` (the paper's Fig. 3 analogue): explained variance per variant and robot."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import Any

from morfic_cli.rl.variants import variant_label

EV_LINEAR_FLOOR = -1.0
"""Below this EV the axis turns logarithmic (symmetric log): EV is unbounded below (-105.8 happens), and a bar is
never cut; within [-1, 1] the axis is linear."""


def ev_plot(rows: Sequence[dict[str, Any]]):
    """The EV figure (a matplotlib Figure): grouped bars, robots on the x axis, one bar per run.

    Every bar is drawn to its value and labelled with it; when some EV is below :data:`EV_LINEAR_FLOOR` the y
    axis is symmetric-log (linear in [-1, 1]) and says so. Missing values (NaN) get no bar and an "n/a" mark.

    Args:
        rows: Calibration rows with ``run``, ``variant``, ``robot`` and ``ev``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = list(dict.fromkeys(r["robot"] for r in rows))
    runs = list(dict.fromkeys((r["run"], r["variant"]) for r in rows))
    ev = {(r["run"], r["robot"]): r["ev"] for r in rows}
    finite = [v for v in ev.values() if v is not None and not math.isnan(v)]
    width = 0.8 / max(len(runs), 1)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.0 * len(robots) * max(1.0, len(runs) / 3)), 4.0),
                           constrained_layout=True)
    log_below = bool(finite) and min(finite) < EV_LINEAR_FLOOR
    for k, (run, variant) in enumerate(runs):
        xs = [i + (k - (len(runs) - 1) / 2) * width for i in range(len(robots))]
        values = [ev.get((run, robot), math.nan) for robot in robots]
        values = [math.nan if v is None else float(v) for v in values]
        label = f"{variant_label(variant)} ({run})"
        ax.bar(xs, values, width=width * 0.92, label=label, color=f"C{k}")
        for x, v in zip(xs, values, strict=True):
            if math.isnan(v):
                ax.annotate("n/a", (x, 0.0), ha="center", va="bottom", fontsize=7, color="grey")
            else:
                ax.annotate(f"{v:.2f}" if abs(v) < 10 else f"{v:.1f}", (x, v), ha="center",
                            va="bottom" if v >= 0 else "top", fontsize=7, xytext=(0, 2 if v >= 0 else -2),
                            textcoords="offset points")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xticks(range(len(robots)), robots, fontsize=9)
    if log_below:
        bottom = min(finite) * 3.0
        ax.set_yscale("symlog", linthresh=1.0, linscale=1.5)
        decades = [-(10.0 ** k) for k in range(1, int(math.ceil(math.log10(-min(finite)))) + 1)]
        ticks = sorted([t for t in decades if t >= bottom] + [-1.0, -0.5, 0.0, 0.5, 1.0])
        ax.set_yticks(ticks, [f"{t:g}" for t in ticks], fontsize=8)
        ax.axhspan(bottom, -1.0, color="grey", alpha=0.07, lw=0)
        ax.set_ylim(bottom, 1.5)
        ax.set_ylabel("explained variance EV\n(linear in [-1, 1], log below)", fontsize=9)
    else:
        ax.set_ylim(min([0.0, *finite]) - 0.12, 1.12)
        ax.set_ylabel("explained variance EV", fontsize=9)
    ax.set_title("Critic calibration under morphology shift (higher is better, 1 = perfect, dashed)", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    if runs:  # no diagnosis rows (a report of evals only): no bars, no legend (ncol=0 is an error)
        ax.legend(fontsize=7, ncol=min(len(runs), 4), loc="upper center", bbox_to_anchor=(0.5, -0.1), frameon=False)
    return fig


def ev_figure(rows: Sequence[dict[str, Any]]) -> tuple[bytes, bytes]:
    """:func:`ev_plot` as ``(png, pdf)`` bytes (the PDF without a creation date, so equal inputs give equal bytes).

    Args:
        rows: Calibration rows with ``run``, ``variant``, ``robot`` and ``ev``.
    """
    import matplotlib.pyplot as plt

    fig = ev_plot(rows)
    png, pdf = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=120)
    fig.savefig(pdf, format="pdf", metadata={"CreationDate": None})
    plt.close(fig)
    return png.getvalue(), pdf.getvalue()
