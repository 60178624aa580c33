"""The figure of one evaluation rollout (``morfic eval``): validity verdict, forward speed, foot slip and survival.

Above the plots, the table's validity verdict (green when ``ok``, red otherwise) and how many envs are valid, with
the count of each failure (``falls``, ``stands still``, ``lies down``, ``drags feet``) and, under it, the envs each
termination term ended (:mod:`morfic_cli.evaluation.terminations`; an env that tripped two counts under both). Top:
v_x (body frame) of the envs still alive (:func:`~morfic_cli.evaluation.metrics.alive_mask`, the metrics'
definition) against time: their mean, a band from the 10th to the 90th percentile, the command as a dashed line, and
a red tick at the time of each fall (a termination that is not a time-out). Middle: foot slip, the mean horizontal
speed of the feet in contact, over the same alive envs (mean and band), with the validity threshold (an env whose
mean slip is above it drags its feet). Bottom: survival S(t), the fraction of envs alive at t, which ends at the
table's S. Legends sit right of the axes, off the data. Each figure is ``(png, pdf)`` bytes (the PDF without a
creation date).

A rollout imported from a results-only bundle has neither its log nor its figure (docs/concepts.md, "Results-only
bundles"); :func:`table_figure` then draws the same verdict line with the eval table's numbers instead of the time
series (:func:`figure_or_table`).
"""

from __future__ import annotations

import io
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from morfic_cli.evaluation.metrics import FAILURES, ValidityCfg, alive_mask
from morfic_cli.evaluation.names import FIGURE_PDF, FIGURE_PNG, media_name, rollout_role
from morfic_cli.evaluation.terminations import failure_text

if TYPE_CHECKING:
    from morfic_cli.store import Store

BAND = (10.0, 90.0)
"""Percentiles of v_x over alive envs drawn as the band."""


def speed_survival(vx: np.ndarray, terminated: np.ndarray, dt: float) -> dict[str, np.ndarray]:
    """The curves of the figure.

    Args:
        vx: Forward base velocity (m/s, body frame). Shape: (T, N).
        terminated: Falls (done and not a time-out). Shape: (T, N) bool.
        dt: Policy step (s).

    Returns:
        ``t`` (T,) s (step k ends at (k + 1) dt); ``mean``, ``low``, ``high`` (T,) over alive envs (NaN where none
        is alive); ``survival`` (T,); ``fall_t`` (F,) the time of each fall (an env's first termination).
    """
    alive = alive_mask(terminated)
    t = (np.arange(vx.shape[0]) + 1) * dt
    masked = np.where(alive, vx.astype(np.float64), np.nan)
    any_alive = alive.any(axis=1)
    mean = np.full(len(t), np.nan)
    low, high = mean.copy(), mean.copy()
    if any_alive.any():
        rows = masked[any_alive]
        mean[any_alive] = np.nanmean(rows, axis=1)
        low[any_alive], high[any_alive] = np.nanpercentile(rows, BAND, axis=1)
    fell = terminated.any(axis=0)
    fall_t = t[np.argmax(terminated, axis=0)[fell]]
    return {"t": t, "mean": mean, "low": low, "high": high, "survival": alive.mean(axis=1), "fall_t": fall_t}


def running_mean(x: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Each env's mean of ``x`` over its alive steps up to t (NaN before its first alive step).

    At the last step this is what the validity verdict compares with its threshold (e.g. the mean foot slip).
    Shapes: (T, N), (T, N) bool -> (T, N).
    """
    n = np.cumsum(alive, axis=0)
    total = np.cumsum(np.where(alive, x, 0.0), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def verdict_line(
    outcomes: np.ndarray, verdict: str | None = None, terminations: Mapping[str, int] | None = None
) -> tuple[str, bool]:
    """The figure's verdict line and whether it reads ``ok``.

    Args:
        outcomes: Each env's validity, ``"ok"`` or its failure. Shape: (N,).
        verdict: The table's verdict; None: ``ok`` when at least half the envs are valid, else the most common
            failure (the table's rule).
        terminations: Envs each termination term ended; when any did, a second line ``ended by ...`` (an env that
            tripped several terms counts under each).

    Returns:
        E.g. ``("verdict: drags feet \u2013 valid 0/8 (drags feet 8)", False)``; with ``terminations`` and falls,
        a second line such as ``ended by illegal_contact 8, base_too_low 2``.
    """
    counts = Counter(str(o) for o in outcomes)
    ok = counts["ok"]
    if verdict is None:
        verdict = "ok" if 2 * ok >= len(outcomes) else max(FAILURES, key=lambda k: counts[k])
    detail = ", ".join(f"{k} {counts[k]}" for k in FAILURES if counts[k])
    ended = failure_text(terminations)
    return (
        f"verdict: {verdict} \u2013 valid {ok}/{len(outcomes)}"
        + (f" ({detail})" if detail else "")
        + (f"\nended by {ended}" if ended else ""),
        verdict == "ok",
    )


def rollout_figure(
    vx: np.ndarray,
    terminated: np.ndarray,
    dt: float,
    command_vx: float,
    title: str,
    *,
    foot_slip: np.ndarray | None = None,
    outcomes: np.ndarray | None = None,
    verdict: str | None = None,
    terminations: Mapping[str, int] | None = None,
    max_foot_slip: float = ValidityCfg.max_foot_slip,
) -> tuple[bytes, bytes]:
    """Speed, foot slip, survival and the validity verdict of one rollout (module docstring).

    Args:
        vx: Forward base velocity (m/s). Shape: (T, N).
        terminated: Falls. Shape: (T, N) bool.
        dt: Policy step (s).
        command_vx: The commanded forward speed (m/s).
        title: Figure title, e.g. ``go1, descriptor, command 2.0 m/s``.
        foot_slip: Mean horizontal speed of the feet in contact (m/s). Shape: (T, N). None: no slip panel.
        outcomes: Each env's validity, ``"ok"`` or its failure
            (:func:`~morfic_cli.evaluation.metrics.env_outcomes`). Shape: (N,). None: no verdict line.
        verdict: The table's verdict (``ok`` or the most common failure); with ``outcomes``.
        terminations: Envs each termination term ended (``Rollout.termination_counts``), a second verdict line
            when any did; with ``outcomes``.
        max_foot_slip: The slip above which a survivor drags its feet (m/s), drawn as a line.

    Returns:
        ``(png, pdf)`` bytes.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = speed_survival(vx, terminated, dt)
    n = vx.shape[1]
    panels = 3 if foot_slip is not None else 2
    ratios = (2.2, 1.2, 1.0)[:panels] if panels == 3 else (2.2, 1.0)
    fig, axes = plt.subplots(
        panels, 1, figsize=(6.4, 2.0 + 1.25 * panels), sharex=True, height_ratios=ratios, constrained_layout=True
    )
    ax, ax_s = axes[0], axes[-1]
    ax.fill_between(
        c["t"], c["low"], c["high"], color="C0", alpha=0.25, lw=0, label=f"{BAND[0]:g}\u2013{BAND[1]:g}th pct."
    )
    ax.plot(c["t"], c["mean"], color="C0", lw=1.4, label=f"mean, alive of {n}")
    ax.axhline(command_vx, color="black", ls="--", lw=1.0, label=f"command {command_vx:g} m/s")
    if len(c["fall_t"]):
        ax.plot(
            c["fall_t"],
            np.zeros_like(c["fall_t"]),
            "|",
            color="C3",
            ms=10,
            mew=1.5,
            label=f"falls ({len(c['fall_t'])})",
            transform=ax.get_xaxis_transform(),
            clip_on=False,
        )
    top = np.nanmax([command_vx, *(c["high"][np.isfinite(c["high"])] if np.isfinite(c["high"]).any() else [0])])
    bottom = min(0.0, np.nanmin(c["low"]) if np.isfinite(c["low"]).any() else 0.0)
    ax.set_ylim(bottom - 0.1, 1.15 * top + 0.1)
    ax.set_ylabel("v_x (m/s)", fontsize=9)
    ax.set_title(title, fontsize=9)
    if outcomes is not None:
        text, ok = verdict_line(outcomes, verdict, terminations)
        fig.suptitle(text, fontsize=9, fontweight="bold", color="C2" if ok else "C3")
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=8)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, handlelength=1.2)
    if foot_slip is not None:
        ax_f = axes[1]
        slip = np.asarray(foot_slip, dtype=np.float64)
        now = speed_survival(slip, terminated, dt)  # per step, over the envs alive then
        run = speed_survival(running_mean(slip, alive_mask(terminated)), terminated, dt)
        ax_f.plot(now["t"], now["mean"], color="C1", lw=0.7, alpha=0.45, label="per step (mean)")
        ax_f.fill_between(run["t"], run["low"], run["high"], color="C1", alpha=0.25, lw=0)
        ax_f.plot(
            run["t"],
            run["mean"],
            color="C1",
            lw=1.6,
            label=f"each env's mean so far\n(mean, {BAND[0]:g}\u2013{BAND[1]:g}th pct.)",
        )
        ax_f.axhline(max_foot_slip, color="C3", ls=":", lw=1.2, label=f"drags feet above\n{max_foot_slip:g} m/s")
        tops = [2.0 * max_foot_slip, *(1.1 * np.nanmax(x) for x in (run["high"], now["mean"]) if np.isfinite(x).any())]
        ax_f.set_ylim(0.0, max(tops))
        ax_f.set_ylabel("foot slip\n(m/s)", fontsize=9)
        ax_f.grid(alpha=0.3)
        ax_f.tick_params(labelsize=8)
        ax_f.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, handlelength=1.2)
    ax_s.plot(c["t"], 100.0 * c["survival"], color="C2", lw=1.4, drawstyle="steps-post")
    ax_s.set_ylim(-5, 105)
    ax_s.set_ylabel("alive (%)", fontsize=9)
    ax_s.set_xlabel("time (s)", fontsize=9)
    ax_s.tick_params(labelsize=8)
    ax_s.grid(alpha=0.3)
    ax_s.set_xlim(0, c["t"][-1] if len(c["t"]) else 1.0)
    png, pdf = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=150)
    fig.savefig(pdf, format="pdf", metadata={"CreationDate": None})
    plt.close(fig)
    return png.getvalue(), pdf.getvalue()


def _number(row: dict[str, Any], key: str) -> float:
    """``row[key]`` as a float (NaN when empty or missing): eval rows come from CSV text or pandas."""
    value = row.get(key)
    if value is None:
        return float("nan")
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def table_figure(row: dict[str, Any], title: str) -> tuple[bytes, bytes]:
    """One rollout's figure drawn from its eval-table row, for a rollout whose time series is not in the store.

    The verdict line as :func:`rollout_figure` draws it (valid envs out of ``num_envs``); left, v_x over the
    rollout (``vx_mean``, error bar ``vx_std``) and its best 1 s (``vx_peak_1s_mean`` ± ``vx_peak_1s_std``) beside
    the command (dashed); right, the survival S and the valid fraction in percent. A note under the axes says the
    time series was left out (a results-only bundle) and how to draw it again.

    Args:
        row: One row of ``eval.csv`` (:func:`~morfic_cli.evaluation.protocol.eval_columns`; strings or numbers).
        title: Figure title, e.g. ``film-cpu-s0 on go1, descriptor mode, command 2.0 m/s``.

    Returns:
        ``(png, pdf)`` bytes (the PDF without a creation date).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    command = _number(row, "command_vx")
    n = _number(row, "num_envs")
    valid = _number(row, "valid_fraction")
    fig, (ax, ax_s) = plt.subplots(1, 2, figsize=(6.4, 3.4), width_ratios=(1.6, 1.0), constrained_layout=True)
    labels = ("whole rollout", "best 1 s")
    means = [_number(row, "vx_mean"), _number(row, "vx_peak_1s_mean")]
    errors = [_number(row, "vx_std"), _number(row, "vx_peak_1s_std")]
    for k, (mean, err) in enumerate(zip(means, errors, strict=True)):
        ax.errorbar([k], [mean], yerr=[0.0 if np.isnan(err) else err], fmt="o", color=f"C{k}", capsize=4, ms=7)
        if np.isfinite(mean):
            ax.annotate(f"{mean:.2f}", (k, mean), xytext=(8, 0), textcoords="offset points", va="center", fontsize=8)
    if np.isfinite(command):
        ax.axhline(command, color="black", ls="--", lw=1.0, label=f"command {command:g} m/s")
        ax.legend(fontsize=7, loc="lower right")
    ax.set_xticks(range(len(labels)), labels, fontsize=8)
    ax.set_xlim(-0.6, len(labels) - 0.4)
    top = np.nanmax([command, *(m + (e if np.isfinite(e) else 0.0) for m, e in zip(means, errors, strict=True))])
    ax.set_ylim(min(0.0, np.nanmin([*means, 0.0])) - 0.1, 1.15 * (top if np.isfinite(top) else 1.0) + 0.1)
    ax.set_ylabel("v_x (m/s), mean ± σ", fontsize=9)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, axis="y")
    ax.tick_params(labelsize=8)
    shares = [100.0 * _number(row, "survival"), 100.0 * valid]
    ax_s.bar([0, 1], [0.0 if np.isnan(v) else v for v in shares], color=["C2", "C4"], width=0.6)
    for k, v in enumerate(shares):
        ax_s.annotate(
            "n/a" if np.isnan(v) else f"{v:.0f} %",
            (k, 0.0 if np.isnan(v) else v),
            xytext=(0, 3),
            textcoords="offset points",
            ha="center",
            fontsize=8,
        )
    ax_s.set_xticks([0, 1], ["alive at the end (S)", "valid gait"], fontsize=8)
    ax_s.set_ylim(0, 112)
    ax_s.set_ylabel("envs (%)", fontsize=9)
    ax_s.grid(alpha=0.3, axis="y")
    ax_s.tick_params(labelsize=8)
    verdict = str(row.get("verdict") or "n/a")
    counted = f"valid {round(valid * n)}/{int(n)}" if np.isfinite(valid) and np.isfinite(n) else "valid n/a"
    fig.suptitle(
        f"verdict: {verdict} – {counted}", fontsize=9, fontweight="bold", color="C2" if verdict == "ok" else "C3"
    )
    fig.text(
        0.5,
        -0.02,
        "from the eval table: the time series was left out (a results-only bundle); import the "
        "run's weights and `morfic eval` it to draw it",
        ha="center",
        va="top",
        fontsize=7,
        color="0.35",
    )
    png, pdf = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=110, bbox_inches="tight")
    fig.savefig(pdf, format="pdf", metadata={"CreationDate": None}, bbox_inches="tight")
    plt.close(fig)
    return png.getvalue(), pdf.getvalue()


def figure_or_table(
    store: Store, rollout_id: str, row: dict[str, Any] | None, title: str
) -> tuple[bytes, bytes] | None:
    """The ``(png, pdf)`` figure of rollout ``rollout_id``: the stored one, or :func:`table_figure` of ``row``.

    The stored ``speed.png`` / ``speed.pdf`` when the store holds them; drawn from the eval row when a
    results-only bundle left them out (``store.omitted_files``); None when the rollout has no figure (or it was
    left out and there is no row to draw from).
    """
    manifest = store.read_manifest(rollout_id)
    if FIGURE_PNG not in manifest.files or FIGURE_PDF not in manifest.files:
        return None
    if not {FIGURE_PNG, FIGURE_PDF} & set(store.omitted_files(manifest)):
        return store.read_file(rollout_id, FIGURE_PNG), store.read_file(rollout_id, FIGURE_PDF)
    return None if row is None else table_figure(row, title)


def write_figures(store: Store, eval_id: str, out: Path) -> list[Path]:
    """Write the figure of every rollout of eval ``eval_id`` into the ``--out`` directory.

    The stored figure, or (left out by a results-only bundle) one drawn from the eval's table
    (:func:`figure_or_table`). Names: ``<robot>-<mode>-vx<cmd>-speed.png`` (and ``.pdf``) in ``out``.

    Returns:
        The paths written.
    """
    import csv

    manifest = store.read_manifest(eval_id)
    rows = {}
    if "eval.csv" in manifest.files:
        text = store.read_file(eval_id, "eval.csv").decode()
        rows = {
            rollout_role(r["robot"], r["mode"], float(r["command_vx"])): r for r in csv.DictReader(io.StringIO(text))
        }
    run = manifest.meta.get("run", "")
    written = []
    for role, rid in manifest.inputs.items():
        if not role.startswith("rollout/"):
            continue
        row = rows.get(role)
        title = (
            f"{run} on {row['robot']}, {row['mode']} mode, command {float(row['command_vx']):g} m/s" if row else role
        )
        figure = figure_or_table(store, rid, row, title)
        if figure is None:
            continue
        stem = f"{media_name(role)}-speed"
        for suffix, data in zip((".png", ".pdf"), figure, strict=True):
            path = out / (stem + suffix)
            path.write_bytes(data)
            written.append(path)
    return written
