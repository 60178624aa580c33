"""docs/results.md's transfer and calibration tables, from the run CSVs under docs/results/, beside the paper's.

Every ``<run>-eval.csv`` and ``<run>-calibration.csv`` that scripts/experiment_tables.py copied out of the experiment
store becomes a column (runs ordered as the paper orders the variants, then by seed); the paper's own columns are
added for each trained variant it reports. With ``--write FILE`` the tables replace what stands between the
markers ``<!-- results-tables:begin -->`` and ``<!-- results-tables:end -->`` in FILE; without it they go to stdout.

Usage: python scripts/results_tables.py [--results docs/results] [--write docs/results.md]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

BEGIN, END = "<!-- results-tables:begin -->", "<!-- results-tables:end -->"
ROBOTS = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c")


def load(results: Path, kind: str) -> pd.DataFrame:
    """Every ``<run>-<kind>.csv`` in ``results`` in one frame with a ``run`` column, runs in the paper's order."""
    from morfic_cli.rl.variants import variant_order

    frames = []
    for path in sorted(results.glob(f"*-cpu-s[0-9]-{kind}.csv")):
        frame = pd.read_csv(path)
        frame["run"] = path.name[: -len(f"-{kind}.csv")]
        frames.append(frame)
    if not frames:
        return pd.DataFrame()
    out = pd.concat(frames, ignore_index=True)
    out["variant"] = out["run"].str.replace(r"-cpu-s\d$", "", regex=True)
    out["_order"] = [(variant_order(v), r) for v, r in zip(out["variant"], out["run"], strict=True)]
    return out.sort_values("_order", kind="stable").drop(columns="_order")


def _cell(vx: float | None, std: float | None, s: float | None, verdict: str | None = None) -> str:
    if vx is None or pd.isna(vx):
        return "-"
    text = f"{vx:.2f} ± {std:.2f} / {s:.3f}"
    return f"{text} ({verdict})" if verdict else text


def transfer_table(ev: pd.DataFrame, mode: str, command_vx: float) -> list[str]:
    """One markdown table: robots x runs (v̄x ± σ / S (verdict)), then the paper's columns in descriptor mode."""
    from morfic_cli.report.paper import transfer_values

    rows = ev[(ev["mode"] == mode) & ((ev["command_vx"] - command_vx).abs() < 1e-9)]
    runs = list(dict.fromkeys(rows["run"]))
    variants = list(dict.fromkeys(rows["variant"]))
    paper = [v for v in variants if mode == "descriptor" and any(
        transfer_values(v, r, command_vx)["vx"] is not None for r in ROBOTS)]
    head = ["robot", "d", *[f"`{r}`" for r in runs], *[f"paper {v}" for v in paper]]
    lines = ["| " + " | ".join(head) + " |", "|---|---:|" + "---|" * (len(head) - 2)]
    for robot in ROBOTS:
        at = rows[rows["robot"] == robot].set_index("run")
        if at.empty:
            continue
        cells = [_cell(at.at[r, "vx_mean"], at.at[r, "vx_std"], at.at[r, "survival"], at.at[r, "verdict"])
                 if r in at.index else "-" for r in runs]
        for v in paper:
            p = transfer_values(v, robot, command_vx)
            cells.append(_cell(p["vx"], p["vx_std"], p["survival"]))
        lines.append(f"| {robot} | {float(at['d'].iloc[0]):.3f} | " + " | ".join(cells) + " |")
    return lines


def calibration_table(cal: pd.DataFrame) -> list[str]:
    """Robots x runs: EV and |NVB|/NVE/ASA, then the paper's |NVB|/NVE/ASA for the variants it reports."""
    from morfic_cli.report.paper import critic_values

    runs = list(dict.fromkeys(cal["run"]))
    paper = [v for v in dict.fromkeys(cal["variant"]) if critic_values(v, "go2")["abs_nvb"] is not None]
    head = ["robot", *[f"`{r}` EV" for r in runs], *[f"`{r}` \\|NVB\\|/NVE/ASA" for r in runs],
            *[f"paper {v} \\|NVB\\|/NVE/ASA" for v in paper]]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * len(runs) + "---|" * (len(head) - 1 - len(runs))]
    for robot in ROBOTS:
        at = cal[cal["robot"] == robot].set_index("run")
        if at.empty:
            continue
        evs = [f"{at.at[r, 'ev']:.3f}" if r in at.index else "-" for r in runs]
        trio = [f"{at.at[r, 'abs_nvb']:.3f}/{at.at[r, 'nve']:.3f}/{at.at[r, 'asa']:.3f}" if r in at.index else "-"
                for r in runs]
        ours = []
        for v in paper:
            p = critic_values(v, robot)
            ours.append("-" if p["abs_nvb"] is None else f"{p['abs_nvb']:.3f}/{p['nve']:.3f}/{p['asa']:.3f}")
        lines.append(f"| {robot} | " + " | ".join(evs + trio + ours) + " |")
    return lines


def render(results: Path) -> str:
    """All tables as one markdown block (without the markers)."""
    ev, cal = load(results, "eval"), load(results, "calibration")
    out: list[str] = []
    titles = {("descriptor", 2.0): "Descriptor mode (the paper's protocol), 2.0 m/s",
              ("descriptor", 2.5): "Descriptor mode, 2.5 m/s (the paper reports only MorFiC-F, as v_x^max)",
              ("full", 2.0): "Full mode (the targets' own models; a morfic extension, no paper column), 2.0 m/s",
              ("full", 2.5): "Full mode, 2.5 m/s"}
    if not ev.empty:
        for (mode, vx), title in titles.items():
            out += [f"### {title}", "", *transfer_table(ev, mode, vx), ""]
    if not cal.empty:
        out += ["### Critic calibration (`morfic diagnose RUN`: descriptor mode, 2.0 m/s, 64 envs x 800 steps)", "",
                *calibration_table(cal), ""]
    return "\n".join(out).rstrip() + "\n"


def write_between_markers(path: Path, block: str) -> None:
    """Replace the text between :data:`BEGIN` and :data:`END` in ``path`` with ``block``."""
    text = path.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"Error: {path} has no {BEGIN} ... {END} markers; add them where the tables go.")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    path.write_text(f"{head}{BEGIN}\n{block}{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    """Print the tables, or write them into ``--write``'s marked block; 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", type=Path, default=Path("docs/results"))
    p.add_argument("--write", type=Path, default=None, help="markdown file whose marked block to replace")
    args = p.parse_args(argv)
    block = render(args.results)
    if args.write is None:
        sys.stdout.write(block)
    else:
        write_between_markers(args.write, block)
        print(f"{args.write}: tables of {len(load(args.results, 'eval')['run'].unique())} run(s) written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
