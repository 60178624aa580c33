"""The paper's tables built from comparison rows (:mod:`morfic_cli.report.compare`), and from the paper's data.

Each builder returns a :class:`~morfic_cli.report.model.Table` laid out as the paper lays it out, with the best
value of each row (or column) in bold as the paper does: transfer tables bold the best speed and the best survival
of each robot independently; critic tables the lowest |NVB| and NVE and the highest ASA; the fixed-rollout table the
best learned critic per robot and metric (the Monte-Carlo row is the reference, never bold); the compute table the
cheapest entry per column. A builder returns None when the store has nothing for it.

The critic and fixed-rollout builders take the command the diagnoses were run at (``command_vx``, the paper's 2.0
m/s by default) and show the rows at that command only: a run diagnosed at two commands is never pooled over them.
At another command than the paper's the table's key and title carry it (:func:`_command_key`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from morfic_cli.report import paper
from morfic_cli.report.claims import PAPER_COMMAND, at_command, is_paper_command
from morfic_cli.report.compare import (
    EXTERNAL_PAPER_TABLES,
    EXTERNAL_TABLE_VARIANTS,
    OURS_GROUP,
    PAPER_GROUP,
    PAPER_ONLY,
    external_note,
    method_name,
    our_variant,
    robot_order,
)
from morfic_cli.report.model import Part, Row, Table, bold_best
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, table_variants, variant_order

MAIN_VARIANTS: tuple[str, ...] = table_variants("main")
"""The zero-shot transfer table's variants (paper Table "Zero-shot cross-morphology transfer")."""
ABLATION_VARIANTS: tuple[str, ...] = table_variants("ablation")
"""The ablation table's variants (paper Table "Ablation")."""


def method_label(variant: str, preset: str, multi_preset: bool) -> str:
    """The paper's name of a variant (``MorFiC-F``), with the preset when several are compared."""
    label = paper.METHOD_LABELS.get(variant, variant)
    return f"{label} ({preset})" if multi_preset else label


def robot_label(robot: str) -> str:
    """The paper's name of a robot (``Cheetah`` for mini_cheetah)."""
    return paper.ROBOT_LABELS.get(robot, robot)


def _columns(rows: Sequence[dict[str, Any]], variants: Sequence[str] | None) -> list[tuple[str, str]]:
    """(preset, variant) columns present in ``rows``: in the order of ``variants`` (the paper table's), else ours."""
    pairs = {(r["preset"], r["variant"]) for r in rows if variants is None or r["variant"] in variants}
    order = (lambda v: list(variants).index(v)) if variants is not None else variant_order  # noqa: E731
    return sorted(pairs, key=lambda p: (p[0], order(p[1])))


def _command_key(key: str, title: str, command_vx: float) -> tuple[str, str]:
    """A table's (key, title) at ``command_vx``: as given at the paper's command, else naming the command.

    Example: ``("critic_ev", "Explained variance of the critics")`` at 1.0 m/s is ``("critic_ev_1_0", "Explained
    variance of the critics at 1.0 m/s")``; at 2.0 m/s it is unchanged.
    """
    if is_paper_command(command_vx):
        return key, title
    return f"{key}_{command_vx:.1f}".replace(".", "_"), f"{title} at {command_vx:.1f} m/s"


def _seed_note(rows: Sequence[dict[str, Any]], pooled: bool = False) -> str:
    seeds = sorted({int(r["n_seeds"]) for r in rows})
    what = f"{seeds[0]} seed" + ("s" if seeds[0] != 1 else "") if len(seeds) == 1 else f"{seeds[0]}-{seeds[-1]} seeds"
    sigma = " (σ over all alive env-steps, pooled over seeds)" if pooled else ""
    return f"Mean over {what} per cell{sigma}; numbers from the artifacts listed under Provenance."


def transfer_table(
    rows: Sequence[dict[str, Any]],
    *,
    key: str,
    title: str,
    command_vx: float,
    mode: str,
    variants: Sequence[str] | None = None,
    use_max: bool = False,
    min_columns: int = 1,
) -> Table | None:
    """Robots x variants, cells ``v ± σ / S``; bold best speed and survival per robot.

    ``use_max`` labels the speed v_x^max, as the paper's 2.5 m/s table does: the paper's v_x^max is the forward speed
    v_x under that (higher) command, so the cell holds the same ``vx`` / ``vx_std`` either way.
    """
    sel = [r for r in rows if r["mode"] == mode and abs(r["command_vx"] - command_vx) < 1e-9]
    cols = _columns(sel, variants)
    if len(cols) < min_columns or not cols:
        return None
    multi = len({p for p, _ in cols}) > 1
    by = {(r["robot"], r["preset"], r["variant"]): r for r in sel}
    speed, std = "vx", "vx_std"
    out_rows = []
    for robot in sorted({r["robot"] for r in sel}, key=robot_order):
        cells = [by.get((robot, p, v)) for p, v in cols]
        v_bold = bold_best([c[speed] if c else None for c in cells], True)
        s_bold = bold_best([c["survival"] if c else None for c in cells], True)
        out_rows.append(
            Row(
                robot_label(robot),
                tuple(
                    (
                        Part(c[speed] if c else None, c[std] if c else None, 2, vb),
                        Part(c["survival"] if c else None, None, 3, sb),
                    )
                    for c, vb, sb in zip(cells, v_bold, s_bold, strict=True)
                ),
            )
        )
    quantity = r"$v_x^{\max} \pm \sigma / S$" if use_max else r"$\bar{v}_x \pm \sigma / S$"
    meaning = r" ($v_x^{\max}$ as the paper uses it: the mean forward speed under this command)" if use_max else ""
    where = {
        "descriptor": "the target descriptor on the Go2 template",
        "actuation-matched": "the target descriptor on the Go2 template with Kp, Kd and torque limits x the "
        "target's mass / Go2's",
    }.get(mode, "the target robot model itself")
    where = f"{where} ({protocol_text(sel)})"
    caption = (
        f"Each cell is {quantity} (m/s; survival) at a commanded {command_vx:.1f} m/s{meaning}, "
        f"σ over all alive env-steps, {where}; bold: best speed and best survival per robot."
    )
    return Table(
        key,
        title,
        caption,
        "Target",
        tuple(method_label(v, p, multi) for p, v in cols),
        tuple(out_rows),
        notes=(_seed_note(sel, pooled=True),),
    )


def protocol_text(rows: Sequence[dict[str, Any]]) -> str:
    """Say whether ``rows`` were measured with the paper's protocol (envs x steps), naming a reduced one's budget.

    Example: ``"a reduced protocol: 16 envs x 250 steps; the paper's is 64 x 500"``.
    """
    from morfic_cli.evaluation.protocol import EvalCfg

    paper = (EvalCfg.num_envs, EvalCfg.steps)
    sizes = sorted(
        {
            (int(r["num_envs"]), int(r["steps"]))
            for r in rows
            if r.get("num_envs") is not None and r.get("steps") is not None
        }
    )
    if sizes == [paper]:
        return f"the paper protocol: {paper[0]} envs x {paper[1]} steps"
    if not sizes:
        return "envs and steps not recorded"
    shown = ", ".join(f"{n} envs x {t} steps" for n, t in sizes)
    return f"a reduced protocol: {shown}; the paper's is {paper[0]} x {paper[1]}"


def critic_table(
    rows: Sequence[dict[str, Any]],
    mode: str = "descriptor",
    command_vx: float = PAPER_COMMAND,
    *,
    key: str = "critic_metrics_variants",
    title: str = "Critic calibration diagnostics",
) -> Table | None:
    """Robots x variants, cells ``|NVB|/NVE/ASA``; bold lowest |NVB| and NVE, highest ASA per robot.

    Only the diagnoses at ``command_vx`` (m/s) are shown.
    """
    sel = at_command(rows, command_vx, mode)
    cols = _columns(sel, None)
    if not cols:
        return None
    multi = len({p for p, _ in cols}) > 1
    by = {(r["robot"], r["preset"], r["variant"]): r for r in sel}
    out_rows = []
    for robot in sorted({r["robot"] for r in sel}, key=robot_order):
        cells = [by.get((robot, p, v)) for p, v in cols]
        bolds = [
            bold_best([c[m] if c else None for c in cells], hib)
            for m, hib in (("abs_nvb", False), ("nve", False), ("asa", True))
        ]
        out_rows.append(
            Row(
                robot_label(robot),
                tuple(
                    tuple(
                        Part(c[m] if c else None, None, 3, bolds[k][j]) for k, m in enumerate(("abs_nvb", "nve", "asa"))
                    )
                    for j, c in enumerate(cells)
                ),
            )
        )
    caption = (
        r"Each cell is $|\mathrm{NVB}|$/NVE/ASA of the critic against Monte-Carlo returns on its own "
        "actor's rollouts; "
        r"lower $|\mathrm{NVB}|$ and NVE, higher ASA are better; bold: best per robot and metric."
    )
    key, title = _command_key(key, title, command_vx)
    return Table(
        key,
        title,
        caption,
        "Target",
        tuple(method_label(v, p, multi) for p, v in cols),
        tuple(out_rows),
        notes=(_seed_note(sel),),
    )


def ev_table(
    rows: Sequence[dict[str, Any]],
    mode: str = "descriptor",
    command_vx: float = PAPER_COMMAND,
    *,
    key: str = "critic_ev",
    title: str = "Explained variance of the critics",
) -> Table | None:
    """Robots x variants, explained variance EV (higher is better; 1 is perfect).

    Only the diagnoses at ``command_vx`` (m/s) are shown.
    """
    sel = at_command(rows, command_vx, mode)
    cols = _columns(sel, None)
    if not cols:
        return None
    multi = len({p for p, _ in cols}) > 1
    by = {(r["robot"], r["preset"], r["variant"]): r for r in sel}
    out_rows = []
    for robot in sorted({r["robot"] for r in sel}, key=robot_order):
        cells = [by.get((robot, p, v)) for p, v in cols]
        bold = bold_best([c["ev"] if c else None for c in cells], True)
        out_rows.append(
            Row(
                robot_label(robot),
                tuple(
                    (Part(c["ev"] if c else None, c["ev_seed_std"] if c else None, 3, b),)
                    for c, b in zip(cells, bold, strict=True)
                ),
            )
        )
    caption = (
        r"$\mathrm{EV} = 1 - \mathrm{Var}(G - V) / \mathrm{Var}(G)$ over $I_\epsilon$ (± std over seeds "
        "where there are several); bold: best."
    )
    key, title = _command_key(key, title, command_vx)
    return Table(
        key,
        title,
        caption,
        "Target",
        tuple(method_label(v, p, multi) for p, v in cols),
        tuple(out_rows),
        notes=(_seed_note(sel),),
    )


def fixed_rollout_table(rows: Sequence[dict[str, Any]], command_vx: float = PAPER_COMMAND) -> Table | None:
    """Critic sources x (robot: Flip, Cos.); MC first; bold the best learned critic per robot and metric.

    Only the rollouts at ``command_vx`` (m/s) are shown. A source is (frozen actor's variant, preset, critic
    variant): critics are compared only on the same actor's rollouts, so with several actors each gets its own block
    of rows (its label names the actor) and its own bold.
    """
    rows = at_command(rows, command_vx)
    if not rows:
        return None
    robots = sorted({r["robot"] for r in rows}, key=robot_order)
    actor_of = lambda r: r.get("actor_variant") or "?"  # noqa: E731
    actors = sorted({actor_of(r) for r in rows}, key=lambda a: (a != FIXED_ROLLOUT_ACTOR, a))
    sources = sorted(
        {(actor_of(r), r["preset"], r["variant"]) for r in rows},
        key=lambda s: (actors.index(s[0]), s[2] != "mc", s[1], variant_order(s[2])),
    )
    multi = len({p for _, p, v in sources if v != "mc"}) > 1
    by = {(actor_of(r), r["preset"], r["variant"], r["robot"]): r for r in rows}
    bold: dict[tuple, bool] = {}
    for actor in actors:
        learned = [s for s in sources if s[2] != "mc" and s[0] == actor]
        for robot in robots:
            for m, hib in (("flip", False), ("cos_grad", True)):
                values = [by[(*s, robot)][m] if (*s, robot) in by else None for s in learned]
                for s, b in zip(learned, bold_best(values, hib), strict=True):
                    bold[(s, robot, m)] = b
    out_rows = []
    for s in sources:
        a, p, v = s
        cells = []
        for robot in robots:
            r = by.get((*s, robot))
            for m in ("flip", "cos_grad"):
                cells.append((Part(r[m] if r else None, None, 3, bold.get((s, robot, m), False)),))
        label = "MC" if v == "mc" else method_label(v, p, multi)
        if len(actors) > 1:
            label += f" ({method_label(a, p, False)}'s rollout)"
        out_rows.append(Row(label, tuple(cells)))
    caption = (
        "One frozen actor's rollout per robot; each critic scored on exactly those samples. Flip: sign-flip "
        "rate vs. the MC advantage (lower is better); Cos.: actor-gradient cosine with the MC gradient "
        "(higher is better); the MC row is the reference."
    )
    if len(actors) > 1:
        caption += " Several actors were frozen: each block of rows is one actor's rollout, bold within the block."
    runs = sorted({a for r in rows for a in str(r.get("actors", "")).split(";") if a and a != "None"})
    key, title = _command_key("causal_adv_all", "Fixed-rollout critic diagnostic", command_vx)
    return Table(
        key,
        title,
        caption,
        "Src.",
        ("Flip", "Cos.") * len(robots),
        tuple(out_rows),
        groups=tuple((robot_label(r), 2) for r in robots),
        math=False,
        notes=(f"Frozen actor(s): {', '.join(runs) or '-'}.",),
    )


def _si(value: float | None) -> str:
    if value is None:
        return "-"
    for div, suffix in ((1e9, "B"), (1e6, "M"), (1e3, "k")):
        if abs(value) >= div:
            return f"{value / div:.3g}{suffix}"
    return f"{value:.0f}"


def compute_table(rows: Sequence[dict[str, Any]]) -> Table | None:
    """Variants x (transitions, iterations, s/iter, device-h, device-h@400M); bold the cheapest per column."""
    if not rows:
        return None
    bolds = {
        m: bold_best([r[m] for r in rows], False) for m in ("s_per_iteration", "device_hours", "device_hours_400m")
    }
    out_rows = []
    for i, r in enumerate(rows):
        iters = r["iterations"]
        out_rows.append(
            Row(
                f"{paper.METHOD_LABELS.get(r['variant'], r['variant'])} ({r['preset']})",
                (
                    (Part(None, text=_si(r["transitions"])),),
                    (Part(None, text=f"{iters:,.0f}" if iters is not None else "-"),),
                    (Part(r["s_per_iteration"], None, 2, bolds["s_per_iteration"][i]),),
                    (Part(r["device_hours"], None, 3, bolds["device_hours"][i]),),
                    (Part(r["device_hours_400m"], None, 1, bolds["device_hours_400m"][i]),),
                    (Part(None, text=r["device"]),),
                ),
            )
        )
    caption = (
        "Transitions and iterations as trained; s/iter = wall time / iterations; device-hours on the device "
        "of the run (CPU threads or one GPU); hours normalised to 400M transitions as the paper does. Bold: "
        "cheapest."
    )
    return Table(
        "training_compute",
        "Training compute",
        caption,
        "Method",
        ("Transitions", "Iters.", "Sec/iter", "Device-h", "Device-h@400M", "Device"),
        tuple(out_rows),
        math=False,
        notes=(_seed_note(rows),),
    )


def support_table(rows: Sequence[dict[str, Any]]) -> Table | None:
    """Descriptor dimensions x (train min, train max, robots); out-of-support values bold with ↑ / ↓."""
    if not rows:
        return None
    robots = sorted(
        {r["robot"] for r in rows}, key=lambda n: paper.SUPPORT_COLUMNS.index(n) if n in paper.SUPPORT_COLUMNS else 99
    )
    params = list(dict.fromkeys(r["parameter"] for r in rows))
    by = {(r["parameter"], r["robot"]): r for r in rows}
    out_rows = []
    for name in params:
        first = by[(name, robots[0])]
        cells = [(Part(float(first["train_min"]), None, 3),), (Part(float(first["train_max"]), None, 3),)]
        for robot in robots:
            r = by.get((name, robot))
            flag = int(r["support"]) if r else 0
            cells.append(
                (Part(float(r["value"]) if r else None, None, 3, flag != 0, {1: "up", -1: "down"}.get(flag, "")),)
            )
        out_rows.append(Row(f"{first['label']} ({first['unit']})", tuple(cells)))
    caption = (
        "The 11-D morphology descriptor of each robot and the training support; values outside it in bold "
        r"with $\uparrow$ (above) / $\downarrow$ (below)."
    )
    return Table(
        "morphology_support",
        "Morphology support",
        caption,
        "Parameter",
        ("Train min", "Train max", *(robot_label(r) for r in robots)),
        tuple(out_rows),
        math=False,
    )


# ---------------------------------------------------------------------------- the paper's own tables
def paper_table(t: paper.PaperTable) -> Table:
    """A paper table in the report's model, as the paper prints it (its bold marks included).

    Tables whose rows are methods and columns robots (the fixed-rollout diagnostic) get one column per part under
    a header group per robot, as in the paper.
    """
    math_mode = t.key not in ("morphology_support", "causal_adv", "causal_adv_all")

    def part(p: paper.PaperPart) -> Part:
        return Part(p.value, p.std, p.decimals, p.bold, p.mark)

    if t.key in ("causal_adv", "causal_adv_all"):
        rows = tuple(
            Row(t.row_labels.get(r, r), tuple((part(p),) for c in t.columns for p in t.cells[(r, c)])) for r in t.rows
        )
        columns = tuple(name for _ in t.columns for name in ("Flip", "Cos."))
        groups = tuple((t.column_labels.get(c, c), len(t.parts)) for c in t.columns)
        return Table(t.key, t.title, t.caption, "Src.", columns, rows, groups=groups, math=math_mode, source="paper")
    rows = tuple(
        Row(t.row_labels.get(r, r), tuple(tuple(part(p) for p in t.cells[(r, c)]) for c in t.columns)) for r in t.rows
    )
    corner = "Parameter" if t.key == "morphology_support" else "Target"
    return Table(
        t.key,
        t.title,
        t.caption,
        corner,
        tuple(t.column_labels.get(c, c) for c in t.columns),
        rows,
        math=math_mode,
        source="paper",
    )


def paper_compute_table() -> Table:
    """The paper's training-compute table (ranges as printed, expert-pool methods in their own section)."""

    def rng(text: str, bold: bool) -> Part:
        return Part(None, text=text.replace("--", "–"), bold=bold)

    rows: list[Row] = []
    for i, r in enumerate(paper.TRAINING_COMPUTE):
        if r.expert_pool and not paper.TRAINING_COMPUTE[i - 1].expert_pool:
            rows.append(Row("Expert-pool / selected-expert methods"))
        rows.append(
            Row(
                r.label,
                (
                    (Part(None, text=r.transitions_text),),
                    (Part(None, text=r.iterations_text),),
                    (rng(r.sec_per_iter_text, "sec_per_iter" in r.bold),),
                    (rng(r.gpu_hours_text, "gpu_hours" in r.bold),),
                    (rng(r.gpu_hours_400m_text, "gpu_hours_400m" in r.bold),),
                    (Part(None, text=r.notes),),
                ),
            )
        )
    return Table(
        "training_compute",
        paper.TRAINING_COMPUTE_TITLE,
        "Total transitions, PPO iterations, seconds per iteration, single-GPU hours and GPU-hours per 400M "
        "transitions.",
        "Method",
        ("Transitions", "Iters.", "Sec/iter", "GPU-h", "GPU-h@400M", "Notes"),
        tuple(rows),
        math=False,
        source="paper",
    )


# ---------------------------------------------------------------------------- the external baselines
def _paper_external(command_vx: float) -> paper.PaperTable | None:
    """The paper's external-baselines table at ``command_vx`` (2.0 or 2.5 m/s), else None."""
    return next((t for t in EXTERNAL_PAPER_TABLES if abs(float(t.command_vx or 0.0) - command_vx) < 1e-9), None)


def external_table(rows: Sequence[dict[str, Any]], command_vx: float, *, mode: str = "descriptor") -> Table | None:
    """Methods x robots, cells ``v ± σ / S`` at ``command_vx``, in two row groups: the paper's, then ours.

    The paper's group is its Table "External baselines vs. MorFiC" (2.0 m/s) or the 2.5 m/s one, as printed (its
    bold marks: the best of its five methods). Ours are the ``ours`` rows of the ``external`` comparison table
    (:func:`~morfic_cli.report.compare.external_rows`): mean over seeds, σ over all alive env-steps, bold the best
    speed and survival per robot among ours. The groups come from different simulators, robot models and rewards,
    so no bold compares across them. Without a run of ours the group says "not trained yet" (and the note how).
    Full mode (morfic's extension) has ours only. None when there is nothing to show.
    """
    src = _paper_external(command_vx) if mode == "descriptor" else None
    ours = [
        r
        for r in rows
        if r.get("group") == "ours" and r["mode"] == mode and abs(float(r["command_vx"]) - command_vx) < 1e-9
    ]
    if src is None and not ours:
        return None
    robots = [*paper.ROBOTS, *sorted({r["robot"] for r in ours} - set(paper.ROBOTS))]
    out_rows: list[Row] = []
    if src is not None:
        out_rows.append(Row(PAPER_GROUP))
        missing = (Part(None), Part(None))
        for method in src.columns:
            out_rows.append(
                Row(
                    f"{method_name(method)} (paper)",
                    tuple(
                        tuple(Part(p.value, p.std, p.decimals, p.bold, p.mark) for p in src.cells[(robot, method)])
                        if (robot, method) in src.cells
                        else missing
                        for robot in robots
                    ),
                )
            )
    cols = sorted(
        {(r["preset"], r["variant"]) for r in ours}, key=lambda p: (p[0], EXTERNAL_TABLE_VARIANTS.index(p[1]))
    )
    has_external = any(v != "film" for _, v in cols)
    out_rows.append(Row(OURS_GROUP if has_external else "Ours: not trained yet"))
    by = {(r["robot"], r["preset"], r["variant"]): r for r in ours}
    cells = {c: [by.get((robot, *c)) for robot in robots] for c in cols} if has_external else {}
    v_bold = [bold_best([(cells[c][i] or {}).get("vx") for c in cells], True) for i in range(len(robots))]
    s_bold = [bold_best([(cells[c][i] or {}).get("survival") for c in cells], True) for i in range(len(robots))]
    for k, (preset, variant) in enumerate(cells):
        n = max(int(r["n_seeds"]) for r in cells[(preset, variant)] if r)
        out_rows.append(
            Row(
                f"{method_name(variant)} ({preset}, {n} seed{'s' if n != 1 else ''})",
                tuple(
                    (
                        Part(c["vx"] if c else None, c["vx_std"] if c else None, 2, v_bold[i][k]),
                        Part(c["survival"] if c else None, None, 3, s_bold[i][k]),
                    )
                    for i, c in enumerate(cells[(preset, variant)])
                ),
            )
        )
    use_max = src is not None and src.parts[0] == "vx_max"
    quantity = r"$v_x^{\max} \pm \sigma / S$" if use_max else r"$\bar{v}_x \pm \sigma / S$"
    ours_rows = [r for c in cells for r in cells[c] if r]
    where = "the target descriptor on the Go2 template" if mode == "descriptor" else "the target robot model itself"
    caption = (
        f"Each cell is {quantity} (m/s; survival) at a commanded {command_vx:.1f} m/s"
        + (r" ($v_x^{\max}$ as the paper uses it: the mean forward speed under this command)" if use_max else "")
        + (
            "; the paper's rows are its published numbers (URMA, GenLoco and Embodiment Scaling from their "
            "released weights, BodyTransformer trained by the paper to 400M transitions; each in its own "
            "simulator with its own robot models and commands; GenLoco takes no command; - = no forward "
            "motion), bold the paper's"
            if src is not None
            else ""
        )
        + "; ours re-implement each approach in morfic's pipeline (the Go2 template, rewards, curriculum and "
        f"budget of MorFiC-F), on {where}"
        + (f" ({protocol_text(ours_rows)})" if ours_rows else "")
        + ", bold the best of ours per robot."
    )
    notes = [PAPER_ONLY[m] for m in (src.columns if src is not None else ()) if m in PAPER_ONLY]
    notes += [_seed_note(ours_rows, pooled=True)] if ours_rows else [external_note(False)]
    key = f"external_baselines_{command_vx:.1f}".replace(".", "_") + ("" if mode == "descriptor" else "_full")
    title = f"External baselines vs. MorFiC-F at {command_vx:.1f} m/s" + (
        "" if mode == "descriptor" else " on the targets' own models"
    )
    return Table(
        key, title, caption, "Method", tuple(robot_label(r) for r in robots), tuple(out_rows), notes=tuple(notes)
    )


def _duration(seconds: float | None) -> str:
    """``"1.25 h"`` from an hour up, ``"38 s"`` / ``"12.5 min"`` below; "-" when unknown."""
    if seconds is None:
        return "-"
    if seconds >= 3600:
        return f"{seconds / 3600:.2f} h"
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"


def external_compute_table(rows: Sequence[dict[str, Any]]) -> Table:
    """The compute of the external baselines and MorFiC-F: ours (per preset), then the paper's.

    Ours: the actor's and the critic's parameters (``sum(p.numel())`` of the models each run's stored config builds),
    transitions, the training wall time here (``meta.wall_time_s``, mean over seeds) and where (the device, and the
    machine where the run records one). The paper's: its Table "Training compute" rows of these methods, their
    single-GPU hours as printed (the paper counts no parameters).
    """

    def count(n: Any) -> Part:
        return Part(None, text="-" if n is None else f"{int(n):,}")

    ours = sorted(
        (r for r in rows if r["variant"] in EXTERNAL_TABLE_VARIANTS),
        key=lambda r: (r["preset"], EXTERNAL_TABLE_VARIANTS.index(r["variant"])),
    )
    out_rows: list[Row] = [Row(OURS_GROUP)] if ours else []
    for r in ours:
        n = int(r["n_seeds"])
        where = r["device"] + (f" ({r['machine']})" if r.get("machine") else "")
        out_rows.append(
            Row(
                f"{method_name(r['variant'])} ({r['preset']}, {n} seed{'s' if n != 1 else ''})",
                (
                    (count(r.get("actor_params")),),
                    (count(r.get("critic_params")),),
                    (Part(None, text=_si(r["transitions"])),),
                    (Part(None, text=_duration(r.get("wall_time_s"))),),
                    (Part(None, text=where),),
                ),
            )
        )
    out_rows.append(Row(f'The paper\'s (its Table "{paper.TRAINING_COMPUTE_TITLE}")'))
    for p in paper.TRAINING_COMPUTE:
        if our_variant(p.method) in EXTERNAL_TABLE_VARIANTS or p.method == "embodiment-scaling":
            out_rows.append(
                Row(
                    f"{p.label} (paper)",
                    (
                        (Part(None, text="-"),),
                        (Part(None, text="-"),),
                        (Part(None, text=p.transitions_text),),
                        (Part(None, text=f"{p.gpu_hours_text.replace('--', '–')} GPU-h"),),
                        (Part(None, text=f"the paper's GPU; {p.notes}"),),
                    ),
                )
            )
    caption = (
        "Parameters of the actor and of the critic (a module they share counts in both), transitions, the "
        "training time and where it ran: ours as measured here (the run's wall time, mean over seeds), the "
        "paper's as it prints them (single-GPU hours)."
    )
    notes = (_seed_note(ours),) if ours else ()
    return Table(
        "external_compute",
        "Compute of the external baselines",
        caption,
        "Method",
        ("Actor params", "Critic params", "Transitions", "Time", "Where"),
        tuple(out_rows),
        math=False,
        notes=notes,
    )
