"""`morfic train --logger`: TensorBoard event files with rsl-rl's tags, read back by tensorboard's own reader."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from morfic_cli.recording.curves import read_curve_csv
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _scalars(folder: Path) -> EventAccumulator:
    acc = EventAccumulator(str(folder))
    acc.Reload()
    return acc


def test_train_writes_tensorboard_curves_into_the_run_folder(run_cli, tmp_path):
    logs = Path(os.environ["MORFIC_LOG_DIR"])
    code, out, err = run_cli("train", "--preset", "smoke", "--set", "max_iterations=3", "-f", "json")
    assert code == 0, err
    folder = logs / "film-smoke-s0"
    assert f"live curves (tensorboard) in {folder}" in err  # printed at start
    assert "it 3/3" in err and "nan" not in err and "  ep -  " in err and "reward -" in err  # no episode ended yet
    acc = _scalars(folder)
    tags = set(acc.Tags()["scalars"])
    assert {"Loss/value", "Loss/surrogate", "Loss/entropy", "Loss/learning_rate", "Loss/explained_variance",
            "Loss/adaptation_error", "Policy/mean_std", "Perf/total_fps", "Perf/collection_time",
            "Perf/learning_time", "curriculum/vx_max"} <= tags
    # the event file holds the store's curve: same learning rate and action std at each iteration
    rows = read_curve_csv(Store(os.environ["MORFIC_STORE"]).read_file("runs/film-smoke-s0", "curve.csv"))
    lr = acc.Scalars("Loss/learning_rate")
    assert [e.step for e in lr] == [0, 1, 2]
    assert [e.value for e in lr] == pytest.approx([r["learning_rate"] for r in rows], rel=1e-6)
    std = acc.Scalars("Policy/mean_std")
    assert [e.value for e in std] == pytest.approx([r["action_std"] for r in rows], rel=1e-6)
    ev = acc.Scalars("Loss/explained_variance")
    assert [e.value for e in ev] == pytest.approx([r["explained_variance"] for r in rows], rel=1e-5, abs=1e-6)

    # a resumed run continues the same folder at the next step
    code, _, err = run_cli("train", "--resume", "runs/film-smoke-s0", "--set", "max_iterations=4", "-q")
    assert code == 0, err
    assert [e.step for e in _scalars(folder).Scalars("Loss/learning_rate")] == [0, 1, 2, 3]
    assert json.loads(out)["iteration"] == 3


def test_logger_none_writes_no_folder(run_cli):
    code, _, err = run_cli("train", "--preset", "smoke", "--set", "max_iterations=1", "--logger", "none", "-q")
    assert code == 0, err
    assert not (Path(os.environ["MORFIC_LOG_DIR"]) / "film-smoke-s0").exists()


def test_bad_logger_input_is_an_error_line(run_cli, tmp_path):
    code, _, err = run_cli("train", "--preset", "smoke", "--logger", "mlflow")
    assert code != 0 and "mlflow" in err
    (tmp_path / "afile").write_text("x")
    code, _, err = run_cli("train", "--preset", "smoke", "--log-dir", str(tmp_path / "afile"))
    assert code == 1 and err.startswith("Error: ") and "is a file" in err
    assert not Store(os.environ["MORFIC_STORE"]).has_ref("runs/film-smoke-s0")
