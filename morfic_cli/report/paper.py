r"""The paper's published numbers, once, as data (the paper's LaTeX source), for side-by-side comparison.

Every table of the paper that reports results is here, named after its ``\label``: zero-shot transfer,
external baselines at 2.0 and 2.5 m/s, the conditioning ablation, the expanded morphology range, the critic
diagnostics of the variants and of the external baselines, the fixed-rollout diagnostic, training compute and
the morphology support. Cells are written as the paper prints them, in a small notation parsed once at import:

- a cell is parts separated by ``/`` (``"1.79±0.31/0.984"`` is v_x ± σ / S; ``"0.535/0.960/0.670"`` is
  |NVB|/NVE/ASA);
- ``*x*`` is a part the paper sets in bold; a trailing ``↑`` / ``↓`` is the morphology table's out-of-support mark;
- ``-`` is a part the paper leaves out ("--": no forward motion, not run); ``--`` alone is a whole missing cell.

A missing entry stays missing (``None``), never zero. The paper is not always self-consistent (e.g. MorFiC-F's
Go1 survival is 0.547 in the transfer table and 0.647 in the ablation; FiLM's B1 NVE 1.279 is bold although
1.134 is lower): each table is encoded exactly as printed. Numbers keep their printed decimals so a table renders
back to the paper's LaTeX (:func:`morfic_cli.report.latex.table_latex`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from morfic_cli.morphology.descriptor import DESCRIPTOR_LABELS, DESCRIPTOR_NAMES
from morfic_cli.rl.variants import STOCK

#: The paper's robot order and names (its tables' row labels).
ROBOTS: tuple[str, ...] = ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c")
ROBOT_LABELS: dict[str, str] = {
    "go2": "Go2",
    "go1": "Go1",
    "a1": "A1",
    "aliengo": "AlienGo",
    "b1": "B1",
    "mini_cheetah": "Cheetah",
    "anymal_c": "ANYmal-C",
}

#: Method keys: morfic's variant names for the paper's own variants (labels from the variant registry), the
#: Monte-Carlo reference and the external baselines.
METHOD_LABELS: dict[str, str] = {
    **{name: v.label for name, v in STOCK.items()},
    "mc": "MC",
    "expanded-range": "Expanded range",
    "urma": "URMA",
    "bodytransformer": "BodyTrans.",
    "genloco": "GenLoco",
    "embodiment-scaling": "Embod.",
}
EXTERNAL_BASELINES: tuple[str, ...] = ("urma", "bodytransformer", "genloco", "embodiment-scaling")


@dataclass(frozen=True)
class PaperPart:
    """One part of a paper cell, e.g. ``2.04±0.37`` (value and std) or ``0.984`` (value).

    Attributes:
        value: The number; None where the paper prints "-" (missing, never zero).
        std: The ± term, or None.
        decimals: Decimals as printed (to render it back identically).
        bold: Set in bold in the paper.
        mark: "up" / "down" for an out-of-support descriptor value, else "".
    """

    value: float | None
    std: float | None = None
    decimals: int = 3
    bold: bool = False
    mark: str = ""


Cell = tuple[PaperPart, ...]


@dataclass(frozen=True)
class PaperTable:
    r"""A results table of the paper: cells keyed by (row, column) as the paper lays them out.

    Attributes:
        key: The paper's ``\label`` without ``tab:`` (``zero_shot_transfer``).
        title: Caption title as printed.
        caption: What a cell holds.
        rows: Row keys (robots, methods or descriptor dimensions).
        columns: Column keys (methods or robots).
        parts: Metric name of each part of a cell (``("vx", "survival")``); a part with a std also has
            ``<name>_std``.
        higher_is_better: Per part, True / False / None (not ranked).
        row_labels: Row key -> the label the paper prints.
        column_labels: Column key -> the label the paper prints.
        cells: (row, column) -> the parts.
        command_vx: The commanded forward velocity (m/s) of a transfer table.
        mode: morfic's eval mode that matches the paper's protocol ("descriptor") for transfer tables.
    """

    key: str
    title: str
    caption: str
    rows: tuple[str, ...]
    columns: tuple[str, ...]
    parts: tuple[str, ...]
    higher_is_better: tuple[bool | None, ...]
    row_labels: Mapping[str, str]
    column_labels: Mapping[str, str]
    cells: Mapping[tuple[str, str], Cell]
    command_vx: float | None = None
    mode: str | None = None

    @property
    def label(self) -> str:
        """The LaTeX label, ``tab:<key>``."""
        return f"tab:{self.key}"

    def cell(self, row: str, column: str) -> Cell | None:
        """The parts of a cell, or None when the table has no such row or column."""
        return self.cells.get((row, column))

    def value(self, row: str, column: str, metric: str) -> float | None:
        """One number: ``metric`` is a part name (``vx``) or a part name + ``_std`` (``vx_std``).

        Returns None where the paper prints no number (or has no such row/column).
        """
        cell = self.cell(row, column)
        if cell is None:
            return None
        for name, part in zip(self.parts, cell, strict=True):
            if metric == name:
                return part.value
            if metric == f"{name}_std":
                return part.std
        raise KeyError(f"table {self.key} has no metric '{metric}' (parts: {', '.join(self.parts)})")


def parse_part(text: str) -> PaperPart:
    """``"*2.04±0.37*"`` -> PaperPart(2.04, 0.37, 2, bold=True); ``"-"`` -> missing; ``"4.300↑"`` -> mark up."""
    text = text.strip()
    bold = len(text) > 2 and text.startswith("*") and text.endswith("*")
    if bold:
        text = text[1:-1].strip()
    mark = ""
    if text.endswith(("↑", "↓")):
        mark = "up" if text.endswith("↑") else "down"
        text = text[:-1].strip()
    if text in ("-", ""):
        return PaperPart(None, None, 0, bold, mark)
    mean, _, std = text.partition("±")
    decimals = len(mean.partition(".")[2])
    return PaperPart(float(mean), float(std) if std else None, decimals, bold, mark)


def parse_cell(text: str, n_parts: int) -> Cell:
    """A cell of ``n_parts`` parts; ``"--"`` is a cell with every part missing.

    Raises:
        ValueError: The cell has another number of parts.
    """
    if text.strip() == "--":
        return tuple(PaperPart(None, None, 0) for _ in range(n_parts))
    parts = tuple(parse_part(p) for p in text.split("/"))
    if len(parts) != n_parts:
        raise ValueError(f"paper cell '{text}' has {len(parts)} parts, expected {n_parts}")
    return parts


def _table(
    key: str,
    title: str,
    caption: str,
    *,
    rows: tuple[str, ...],
    columns: tuple[str, ...],
    parts: tuple[str, ...],
    higher: tuple[bool | None, ...],
    data: Mapping[str, str],
    row_labels: Mapping[str, str] | None = None,
    column_labels: Mapping[str, str] | None = None,
    command_vx: float | None = None,
    mode: str | None = None,
) -> PaperTable:
    """Build a table from one ``" | "``-separated string of cells per row (in ``columns`` order)."""
    cells: dict[tuple[str, str], Cell] = {}
    for row in rows:
        texts = data[row].split("|")
        if len(texts) != len(columns):
            raise ValueError(f"{key}: row {row} has {len(texts)} cells, expected {len(columns)}")
        for column, text in zip(columns, texts, strict=True):
            cells[(row, column)] = parse_cell(text, len(parts))
    return PaperTable(
        key=key,
        title=title,
        caption=caption,
        rows=rows,
        columns=columns,
        parts=parts,
        higher_is_better=higher,
        row_labels=dict(row_labels or ROBOT_LABELS),
        column_labels=dict(column_labels or METHOD_LABELS),
        cells=cells,
        command_vx=command_vx,
        mode=mode,
    )


_VX_S = ("vx", "survival")
_VXMAX_S = ("vx_max", "survival")
_CRITIC = ("abs_nvb", "nve", "asa")

ZERO_SHOT_TRANSFER = _table(
    "zero_shot_transfer",
    "Zero-shot cross-morphology transfer",
    r"$\bar{v}_x \pm \sigma / S$ at $v^{cmd}_x = 2.0$ m/s; 64 envs, 500 steps; trained on Go2.",
    rows=ROBOTS,
    columns=("ppo", "actor-only", "concat", "film"),
    parts=_VX_S,
    higher=(True, True),
    command_vx=2.0,
    mode="descriptor",
    data={
        "go2": "1.79±0.31/0.984 | 0.88±0.23/0.265 | 1.70±0.30/0.891 | *2.04±0.37*/*0.984*",
        "go1": "1.93±0.27/*0.906* | 1.49±0.36/0.594 | 1.82±0.32/0.859 | *2.06±0.46*/0.547",
        "a1": "1.41±0.42/0.406 | 0.01±0.06/0.000 | 1.52±0.27/0.422 | *2.14±0.36*/*0.516*",
        "aliengo": "0.27±0.07/0.000 | 0.64±0.26/*1.000* | 0.40±0.18/0.156 | *1.98±0.51*/*1.000*",
        "b1": "0.21±0.06/*1.000* | 0.04±0.07/*1.000* | 0.12±0.07/*1.000* | *0.22±0.08*/*1.000*",
        "mini_cheetah": "0.68±0.51/0.282 | 0.32±0.49/*1.000* | 1.28±0.58/0.382 | *1.39±0.69*/0.422",
        "anymal_c": "0.11±0.04/0.135 | 0.17±0.08/0.469 | 0.16±0.10/0.216 | *0.25±0.21*/*0.969*",
    },
)

CROSS_EMBODIMENT_BASELINES = _table(
    "cross_embodiment_baselines",
    "External baselines vs. MorFiC",
    r"$\bar{v}_x \pm \sigma / S$ at $v^{cmd}_x = 2.0$ m/s (GenLoco: no command input); - = no forward motion.",
    rows=ROBOTS,
    columns=(*EXTERNAL_BASELINES, "film"),
    parts=_VX_S,
    higher=(True, True),
    command_vx=2.0,
    mode="descriptor",
    data={
        "go2": "1.84±0.26/*1.000* | 0.30±0.21/0.656 | 0.59±0.05/0.922 | 1.23±0.06/0.906 | *2.04±0.37*/0.984",
        "go1": "1.93±0.28/*1.000* | 0.21±0.13/*1.000* | 0.98±0.01/*1.000* | 1.94±0.09/0.953 | *2.06±0.46*/0.547",
        "a1": "1.79±0.25/*1.000* | 0.39±0.15/0.421 | 0.92±0.01/*1.000* | 1.86±0.08/0.906 | *2.14±0.36*/0.516",
        "aliengo": "-/- | 0.30±0.28/0.234 | 0.96±0.03/*1.000* | 0.41±0.08/0.000 | *1.98±0.51*/*1.000*",
        "b1": "-/- | 0.04±0.11/0.796 | 0.00/0.000 | *2.86±0.11*/0.969 | 0.21±0.08/*1.000*",
        "mini_cheetah": "-/- | -/*1.000* | 0.73±0.06/0.969 | 0.06±0.09/0.000 | *1.39±0.69*/0.422",
        "anymal_c": "*1.80±0.28*/*1.000* | 0.01±0.06/0.875 | 0.71±0.01/*1.000* | 0.44±0.15/0.656 | 0.25±0.21/0.969",
    },
)

CROSS_EMBODIMENT_BASELINES_25 = _table(
    "cross_embodiment_baselines_25",
    "External baselines vs. MorFiC at higher commanded speed",
    r"$v_x^{\max} \pm \sigma / S$ at $v^{cmd}_x = 2.5$ m/s (GenLoco: no command input).",
    rows=ROBOTS,
    columns=(*EXTERNAL_BASELINES, "film"),
    parts=_VXMAX_S,
    higher=(True, True),
    command_vx=2.5,
    mode="descriptor",
    data={
        "go2": "2.389±0.405/*1.000* | 0.313±0.232/0.625 | 0.592±0.047/0.922 | 1.072±0.092/0.859 | *2.405±0.405*/0.859",
        "go1": "*2.514±0.430*/*1.000* | 0.206±0.151/*1.000* | 0.985±0.007/*1.000* | 2.343±0.131/0.797 | "
        "1.972±0.442/0.516",
        "a1": "*2.230±0.336*/*1.000* | 0.374±0.183/0.515 | 0.919±0.011/*1.000* | 2.143±0.116/0.719 | 1.595±0.467/0.156",
        "aliengo": "-/0.000 | 0.358±0.315/0.203 | *0.964±0.032*/*1.000* | 0.452±0.085/0.000 | 0.832±0.542/*1.000*",
        "b1": "-/0.000 | 0.080±0.140/0.640 | 0.00/0.000 | *3.062±0.214*/*0.797* | 0.121±0.060/0.000",
        "mini_cheetah": "-/0.000 | -/*1.000* | 0.729±0.061/0.969 | -0.118±0.091/0.000 | *1.128±0.986*/0.234",
        "anymal_c": "*2.159±0.354*/*1.000* | 0.014±0.081/0.843 | 0.708±0.005/*1.000* | 0.359±0.150/0.453 | "
        "0.303±0.422/0.984",
    },
)

CRITIC_CONDITIONING_ABLATION = _table(
    "critic_conditioning_ablation",
    "Ablation Table",
    r"$\bar{v}_x \pm \sigma / S$ at $v^{cmd}_x = 2.0$ m/s of the multiplicative critic variants.",
    rows=ROBOTS,
    columns=("film", "film-scaled", "hyper", "adaln"),
    parts=_VX_S,
    higher=(True, True),
    command_vx=2.0,
    mode="descriptor",
    row_labels={**ROBOT_LABELS, "anymal_c": "ANYmal"},
    data={
        "go2": "2.04±0.37/0.984 | 2.03±0.26/0.875 | *2.10±0.28*/0.953 | 2.03±0.19/*1.000*",
        "go1": "*2.06±0.46*/0.647 | 1.98±0.34/0.823 | 1.99±0.31/0.766 | 1.99±0.35/*0.853*",
        "a1": "*2.14±0.36*/0.516 | 2.04±0.24/0.531 | 2.02±0.26/*0.766* | 1.76±0.26/0.609",
        "aliengo": "*1.98±0.51*/*1.000* | 1.78±0.45/*1.000* | 1.75±0.46/*1.000* | 1.79±0.52/*1.000*",
        "b1": "*0.21±0.08*/*1.000* | 0.18±0.08/*1.000* | 0.20±0.03/*1.000* | 0.18±0.06/*1.000*",
        "mini_cheetah": "1.39±0.69/0.422 | *1.97±0.62*/0.359 | 1.61±0.45/0.344 | 1.57±0.56/*0.703*",
        "anymal_c": "0.25±0.21/0.969 | 0.24±0.06/*1.000* | *0.46±0.19*/*1.000* | 0.39±0.28/*1.000*",
    },
)

FILM_MORPH_RANGE_ABLATION = _table(
    "film_morph_range_ablation",
    "Effect of expanded morphology ranges and FiLM conditioning",
    r"$v_x^{\max} \pm \sigma / S$; training on a wider morphology support vs. the paper's.",
    rows=ROBOTS,
    columns=("expanded-range", "film"),
    parts=_VXMAX_S,
    higher=(True, True),
    command_vx=2.0,
    mode="descriptor",
    column_labels={**METHOD_LABELS, "film": "FiLM"},
    data={
        "go2": "1.9013±0.3510/0.8531 | *2.0415±0.3670*/*0.9844*",
        "go1": "1.9208±0.3087/*0.7656* | *2.0649±0.4552*/0.5469",
        "a1": "1.8241±0.2322/*0.7596* | *2.1404±0.3608*/0.5156",
        "aliengo": "1.5499±0.5078/*1.0000* | *1.9812±0.5146*/*1.0000*",
        "b1": "0.2001±0.0215/*1.0000* | *0.2109±0.0768*/*1.0000*",
        "mini_cheetah": "1.2362±0.4805/0.3348 | *1.3922±0.6902*/*0.4219*",
        "anymal_c": "*0.3079±0.1803*/*1.0000* | 0.2505±0.2147/0.9688",
    },
)

CRITIC_METRICS_VARIANTS = _table(
    "critic_metrics_variants",
    "Extended critic calibration diagnostics across PPO variants",
    r"$|\mathrm{NVB}|$/NVE/ASA; lower $|\mathrm{NVB}|$ and NVE, higher ASA are better.",
    rows=ROBOTS,
    columns=("ppo", "actor-only", "concat", "film"),
    parts=_CRITIC,
    higher=(False, False, True),
    column_labels={
        **METHOD_LABELS,
        "ppo": "Vanilla PPO",
        "actor-only": "Concat-z Actor only",
        "concat": "Concat-z Actor+Critic",
        "film": "FiLM",
    },
    data={
        "go2": "1.944/1.981/0.610 | *0.177*/1.168/0.689 | 0.535/*0.960*/0.670 | 1.768/1.943/*0.771*",
        "go1": "1.591/1.817/0.612 | *0.068*/*1.096*/0.662 | 1.623/1.834/0.674 | 1.375/1.653/*0.681*",
        "a1": "2.027/2.203/0.603 | 2.033/16.463/*0.754* | *0.199*/*0.936*/0.701 | 1.482/1.813/0.675",
        "aliengo": "0.070/1.454/0.612 | 0.468/1.209/0.569 | 0.153/1.117/0.607 | *0.048*/*0.835*/*0.706*",
        "b1": "0.182/1.231/0.618 | 0.358/1.187/0.570 | *0.040*/1.134/*0.624* | 0.645/*1.279*/0.618",
        "mini_cheetah": "0.362/1.869/0.428 | *0.220*/1.086/0.638 | 1.085/1.344/0.730 | 0.464/*0.947*/*0.768*",
        "anymal_c": "*0.091*/1.229/0.514 | 0.411/*1.227*/0.528 | 0.385/1.307/*0.620* | 0.120/1.229/0.578",
    },
)

CRITIC_METRICS_EXTERNAL = _table(
    "critic_metrics_external",
    "Extended critic calibration diagnostics for external baselines",
    r"$|\mathrm{NVB}|$/NVE/ASA; -- = not reported.",
    rows=ROBOTS,
    columns=("embodiment-scaling", "urma", "bodytransformer", "genloco", "film"),
    parts=_CRITIC,
    higher=(False, False, True),
    column_labels={**METHOD_LABELS, "embodiment-scaling": "Embod. Scale"},
    data={
        "go2": "3.437/3.646/0.657 | 3.005/3.178/*0.702* | 3.319/3.492/0.652 | "
        "5.458/5.674/0.561 | *1.768*/*1.943*/0.671",
        "go1": "2.569/2.772/0.607 | 3.170/3.333/0.692 | 4.771/4.983/*0.724* | "
        "3.402/3.594/0.623 | *1.375*/*1.653*/0.681",
        "a1": "2.368/2.585/0.599 | 3.390/3.551/*0.686* | 3.853/4.032/0.686 | 2.956/3.128/0.612 | *1.482*/*1.813*/0.675",
        "aliengo": "-- | -- | 3.104/3.476/0.661 | 1.170/1.522/*0.709* | *0.098*/*0.835*/0.706",
        "b1": "3.330/3.590/0.657 | -- | 3.571/3.781/*0.694* | 7.428/7.729/0.667 | *0.645*/*1.279*/0.618",
        "mini_cheetah": "-- | -- | -- | 5.294/5.511/0.594 | *0.464*/*0.947*/*0.768*",
        "anymal_c": "3.589/3.812/0.667 | 2.538/2.740/0.728 | 3.368/3.529/0.674 | 1.107/2.324/*0.733* | "
        "*0.120*/*1.229*/0.578",
    },
)

_FIXED_METHODS = ("mc", "film", "concat", "actor-only", "ppo")
CAUSAL_ADV_ALL = _table(
    "causal_adv_all",
    "Fixed-rollout critic diagnostic across target morphologies",
    "Flip/Cos.: sign-flip rate vs. the MC advantage (lower is better) / actor-gradient cosine with the MC "
    "gradient (higher is better); the MC row is the reference.",
    rows=_FIXED_METHODS,
    columns=ROBOTS,
    parts=("flip", "cos_grad"),
    higher=(False, True),
    row_labels={**METHOD_LABELS, "film": "MorFiC", "concat": "Concat", "actor-only": "Act-only", "ppo": "Vanilla PPO"},
    column_labels=ROBOT_LABELS,
    mode="descriptor",
    data={
        "mc": " | ".join(["0.000/1.000"] * 7),
        "film": "*0.227*/0.880 | 0.187/*0.972* | *0.239*/*0.785* | *0.255*/*0.366* | 0.272/-0.182 | "
        "*0.209*/*0.679* | *0.402*/-0.149",
        "concat": "0.307/0.720 | *0.151*/0.830 | 0.344/0.427 | 0.329/0.004 | 0.269/0.106 | 0.236/0.575 | 0.479/-0.419",
        "actor-only": "0.524/*0.890* | 0.502/0.924 | 0.511/0.717 | 0.318/0.342 | 0.565/*0.647* | 0.265/0.644 | "
        "0.470/*-0.044*",
        "ppo": "0.235/0.865 | 0.229/0.684 | 0.260/0.653 | 0.322/-0.113 | *0.176*/0.601 | 0.253/0.264 | 0.461/-0.074",
    },
)


def _subset(
    table: PaperTable, key: str, title: str, columns: tuple[str, ...], row_labels: Mapping[str, str]
) -> PaperTable:
    cells = {(r, c): v for (r, c), v in table.cells.items() if c in columns}
    return PaperTable(
        key=key,
        title=title,
        caption=table.caption,
        rows=table.rows,
        columns=columns,
        parts=table.parts,
        higher_is_better=table.higher_is_better,
        row_labels=dict(row_labels),
        column_labels=table.column_labels,
        cells=cells,
        command_vx=table.command_vx,
        mode=table.mode,
    )


#: The main text's fixed-rollout table: the AlienGo and Cheetah columns of :data:`CAUSAL_ADV_ALL`.
CAUSAL_ADV = _subset(
    CAUSAL_ADV_ALL,
    "causal_adv",
    "Fixed-rollout diagnostic",
    ("aliengo", "mini_cheetah"),
    {**CAUSAL_ADV_ALL.row_labels, "ppo": "PPO"},
)


def parse_count(text: str) -> float:
    """A count as the paper prints it: ``"400M"`` -> 4e8, ``"1.600B"`` -> 1.6e9, ``"~5.80M"``, ``"4,000"``."""
    t = text.strip().lstrip("~").replace(",", "")
    scale = {"k": 1e3, "M": 1e6, "B": 1e9}.get(t[-1:], 1.0)
    return float(t[:-1] if scale != 1.0 else t) * scale


def parse_range(text: str) -> tuple[float, float]:
    """``"1.98--2.70"`` -> (1.98, 2.70); ``"17.25"`` -> (17.25, 17.25)."""
    lo, _, hi = text.partition("--")
    return float(lo), float(hi or lo)


@dataclass(frozen=True)
class ComputeRow:
    """One row of the paper's training-compute table, every entry as printed (ranges as ``lo--hi``).

    ``bold`` names the columns set in bold; the numbers are the properties (ranges as (low, high)).
    """

    method: str
    label: str
    transitions_text: str
    iterations_text: str
    sec_per_iter_text: str
    gpu_hours_text: str
    gpu_hours_400m_text: str
    notes: str
    expert_pool: bool = False
    bold: tuple[str, ...] = field(default=())

    @property
    def transitions(self) -> float:
        """Total transitions."""
        return parse_count(self.transitions_text)

    @property
    def iterations(self) -> float:
        """PPO iterations (approximate where the paper writes ~)."""
        return parse_count(self.iterations_text)

    @property
    def sec_per_iter(self) -> tuple[float, float]:
        """Wall-clock seconds per iteration (low, high)."""
        return parse_range(self.sec_per_iter_text)

    @property
    def gpu_hours(self) -> tuple[float, float]:
        """Single-GPU-equivalent training hours (low, high)."""
        return parse_range(self.gpu_hours_text)

    @property
    def gpu_hours_400m(self) -> tuple[float, float]:
        """GPU-hours normalised to 400M transitions (low, high)."""
        return parse_range(self.gpu_hours_400m_text)


TRAINING_COMPUTE_TITLE = "Training compute comparison"
TRAINING_COMPUTE: tuple[ComputeRow, ...] = (
    ComputeRow(
        "film",
        "MorFiC",
        "400M",
        "4,000",
        "1.98--2.70",
        "2.2--3.0",
        "2.2--3.0",
        "Single generalist policy; local run",
        bold=("sec_per_iter", "gpu_hours", "gpu_hours_400m"),
    ),
    ComputeRow("bodytransformer", "BodyTransformer", "400M", "8,000", "17.25", "38.3", "39.0", "Reproduced model_8000"),
    ComputeRow("urma", "URMA", "1.600B", "3,064", "366--392", "311--333", "77.8--83.3", "Original training budget"),
    ComputeRow("genloco", "GenLoco", "200M", "1,526", "125.8", "53.3", "106.6", "200M setting"),
    ComputeRow("genloco", "GenLoco", "800M", "6,104", "125.8", "213.5", "106.8", "800M setting"),
    ComputeRow(
        "embodiment-scaling",
        "Embod. Scaling, Gendog8 expert",
        "1.720B",
        "17,499",
        "0.94",
        "4.5",
        "1.05",
        "One selected released expert",
        expert_pool=True,
    ),
    ComputeRow(
        "embodiment-scaling",
        "Embod. Scaling, full Gendog pool",
        "570.6B",
        "~5.80M",
        "0.94",
        "1507",
        "1.06",
        "332 experts; ~5 TB storage",
        expert_pool=True,
    ),
)

#: Column order of the paper's morphology-support table: the training support, then the robots.
SUPPORT_COLUMNS: tuple[str, ...] = (
    "train_min",
    "train_max",
    "go2",
    "go1",
    "a1",
    "mini_cheetah",
    "aliengo",
    "anymal_c",
    "b1",
)
MORPHOLOGY_SUPPORT = _table(
    "morphology_support",
    "Morphology randomization parameters",
    r"Training support and each robot's 11-D descriptor; out-of-support values in bold with $\uparrow$/$\downarrow$.",
    rows=DESCRIPTOR_NAMES,
    columns=SUPPORT_COLUMNS,
    parts=("value",),
    higher=(None,),
    row_labels=dict(zip(DESCRIPTOR_NAMES, DESCRIPTOR_LABELS, strict=True)),
    column_labels={**ROBOT_LABELS, "train_min": "Train min", "train_max": "Train max", "anymal_c": "ANYmal"},
    data={
        "thigh_mass": "0.634 | 1.152 | 1.152 | 0.899 | 1.013 | 0.634 | 0.639 | 0.740 | *4.300↑*",
        "calf_mass": "0.064 | 0.166 | 0.154 | 0.158 | 0.166 | 0.064 | *0.207↑* | *0.337↑* | *1.050↑*",
        "hip_mass": "0.510 | 0.696 | 0.678 | 0.510 | 0.696 | 0.540 | *1.000↑* | *0.740↑* | *2.150↑*",
        "foot_mass": "0.000 | 0.060 | 0.040 | 0.060 | 0.060 | 0.060 | 0.060 | *0.250↑* | 0.050",
        "base_mass": "3.300 | 6.921 | 6.921 | 4.800 | 6.000 | 3.300 | *11.644↑* | *18.210↑* | *29.450↑*",
        "hip_limit_min": "-1.100 | -0.800 | -1.047 | -0.803 | -0.803 | *-1.600↓* | *-1.222↓* | *-0.720↑* | *-0.750↑*",
        "hip_limit_max": "0.800 | 1.100 | 1.047 | 0.803 | 0.803 | *1.600↑* | *1.222↑* | *0.720↓* | *0.750↓*",
        "thigh_limit_min": "-1.650 | -1.050 | -1.571 | *-1.047↑* | *-1.047↑* | *-2.600↓* | *-3.142↓* | -1.650 | "
        "*-1.000↑*",
        "thigh_limit_max": "3.490 | 4.050 | 3.491 | *4.189↑* | *4.189↑* | *2.600↓* | *3.142↓* | 4.050 | 3.500",
        "calf_limit_min": "-2.720 | -2.600 | *-2.723↓* | -2.697 | -2.697 | -2.600 | *-2.775↓* | -2.720 | -2.600",
        "calf_limit_max": "-0.950 | -0.780 | -0.838 | -0.916 | -0.916 | -0.800 | *-0.646↑* | -0.780 | *-0.600↑*",
    },
)

#: Every results table of the paper, by key.
TABLES: dict[str, PaperTable] = {
    t.key: t
    for t in (
        ZERO_SHOT_TRANSFER,
        CROSS_EMBODIMENT_BASELINES,
        CROSS_EMBODIMENT_BASELINES_25,
        CRITIC_CONDITIONING_ABLATION,
        FILM_MORPH_RANGE_ABLATION,
        CRITIC_METRICS_VARIANTS,
        CRITIC_METRICS_EXTERNAL,
        CAUSAL_ADV,
        CAUSAL_ADV_ALL,
        MORPHOLOGY_SUPPORT,
    )
}


# ---------------------------------------------------------------------------- lookups for --with-paper
def transfer_source(variant: str, command_vx: float) -> PaperTable | None:
    """The paper table that reports ``variant`` at ``command_vx`` in the paper's protocol, or None.

    2.0 m/s: the zero-shot table for PPO / Actor-only / Actor+Critic / MorFiC-F, the ablation for the other
    multiplicative variants. 2.5 m/s: only MorFiC-F (the external-baselines table, which reports v_x^max).
    """
    for table in (ZERO_SHOT_TRANSFER, CRITIC_CONDITIONING_ABLATION, CROSS_EMBODIMENT_BASELINES_25):
        if table.command_vx is not None and abs(table.command_vx - command_vx) < 1e-9 and variant in table.columns:
            return table
    return None


def speed_quantity(table: PaperTable) -> str:
    """Which speed a transfer table prints: ``v_x`` or ``v_x^max`` (the paper's name for v_x under 2.5 m/s)."""
    return "v_x^max" if table.parts[0] == "vx_max" else "v_x"


def transfer_values(variant: str, robot: str, command_vx: float) -> dict[str, float | None]:
    """The paper's forward speed, its σ and S for a variant on a robot at a command (None where it has none).

    ``vx`` / ``vx_std`` are the table's speed part whichever name the paper gives it: its v_x^max (2.5 m/s table)
    is the forward speed v_x measured under the higher command — at 2.0 m/s its v_x^max cells (Table "Effect of
    expanded morphology ranges") equal its v_x cells — so it sits beside morfic's v_x of that command, not beside a
    peak. :func:`speed_quantity` names which the paper printed.
    """
    table = transfer_source(variant, command_vx)
    out: dict[str, float | None] = dict.fromkeys(("vx", "vx_std", "survival"))
    if table is None or robot not in table.rows:
        return out
    speed = table.parts[0]
    out["vx"] = table.value(robot, variant, speed)
    out["vx_std"] = table.value(robot, variant, f"{speed}_std")
    out["survival"] = table.value(robot, variant, "survival")
    return out


def critic_values(variant: str, robot: str) -> dict[str, float | None]:
    """The paper's |NVB|, NVE and ASA of a variant's critic on a robot (None where it has none)."""
    table = CRITIC_METRICS_VARIANTS
    if variant not in table.columns or robot not in table.rows:
        return dict.fromkeys(table.parts)
    return {m: table.value(robot, variant, m) for m in table.parts}


def fixed_rollout_values(variant: str, robot: str) -> dict[str, float | None]:
    """The paper's fixed-rollout Flip and Cos. of a critic variant (or ``mc``) on a robot."""
    table = CAUSAL_ADV_ALL
    if variant not in table.rows or robot not in table.columns:
        return dict.fromkeys(table.parts)
    return {m: table.value(variant, robot, m) for m in table.parts}


def compute_row(method: str = "film") -> ComputeRow | None:
    """The first compute row of a method (MorFiC is ``film``)."""
    return next((r for r in TRAINING_COMPUTE if r.method == method), None)
