"""Issue 58's goal, in one place: one Go2-trained policy that walks all seven robots in their own bodies.

The goal (issue 58, "Beyond the paper"): from the Go2 template alone, at the ``cpu`` budget, a policy that walks
every one of the seven robots in full mode (each robot's own model) with S >= 0.95 and v_x >= 0.9 m/s at a commanded
1.0 m/s, and S >= 0.9 with v_x >= 1.5 m/s at 2.0 m/s, with a valid gait (the eval's validity verdict ``ok``), while
Go2, Go1 and A1 stay at least as good as today's film. :data:`GOAL` holds those bars; :func:`meets_goal` judges one
eval row (one run, one robot, one mode and command) against them; :func:`goal_table` lays the seven robots out
against them for docs/results.md ("One policy for seven robots") and ``morfic report``; :func:`reference_effects`
compares Go2, Go1 and A1 with film's seeds (Welch's t, Holm-corrected: :mod:`morfic_cli.report.stats`);
:func:`ended_by_table` says, per robot and column, what ended the failed episodes (the evals' termination counts);
:func:`goal_evals` which evals the goal needs beyond a run's own (film's full mode at 1.0 m/s).

Rows are eval rows (``eval.csv``'s columns, with ``variant`` and ``seed``): ``vx_mean`` (or a comparison row's
``vx``), ``survival``, ``verdict``, ``mode``, ``command_vx``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from morfic_cli.report import stats
from morfic_cli.report.claims import TRAINED_COMMAND, command_suffix, is_paper_command, row_command
from morfic_cli.report.model import Part, Row, Table
from morfic_cli.report.paper import ROBOT_LABELS, ROBOTS
from morfic_cli.rl.variants import eval_modes


@dataclass(frozen=True)
class GoalBar:
    """The goal's bar at one command.

    Attributes:
        command_vx: The commanded forward speed (m/s).
        min_vx: The least mean forward speed v_x over the alive steps (m/s).
        min_survival: The least survival S (share of envs alive to the end).
    """

    command_vx: float
    min_vx: float
    min_survival: float


@dataclass(frozen=True)
class Goal:
    """Issue 58's goal (see the module docstring).

    Attributes:
        mode: The eval mode the goal is judged in (``full``: each robot's own model).
        verdict: The validity verdict a row must have (``ok``: moving, upright, no dragging).
        bars: One bar per command.
        kept: The robots that must stay at least as good as :attr:`reference`.
        reference: Today's policy they are compared with (``film``).
    """

    mode: str = "full"
    verdict: str = "ok"
    bars: tuple[GoalBar, ...] = (GoalBar(1.0, 0.9, 0.95), GoalBar(2.0, 1.5, 0.9))
    kept: tuple[str, ...] = ("go2", "go1", "a1")
    reference: str = "film"

    @property
    def commands(self) -> tuple[float, ...]:
        """The commands (m/s) the goal has a bar at, ascending."""
        return tuple(sorted(b.command_vx for b in self.bars))

    def bar(self, command_vx: float) -> GoalBar | None:
        """The bar at ``command_vx`` (m/s), else None."""
        return next((b for b in self.bars if abs(b.command_vx - command_vx) < 1e-9), None)

    def text(self) -> str:
        """The goal in one sentence, from the bars (docs and the report print it)."""
        bars = "; ".join(
            f"S >= {b.min_survival:g} and v_x >= {b.min_vx:g} m/s at {b.command_vx:.1f} m/s"
            for b in sorted(self.bars, key=lambda b: b.command_vx)
        )
        names = [_label(r) for r in self.kept]
        kept = ", ".join(names[:-1]) + f" and {names[-1]}" if len(names) > 1 else names[0]
        return (
            f"{self.mode} mode, every robot: {bars}, with the validity verdict `{self.verdict}`; "
            f"{kept} at least as good as today's `{self.reference}`"
        )


GOAL = Goal()
"""Issue 58's goal: the one place its numbers live."""


def goal_evals(variant: str, goal: Goal = GOAL) -> tuple[float, ...]:
    """The goal commands (m/s) at which a run of ``variant`` needs one more eval, in the goal's mode, for the goal.

    Only the reference's runs are compared with (Go2, Go1 and A1 against film), so only they can lack rows: at each
    goal command, the goal's mode unless the run's own eval there has it (:func:`~morfic_cli.rl.variants.eval_modes`
    at 2.0 m/s, with ``trained_regime`` at 1.0 m/s; none at another command). film: ``(1.0,)``, its 1.0 m/s eval
    being descriptor mode alone (the shipped runs' config, which stays). Every other variant: ``()``. The one place
    that says which extra evals the goal needs: scripts/experiment_tables.py makes and copies them
    (:func:`goal_eval_name`), scripts/results_tables.py reads them.
    """
    if variant != goal.reference:
        return ()

    def own_modes(command: float) -> tuple[str, ...]:
        if is_paper_command(command):
            return eval_modes(variant)
        return eval_modes(variant, trained_regime=True) if abs(command - TRAINED_COMMAND) < 1e-9 else ()

    return tuple(c for c in goal.commands if goal.mode not in own_modes(c))


def goal_eval_name(command_vx: float, kind: str = "eval", goal: Goal = GOAL) -> str:
    """The name of the goal's extra eval at ``command_vx`` (:func:`goal_evals`) beside a run's other results.

    ``eval-1.0-full``: docs/results/ holds ``<run>-eval-1.0-full.csv`` and, with ``kind`` ``terminations``, its
    termination counts ``<run>-terminations-1.0-full.csv``; ``<run>-artifacts.json`` its id under ``eval-1.0-full``.
    """
    return f"{kind}{command_suffix(command_vx)}-{goal.mode}"


def row_vx(row: Mapping[str, Any]) -> float:
    """A row's v_x (m/s): an eval row's ``vx_mean``, a comparison row's ``vx``; NaN when it has none."""
    value = row.get("vx_mean", row.get("vx"))
    return math.nan if value is None else float(value)


def passes_bar(row: Mapping[str, Any], goal: Goal = GOAL) -> bool:
    """Whether one eval row clears the goal's bar at its command, in whatever mode it was measured.

    S >= the bar's S, v_x >= the bar's v_x (both inclusive) and the verdict the goal asks for. False at a command
    with no bar. :func:`meets_goal` also asks for the goal's mode; this one lets the descriptor-mode and
    actuation-matched tables be read against the same bars.
    """
    bar = goal.bar(row_command(dict(row)))
    if bar is None:
        return False
    survival = row.get("survival")
    s = math.nan if survival is None else float(survival)
    return bool(row_vx(row) >= bar.min_vx and s >= bar.min_survival and str(row.get("verdict")) == goal.verdict)


def meets_goal(row: Mapping[str, Any], goal: Goal = GOAL) -> bool:
    """Whether one eval row meets issue 58's goal: full mode and :func:`passes_bar`.

    Issue 58: "S >= 0.95 and v_x >= 0.9 m/s at 1.0 m/s, and S >= 0.9 with v_x >= 1.5 m/s at 2.0 m/s, with a valid
    gait (the eval's validity verdict ``ok``)", every robot in full mode. Edges count as met (``>=``); a row at a
    command without a bar (2.5 m/s) or in another mode never meets it.
    """
    return row.get("mode") == goal.mode and passes_bar(row, goal)


# ----------------------------------------------------------------------------------------------- cells
@dataclass(frozen=True)
class GoalCell:
    """One column's seeds on one robot at one mode and command.

    Attributes:
        vx: v_x per seed (m/s).
        survival: S per seed.
        verdicts: The validity verdict per seed.
        passed: Whether each seed clears the bar (:func:`passes_bar`).
    """

    vx: tuple[float, ...]
    survival: tuple[float, ...]
    verdicts: tuple[str, ...]
    passed: tuple[bool, ...]

    @property
    def n(self) -> int:
        """Seeds."""
        return len(self.vx)

    @property
    def met(self) -> bool:
        """Every seed clears the bar."""
        return bool(self.passed) and all(self.passed)

    def verdict_text(self) -> str:
        """``ok`` for one seed; over several each verdict with its count, ``drags feet 2/3, ok 1/3``."""
        if self.n == 1:
            return self.verdicts[0]
        counts = {v: self.verdicts.count(v) for v in dict.fromkeys(self.verdicts)}
        return ", ".join(f"{v} {c}/{self.n}" for v, c in sorted(counts.items(), key=lambda kv: -kv[1]))

    def mark(self) -> str:
        """``meets`` (every seed), ``misses`` (none), ``meets in k of n seeds``."""
        k = sum(self.passed)
        if k == self.n:
            return "meets"
        return "misses" if k == 0 else f"meets in {k} of {self.n} seeds"


def _number(values: Sequence[float], decimals: int, bounds: tuple[float, float] | None = None) -> str:
    """One seed's value; over several the seed mean with its 95 % t interval (:func:`stats.mean_interval`).

    ``bounds``: the range the quantity cannot leave (S: [0, 1]); the interval's ends are clipped to it.
    """
    if len(values) == 1:
        return f"{values[0]:.{decimals}f}"
    mean, lo, hi = stats.mean_interval(values)
    if bounds is not None:
        lo, hi = max(lo, bounds[0]), min(hi, bounds[1])
    return f"{mean:.{decimals}f} [{lo:.{decimals}f}, {hi:.{decimals}f}]"


def _by_seed(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """One row per seed (a later row replaces an earlier one), in seed order."""
    seeds = {r.get("seed", 0): r for r in rows}
    return [seeds[k] for k in sorted(seeds, key=str)]


def goal_cells(
    rows: Sequence[Mapping[str, Any]],
    mode: str,
    command_vx: float,
    column: Callable[[Mapping[str, Any]], str],
    goal: Goal = GOAL,
) -> dict[tuple[str, str], GoalCell]:
    """(column, robot) -> its :class:`GoalCell` in ``mode`` at ``command_vx``, from per-seed eval rows."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        if r.get("mode") == mode and abs(row_command(dict(r)) - command_vx) < 1e-9:
            groups.setdefault((column(r), str(r["robot"])), []).append(r)
    out = {}
    for key, group in groups.items():
        seeds = _by_seed(group)
        out[key] = GoalCell(
            tuple(row_vx(r) for r in seeds),
            tuple(float(r["survival"]) for r in seeds),
            tuple(str(r.get("verdict")) for r in seeds),
            tuple(passes_bar(r, goal) for r in seeds),
        )
    return out


def robots_meeting(
    rows: Sequence[Mapping[str, Any]], col: str, column: Callable[[Mapping[str, Any]], str], goal: Goal = GOAL
) -> tuple[list[str], list[float]]:
    """(robots on which every seed of ``col`` meets the goal at every command, the commands with no rows of it)."""
    cells = {c: goal_cells(rows, goal.mode, c, column, goal) for c in goal.commands}
    missing = [c for c in goal.commands if not any(k[0] == col for k in cells[c])]
    met = [r for r in ROBOTS if all((col, r) in cells[c] and cells[c][(col, r)].met for c in goal.commands)]
    return met, missing


def goal_table(
    rows: Sequence[Mapping[str, Any]],
    mode: str,
    command_vx: float,
    columns: Sequence[tuple[str, str]],
    column: Callable[[Mapping[str, Any]], str],
    goal: Goal = GOAL,
) -> Table | None:
    """The seven robots x ``columns`` in ``mode`` at ``command_vx``: v_x / S / verdict / the goal's mark.

    Args:
        rows: Per-seed eval rows.
        mode: ``full`` (the goal's), ``descriptor`` or ``actuation-matched`` (read against the same bars).
        command_vx: One of the goal's commands (m/s).
        columns: (key, header) per column, ``key`` as ``column`` returns it.
        column: A row's column key (its variant, or preset and variant).
        goal: The bars.

    Returns:
        The table, its last row the robots clearing the bar per column (k of 7); None when no column has a row.
    """
    bar = goal.bar(command_vx)
    cells = goal_cells(rows, mode, command_vx, column, goal)
    cols = [(k, h) for k, h in columns if any(key[0] == k for key in cells)]
    if bar is None or not cols:
        return None
    out_rows = []
    for robot in ROBOTS:
        parts = []
        for key, _ in cols:
            c = cells.get((key, robot))
            if c is None:
                parts.append((Part(None), Part(None), Part(None), Part(None)))
                continue
            parts.append(
                (
                    Part(None, text=_number(c.vx, 2)),
                    Part(None, text=_number(c.survival, 3, (0.0, 1.0))),
                    Part(None, text=c.verdict_text()),
                    Part(None, text=c.mark(), bold=c.met),
                )
            )
        out_rows.append(Row(_label(robot), tuple(parts)))
    counts = [sum(1 for r in ROBOTS if (k, r) in cells and cells[(k, r)].met) for k, _ in cols]
    out_rows.append(Row("clears the bar", tuple((Part(None, text=f"{n} of {len(ROBOTS)}"),) for n in counts)))
    own = mode == goal.mode
    caption = (
        f"Each cell is v_x / S / validity verdict / the goal's mark at a commanded {command_vx:.1f} m/s in "
        f"{mode} mode; the bar: v_x >= {bar.min_vx:g} m/s, S >= {bar.min_survival:g}, verdict `{goal.verdict}`"
        + ("" if own else f" (the goal is judged in {goal.mode} mode; here its bar is read in {mode} mode)")
        + ". One seed: its own numbers; several: the seed mean with its 95 % t interval over seeds (S's clipped to "
        "[0, 1]); a cell meets the bar when every seed does."
    )
    key = f"goal_{mode}_{command_vx:.1f}".replace(".", "_").replace("-", "_")
    title = f"Against issue 58's goal: {mode} mode at {command_vx:.1f} m/s"
    return Table(key, title, caption, "Robot", tuple(h for _, h in cols), tuple(out_rows), math=False)


def _label(robot: str) -> str:
    """The paper's name of a robot (``Cheetah`` for mini_cheetah)."""
    return ROBOT_LABELS.get(robot, robot)


# ----------------------------------------------------------------------------------------------- against film
@dataclass(frozen=True)
class ReferenceEffect:
    """A column minus today's reference (film) on one kept robot, one command, one metric, full mode.

    Attributes:
        robot: One of :attr:`Goal.kept`.
        command_vx: The command (m/s).
        metric: ``vx`` or ``survival``.
        effect: The difference of seed means with its Welch t interval (none at one seed).
        p_holm: Holm-adjusted p over the column's comparisons (NaN without a test).
    """

    robot: str
    command_vx: float
    metric: str
    effect: stats.Effect
    p_holm: float

    @property
    def below(self) -> bool:
        """Significantly below the reference after Holm (:data:`stats.ALPHA`)."""
        return bool(self.effect.estimate < 0 and self.p_holm < stats.ALPHA)


def reference_effects(
    rows: Sequence[Mapping[str, Any]],
    col: str,
    column: Callable[[Mapping[str, Any]], str],
    reference: str | None = None,
    goal: Goal = GOAL,
) -> list[ReferenceEffect]:
    """``col`` minus the reference on each kept robot, goal command and metric (v_x, S), in the goal's mode.

    Welch's t over seeds (:func:`stats.mean_difference`), Holm over the column's comparisons together; a
    comparison with a one-seed side has no test (NaN p). Comparisons where either side has no row are left out.
    """
    ref = goal.reference if reference is None else reference
    found: list[tuple[str, float, str, stats.Effect]] = []
    for command in goal.commands:
        cells = goal_cells(rows, goal.mode, command, column, goal)
        for robot in goal.kept:
            a, b = cells.get((col, robot)), cells.get((ref, robot))
            if a is None or b is None:
                continue
            found.append((robot, command, "vx", stats.mean_difference(a.vx, b.vx)))
            found.append((robot, command, "survival", stats.mean_difference(a.survival, b.survival)))
    adjusted = stats.holm([e.p for *_, e in found])
    return [ReferenceEffect(r, c, m, e, float(p)) for (r, c, m, e), p in zip(found, adjusted, strict=True)]


def reference_text(effects: Sequence[ReferenceEffect], reference: str = GOAL.reference) -> str:
    """Where a column stands against the reference on the kept robots, one sentence (empty without comparisons).

    Example: ``significantly below film: none (Welch t over seeds, Holm over 12); Go2 at 2.0 m/s v_x +0.10 (n 1
    vs 3: no test), S ...``.
    """
    if not effects:
        return ""
    below = [e for e in effects if e.below]
    head = (
        f"significantly below `{reference}`: "
        + (", ".join(f"{_label(e.robot)} {e.metric} at {e.command_vx:.1f} m/s" for e in below) or "none")
        + f" (Welch t over seeds, Holm over these {len(effects)})"
    )
    parts = [
        f"{_label(e.robot)} at {e.command_vx:.1f} m/s {'v_x' if e.metric == 'vx' else 'S'} "
        + e.effect.text(2 if e.metric == "vx" else 3, e.p_holm)
        for e in effects
    ]
    return head + "; " + ", ".join(parts)


# ----------------------------------------------------------------------------------------------- ended by
def ended_by_counts(
    lines: Sequence[Mapping[str, Any]], mode: str, command_vx: float, column: Callable[[Mapping[str, Any]], str]
) -> dict[tuple[str, str], tuple[dict[str, int], int]]:
    """(column, robot) -> (term -> envs summed over seeds, seeds that recorded counts) in ``mode`` at ``command_vx``.

    Args:
        lines: Termination lines (``terminations.csv``'s columns: ``robot``, ``mode``, ``command_vx``, ``term``,
            ``envs``; docs/eval.md, "Termination counts") with the keys ``column`` reads and ``seed``.
        mode: The eval mode.
        command_vx: The command (m/s).
        column: A line's column key (its variant, or preset and variant).
    """
    groups: dict[tuple[str, str], dict[Any, dict[str, int]]] = {}
    for line in lines:
        if line.get("mode") == mode and abs(float(line["command_vx"]) - command_vx) < 1e-9:
            seeds = groups.setdefault((column(line), str(line["robot"])), {})
            seeds.setdefault(line.get("seed", 0), {})[str(line["term"])] = int(line["envs"])
    out: dict[tuple[str, str], tuple[dict[str, int], int]] = {}
    for key, seeds in groups.items():
        total: dict[str, int] = {}
        for counts in seeds.values():
            for term, n in counts.items():
                total[term] = total.get(term, 0) + n
        out[key] = (total, len(seeds))
    return out


def ended_by_text(counts: Mapping[str, int]) -> str:
    """The terms that ended envs, most first (ties in recorded order), e.g. ``illegal_contact 12, excessive_tilt 3``.

    ``none`` when counts were recorded and no env failed.
    """
    from morfic_cli.evaluation.terminations import failure_text

    ranked = dict(sorted(counts.items(), key=lambda kv: -kv[1]))  # stable: ties keep the recorded order
    return failure_text(ranked) or "none"


def ended_by_table(
    lines: Sequence[Mapping[str, Any]],
    rows: Sequence[Mapping[str, Any]],
    mode: str,
    command_vx: float,
    columns: Sequence[tuple[str, str]],
    column: Callable[[Mapping[str, Any]], str],
) -> Table | None:
    """The seven robots x ``columns``: what ended the failed episodes in ``mode`` at ``command_vx``.

    Each cell is :func:`ended_by_text` of the counts summed over the column's seeds; where fewer seeds recorded
    counts than have eval rows (``rows``: evals made before ``terminations.csv`` existed), ``(k of n seeds)``.
    A cell without counts is missing (``-``), never ``none``.

    Returns:
        The table; None when no column has counts in ``mode`` at ``command_vx``.
    """
    counts = ended_by_counts(lines, mode, command_vx, column)
    cols = [(k, h) for k, h in columns if any(key[0] == k for key in counts)]
    if not cols:
        return None
    seeds = {key: cell.n for key, cell in goal_cells(rows, mode, command_vx, column).items()}
    out_rows = []
    for robot in ROBOTS:
        parts: list[tuple[Part, ...]] = []
        for key, _ in cols:
            found = counts.get((key, robot))
            if found is None:
                parts.append((Part(None),))
                continue
            total, k = found
            n = max(seeds.get((key, robot), k), k)
            parts.append((Part(None, text=ended_by_text(total) + (f" ({k} of {n} seeds)" if k < n else "")),))
        out_rows.append(Row(_label(robot), tuple(parts)))
    caption = (
        f"What ended the failed episodes in {mode} mode at a commanded {command_vx:.1f} m/s: the envs each "
        'termination term ended, summed over the seeds (docs/eval.md, "Termination counts"); an env counts under '
        "every term it tripped on its fatal step. `none`: no env failed; `-`: no counts recorded (an eval made "
        "before they were)."
    )
    key = f"ended_by_{mode}_{command_vx:.1f}".replace(".", "_").replace("-", "_")
    title = f"What ended the failed episodes: {mode} mode at {command_vx:.1f} m/s"
    return Table(key, title, caption, "Robot", tuple(h for _, h in cols), tuple(out_rows), math=False)
