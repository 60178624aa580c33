"""``morfic distance``: the paper's robots, eq. (morph_dist), and the table artifact in the store."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pandas as pd
import pytest
from paper_facts import PAPER_DESCRIPTORS, TRAIN_MAX, TRAIN_MIN

PAPER = PAPER_DESCRIPTORS


def _independent_span_distances() -> dict[str, float]:
    stack = np.array([TRAIN_MIN, TRAIN_MAX, *PAPER.values()])
    lo, hi = stack.min(0), stack.max(0)
    norm = {k: (np.array(v) - lo) / (hi - lo) for k, v in PAPER.items()}
    return {k: float(np.sqrt(np.sum((norm[k] - norm["go2"]) ** 2) / 11)) for k in PAPER}


def test_distance_json_covers_all_robots_go2_zero_b1_farthest(run_cli):
    code, out, err = run_cli("distance", "--format", "json")
    assert code == 0, err
    rows = json.loads(out)
    d = {r["robot"]: r["d"] for r in rows}
    assert set(d) == set(PAPER)
    assert d["go2"] == 0.0
    assert max(d, key=d.get) == "b1"
    assert all(0.0 <= v <= 1.0 for v in d.values())
    expected = _independent_span_distances()
    for name, value in expected.items():
        assert d[name] == pytest.approx(value, abs=1e-6), name
    # B1's outside-support marks as in the paper (thigh, calf, hip, base mass up, ...).
    b1 = next(r for r in rows if r["robot"] == "b1")
    outside = {o["dim"]: o["side"] for o in b1["outside"]}
    assert outside["thigh_mass"] == "above" and outside["hip_limit_max"] == "below"
    assert "foot_mass" not in outside and b1["n_outside"] == len(b1["outside"])


def test_distance_again_adds_no_ref_version(run_cli):
    import os

    from morfic_cli.store import Store

    for _ in range(3):
        assert run_cli("distance", "-q")[0] == 0
    store = Store(os.environ["MORFIC_STORE"])
    assert len(store.ref_history("tables/distance")) == 1 and len(store.ls("table")) == 1
    assert run_cli("distance", "--normalize", "support", "-q")[0] == 0  # another result: a new version
    assert len(store.ref_history("tables/distance")) == 2


def test_distance_writes_a_table_artifact(run_cli):
    code, out, _ = run_cli("distance", "--format", "json")
    assert code == 0
    code, ls_out, _ = run_cli("store", "ls", "--format", "json")
    assert code == 0
    tables = [r for r in json.loads(ls_out) if r["kind"] == "table"]
    assert len(tables) == 1 and tables[0]["ref"] == "tables/distance"

    import os

    from morfic_cli.store import Store

    store = Store(os.environ["MORFIC_STORE"])
    manifest = store.read_manifest("tables/distance")
    assert manifest.config["normalize"] == "span" and manifest.config["reference"] == "go2"
    frame = pd.read_csv(io.BytesIO(store.read_file("tables/distance", "distance.csv")))
    assert dict(zip(frame.robot, frame.d, strict=True)) == {r["robot"]: r["d"] for r in json.loads(out)}


def test_support_normalisation_and_subset(run_cli):
    code, out, _ = run_cli("distance", "--robots", "go1,b1", "--normalize", "support", "--format", "json")
    assert code == 0
    d = {r["robot"]: r["d"] for r in json.loads(out)}
    assert list(d) == ["go1", "b1"]
    lo, hi = np.array(TRAIN_MIN), np.array(TRAIN_MAX)
    want = math.sqrt(np.sum(((np.array(PAPER["b1"]) - np.array(PAPER["go2"])) / (hi - lo)) ** 2) / 11)
    assert d["b1"] == pytest.approx(want, abs=1e-6)
    assert d["b1"] > 1.0  # outside the support, "support" normalisation is not bounded by 1


def test_csv_and_table_formats(run_cli):
    code, out, _ = run_cli("distance", "--format", "csv")
    assert code == 0 and out.splitlines()[0].startswith("robot,d,")
    code, out, _ = run_cli("distance")
    assert code == 0 and "b1" in out and "↑" in out


def test_unknown_robot_is_an_error_listing_valid_names(run_cli):
    code, out, err = run_cli("distance", "--robots", "go1,spot")
    assert code == 1
    assert err.startswith("Error: unknown robot 'spot'")
    assert "go2" in err and out == ""
