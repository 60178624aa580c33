"""Training curves: one row per PPO iteration, stored with every checkpoint as CSV and PNG."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

#: Columns that always come first, in this order; the rest (reward terms, terminations, ...) follow sorted.
CURVE_COLUMNS: tuple[str, ...] = (
    "iteration", "env_steps", "wall_time_s", "steps_per_s", "collect_s", "learn_s", "mean_reward",
    "episode_length_s", "explained_variance", "value_loss", "surrogate", "entropy", "kl", "clip_fraction",
    "adaptation_error", "learning_rate", "action_std", "tracking.vx_error", "curriculum.vx_max",
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
    return [{k: int(v) if k in ints else float(v) for k, v in rec.items()
             if not (isinstance(v, float) and math.isnan(v))} for rec in df.to_dict("records")]


def curve_png(rows: Sequence[dict], title: str = "") -> bytes:
    """A 2 x 3 figure of the curve: reward, reward terms, EV, episode length, vx tracking, throughput."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), constrained_layout=True)
    it = [r.get("iteration", i + 1) for i, r in enumerate(rows)]

    def series(key: str) -> list[float]:
        return [r.get(key, float("nan")) for r in rows]

    panels = [
        (axes[0, 0], ["mean_reward"], "mean episode return"),
        (axes[0, 2], ["explained_variance"], "critic explained variance"),
        (axes[1, 0], ["episode_length_s"], "mean episode length (s)"),
        (axes[1, 1], ["tracking.vx_error", "curriculum.vx_max"], "vx: |cmd - actual| (m/s), curriculum max"),
        (axes[1, 2], ["steps_per_s"], "env steps/s (incl. learning)"),
    ]
    for ax, keys, label in panels:
        for key in keys:
            ax.plot(it, series(key), label=key, lw=1.2)
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
        if len(keys) > 1:
            ax.legend(fontsize=7)
    ax = axes[0, 1]
    terms = sorted({k for r in rows for k in r if k.startswith("episode_reward.")})
    for key in terms:
        ax.plot(it, series(key), lw=0.9, label=key.removeprefix("episode_reward."))
    ax.set_title("reward terms (per second of episode)", fontsize=10)
    ax.grid(alpha=0.3)
    if terms:
        ax.legend(fontsize=5, ncol=2)
    for ax in axes[1]:
        ax.set_xlabel("iteration")
    if title:
        fig.suptitle(title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()
