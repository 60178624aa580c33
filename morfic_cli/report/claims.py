"""The paper's five claims, checked against the store's results: a verdict per claim, computed, never typed in.

Pure functions over the rows :func:`~morfic_cli.report.gather.gather` reads (eval.csv, calibration.csv and
fixed_rollout.csv rows, each with ``variant``, ``seed`` and ``artifact``). Each claim compares seed means of a
metric between variants; with several seeds a difference counts only when it exceeds the seeds' spread (the
larger of the two sides' standard deviations), with one seed every difference counts and the reason says so.

Differences smaller than a metric's :data:`RESOLUTION` are ties.

Verdicts: ``holds`` (on every robot the claim names), ``holds partly`` (on some), ``does not hold`` (on none) and
``cannot tell`` (a variant the claim needs has no result in the store, or every difference is within the seeds'
spread). The claims (paper Sec. "Results" and the abstract):

- (a) multiplicative critics (film, film-scaled, adaln, hyper) keep a higher EV than the additive ones
  (concat, ppo, actor-only) on the out-of-distribution robots;
- (b) MorFiC-F transfers better than PPO, actor-only and concat (1.98 m/s on AlienGo against below 0.65), compared
  as v_x x S, the speed kept over the episode (the paper's AlienGo cells: film survives, the additive ones mostly
  do not);
- (c) in the fixed-rollout analysis the film critic has the lowest Flip and the highest Cos on AlienGo and
  Mini Cheetah;
- (d) all multiplicative variants transfer similarly (the ablation);
- (e) transfer degrades with the normalised morphology distance d.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from morfic_cli.report import paper
from morfic_cli.rl.variants import FIXED_ROLLOUT_ACTOR, STOCK

#: The out-of-distribution targets of claims (a), (b) and (d) (the paper's "heavier and out of distribution
#: robots"; its transfer claim is about AlienGo, its calibration claim about Cheetah and AlienGo).
OOD_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah", "anymal_c")
#: The robots of the fixed-rollout claim (c) (paper Table "causal advantage").
FIXED_ROBOTS: tuple[str, ...] = ("aliengo", "mini_cheetah")
#: Multiplicative and additive critics (claim (a)) among the stock variants.
MULTIPLICATIVE: tuple[str, ...] = tuple(n for n, v in STOCK.items() if v.multiplicative)
ADDITIVE: tuple[str, ...] = tuple(n for n, v in STOCK.items() if not v.multiplicative)
#: Claim (b): the additive baselines MorFiC-F is compared with.
BASELINES: tuple[str, ...] = ("ppo", "actor-only", "concat")
#: Claim (d): "similar" transfer = the multiplicative variants' v_x within this many m/s of each other on a robot,
#: or within the paper's own spread there where that is larger (0.23 / 0.58 / 0.22 m/s on AlienGo / Mini Cheetah /
#: ANYmal-C, :func:`paper_spread`).
SIMILAR_VX: float = 0.3
#: Claim (e): the rank correlation between d and v_x below which "degrades with distance" holds.
DEGRADES_RHO: float = -0.5

#: Smallest difference that counts as one side beating the other, per metric (m/s for speeds): below it two
#: runs are a tie, whatever the seeds (a 0.01 m/s lead is not a better transfer).
RESOLUTION: dict[str, float] = {"vx_s": 0.05, "ev": 0.05, "flip": 0.02, "cos_grad": 0.02}

HOLDS, PARTLY, NOT, CANNOT = "holds", "holds partly", "does not hold", "cannot tell"


@dataclass(frozen=True)
class Stat:
    """A seed mean: ``mean`` and ``std`` (population std over ``n`` seeds; 0 for one seed)."""

    mean: float
    std: float
    n: int

    def text(self, decimals: int = 2) -> str:
        """``1.23`` or ``1.23 ± 0.04 (n=3)``."""
        if self.n <= 1:
            return f"{self.mean:.{decimals}f}"
        return f"{self.mean:.{decimals}f} ± {self.std:.{decimals}f} (n={self.n})"


@dataclass
class Claim:
    """One claim's check.

    Attributes:
        key: ``a`` .. ``e``.
        claim: What the paper claims.
        paper: The paper's numbers for it.
        ours: Ours, per robot.
        verdict: holds, holds partly, does not hold, cannot tell.
        reason: Why.
        artifacts: Ids of the artifacts the numbers come from.
    """

    key: str
    claim: str
    paper: str
    ours: str
    verdict: str
    reason: str
    artifacts: list[str] = field(default_factory=list)


def seed_stat(values: Iterable[float]) -> Stat | None:
    """Mean and population std of finite values (None when there are none)."""
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not xs:
        return None
    mean = sum(xs) / len(xs)
    return Stat(mean, math.sqrt(sum((x - mean) ** 2 for x in xs) / len(xs)), len(xs))


def by_variant(rows: Sequence[dict[str, Any]], metric: str, robot: str, **match: Any) -> dict[str, Stat]:
    """Variant -> seed statistic of ``metric`` on ``robot`` over the rows matching ``match``.

    One value per seed: a seed's later row replaces an earlier one.
    """
    per_seed: dict[str, dict[Any, float]] = {}
    for r in rows:
        if r.get("robot") != robot or any(_differs(r.get(k), v) for k, v in match.items()):
            continue
        value = r.get(metric)
        if value is None or value == "":
            continue
        per_seed.setdefault(str(r["variant"]), {})[r.get("seed", 0)] = float(value)
    out = {}
    for variant, seeds in per_seed.items():
        stat = seed_stat(seeds.values())
        if stat is not None:
            out[variant] = stat
    return out


def _differs(value: Any, wanted: Any) -> bool:
    if isinstance(wanted, float):
        try:
            return abs(float(value) - wanted) > 1e-9
        except (TypeError, ValueError):
            return True
    return value != wanted


def better(a: Stat, b: Stat, higher: bool = True, resolution: float = 0.0) -> bool | None:
    """Whether ``a`` beats ``b`` (True / False); None within the seeds' spread (several seeds) or ``resolution``.

    The seeds' spread is the larger standard deviation of the sides measured over several seeds: a side with seeds
    counts even when the other has one (its spread is the noise the single seed is just as likely to carry).
    """
    margin = max([s.std for s in (a, b) if s.n > 1] + [resolution])
    diff = (a.mean - b.mean) if higher else (b.mean - a.mean)
    if abs(diff) <= margin:
        return None
    return diff > 0


def all_of(outcomes: Sequence[bool | None]) -> bool | None:
    """False when any comparison is lost, else None when any is undecided, else True."""
    if any(o is False for o in outcomes):
        return False
    return None if any(o is None for o in outcomes) else True


def verdict(outcomes: Sequence[bool | None]) -> str:
    """Verdict: holds (all True), does not hold (none True), holds partly (some), cannot tell (no decided outcome)."""
    decided = [o for o in outcomes if o is not None]
    if not decided:
        return CANNOT
    wins = sum(decided)
    if wins == len(outcomes):
        return HOLDS
    return NOT if wins == 0 else PARTLY


def _ids(rows: Sequence[dict[str, Any]], variants: Iterable[str], robots: Iterable[str]) -> list[str]:
    vs, rs = set(variants), set(robots)
    return sorted({str(r["artifact"]) for r in rows if r.get("variant") in vs and r.get("robot") in rs
                   and r.get("artifact")})


def _seed_note(stats: Iterable[Stat]) -> str:
    ns = sorted({s.n for s in stats})
    if not ns:
        return ""
    if ns == [1]:
        return (" One seed per variant: every difference above the metric's resolution counts; none is tested "
                "against seed noise.")
    return f" Seeds per variant: {'/'.join(map(str, ns))}; a difference within the seeds' spread does not count."


def claim_a(calibration: Sequence[dict[str, Any]]) -> Claim:
    """(a) On each OOD robot, the mean EV of the multiplicative critics vs that of the additive ones."""
    text = "Multiplicative critics keep a higher EV than additive ones on out-of-distribution robots."
    per_robot, outcomes, used = [], [], []
    for robot in OOD_ROBOTS:
        ev = by_variant(calibration, "ev", robot)
        mult = [ev[v] for v in MULTIPLICATIVE if v in ev]
        add = [ev[v] for v in ADDITIVE if v in ev]
        used += mult + add
        if not mult or not add:
            outcomes.append(None)
            per_robot.append(f"{robot}: no {'multiplicative' if not mult else 'additive'} critic diagnosed")
            continue
        m, a = _pool(mult), _pool(add)
        outcomes.append(better(m, a, resolution=RESOLUTION["ev"]))
        per_robot.append(f"{robot}: multiplicative {m.text()} vs additive {a.text()} (" + ", ".join(
            f"{v} {ev[v].text()}" for v in (*MULTIPLICATIVE, *ADDITIVE) if v in ev) + ")")
    v = verdict(outcomes)
    reason = _reason(v, outcomes, OOD_ROBOTS, "the multiplicative mean EV is higher") + _seed_note(used)
    return Claim("a", text, "Fig. 3 (EV, no numbers): additive critics lose calibration on the heavier and "
                 "out-of-distribution robots; multiplicative ones keep it on Mini Cheetah and AlienGo.",
                 "; ".join(per_robot), v, reason, _ids(calibration, (*MULTIPLICATIVE, *ADDITIVE), OOD_ROBOTS))


def _pool(stats: Sequence[Stat]) -> Stat:
    """One statistic for a group of variants.

    Mean: over the variants of their seed means. Std: the largest seed std among the variants with seeds (n > 1).
    n: the most seeds any of them has, so a group with one multi-seed variant brings its spread to :func:`better`.
    """
    seeded = [s.std for s in stats if s.n > 1]
    return Stat(sum(s.mean for s in stats) / len(stats), max(seeded, default=0.0), max(s.n for s in stats))


def _reason(v: str, outcomes: Sequence[bool | None], robots: Sequence[str], what: str) -> str:
    yes = [r for r, o in zip(robots, outcomes, strict=True) if o]
    no = [r for r, o in zip(robots, outcomes, strict=True) if o is False]
    open_ = [r for r, o in zip(robots, outcomes, strict=True) if o is None]
    parts = []
    if yes:
        parts.append(f"{what} on {', '.join(yes)}")
    if no:
        parts.append(f"not on {', '.join(no)}")
    if open_:
        parts.append(f"undecided on {', '.join(open_)} (missing results or within seed noise)")
    text = "; ".join(parts)
    return text[:1].upper() + text[1:] + "." if parts else f"{v}."  # not str.capitalize: it lowercases "EV"


def with_speed_kept(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The eval rows with ``vx_s`` = v_x x S added: the speed a transfer keeps.

    A run that is fast until it falls scores its speed times the fraction of envs that survive.
    """
    return [{**r, "vx_s": float(r["vx_mean"]) * float(r["survival"])} for r in rows
            if r.get("vx_mean") not in (None, "") and r.get("survival") not in (None, "")]


def claim_b(evals: Sequence[dict[str, Any]]) -> Claim:
    """(b) MorFiC-F's v_x x S at 2.0 m/s (descriptor mode) against each of PPO, actor-only and concat, per OOD robot."""
    text = ("MorFiC-F transfers better than PPO, actor-only and concat (v_x x S at 2.0 m/s, descriptor mode: the "
            "speed kept over the episode).")
    per_robot, outcomes, used = [], [], []
    kept_rows = with_speed_kept(evals)
    for robot in OOD_ROBOTS:
        kept = by_variant(kept_rows, "vx_s", robot, mode="descriptor", command_vx=2.0)
        vx = by_variant(evals, "vx_mean", robot, mode="descriptor", command_vx=2.0)
        s = by_variant(evals, "survival", robot, mode="descriptor", command_vx=2.0)
        base = [b for b in BASELINES if b in kept]
        if "film" not in kept or not base:
            outcomes.append(None)
            per_robot.append(f"{robot}: film not evaluated" if "film" not in kept
                             else f"{robot}: no baseline (ppo, actor-only, concat) evaluated")
            continue
        used += [kept["film"], *(kept[b] for b in base)]
        wins = [better(kept["film"], kept[b], resolution=RESOLUTION["vx_s"]) for b in base]
        outcomes.append(all_of(wins))
        per_robot.append(f"{robot}: " + ", ".join(
            f"{v} {kept[v].text()} (v_x {vx[v].mean:.2f}, S {s[v].mean:.2f})" for v in ("film", *base)))
    paper_cells = []
    for v in ("film", *BASELINES):
        cell = paper.transfer_values(v, "aliengo", 2.0)
        if cell["vx"] is not None:
            paper_cells.append(f"{v} {cell['vx']:.2f} m/s, S {cell['survival']:.2f}")
    v = verdict(outcomes)
    reason = _reason(v, outcomes, OOD_ROBOTS, "film keeps more speed than every baseline") + _seed_note(used)
    return Claim("b", text, "AlienGo: " + "; ".join(paper_cells) + " (Table \"zero-shot transfer\").",
                 "; ".join(per_robot), v, reason, _ids(evals, ("film", *BASELINES), OOD_ROBOTS))


def claim_c(fixed: Sequence[dict[str, Any]]) -> Claim:
    """(c) In the fixed-rollout analysis, film's Flip is the lowest and its Cos the highest of the critics."""
    text = ("With the film actor frozen, the film critic has the lowest Flip and the highest Cos (AlienGo, Mini "
            "Cheetah).")
    # Only critics scored on the frozen film actor's rollouts compare (a store may hold analyses of other actors).
    rows = [r for r in fixed if r.get("variant") in STOCK and r.get("actor_variant") == FIXED_ROLLOUT_ACTOR]
    per_robot, outcomes = [], []
    for robot in FIXED_ROBOTS:
        flip = by_variant(rows, "flip", robot)
        cos = by_variant(rows, "cos_grad", robot)
        others = [v for v in flip if v != "film"]
        if "film" not in flip or not others:
            outcomes.append(None)
            per_robot.append(f"{robot}: {'no film critic' if 'film' not in flip else 'no other critic'} scored")
            continue
        low = [better(flip["film"], flip[v], higher=False, resolution=RESOLUTION["flip"]) for v in others]
        high = [better(cos["film"], cos[v], resolution=RESOLUTION["cos_grad"]) for v in others
                if v in cos and "film" in cos]
        outcomes.append(all_of(low + high))
        per_robot.append(f"{robot}: " + ", ".join(f"{v} Flip {flip[v].text(3)} Cos {cos[v].text(3)}"
                                                  for v in ("film", *others) if v in cos))
    paper_cells = []
    for robot in FIXED_ROBOTS:
        cells = [(v, paper.fixed_rollout_values(v, robot)) for v in ("film", *BASELINES)]
        paper_cells.append(f"{robot}: " + ", ".join(f"{v} {c['flip']:.3f}/{c['cos_grad']:.3f}" for v, c in cells
                                                    if c.get("flip") is not None and c.get("cos_grad") is not None))
    v = verdict(outcomes)
    return Claim("c", text, "Flip/Cos. " + "; ".join(paper_cells) + " (Table \"causal advantage\").",
                 "; ".join(per_robot), v, _reason(v, outcomes, FIXED_ROBOTS, "film has the lowest Flip and the "
                                                                            "highest Cos"),
                 _ids(rows, STOCK, FIXED_ROBOTS))


def paper_spread(robot: str) -> float | None:
    """The max - min of the paper's v_x over its multiplicative variants at 2.0 m/s on ``robot`` (None: none)."""
    vals = [paper.transfer_values(v, robot, 2.0)["vx"] for v in MULTIPLICATIVE]
    vals = [x for x in vals if x is not None]
    return max(vals) - min(vals) if len(vals) >= 2 else None


def claim_d(evals: Sequence[dict[str, Any]]) -> Claim:
    """(d) The multiplicative variants' v_x (2.0 m/s, descriptor) within :data:`SIMILAR_VX` of each other per robot."""
    text = "All multiplicative variants (film, film-scaled, adaln, hyper) transfer similarly."
    per_robot, outcomes = [], []
    for robot in OOD_ROBOTS:
        vx = by_variant(evals, "vx_mean", robot, mode="descriptor", command_vx=2.0)
        got = {v: vx[v] for v in MULTIPLICATIVE if v in vx}
        if len(got) < len(MULTIPLICATIVE):
            outcomes.append(None)
            missing = [v for v in MULTIPLICATIVE if v not in got]
            per_robot.append(f"{robot}: {', '.join(missing)} not evaluated")
            continue
        spread = max(s.mean for s in got.values()) - min(s.mean for s in got.values())
        tol = max(SIMILAR_VX, paper_spread(robot) or 0.0)
        outcomes.append(spread <= tol)
        per_robot.append(f"{robot}: spread {spread:.2f} m/s, tolerance {tol:.2f} (" + ", ".join(
            f"{v} {s.text()}" for v, s in got.items()) + ")")
    v = verdict(outcomes)
    paper_text = ("Spread of v_x over its multiplicative variants (Table \"critic conditioning ablation\"): "
                  + ", ".join(f"{r} {paper_spread(r):.2f}" if paper_spread(r) is not None else f"{r} -"
                              for r in OOD_ROBOTS) + " m/s.")
    return Claim("d", text, paper_text, "; ".join(per_robot), v,
                 _reason(v, outcomes, OOD_ROBOTS, "their v_x lie within the tolerance"),
                 _ids(evals, MULTIPLICATIVE, OOD_ROBOTS))


def spearman(xs: Sequence[float], ys: Sequence[float]) -> float | None:
    """Spearman's rank correlation (average ranks for ties); None for fewer than 3 pairs or a constant side."""
    if len(xs) != len(ys) or len(xs) < 3:
        return None
    rx, ry = _ranks(xs), _ranks(ys)
    mx, my = sum(rx) / len(rx), sum(ry) / len(ry)
    sxy = sum((a - mx) * (b - my) for a, b in zip(rx, ry, strict=True))
    sxx, syy = sum((a - mx) ** 2 for a in rx), sum((b - my) ** 2 for b in ry)
    if sxx == 0 or syy == 0:
        return None
    return sxy / math.sqrt(sxx * syy)


def _ranks(xs: Sequence[float]) -> list[float]:
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    ranks = [0.0] * len(xs)
    i = 0
    while i < len(order):
        j = i
        while j + 1 < len(order) and xs[order[j + 1]] == xs[order[i]]:
            j += 1
        for k in range(i, j + 1):
            ranks[order[k]] = (i + j) / 2 + 1
        i = j + 1
    return ranks


def claim_e(evals: Sequence[dict[str, Any]]) -> Claim:
    """(e) Per evaluated variant, Spearman's rho between d and v_x x S (2.0 m/s, descriptor) over the robots."""
    text = "Transfer degrades with the normalised morphology distance d (v_x x S against d, 2.0 m/s)."
    rows = [r for r in evals if r.get("mode") == "descriptor" and not _differs(r.get("command_vx"), 2.0)]
    variants = [v for v in STOCK if any(r.get("variant") == v for r in rows)]
    per_variant, outcomes = [], []
    for variant in variants:
        pts = []
        for robot in paper.ROBOTS:
            vx = by_variant(rows, "vx_mean", robot).get(variant)
            s = by_variant(rows, "survival", robot).get(variant)
            d = next((float(r["d"]) for r in rows if r.get("robot") == robot and r.get("d") not in (None, "")), None)
            if vx is not None and s is not None and d is not None:
                pts.append((d, vx.mean * s.mean))
        rho = spearman([p[0] for p in pts], [p[1] for p in pts])
        outcomes.append(None if rho is None else rho <= DEGRADES_RHO)
        per_variant.append(f"{variant}: rho {rho:+.2f} over {len(pts)} robots" if rho is not None
                           else f"{variant}: too few robots")
    rho_paper = _paper_rho()
    v = verdict(outcomes) if outcomes else CANNOT
    reason = (_reason(v, outcomes, variants, f"rho <= {DEGRADES_RHO}") if outcomes
              else "No descriptor-mode evaluation at 2.0 m/s in the store.")
    return Claim("e", text, f"MorFiC-F, from its zero-shot table: rho {rho_paper:+.2f} (Fig. \"distance\")."
                 if rho_paper is not None else "Fig. \"distance\".", "; ".join(per_variant), v, reason,
                 sorted({str(r["artifact"]) for r in rows if r.get("artifact")}))


def _paper_rho() -> float | None:
    from morfic_cli.morphology.distance import distance_table

    dist = {r.robot: r.d for r in distance_table(paper.ROBOTS)}
    pts = []
    for robot in paper.ROBOTS:
        cell = paper.transfer_values("film", robot, 2.0)
        if cell["vx"] is not None and cell["survival"] is not None and robot in dist:
            pts.append((dist[robot], cell["vx"] * cell["survival"]))
    return spearman([p[0] for p in pts], [p[1] for p in pts])


def claim_parts(claim: Claim) -> list[tuple[str, str]]:
    """What a report prints under a claim, as (label, plain text): the paper's numbers, ours, why, the ids."""
    return [("Paper", claim.paper), ("Ours", claim.ours or "-"), ("Why", claim.reason),
            ("From", ", ".join(f"`{i[:12]}`" for i in claim.artifacts) or "-")]


def check_claims(evals: Sequence[dict[str, Any]], calibration: Sequence[dict[str, Any]],
                 fixed: Sequence[dict[str, Any]]) -> list[Claim]:
    """Claims (a)-(e) on the store's results (rows as :class:`~morfic_cli.report.gather.StoreData` holds them)."""
    return [claim_a(calibration), claim_b(evals), claim_c(fixed), claim_d(evals), claim_e(evals)]
