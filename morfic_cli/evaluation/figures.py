"""The figure of one evaluation rollout (``morfic eval``): validity verdict, forward speed, foot slip and survival.

Above the plots, the table's validity verdict (green when ``ok``, red otherwise) and how many envs are valid, with
the count of each failure (``falls``, ``stands still``, ``lies down``, ``drags feet``). Top: v_x (body frame) of
the envs still alive (:func:`~morfic_cli.evaluation.metrics.alive_mask`, the metrics' definition) against time:
their mean, a band from the 10th to the 90th percentile, the command as a dashed line, and a red tick at the time
of each fall (a termination that is not a time-out). Middle: foot slip, the mean horizontal speed of the feet in
contact, over the same alive envs (mean and band), with the validity threshold (an env whose mean slip is above it
drags its feet). Bottom: survival S(t), the fraction of envs alive at t, which ends at the table's S. Legends sit
right of the axes, off the data. Each figure is ``(png, pdf)`` bytes (the PDF without a creation date).
"""

from __future__ import annotations

import io
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from morfic_cli.evaluation.metrics import FAILURES, ValidityCfg, alive_mask

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


def verdict_line(outcomes: np.ndarray, verdict: str | None = None) -> tuple[str, bool]:
    """The figure's verdict line and whether it reads ``ok``.

    Args:
        outcomes: Each env's validity, ``"ok"`` or its failure. Shape: (N,).
        verdict: The table's verdict; None: ``ok`` when at least half the envs are valid, else the most common
            failure (the table's rule).

    Returns:
        E.g. ``("verdict: drags feet \u2013 valid 0/8 (drags feet 8)", False)``.
    """
    counts = Counter(str(o) for o in outcomes)
    ok = counts["ok"]
    if verdict is None:
        verdict = "ok" if 2 * ok >= len(outcomes) else max(FAILURES, key=lambda k: counts[k])
    detail = ", ".join(f"{k} {counts[k]}" for k in FAILURES if counts[k])
    return (f"verdict: {verdict} \u2013 valid {ok}/{len(outcomes)}" + (f" ({detail})" if detail else ""),
            verdict == "ok")


def rollout_figure(vx: np.ndarray, terminated: np.ndarray, dt: float, command_vx: float, title: str, *,
                   foot_slip: np.ndarray | None = None, outcomes: np.ndarray | None = None,
                   verdict: str | None = None, max_foot_slip: float = ValidityCfg.max_foot_slip
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
    fig, axes = plt.subplots(panels, 1, figsize=(6.4, 2.0 + 1.25 * panels), sharex=True, height_ratios=ratios,
                             constrained_layout=True)
    ax, ax_s = axes[0], axes[-1]
    ax.fill_between(c["t"], c["low"], c["high"], color="C0", alpha=0.25, lw=0,
                    label=f"{BAND[0]:g}\u2013{BAND[1]:g}th pct.")
    ax.plot(c["t"], c["mean"], color="C0", lw=1.4, label=f"mean, alive of {n}")
    ax.axhline(command_vx, color="black", ls="--", lw=1.0, label=f"command {command_vx:g} m/s")
    if len(c["fall_t"]):
        ax.plot(c["fall_t"], np.zeros_like(c["fall_t"]), "|", color="C3", ms=10, mew=1.5,
                label=f"falls ({len(c['fall_t'])})", transform=ax.get_xaxis_transform(), clip_on=False)
    top = np.nanmax([command_vx, *(c["high"][np.isfinite(c["high"])] if np.isfinite(c["high"]).any() else [0])])
    bottom = min(0.0, np.nanmin(c["low"]) if np.isfinite(c["low"]).any() else 0.0)
    ax.set_ylim(bottom - 0.1, 1.15 * top + 0.1)
    ax.set_ylabel("v_x (m/s)", fontsize=9)
    ax.set_title(title, fontsize=9)
    if outcomes is not None:
        text, ok = verdict_line(outcomes, verdict)
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
        ax_f.plot(run["t"], run["mean"], color="C1", lw=1.6,
                  label=f"each env's mean so far\n(mean, {BAND[0]:g}\u2013{BAND[1]:g}th pct.)")
        ax_f.axhline(max_foot_slip, color="C3", ls=":", lw=1.2, label=f"drags feet above\n{max_foot_slip:g} m/s")
        tops = [2.0 * max_foot_slip, *(1.1 * np.nanmax(x) for x in (run["high"], now["mean"]) if np.isfinite(x).any())]
        ax_f.set_ylim(0.0, max(tops))
        ax_f.set_ylabel("foot slip\n(m/s)", fontsize=9)
        ax_f.grid(alpha=0.3)
        ax_f.tick_params(labelsize=8)
        ax_f.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                    handlelength=1.2)
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


def write_figures(store: Store, eval_id: str, out: Path) -> list[Path]:
    """Copy the stored figure of every rollout of eval ``eval_id`` into the ``--out`` directory.

    Names: ``<robot>-<mode>-vx<cmd>-speed.png`` (and ``.pdf``) in ``out``.

    Returns:
        The paths written.
    """
    from morfic_cli.evaluation.media import media_name
    from morfic_cli.evaluation.protocol import FIGURE_PDF, FIGURE_PNG

    written = []
    for role, rid in store.read_manifest(eval_id).inputs.items():
        if not role.startswith("rollout/"):
            continue
        files = store.read_manifest(rid).files
        stem = f"{media_name(role)}-speed"
        for name in (FIGURE_PNG, FIGURE_PDF):
            if name in files:
                path = out / (stem + Path(name).suffix)
                path.write_bytes(store.read_file(rid, name))
                written.append(path)
    return written
