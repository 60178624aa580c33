"""The report's figures (matplotlib, Agg); each ``*_figure`` returns ``(png, pdf)`` bytes, each ``*_plot`` the Figure.

EV per variant and robot, v_x against the normalised morphology distance, training compute per run, and training
curves; the eval figures (speed and survival over time per robot) come from the store as ``morfic eval`` drew them.
"""

from __future__ import annotations

import io
import math
import warnings
from collections.abc import Sequence
from typing import Any

from morfic_cli.report import paper
from morfic_cli.rl.variants import variant_order


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig) -> tuple[bytes, bytes]:
    png, pdf = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=110)
    fig.savefig(pdf, format="pdf", metadata={"CreationDate": None})
    _plt().close(fig)
    return png.getvalue(), pdf.getvalue()


def _label(preset: str, variant: str, multi: bool) -> str:
    name = paper.METHOD_LABELS.get(variant, variant)
    return f"{name} ({preset})" if multi else name


def ev_figure(calibration: Sequence[dict[str, Any]]) -> tuple[bytes, bytes]:
    """Grouped EV bars: robots on the x axis, one bar per variant (the paper's Fig. 3, left)."""
    from morfic_cli.diagnostics.figures import ev_figure as bars

    rows = [
        {
            "run": f"{r['variant']}, {r['preset']}, {r['n_seeds']} seed" + ("s" if r["n_seeds"] != 1 else ""),
            "variant": r["variant"],
            "robot": paper.ROBOT_LABELS.get(r["robot"], r["robot"]),
            "ev": r["ev"],
        }
        for r in calibration
        if r["mode"] == "descriptor" and r["ev"] is not None
    ]
    return bars(rows)


MARKERS = "osD^vP*X"
"""Marker per variant (colour and marker both tell variants apart)."""


def distance_plot(transfer: Sequence[dict[str, Any]], *, command_vx: float = 2.0, with_paper: bool = False):
    """v_x (± σ over envs) at ``command_vx`` against each robot's normalised distance d to Go2 (a Figure).

    Robots are separate points, never joined by lines (d orders them, it is not a path); each point is labelled
    with its robot. Variants are told apart by colour and marker, slightly offset along d when several share a
    robot; the paper's values (``with_paper``) are black crosses.
    """
    plt = _plt()
    sel = [
        r
        for r in transfer
        if r["mode"] == "descriptor" and abs(r["command_vx"] - command_vx) < 1e-9 and r.get("d") is not None
    ]
    multi = len({r["preset"] for r in sel}) > 1
    fig, ax = plt.subplots(figsize=(8.4, 4.0), constrained_layout=True)
    groups = sorted({(r["preset"], r["variant"]) for r in sel}, key=lambda p: (p[0], variant_order(p[1])))
    span = max([float(r["d"]) for r in sel] + [0.1])
    step = 0.012 * span
    for k, (preset, variant) in enumerate(groups):
        pts = sorted(
            (float(r["d"]), r["vx"], r["vx_std"] or 0.0)
            for r in sel
            if (r["preset"], r["variant"]) == (preset, variant) and r["vx"] is not None
        )
        if pts:
            xs, ys, es = zip(*pts, strict=True)
            shift = (k - (len(groups) - 1) / 2) * step
            ax.errorbar(
                [x + shift for x in xs],
                ys,
                yerr=es,
                ls="none",
                marker=MARKERS[k % len(MARKERS)],
                ms=6,
                capsize=3,
                color=f"C{k}",
                label=_label(preset, variant, multi),
            )
    if with_paper:
        d_of = {r["robot"]: float(r["d"]) for r in sel}
        for j, variant in enumerate(("ppo", "film")):
            printed = {robot: paper.transfer_values(variant, robot, command_vx)["vx"] for robot in d_of}
            marks = [(d_of[robot], vx) for robot, vx in printed.items() if vx is not None]
            if marks:
                xs, ys = zip(*marks, strict=True)
                ax.scatter(
                    xs,
                    ys,
                    marker="x" if j else "+",
                    s=40,
                    color="black",
                    lw=1.0,
                    label=f"paper: {paper.METHOD_LABELS[variant]}",
                )
    robots = sorted({r["robot"]: r for r in sel}.values(), key=lambda r: float(r["d"]))
    for k, r in enumerate(robots):  # alternate above / below so neighbours in d do not overlap
        best = max((x["vx"] for x in sel if x["robot"] == r["robot"] and x["vx"] is not None), default=0.0)
        ax.annotate(
            paper.ROBOT_LABELS.get(r["robot"], r["robot"]),
            (float(r["d"]), best),
            fontsize=8,
            xytext=(5, 5 if k % 2 == 0 else -11),
            textcoords="offset points",
        )
    ax.axhline(command_vx, color="grey", lw=0.8, ls=":", label=f"command {command_vx:g} m/s")
    ax.set_xlabel("normalised morphology distance d to Go2", fontsize=9)
    ax.set_ylabel("forward speed v_x (m/s)", fontsize=9)
    ax.set_xlim(-0.03 * span, 1.15 * span)
    ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]), top=max(ax.get_ylim()[1], 1.2 * command_vx))
    ax.set_title(f"Transfer against morphology distance (command {command_vx:g} m/s, descriptor mode)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # off the data
    return fig


def distance_figure(
    transfer: Sequence[dict[str, Any]], *, command_vx: float = 2.0, with_paper: bool = False
) -> tuple[bytes, bytes]:
    """:func:`distance_plot` as ``(png, pdf)`` bytes."""
    return _save(distance_plot(transfer, command_vx=command_vx, with_paper=with_paper))


def compute_plot(compute: Sequence[dict[str, Any]], *, with_paper: bool = False):
    """Training device-hours per run, normalised to 400M transitions as the paper's table is (a Figure).

    Horizontal bars, one per run (labelled with its variant, preset, device and transitions) and, with
    ``with_paper``, one per paper method (its range's midpoint, the range as an error bar), on a log axis when
    the hours span more than a factor of 20. A bar chart, not a scatter of hours against transitions: our runs
    often share one budget, and one point on log-log axes says nothing.
    """
    plt = _plt()
    bars: list[tuple[str, float, float, float, str]] = []  # label, value, low, high, colour
    multi = len({r["preset"] for r in compute}) > 1
    for r in compute:
        if r["transitions"] and r["device_hours_400m"]:
            label = (
                f"{_label(r['preset'], r['variant'], multi)}, {r['preset']} on {r['device']}\n"
                f"({r['transitions'] / 1e6:.1f}M transitions)"
            )
            v = float(r["device_hours_400m"])
            bars.append((label, v, v, v, "C0"))
    if with_paper:
        for row in paper.TRAINING_COMPUTE:
            lo, hi = row.gpu_hours_400m
            bars.append((f"paper: {row.label} (GPU)", (lo + hi) / 2, lo, hi, "grey"))
    fig, ax = plt.subplots(figsize=(6.4, max(1.8, 0.4 * len(bars) + 1.2)), constrained_layout=True)
    ys = list(range(len(bars)))[::-1]
    for y, (_label_text, v, lo, hi, colour) in zip(ys, bars, strict=True):
        ax.barh(y, v, color=colour, height=0.5, xerr=[[v - lo], [hi - v]] if hi > lo else None, capsize=3)
        ax.annotate(
            f"{v:.1f} h" if v >= 1 else f"{v:.2f} h",
            (v, y),
            xytext=(4, 0),
            textcoords="offset points",
            va="center",
            fontsize=8,
        )
    ax.set_yticks(ys, [b[0] for b in bars], fontsize=8)
    values = [b[1] for b in bars]
    if values and max(values) / max(min(values), 1e-9) > 20:
        ax.set_xscale("log")
        ax.set_xlim(min(values) / 2, max(values) * 4)
    elif values:
        ax.set_xlim(0, max(b[3] for b in bars) * 1.25)
    ax.set_xlabel("device-hours per 400M transitions (CPU threads or one GPU)", fontsize=9)
    ax.set_title("Training compute", fontsize=10)
    ax.grid(axis="x", alpha=0.3, which="both")
    if not bars:
        ax.text(0.5, 0.5, "no training runs with timing", ha="center", va="center", transform=ax.transAxes)
    return fig


def compute_figure(compute: Sequence[dict[str, Any]], *, with_paper: bool = False) -> tuple[bytes, bytes]:
    """:func:`compute_plot` as ``(png, pdf)`` bytes."""
    return _save(compute_plot(compute, with_paper=with_paper))


def _has_values(series: Sequence[float]) -> bool:
    return any(v is not None and not (isinstance(v, float) and math.isnan(v)) for v in series)


CURVE_PANELS: tuple[tuple[str, str], ...] = (
    ("mean_reward", "mean episode return"),
    ("explained_variance", "critic explained variance (training)"),
    ("action_std", "policy action std (exploration noise)"),
    ("curriculum.vx_max", "curriculum: top of the v_x command range (m/s)"),
)
"""The training-curve panels: curve column and title (``recording/curves.py`` names the columns)."""


def seed_band(runs: Sequence[Sequence[dict[str, float]]], key: str) -> dict[str, list[float]]:
    """Mean and min-max band over seeds of one curve column, on the union of the runs' env steps.

    Each run is interpolated linearly onto the common steps inside its own range (NaN outside it, so a run that
    stopped early stops counting); ``n`` is how many runs count at each step.

    Args:
        runs: Each seed's curve rows (``env_steps`` and ``key``).
        key: The curve column.

    Returns:
        ``x`` (env steps), ``mean``, ``low``, ``high`` (min and max over seeds) and ``n``, lists of one length.
    """
    import numpy as np

    series = []
    for rows in runs:
        pts = sorted(
            (float(r["env_steps"]), float(r[key]))
            for r in rows
            if r.get("env_steps") is not None
            and _has_values([r.get(key, math.nan)])
            and math.isfinite(float(r["env_steps"]))
        )
        series.append(pts)
    x = np.array(sorted({p[0] for pts in series for p in pts}))
    ys = np.full((len(series), len(x)), np.nan)
    for i, pts in enumerate(series):
        if pts:
            px, py = np.array(pts).T
            inside = (x >= px[0]) & (x <= px[-1])
            ys[i, inside] = np.interp(x[inside], px, py)
    n = np.isfinite(ys).sum(axis=0)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: a step no run reached
        mean, low, high = np.nanmean(ys, axis=0), np.nanmin(ys, axis=0), np.nanmax(ys, axis=0)
    return {"x": x.tolist(), "mean": mean.tolist(), "low": low.tolist(), "high": high.tolist(), "n": n.tolist()}


def curves_plot(
    curves: dict[str, list[dict[str, float]]], variants: dict[str, str], presets: dict[str, str] | None = None
):
    """:data:`CURVE_PANELS` against env steps, one line per variant and preset (a Figure; two panels a row).

    The seeds of a variant and preset are drawn as their mean with a band from the lowest to the highest seed
    (:func:`seed_band`), not as one line per seed; a lone run is its own line. The legend sits below the panels,
    off the data. A panel whose series are all missing (NaN) is not drawn.

    Args:
        curves: Run name -> training-curve rows.
        variants: Run name -> its variant.
        presets: Run name -> its preset (None: all one preset); groups of different presets are labelled apart.
    """
    plt = _plt()
    presets = presets or {}
    groups: dict[tuple[str, str], list[str]] = {}
    for name in sorted(curves):
        groups.setdefault((presets.get(name, ""), variants.get(name, "")), []).append(name)
    order = sorted(groups, key=lambda g: (variant_order(g[1]), g[0]))
    colours = {v: f"C{i}" for i, v in enumerate(sorted({g[1] for g in groups}, key=variant_order))}
    multi = len({g[0] for g in groups}) > 1
    styles = {p: ("-", "--", ":", "-.")[i % 4] for i, p in enumerate(sorted({g[0] for g in groups}))}
    panels = [
        (key, title)
        for key, title in CURVE_PANELS
        if any(_has_values([r.get(key, math.nan) for r in curves[n]]) for n in curves)
    ]
    cols = min(max(len(panels), 1), 2)
    rows_n = max(math.ceil(len(panels) / 2), 1)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4.5 * cols, 3.4 * rows_n), constrained_layout=True, squeeze=False)
    flat = list(axes.flat)
    handles: dict[str, Any] = {}
    for ax, (key, title) in zip(flat, panels, strict=False):
        for preset, variant in order:
            names = groups[(preset, variant)]
            label = _label(preset, variant, multi) if preset else paper.METHOD_LABELS.get(variant, variant)
            colour, style = colours.get(variant), styles.get(preset, "-")
            if len(names) == 1:
                rows = curves[names[0]]
                (line,) = ax.plot(
                    [r.get("env_steps", math.nan) for r in rows],
                    [r.get(key, math.nan) for r in rows],
                    lw=1.0,
                    color=colour,
                    ls=style,
                    marker="." if len(rows) < 5 else None,
                )
                handles.setdefault(f"{label} ({names[0]})", line)
                continue
            band = seed_band([curves[n] for n in names], key)
            if not band["x"]:
                continue
            (line,) = ax.plot(band["x"], band["mean"], lw=1.2, color=colour, ls=style)
            ax.fill_between(band["x"], band["low"], band["high"], color=colour, alpha=0.2, lw=0)
            handles.setdefault(f"{label}: mean of {len(names)} seeds, band min\u2013max", line)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("env steps", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in flat[len(panels) :] if panels else ():
        fig.delaxes(ax)
    if not panels:
        flat[0].text(0.5, 0.5, "no training curves", ha="center", va="center", transform=flat[0].transAxes)
    elif handles:
        fig.legend(
            list(handles.values()),
            list(handles),
            loc="outside lower center",
            fontsize=8,
            ncol=min(len(handles), 2 if cols == 2 else 1),
            frameon=False,
        )
    return fig


def curves_figure(
    curves: dict[str, list[dict[str, float]]], variants: dict[str, str], presets: dict[str, str] | None = None
) -> tuple[bytes, bytes]:
    """:func:`curves_plot` as ``(png, pdf)`` bytes.

    Args:
        curves: Run name -> training-curve rows.
        variants: Run name -> its variant.
        presets: Run name -> its preset.
    """
    return _save(curves_plot(curves, variants, presets))
