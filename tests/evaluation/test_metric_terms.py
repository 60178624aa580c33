"""Eval metrics as registered terms: the stock terms keep eval.csv's layout; a registered metric (docs/extending.md,
"An eval metric") reaches eval.csv, the `morfic eval` table and compare-baselines' aggregation with no other edit."""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from smoke_runs import LEGACY_BUNDLE

from morfic_cli.evaluation import metric_terms
from morfic_cli.evaluation.metric_terms import (
    MetricTerm,
    RolloutData,
    SeedColumn,
    register_metric,
    seed_mean,
)
from morfic_cli.evaluation.metrics import mean_std, per_env_mean
from morfic_cli.evaluation.protocol import eval_columns

pytestmark = pytest.mark.usefixtures("one_torch_thread")

DOCS = Path(__file__).resolve().parents[2] / "docs"


# --- the worked example of docs/extending.md, "An eval metric" ---
def yaw_rate_abs(r: RolloutData) -> float:
    """Mean over envs of each env's mean |yaw rate| over its alive steps (rad/s). (T, N) -> float."""
    return mean_std(per_env_mean(np.abs(r.arrays["base_ang_vel"][..., 2]), r.alive))[0]


YAW_RATE = MetricTerm(
    "yaw_rate_abs",
    yaw_rate_abs,
    "rad/s",
    "mean |yaw rate| over alive steps, mean over envs",
    fmt=".2f",
    higher_is_better=False,
    seeds=(SeedColumn("yaw_rate_abs", seed_mean("yaw_rate_abs"), header="|yaw|"),),
    show=5,
    header="|yaw|",
    legend="|yaw|: mean |yaw rate| (rad/s)",
    drop=4,
)


@pytest.fixture
def with_yaw(monkeypatch):
    """The registry with the example metric registered (a copy: the next test sees the stock one)."""
    monkeypatch.setattr(metric_terms, "METRICS", list(metric_terms.METRICS))
    register_metric(YAW_RATE)


STOCK_COLUMNS = (
    "robot",
    "mode",
    "command_vx",
    "d",
    "vx_mean",
    "vx_std",
    "vx_env_std",
    "vx_step_mean",
    "n_alive",
    "vx_peak_1s_mean",
    "vx_peak_1s_std",
    "survival",
    "tracking_ratio",
    "valid",
    "valid_fraction",
    "verdict",
    "cell",
    "num_envs",
    "steps",
)


def test_the_stock_terms_keep_eval_csvs_columns_and_the_shipped_tables_header():
    assert eval_columns() == STOCK_COLUMNS
    shipped = (DOCS / "results" / "film-cpu-transfer-paper-metrics.csv").read_text().splitlines()[0]
    assert tuple(shipped.split(",")) == STOCK_COLUMNS


def test_the_stock_terms_are_the_papers_metrics_of_the_rollout():
    import dataclasses

    from morfic_cli.evaluation.metric_terms import metric_values
    from morfic_cli.evaluation.metrics import paper_cell, transfer_metrics

    rng = np.random.default_rng(0)
    t, n = 60, 4
    done = np.zeros((t, n), bool)
    done[20, 1] = True  # env 1 falls on step 20
    arrays = {
        "base_lin_vel": rng.normal(1.0, 0.3, (t, n, 3)),
        "done": done,
        "time_out": np.zeros((t, n), bool),
        "tilt": rng.uniform(0, 0.3, (t, n)),
        "height_ratio": np.ones((t, n)),
        "foot_slip": np.zeros((t, n)),
    }
    m = transfer_metrics(
        arrays["base_lin_vel"][..., 0],
        done,
        1.0,
        0.02,
        tilt=arrays["tilt"],
        height_ratio=arrays["height_ratio"],
        foot_slip=arrays["foot_slip"],
    )
    values = metric_values(RolloutData(arrays, command_vx=1.0, dt=0.02))
    assert values == {**dataclasses.asdict(m), "cell": paper_cell(m)}
    assert list(values) == list(STOCK_COLUMNS[4:-2])


def test_the_example_metric_by_hand():
    # 3 steps x 2 envs; env 1 falls on step 1: it counts step 0 only
    wz = np.array([[0.5, -1.0], [-0.3, 2.0], [0.1, 3.0]])
    arrays = {
        "base_ang_vel": np.stack([np.zeros_like(wz), np.zeros_like(wz), wz], axis=-1),
        "done": np.array([[False, False], [False, True], [False, False]]),
        "time_out": np.zeros((3, 2), bool),
    }
    data = RolloutData(arrays, command_vx=1.0, dt=0.02)
    # env 0: (0.5 + 0.3 + 0.1) / 3 = 0.3; env 1: 1.0; mean over envs 0.65
    assert yaw_rate_abs(data) == pytest.approx(0.65)


def test_a_name_taken_is_refused(monkeypatch):
    monkeypatch.setattr(metric_terms, "METRICS", list(metric_terms.METRICS))
    with pytest.raises(ValueError, match="vx_mean"):
        register_metric(MetricTerm("vx_mean", yaw_rate_abs, "rad/s", "a clash"))
    with pytest.raises(ValueError, match="survival_seed_std"):
        register_metric(
            MetricTerm(
                "new",
                yaw_rate_abs,
                "1",
                "its seed column clashes",
                seeds=(SeedColumn("survival_seed_std", seed_mean("new")),),
            )
        )


def test_seeds_aggregate_as_declared(with_yaw):
    from morfic_cli.report.compare import transfer_rows
    from morfic_cli.report.gather import StoreData

    def row(seed: int, vx: float, survival: float, yaw: float) -> dict:
        return {
            "preset": "cpu",
            "variant": "film",
            "robot": "go2",
            "mode": "descriptor",
            "command_vx": 2.0,
            "d": 0.0,
            "run": f"film-cpu-s{seed}",
            "vx_mean": vx,
            "vx_std": 0.1,
            "vx_env_std": 0.0,
            "vx_step_mean": vx,
            "n_alive": 100,
            "vx_peak_1s_mean": vx + 0.1,
            "survival": survival,
            "tracking_ratio": vx / 2.0,
            "valid_fraction": 1.0,
            "yaw_rate_abs": yaw,
            "num_envs": 64,
            "steps": 500,
        }

    (out,) = transfer_rows(StoreData(runs=[], evals=[row(0, 1.8, 1.0, 0.2), row(1, 2.0, 0.5, 0.4)]))
    assert out["yaw_rate_abs"] == pytest.approx(0.3)  # mean over seeds, as declared
    assert out["vx"] == pytest.approx(1.9) and out["survival"] == pytest.approx(0.75)
    assert out["vx_seed_std"] == pytest.approx(math.sqrt(0.02))  # sample std of 1.8, 2.0
    # σ pooled over 2 x 100 steps: sqrt(0.1^2 + 0.1^2) (each mean 0.1 off the pooled 1.9)
    assert out["vx_std"] == pytest.approx(math.sqrt(0.02))
    assert out["cell"] == "1.90 ± 0.14 / 0.750"
    keys = list(out)  # the stock layout, the new column after the stock ones and before the budget
    assert keys[keys.index("runs") + 1 :] == [
        "vx",
        "vx_std",
        "vx_seed_std",
        "vx_peak_1s",
        "survival",
        "survival_seed_std",
        "tracking_ratio",
        "valid_fraction",
        "cell",
        "yaw_rate_abs",
        "num_envs",
        "steps",
    ]


def test_a_registered_metric_reaches_eval_csv_the_table_and_compare_baselines(run_cli, tmp_path, with_yaw, wide_tables):
    from morfic_cli.recording.rollout_log import read_rollout

    assert run_cli("store", "import", str(LEGACY_BUNDLE))[0] == 0  # runs/film-cpu
    out = tmp_path / "out"
    code, stdout, err = run_cli(
        "eval",
        "runs/film-cpu",
        "--robots",
        "go2",
        "--envs",
        "3",
        "--steps",
        "20",
        "--scene-envs",
        "0",
        "--out",
        str(out),
        "-q",
    )
    assert code == 0, err
    assert "|yaw|" in stdout and "|yaw|: mean |yaw rate| (rad/s)" in " ".join(stdout.split())  # however it wraps

    (row,) = list(csv.DictReader(io.StringIO((out / "eval.csv").read_text())))
    assert tuple(row) == (*STOCK_COLUMNS[:-2], "yaw_rate_abs", "num_envs", "steps")
    log = read_rollout(next(out.rglob("*.mcap")))  # the rollout's arrays, read back; the value by hand
    wz = np.abs(log.arrays["base_ang_vel"][..., 2].astype(np.float64))
    fell = log.arrays["done"] & ~log.arrays["time_out"]
    spans = [int(np.argmax(fell[:, i])) if fell[:, i].any() else fell.shape[0] for i in range(fell.shape[1])]
    expected = np.mean([wz[:k, i].mean() for i, k in enumerate(spans) if k > 0])
    assert float(row["yaw_rate_abs"]) == pytest.approx(expected, rel=1e-6)
    assert f"{expected:.2f}" in stdout

    code, stdout, err = run_cli("compare-baselines", "runs/film-cpu", "--format", "json")
    assert code == 0, err
    text = json.loads(stdout)
    rows = text if isinstance(text, list) else [r for rs in text.values() for r in rs]
    (transfer,) = [r for r in rows if r.get("table") == "transfer" and r.get("steps") == 20]
    assert transfer["yaw_rate_abs"] == pytest.approx(expected, rel=1e-6)  # one seed: the run's own value


def test_every_metric_has_its_row_in_docs_eval():
    section = (DOCS / "eval.md").read_text().split("## Metrics", 1)[1].split("\n## ", 1)[0]
    documented = set(re.findall(r"`([a-z0-9_]+)`", section))
    missing = [t.name for t in metric_terms.METRICS if t.name not in documented]
    assert not missing, f"add a row for {missing} to docs/eval.md's metrics table"
