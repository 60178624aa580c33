"""The report's figures (matplotlib, Agg); each returns ``(png, pdf)`` bytes.

EV per variant and robot, v_x against the normalised morphology distance, training compute against transitions,
and training curves.
"""

from __future__ import annotations

import io
import math
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

    rows = [{"run": f"{r['variant']}, {r['preset']}, {r['n_seeds']} seed" + ("s" if r["n_seeds"] != 1 else ""),
             "variant": r["variant"], "robot": paper.ROBOT_LABELS.get(r["robot"], r["robot"]), "ev": r["ev"]}
            for r in calibration if r["mode"] == "descriptor" and r["ev"] is not None]
    return bars(rows)


def distance_figure(transfer: Sequence[dict[str, Any]], *, command_vx: float = 2.0,
                    with_paper: bool = False) -> tuple[bytes, bytes]:
    """Forward velocity v_x (± σ over envs) against the normalised distance d of each robot to Go2, per variant."""
    plt = _plt()
    sel = [r for r in transfer if r["mode"] == "descriptor" and abs(r["command_vx"] - command_vx) < 1e-9
           and r.get("d") is not None]
    multi = len({r["preset"] for r in sel}) > 1
    fig, ax = plt.subplots(figsize=(6.4, 3.8), constrained_layout=True)
    groups = sorted({(r["preset"], r["variant"]) for r in sel}, key=lambda p: (p[0], variant_order(p[1])))
    for preset, variant in groups:
        pts = sorted((float(r["d"]), r["vx"], r["vx_std"] or 0.0) for r in sel
                     if (r["preset"], r["variant"]) == (preset, variant) and r["vx"] is not None)
        if pts:
            xs, ys, es = zip(*pts, strict=True)
            ax.errorbar(xs, ys, yerr=es, marker="o", ms=4, capsize=2, lw=1.2, label=_label(preset, variant, multi))
    if with_paper:
        d_of = {r["robot"]: float(r["d"]) for r in sel}
        for variant in ("ppo", "film"):
            pts = sorted((d_of[robot], paper.transfer_values(variant, robot, command_vx)["vx"]) for robot in d_of
                         if paper.transfer_values(variant, robot, command_vx)["vx"] is not None)
            if pts:
                xs, ys = zip(*pts, strict=True)
                ax.plot(xs, ys, ls="--", marker="x", lw=0.9, label=f"paper: {paper.METHOD_LABELS[variant]}")
    for r in {r["robot"]: r for r in sel}.values():
        ax.annotate(paper.ROBOT_LABELS.get(r["robot"], r["robot"]), (float(r["d"]), 0), fontsize=6, rotation=90,
                    va="bottom", ha="center", color="grey", xycoords=("data", "axes fraction"))
    ax.axhline(command_vx, color="grey", lw=0.7, ls=":")
    ax.set_xlabel("normalised morphology distance d to Go2")
    ax.set_ylabel(f"v_x (m/s) at command {command_vx:g} m/s")
    ax.set_title("Transfer against morphology distance", fontsize=9)
    ax.grid(alpha=0.3)
    if groups or with_paper:
        ax.legend(fontsize=7, loc="upper right")
    return _save(fig)


def compute_figure(compute: Sequence[dict[str, Any]], *, with_paper: bool = False) -> tuple[bytes, bytes]:
    """Training hours against transitions (log-log), our runs and, with ``with_paper``, the paper's methods."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.0, 3.8), constrained_layout=True)
    multi = len({r["preset"] for r in compute}) > 1
    for r in compute:
        if r["transitions"] and r["device_hours"]:
            ax.scatter([r["transitions"]], [r["device_hours"]], s=30,
                       label=f"{_label(r['preset'], r['variant'], multi)} on {r['device']}")
    if with_paper:
        for row in paper.TRAINING_COMPUTE:
            hours = sum(row.gpu_hours) / 2
            ax.scatter([row.transitions], [hours], marker="x", s=30, color="black")
            ax.annotate(f"paper: {row.label}", (row.transitions, hours), fontsize=6, xytext=(3, 3),
                        textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("transitions")
    ax.set_ylabel("training hours (device of the run)")
    ax.set_title("Training compute against transitions", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    if compute:
        ax.legend(fontsize=6, loc="lower right")
    return _save(fig)


def curves_figure(curves: dict[str, list[dict[str, float]]], variants: dict[str, str]) -> tuple[bytes, bytes]:
    """Mean episode return and critic EV against env steps, one line per run, coloured by variant.

    Args:
        curves: Run name -> training-curve rows.
        variants: Run name -> its variant.
    """
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4), constrained_layout=True)
    ordered = sorted(curves, key=lambda n: (variant_order(variants.get(n, "")), n))
    colours = {v: f"C{i}" for i, v in enumerate(sorted(set(variants.values()), key=variant_order))}
    for name in ordered:
        rows = curves[name]
        steps = [r.get("env_steps", math.nan) for r in rows]
        variant = variants.get(name, "")
        for ax, key in zip(axes, ("mean_reward", "explained_variance"), strict=True):
            ax.plot(steps, [r.get(key, math.nan) for r in rows], lw=1.0, color=colours.get(variant),
                    label=f"{paper.METHOD_LABELS.get(variant, variant)} ({name})",
                    marker="." if len(rows) < 5 else None)
    for ax, title in zip(axes, ("mean episode return", "critic explained variance (training)"), strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    if ordered:
        axes[0].legend(fontsize=6)
    return _save(fig)
