"""Training curves: one row per PPO iteration, stored with every checkpoint as CSV and PNG."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

#: Columns that always come first, in this order; the rest (reward terms, terminations, ...) follow sorted.
CURVE_COLUMNS: tuple[str, ...] = (
    "iteration",
    "env_steps",
    "wall_time_s",
    "steps_per_s",
    "collect_s",
    "learn_s",
    "mean_reward",
    "episode_length_s",
    "explained_variance",
    "value_loss",
    "surrogate",
    "entropy",
    "kl",
    "clip_fraction",
    "adaptation_error",
    "learning_rate",
    "action_std",
    "tracking.vx_error",
    "curriculum.vx_max",
)


def curve_columns(rows: Sequence[dict]) -> list[str]:
    """The column order of a curve table: :data:`CURVE_COLUMNS` present in the rows, then the rest sorted."""
    keys = dict.fromkeys(k for row in rows for k in row)
    head = [c for c in CURVE_COLUMNS if c in keys]
    return head + sorted(k for k in keys if k not in head)


def curve_csv(rows: Sequence[dict]) -> bytes:
    """The curve rows as CSV bytes (missing values empty)."""
    from morfic_cli.recording.tables import rows_to_csv

    return rows_to_csv(rows, curve_columns(rows))


def read_curve_csv(data: bytes) -> list[dict[str, float]]:
    """Parse :func:`curve_csv` output back into rows (empty cells dropped)."""
    import pandas as pd

    if not data.strip():
        return []
    df = pd.read_csv(io.BytesIO(data))
    ints = ("iteration", "env_steps")
    return [
        {k: int(v) if k in ints else float(v) for k, v in rec.items() if not (isinstance(v, float) and math.isnan(v))}
        for rec in df.to_dict("records")
    ]


def _has_values(values: Sequence[float]) -> bool:
    return any(not math.isnan(v) for v in values)


def curve_png(rows: Sequence[dict], title: str = "") -> bytes:
    """The training curve as one PNG: a 2 x 3 grid of the main curves above small multiples of the reward terms.

    Main panels: mean episode return, critic EV, episode length, v_x tracking error with the curriculum's
    maximum command, env steps/s, PPO's value loss. Below, one small panel per reward term (``episode_reward.*``,
    per second of episode), each with its own y range, so 20+ terms stay readable. A panel whose series are all
    missing is not drawn.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    it = [r.get("iteration", i + 1) for i, r in enumerate(rows)]

    def series(key: str) -> list[float]:
        return [float(r.get(key, math.nan)) for r in rows]

    panels = [
        (["mean_reward"], "mean episode return"),
        (["explained_variance"], "critic explained variance"),
        (["episode_length_s"], "mean episode length (s)"),
        (["tracking.vx_error", "curriculum.vx_max"], "v_x: |command - actual| and curriculum max (m/s)"),
        (["steps_per_s"], "env steps/s (incl. learning)"),
        (["value_loss"], "value loss"),
    ]
    panels = [(keys, label) for keys, label in panels if any(_has_values(series(k)) for k in keys)]
    terms = sorted(k for k in {k for r in rows for k in r if k.startswith("episode_reward.")} if _has_values(series(k)))
    ncols = 6
    term_rows = math.ceil(len(terms) / ncols)
    main_rows = max(1, math.ceil(len(panels) / 3))
    fig = plt.figure(figsize=(14, 3.2 * main_rows + 1.9 * term_rows + (0.5 if title else 0)), constrained_layout=True)
    top, bottom = (
        fig.subfigures(2, 1, squeeze=False, height_ratios=[3.2 * main_rows, max(1.9 * term_rows, 0.01)]).ravel()
        if terms
        else (fig, None)
    )
    axes = top.subplots(main_rows, 3, squeeze=False).ravel()
    for ax, (keys, label) in zip(axes, panels, strict=False):
        for key in keys:
            ax.plot(it, series(key), label=key, lw=1.1)
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_xlabel("iteration", fontsize=8)
        if len(keys) > 1:
            ax.legend(fontsize=8)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    if bottom is not None:
        bottom.suptitle("reward terms (per second of episode; each panel its own scale)", fontsize=10)
        taxes = bottom.subplots(term_rows, ncols, squeeze=False, sharex=True).ravel()
        for ax, key in zip(taxes, terms, strict=False):
            ax.plot(it, series(key), lw=0.9, color="C0")
            ax.set_title(key.removeprefix("episode_reward."), fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        for ax in taxes[len(terms) :]:
            ax.set_visible(False)
    if title:
        fig.suptitle(title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()
