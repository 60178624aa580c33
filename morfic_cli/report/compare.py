"""``compare-baselines``: variants side by side, mean ± std over seeds, optionally beside the paper's numbers.

Runs are grouped by (preset, variant); each group's seeds are aggregated per robot. Five tables, each a list of
flat rows with a ``table`` key (so the CSV of all of them is one file):

- ``transfer``: per (preset, variant, robot, mode, command): ``vx`` = mean over seeds of the per-run v_x,
  ``vx_std`` = σ over all alive (env, step) samples pooled over seeds (the paper's σ; with one seed exactly the
  run's), ``vx_seed_std`` = std of the per-run v_x over seeds (sample std, empty with one seed);
  ``vx_peak_1s`` (mean over seeds of the best 1 s moving average, morfic's extra); ``survival`` (mean over seeds)
  and ``survival_seed_std``; ``cell`` = "v ± σ / S". The paper's v_x^max (its 2.5 m/s table) is the v_x of the
  2.5 m/s rows. Evaluations stored before σ was taken over steps (no ``vx_env_std`` column) leave σ empty.
- ``calibration``: per (preset, variant, robot, mode, command): EV, |NVB|, NVE, ASA, Flip, CosGrad, each mean and
  ``_seed_std``.
- ``fixed_rollout``: per (preset, frozen actor's variant, robot, critic variant, command): Flip and Cos. over the
  critics (seeds); critics scored on different actors' rollouts are never averaged together.
- ``external``: the paper's Tables "External baselines vs. MorFiC" (2.0 m/s) and its 2.5 m/s twin, in two row
  groups (``group``): ``paper``, the paper's numbers for URMA, BodyTransformer, GenLoco, Embodiment Scaling and
  MorFiC-F (released weights, their simulators; ``preset`` and ``n_seeds`` empty; ``note`` says why Embodiment
  Scaling has no row of ours), and ``ours``, the transfer rows (as ``transfer``'s) of the external baselines
  (``bot``, ``urma``, ``genloco``) and ``film`` in morfic's pipeline at the same budget, every mode and command
  they were evaluated at. Present when a run of an external baseline is among the runs or the paper's numbers are
  asked for (``--with-paper``); ours are left out (and :func:`external_note` says so) while no external baseline
  is trained.
- ``compute``: per (preset, variant): transitions, iterations, s/iter, device-hours, hours per 400M transitions,
  the actor's and the critic's parameter counts (``sum(p.numel())`` of the models the stored config builds) and
  the machine, where the run records one.

The ``transfer`` table holds every variant but the external baselines (:data:`EXTERNAL_VARIANTS`): the paper
compares those in their own table, as ``external`` does. The claims' ``verdicts`` are judged on the paper's own
seven variants only (:func:`claim_rows`).
- ``verdicts``: one row per primary comparison of the paper's claims (a)-(e) (:mod:`morfic_cli.report.claims`) at
  each judged command: the effect, its 95 % t interval, p, the Holm-adjusted p, its outcome, the seeds per side
  that would detect it where it is not significant, and the claim's verdict.

Seeds are pooled within one command only: a run diagnosed at 2.0 and at 1.0 m/s is one seed in a row at each
command (``command_vx``; a diagnosis that records none is at the paper's 2.0 m/s), never two seeds of one row.

``--with-paper`` adds ``paper_*`` columns (and ``paper_table``, the paper table they come from) taken from
:mod:`morfic_cli.report.paper`; the paper's numbers are in the descriptor mode of the protocol, so only
descriptor-mode transfer rows get them. A transfer row's ``paper_vx`` / ``paper_vx_std`` hold the paper's speed
for that command, ``paper_quantity`` says which it is (``v_x`` at 2.0 m/s, ``v_x^max`` at 2.5 m/s, the same
quantity under the higher command). The paper diagnoses its critics at 2.0 m/s only, so only calibration and
fixed-rollout rows at that command get its numbers. A number the paper does not print stays empty.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any

from morfic_cli.evaluation.metric_terms import seed_columns
from morfic_cli.evaluation.seeds import mean, seed_std
from morfic_cli.evaluation.seeds import num as _num
from morfic_cli.evaluation.seeds import pooled_std as pooled_std  # re-exported: the tests and older callers
from morfic_cli.evaluation.seeds import step_sigma as step_sigma
from morfic_cli.report import paper
from morfic_cli.report.claims import check_claims, is_paper_command, row_command
from morfic_cli.report.gather import StoreData
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, STOCK, table_variants, variant_order

if TYPE_CHECKING:
    from morfic_cli.store import Published, Store

TABLE_ORDER: tuple[str, ...] = ("transfer", "external", "calibration", "fixed_rollout", "compute", "verdicts")
TRANSITIONS_400M = 400e6
"""The paper normalises compute to 400M transitions (Table "Training compute")."""

CALIBRATION_METRICS: tuple[str, ...] = ("ev", "abs_nvb", "nve", "asa", "flip", "cos_grad")

PAPER_VARIANTS: tuple[str, ...] = tuple(dict.fromkeys(table_variants("main") + table_variants("ablation")))
"""The paper's own seven variants (its zero-shot and ablation tables): the variants its claims are about."""
EXTERNAL_VARIANTS: tuple[str, ...] = table_variants("external")
"""The external baselines re-implemented in morfic's pipeline (``bot``, ``urma``, ``genloco``)."""
EXTERNAL_PAPER_TABLES: tuple[paper.PaperTable, ...] = (
    paper.CROSS_EMBODIMENT_BASELINES,
    paper.CROSS_EMBODIMENT_BASELINES_25,
)
"""The paper's external-baselines tables (2.0 and 2.5 m/s): the ``paper`` group of the ``external`` table."""
PAPER_METHOD: dict[str, str] = {"bot": "bodytransformer"}
"""A variant's key among :mod:`morfic_cli.report.paper`'s methods where it differs from the variant's name."""
_OURS_OF = {m: v for v, m in PAPER_METHOD.items()}
EXTERNAL_TABLE_VARIANTS: tuple[str, ...] = tuple(
    _OURS_OF.get(c, c) for c in paper.CROSS_EMBODIMENT_BASELINES.columns if _OURS_OF.get(c, c) in STOCK
)
"""Our rows of the external-baselines tables, in the paper's column order: ``urma``, ``bot``, ``genloco``, ``film``."""
PAPER_ONLY: dict[str, str] = {
    "embodiment-scaling": "Embodiment Scaling Laws (Ai et al. 2025): the paper's numbers only; not retrainable here "
    "(about 1,500 GPU-hours and terabytes of generated robots) and its weights are out of reach.",
}
"""The paper's external baselines with no row of ours, and the one-line reason."""
PAPER_GROUP = "The paper's (released weights, their simulators)"
OURS_GROUP = "Ours (morfic's pipeline, the same budget)"


def paper_method(variant: str) -> str:
    """The key of :mod:`morfic_cli.report.paper`'s methods for a variant: ``bot`` -> ``bodytransformer``."""
    return PAPER_METHOD.get(variant, variant)


def our_variant(method: str) -> str:
    """The variant of a paper method key (:func:`paper_method` inverted): ``bodytransformer`` -> ``bot``."""
    return _OURS_OF.get(method, method)


def method_name(method: str) -> str:
    """The label of a variant or a paper method key in the external tables.

    ``bot`` and ``bodytransformer`` -> ``BodyTransformer``; ``embodiment-scaling`` -> ``Embodiment Scaling``.
    """
    variant = our_variant(method)
    if variant in STOCK:
        return STOCK[variant].label
    return {"embodiment-scaling": "Embodiment Scaling"}.get(method, paper.METHOD_LABELS.get(method, method))


def is_external(variant: str) -> bool:
    """Whether ``variant`` is one of the external baselines (:data:`EXTERNAL_VARIANTS`)."""
    return variant in EXTERNAL_VARIANTS


def without_external(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of the paper's own variants (and users'): those of :data:`EXTERNAL_VARIANTS` left out."""
    return [r for r in rows if not is_external(str(r.get("variant")))]


def external_note(has_ours: bool) -> str:
    """The line that says our external baselines are not trained yet (empty when some are)."""
    if has_ours:
        return ""
    return (
        f"Ours: not trained yet (no {' / '.join(EXTERNAL_VARIANTS)} run among these runs): `morfic train "
        "--variant bot --preset cpu` (likewise urma, genloco), then `morfic eval` and `morfic diagnose`."
    )


def robot_order(robot: str) -> int:
    """Sort key: the paper's robot order, then anything else."""
    return paper.ROBOTS.index(robot) if robot in paper.ROBOTS else len(paper.ROBOTS)


def _group(rows: Iterable[dict[str, Any]], key: Callable[[dict[str, Any]], tuple]) -> dict[tuple, list[dict]]:
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault(key(row), []).append(row)
    return groups


def transfer_rows(data: StoreData) -> list[dict[str, Any]]:
    """The ``transfer`` table (see the module docstring): the paper's own variants, no external baseline."""
    return _transfer_rows(without_external(data.evals))


def _transfer_rows(evals: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Transfer rows of ``evals`` (eval.csv rows), one per (preset, variant, robot, mode, command)."""
    groups = _group(evals, lambda r: (r["preset"], r["variant"], r["robot"], r["mode"], float(r["command_vx"])))
    out = []
    for (preset, variant, robot, mode, vx_cmd), rows in groups.items():
        out.append(
            {
                "table": "transfer",
                "preset": preset,
                "variant": variant,
                "robot": robot,
                "mode": mode,
                "command_vx": vx_cmd,
                "d": rows[0].get("d"),
                "n_seeds": len(rows),
                "runs": ";".join(sorted(r["run"] for r in rows)),
                **{col.name: col.reduce(rows) for col in seed_columns()},  # each eval metric's columns over seeds
                # the evaluation budget behind the cell (the smallest, when seeds differ): the caption names it
                "num_envs": min((int(r["num_envs"]) for r in rows if r.get("num_envs") is not None), default=None),
                "steps": min((int(r["steps"]) for r in rows if r.get("steps") is not None), default=None),
            }
        )
    out.sort(
        key=lambda r: (r["preset"], r["mode"], r["command_vx"], variant_order(r["variant"]), robot_order(r["robot"]))
    )
    return out


def _paper_cell(vx: float | None, sd: float | None, s: float | None) -> str:
    """``"1.84 ± 0.26 / 1.000"``; a part the paper leaves out is "-" (``"0.00 / 0.000"``, ``"- / 1.000"``)."""
    speed = "-" if vx is None else f"{vx:.2f}" + (f" ± {sd:.2f}" if sd is not None else "")
    return f"{speed} / {_num(s, 3)}"


def paper_external_rows() -> list[dict[str, Any]]:
    """The ``paper`` group of the ``external`` table: every cell of :data:`EXTERNAL_PAPER_TABLES`, as printed.

    ``variant`` is our variant of the paper's method (``bot`` for BodyTransformer), ``embodiment-scaling`` where we
    have none; ``vx`` / ``vx_std`` are the table's speed (``quantity``: ``v_x``, or ``v_x^max`` at 2.5 m/s, the
    forward speed under that command); ``None`` where the paper prints "-".
    """
    out = []
    for table in EXTERNAL_PAPER_TABLES:
        speed = table.parts[0]
        for method in table.columns:
            for robot in table.rows:
                vx, sd = table.value(robot, method, speed), table.value(robot, method, f"{speed}_std")
                s = table.value(robot, method, "survival")
                out.append(
                    {
                        "table": "external",
                        "group": "paper",
                        "preset": None,
                        "variant": our_variant(method),
                        "label": method_name(method),
                        "robot": robot,
                        "mode": table.mode,
                        "command_vx": float(table.command_vx or 0.0),
                        "n_seeds": None,
                        "runs": None,
                        "vx": vx,
                        "vx_std": sd,
                        "survival": s,
                        "cell": _paper_cell(vx, sd, s),
                        "quantity": paper.speed_quantity(table),
                        "source": table.label,
                        "note": PAPER_ONLY.get(method),
                    }
                )
    return out


def external_rows(data: StoreData, *, with_paper: bool = False) -> list[dict[str, Any]]:
    """The ``external`` table (see the module docstring): the paper's group, then ours.

    Empty when no external baseline is among the runs and ``with_paper`` is off (nothing of ours to set beside
    the paper's numbers, which were not asked for).
    """
    has_ours = any(is_external(r.variant) for r in data.runs)
    if not has_ours and not with_paper:
        return []
    ours = _transfer_rows([r for r in data.evals if r["variant"] in EXTERNAL_TABLE_VARIANTS]) if has_ours else []
    for row in ours:
        row.update(
            {
                "table": "external",
                "group": "ours",
                "label": method_name(row["variant"]),
                "quantity": "v_x",
                "source": None,
                "note": None,
            }
        )
    return paper_external_rows() + ours


def calibration_rows(data: StoreData) -> list[dict[str, Any]]:
    """The ``calibration`` table: critic metrics per (preset, variant, robot, mode, command), mean and std over seeds.

    A run diagnosed at two commands is one seed in the row of each: seeds are pooled within one command only.
    """
    groups = _group(data.calibration, lambda r: (r["preset"], r["variant"], r["robot"], r["mode"], row_command(r)))
    out = []
    for (preset, variant, robot, mode, command_vx), rows in groups.items():
        row: dict[str, Any] = {
            "table": "calibration",
            "preset": preset,
            "variant": variant,
            "robot": robot,
            "mode": mode,
            "command_vx": command_vx,
            "d": rows[0].get("d"),
            "n_seeds": len(rows),
            "runs": ";".join(sorted(r["run"] for r in rows)),
        }
        for m in CALIBRATION_METRICS:
            row[m] = mean(r[m] for r in rows)
            row[f"{m}_seed_std"] = seed_std(r[m] for r in rows)
        row["cell"] = "/".join(_num(row[m], 3) for m in ("abs_nvb", "nve", "asa"))
        out.append(row)
    out.sort(
        key=lambda r: (r["preset"], r["mode"], r["command_vx"], variant_order(r["variant"]), robot_order(r["robot"]))
    )
    return out


def fixed_rollout_rows(data: StoreData) -> list[dict[str, Any]]:
    """The ``fixed_rollout`` table: Flip and Cos. per (preset, actor variant, robot, critic variant, command).

    ``mc`` is the reference. The actor's variant is the row's ``actor_variant`` (older CSVs: looked up from its
    checkpoint).
    """
    preset_of = {r.checkpoint: r.preset for r in data.runs}
    variant_of = {r.checkpoint: r.variant for r in data.runs}
    groups = _group(
        data.fixed,
        lambda r: (
            preset_of.get(r["actor_checkpoint"], r.get("preset") or "?"),
            r.get("actor_variant") or variant_of.get(r["actor_checkpoint"], "?"),
            r["robot"],
            r["variant"],
            row_command(r),
        ),
    )
    out = []
    for (preset, actor_variant, robot, variant, command_vx), rows in groups.items():
        row: dict[str, Any] = {
            "table": "fixed_rollout",
            "preset": preset,
            "actor_variant": actor_variant,
            "variant": variant,
            "robot": robot,
            "mode": rows[0].get("mode"),
            "command_vx": command_vx,
            "n_seeds": len(rows),
            "runs": ";".join(sorted(str(r["run"]) for r in rows)),
            "actors": ";".join(sorted({str(r["actor"]) for r in rows})),
        }
        for m in ("flip", "cos_grad", "asa", "ev"):
            row[m] = mean(r[m] for r in rows)
            row[f"{m}_seed_std"] = seed_std(r[m] for r in rows)
        out.append(row)
    out.sort(
        key=lambda r: (
            r["preset"],
            r["command_vx"],
            r["actor_variant"] != FIXED_ROLLOUT_ACTOR,
            r["actor_variant"],
            robot_order(r["robot"]),
            -1 if r["variant"] == "mc" else variant_order(r["variant"]),
        )
    )
    return out


def _one(values: set[Any]) -> Any:
    """The value all seeds share, else None (a count missing for one seed, or seeds built differently)."""
    return next(iter(values)) if len(values) == 1 else None


def paper_hours(variant: str) -> str | None:
    """The paper's single-GPU training hours of a method, as printed, each setting named when it has several.

    Example: ``film`` -> ``"2.2-3.0"``; ``genloco`` -> ``"53.3 (200M); 213.5 (800M)"``; None where the paper has
    no compute row.
    """
    rows = [r for r in paper.TRAINING_COMPUTE if r.method == paper_method(variant)]
    if not rows:
        return None
    text = [r.gpu_hours_text.replace("--", "-") for r in rows]
    return (
        text[0] if len(rows) == 1 else "; ".join(f"{t} ({r.transitions_text})" for t, r in zip(text, rows, strict=True))
    )


def compute_rows(data: StoreData) -> list[dict[str, Any]]:
    """The ``compute`` table: the paper's Table "Training compute" for our runs (device-hours, not GPU-hours)."""
    groups = _group([r.__dict__ for r in data.runs], lambda r: (r["preset"], r["variant"]))
    out = []
    for (preset, variant), rows in groups.items():
        transitions = mean(r["env_steps"] for r in rows)
        iterations = mean(r["iteration"] for r in rows)
        wall = mean(r["wall_time_s"] for r in rows)
        hours = None if wall is None else wall / 3600.0
        out.append(
            {
                "table": "compute",
                "preset": preset,
                "variant": variant,
                "n_seeds": len(rows),
                "runs": ";".join(sorted(r["name"] for r in rows)),
                "device": ",".join(sorted({r["device"] for r in rows})),
                "transitions": transitions,
                "iterations": iterations,
                "s_per_iteration": None if not iterations or wall is None else wall / iterations,
                "s_per_iteration_seed_std": seed_std(r["wall_time_s"] / r["iteration"] for r in rows if r["iteration"]),
                "device_hours": hours,
                "device_hours_400m": None
                if not transitions or hours is None
                else hours * TRANSITIONS_400M / transitions,
                "finished": all(r["finished"] for r in rows),
                "wall_time_s": wall,
                "machine": ",".join(sorted({r.get("machine") or "" for r in rows} - {""})),
                "actor_params": _one({data.params.get(r["checkpoint"], (None, None))[0] for r in rows}),
                "critic_params": _one({data.params.get(r["checkpoint"], (None, None))[1] for r in rows}),
            }
        )
    out.sort(key=lambda r: (r["preset"], variant_order(r["variant"])))
    return out


def claim_rows(data: StoreData) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    """The eval, calibration and fixed-rollout rows the paper's claims are judged on: those of its own variants.

    Only the variants of the paper's zero-shot and ablation tables (:data:`PAPER_VARIANTS`) and the Monte-Carlo
    reference of the fixed-rollout rows: never an external baseline, nor another stock variant of morfic's own.
    """

    def keep(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [r for r in rows if r.get("variant") in PAPER_VARIANTS or r.get("variant") == "mc"]

    return keep(data.evals), keep(data.calibration), keep(data.fixed)


def verdict_rows(data: StoreData) -> list[dict[str, Any]]:
    """The claims' primary comparisons, one row each (:meth:`~morfic_cli.report.claims.Comparison.row`)."""

    def cell(r: dict[str, Any]) -> str:
        if r["effect"] is None:
            return "-"
        return f"{r['effect']:+.3f}" + (f" [{r['lo']:+.3f}, {r['hi']:+.3f}]" if r["lo"] is not None else "")

    claims = check_claims(*claim_rows(data))
    return [
        {
            "table": "verdicts",
            "claim": c.key,
            "command_vx": c.command_vx,
            "verdict": c.verdict,
            **row,
            "cell": cell(row),
        }
        for c in claims
        for row in c.comparisons
    ]


def external_critic_values(variant: str, robot: str) -> tuple[paper.PaperTable, dict[str, float | None]]:
    """The paper table with a variant's critic metrics and its |NVB|, NVE, ASA on ``robot`` (None where none).

    The external baselines' are in Table "critic metrics external" (``bot`` as BodyTransformer), the paper's own
    variants' in Table "critic metrics variants".
    """
    if not is_external(variant):
        return paper.CRITIC_METRICS_VARIANTS, paper.critic_values(variant, robot)
    table, method = paper.CRITIC_METRICS_EXTERNAL, paper_method(variant)
    if method not in table.columns or robot not in table.rows:
        return table, dict.fromkeys(table.parts)
    return table, {m: table.value(robot, method, m) for m in table.parts}


def add_paper_columns(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each row with the paper's numbers for the same variant, robot (and command) in ``paper_*`` columns.

    Calibration and fixed-rollout rows at another command than the paper's get the columns, empty: the paper
    diagnoses its critics at 2.0 m/s only.
    """
    out = []
    for row in rows:
        extra: dict[str, Any] = {}
        table = row["table"]
        if table == "transfer":
            src = paper.transfer_source(row["variant"], row["command_vx"]) if row["mode"] == "descriptor" else None
            values = paper.transfer_values(row["variant"], row["robot"], row["command_vx"]) if src else {}
            extra = {f"paper_{k}": values.get(k) for k in ("vx", "vx_std", "survival")}
            found = src if src is not None and row["robot"] in src.rows else None
            extra["paper_quantity"] = paper.speed_quantity(found) if found is not None else None
            extra["paper_table"] = found.label if found is not None else None
        elif table == "calibration":
            source, values = external_critic_values(row["variant"], row["robot"])
            values = values if is_paper_command(row_command(row)) else dict.fromkeys(values)
            extra = {f"paper_{k}": v for k, v in values.items()}
            extra["paper_table"] = source.label if any(v is not None for v in values.values()) else None
        elif table == "fixed_rollout":
            values = paper.fixed_rollout_values(row["variant"], row["robot"])
            values = values if is_paper_command(row_command(row)) else dict.fromkeys(values)
            extra = {f"paper_{k}": v for k, v in values.items()}
            extra["paper_table"] = paper.CAUSAL_ADV_ALL.label if any(v is not None for v in values.values()) else None
        elif table == "compute":
            known = row["variant"] in EXTERNAL_TABLE_VARIANTS
            ref = paper.compute_row(paper_method(row["variant"])) if known else None
            extra = {
                "paper_transitions": ref.transitions if ref else None,
                "paper_iterations": ref.iterations if ref else None,
                "paper_s_per_iteration": ref.sec_per_iter_text.replace("--", "-") if ref else None,
                "paper_gpu_hours": paper_hours(row["variant"]) if ref else None,
                "paper_gpu_hours_400m": ref.gpu_hours_400m_text.replace("--", "-") if ref else None,
                "paper_table": "tab:training_compute" if ref else None,
            }
        out.append({**row, **extra})
    return out


def compare_tables(data: StoreData, *, with_paper: bool = False) -> dict[str, list[dict[str, Any]]]:
    """Table name -> rows, for every table that has rows (:data:`TABLE_ORDER`)."""
    tables = {
        "transfer": transfer_rows(data),
        "external": external_rows(data, with_paper=with_paper),
        "calibration": calibration_rows(data),
        "fixed_rollout": fixed_rollout_rows(data),
        "compute": compute_rows(data),
    }
    if with_paper:
        tables = {k: add_paper_columns(v) for k, v in tables.items()}
    tables["verdicts"] = verdict_rows(data) if any(tables.values()) else []
    return {k: v for k, v in tables.items() if v}


def flat_rows(tables: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """All tables' rows in one list with the union of their columns (first-seen order), for CSV and JSON."""
    columns: dict[str, None] = {}
    rows = [row for name in TABLE_ORDER for row in tables.get(name, [])]
    for row in rows:
        columns.update(dict.fromkeys(row))
    return [{c: row.get(c) for c in columns} for row in rows]


COMPARE_LAYOUT = 4
"""The comparison's layout (its tables' rows and columns); bump it with any change to what a comparison of the same
results holds, so that one stored by an older morfic is not reused. 1 (no ``layout`` key): a run's diagnoses at two
commands pooled as two seeds; 2: calibration and fixed-rollout rows per command (``command_vx``); 3: the
``verdicts`` table (the claims' comparisons, Holm-corrected t tests); 4: the ``external`` table (the external
baselines out of ``transfer`` and the claims), parameter counts and the machine in ``compute``."""


def compare_config(data: StoreData, with_paper: bool) -> dict[str, Any]:
    """The config of a stored comparison: which runs, whether the paper's columns are in, :data:`COMPARE_LAYOUT`."""
    return json.loads(
        json.dumps(
            {
                "table": "compare-baselines",
                "runs": sorted(r.spec for r in data.runs),
                "with_paper": with_paper,
                "layout": COMPARE_LAYOUT,
            }
        )
    )


COMPARE_REF = "tables/compare-baselines"


def store_comparison(
    store: Store, data: StoreData, tables: dict[str, list[dict[str, Any]]], with_paper: bool
) -> tuple[Published, bool]:
    """Store the comparison as a ``table`` manifest (a CSV per table), or find the identical one already stored.

    Inputs are every artifact the rows came from (:attr:`StoreData.provenance`), so the same runs and results
    give the same comparison and nothing new is written. Advances ref ``tables/compare-baselines``.

    Returns:
        ``(Published, reused)``.
    """
    from morfic_cli.recording.tables import rows_to_csv

    pub = store.publish(
        "table",
        COMPARE_REF,
        config=compare_config(data, with_paper),
        inputs=data.input_ids(),
        reuse=True,
        files=lambda: {
            f"{name}.csv": rows_to_csv(rows, list(flat_rows({name: rows})[0])) for name, rows in tables.items()
        },
        meta={"tables": list(tables), "runs": [r.name for r in data.runs]},
    )
    return pub, pub.reused
