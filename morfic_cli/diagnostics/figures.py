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


LABEL_PT = 22.0
"""Width of a bar's value label (``-0.55`` at 7 pt), in points: narrower bars get upright labels."""


def ev_plot(rows: Sequence[dict[str, Any]]):
    """The EV figure (a matplotlib Figure): grouped bars, robots on the x axis, one bar per run.

    Every bar is drawn to its value and labelled with it (upright when the bar is narrower than its label, so labels
    never overlap); when some EV is below :data:`EV_LINEAR_FLOOR` the y
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
    fig_width = max(6.0, 1.0 * len(robots) * max(1.0, len(runs) / 3))
    fig, ax = plt.subplots(figsize=(fig_width, 4.0), constrained_layout=True)
    log_below = bool(finite) and min(finite) < EV_LINEAR_FLOOR
    # a label wider than its bar would run into its neighbours' ("-0.550.55"): then it stands upright on the bar
    bar_pt = fig_width * 72.0 * 0.85 / max(len(robots), 1) * width * 0.92
    upright = bar_pt < LABEL_PT
    for k, (run, variant) in enumerate(runs):
        xs = [i + (k - (len(runs) - 1) / 2) * width for i in range(len(robots))]
        values = [ev.get((run, robot), math.nan) for robot in robots]
        values = [math.nan if v is None else float(v) for v in values]
        label = f"{variant_label(variant)} ({run})"
        ax.bar(xs, values, width=width * 0.92, label=label, color=f"C{k}")
        for x, v in zip(xs, values, strict=True):
            if math.isnan(v):
                ax.annotate(
                    "n/a", (x, 0.0), ha="center", va="bottom", fontsize=7, color="grey", rotation=90 if upright else 0
                )
            else:
                ax.annotate(
                    f"{v:.2f}" if abs(v) < 10 else f"{v:.1f}",
                    (x, v),
                    ha="center",
                    va="bottom" if v >= 0 else "top",
                    fontsize=7,
                    xytext=(0, 2 if v >= 0 else -2),
                    textcoords="offset points",
                    rotation=90 if upright else 0,
                )
    ax.axhline(0.0, color="black", lw=0.8)
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xticks(range(len(robots)), robots, fontsize=9)
    if log_below:
        bottom = min(finite) * (6.0 if upright else 3.0)  # room for the labels below the longest bar
        ax.set_yscale("symlog", linthresh=1.0, linscale=1.5)
        decades = [-(10.0**k) for k in range(1, int(math.ceil(math.log10(-min(finite)))) + 1)]
        ticks = sorted([t for t in decades if t >= bottom] + [-1.0, -0.5, 0.0, 0.5, 1.0])
        ax.set_yticks(ticks, [f"{t:g}" for t in ticks], fontsize=8)
        ax.axhspan(bottom, -1.0, color="grey", alpha=0.07, lw=0)
        ax.set_ylim(bottom, 2.5 if upright else 1.5)
        ax.set_ylabel("explained variance EV\n(linear in [-1, 1], log below)", fontsize=9)
    else:
        ax.set_ylim(min([0.0, *finite]) - (0.3 if upright else 0.12), 1.3 if upright else 1.12)
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


STUDY_METRICS: tuple[tuple[str, str, bool], ...] = (
    ("ev", "EV (clipped at -1)", True),
    ("flip", "Flip (lower is better)", False),
    ("cos_grad", "CosGrad (higher is better)", True),
)
"""The critic study figure's columns: metric, axis label, higher is better."""


STUDY_LABELS: dict[str, str] = {"ppo": "PPO = Actor-only (no z_m)"}
"""Legend labels of the critic study where a critic stands for more than one variant."""


def critic_study_plot(summary: Sequence[dict[str, Any]]):
    """The critic study figure: one row per command, columns EV / Flip / CosGrad, robots on x, a marker per variant.

    Each marker is a variant's mean over the study's unit (actors) with its 95 % t interval as an error bar
    (:func:`~morfic_cli.diagnostics.study_summary.cell_summary`); multiplicative critics are filled, additive ones
    hollow. EV below -1 is drawn at -1 with a downward triangle (EV is unbounded below on robots that fall).

    Args:
        summary: Rows with ``command_vx, robot, variant, multiplicative, metric, mean, lo, hi``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    commands = sorted({r["command_vx"] for r in summary})
    robots = list(dict.fromkeys(r["robot"] for r in summary))
    variants = list(dict.fromkeys(r["variant"] for r in summary))
    from morfic_cli.diagnostics.study_summary import group_of

    mult = {r["variant"]: bool(group_of(r["multiplicative"])) for r in summary}
    cell = {(r["command_vx"], r["robot"], r["variant"], r["metric"]): r for r in summary}
    fig, axes = plt.subplots(
        len(commands),
        len(STUDY_METRICS),
        squeeze=False,
        constrained_layout=True,
        figsize=(4.6 * len(STUDY_METRICS), 2.9 * len(commands) + 0.6),
    )
    width = 0.8 / max(len(variants), 1)
    for i, command in enumerate(commands):
        for j, (metric, ylabel, _higher) in enumerate(STUDY_METRICS):
            ax = axes[i][j]
            for k, variant in enumerate(variants):
                xs, ys, lo, hi, clipped = [], [], [], [], []
                for x, robot in enumerate(robots):
                    c = cell.get((command, robot, variant, metric))
                    if c is None or c["mean"] is None or math.isnan(c["mean"]):
                        continue
                    m, a, b = c["mean"], c["lo"], c["hi"]
                    a, b = (m, m) if a is None or math.isnan(a) else (a, b)
                    if metric == "ev":
                        m, a, b = max(m, -1.0), max(a, -1.0), max(b, -1.0)
                        clipped.append(c["mean"] < -1.0)
                    else:
                        clipped.append(False)
                    xs.append(x + (k - (len(variants) - 1) / 2) * width)
                    ys.append(m)
                    lo.append(m - a)
                    hi.append(b - m)
                color = f"C{k}"
                face = color if mult.get(variant) else "white"
                ax.errorbar(xs, ys, yerr=[lo, hi], fmt="none", ecolor=color, elinewidth=1.0, capsize=2)
                for px, py, below in zip(xs, ys, clipped, strict=True):
                    ax.plot([px], [py], marker="v" if below else "o", ms=5, mfc=face, mec=color, ls="none")
            if metric == "ev":
                ax.axhline(0.0, color="black", lw=0.6)
                ax.set_ylim(-1.08, 1.05)
            ax.set_xticks(range(len(robots)), robots, fontsize=7, rotation=30)
            ax.set_title(f"{ylabel}, {command:g} m/s", fontsize=9)
            ax.grid(axis="y", alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [
        Line2D(
            [],
            [],
            marker="o",
            ls="none",
            ms=6,
            mec=f"C{k}",
            mfc=f"C{k}" if mult.get(v) else "white",
            label=STUDY_LABELS.get(v, variant_label(v)),
        )
        for k, v in enumerate(variants)
    ]
    handles.append(Line2D([], [], marker="v", ls="none", ms=6, mec="grey", mfc="white", label="EV below -1"))
    if variants:
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False)
    unit = "actors" if any(r.get("unit") == "actor" for r in summary) else "fit seeds of one actor"
    fig.suptitle(
        "Critic study: critics fitted from scratch on frozen actors' data (mean and 95 % t interval over "
        f"{unit}; filled = multiplicative)",
        fontsize=10,
    )
    return fig


def critic_study_figure(summary: Sequence[dict[str, Any]]) -> bytes:
    """:func:`critic_study_plot` as PNG bytes."""
    import matplotlib.pyplot as plt

    fig = critic_study_plot(summary)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=120)
    plt.close(fig)
    return png.getvalue()
