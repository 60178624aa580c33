"""The figure of one evaluation rollout (``morfic eval``): forward speed and survival over time.

Top: v_x (body frame) of the envs still alive (:func:`~morfic_cli.evaluation.metrics.alive_mask`, the metrics'
definition) against time: their mean, a band from the 10th to the 90th percentile, the command as a dashed line, and
a red tick at the time of each fall (a termination that is not a time-out). Bottom: survival S(t), the fraction of
envs alive at t, which ends at the table's S. Each figure is ``(png, pdf)`` bytes (the PDF without a creation date).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from morfic_cli.evaluation.metrics import alive_mask

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


def rollout_figure(vx: np.ndarray, terminated: np.ndarray, dt: float, command_vx: float, title: str
                   ) -> tuple[bytes, bytes]:
    """Speed and survival over time of one rollout (module docstring).

    Args:
        vx: Forward base velocity (m/s). Shape: (T, N).
        terminated: Falls. Shape: (T, N) bool.
        dt: Policy step (s).
        command_vx: The commanded forward speed (m/s).
        title: Figure title, e.g. ``go1, descriptor, command 2.0 m/s``.

    Returns:
        ``(png, pdf)`` bytes.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = speed_survival(vx, terminated, dt)
    n = vx.shape[1]
    fig, (ax, ax_s) = plt.subplots(2, 1, figsize=(4.4, 3.3), sharex=True, height_ratios=(2.2, 1.0),
                                   constrained_layout=True)
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
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=8)
    ax.legend(fontsize=7, loc="lower right", ncol=2, handlelength=1.2, columnspacing=0.8, borderpad=0.3)
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
