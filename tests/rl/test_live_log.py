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
    assert {
        "Loss/value",
        "Loss/surrogate",
        "Loss/entropy",
        "Loss/learning_rate",
        "PPO/explained_variance",
        "PPO/kl",
        "PPO/clip_fraction",
        "Loss/adaptation_error",
        "Policy/mean_std",
        "Perf/total_fps",
        "Perf/collection_time",
        "Perf/learning_time",
        "Curriculum/vx_max",
        "Metrics/vx_error",
        "Train/mean_reward",
        "Train/mean_episode_length",
        "Train/mean_reward/time",
        "Train/mean_episode_length/time",
    } <= tags
    assert any(t.startswith("Step_Reward/") for t in tags) and any(t.startswith("Step_Reward_Raw/") for t in tags)
    assert not {"Loss/value_loss", "Loss/explained_variance", "Loss/kl"} & tags  # no copy of Loss/value
    assert not any(t.startswith(("curriculum/", "episode_reward/", "termination/")) for t in tags)
    # no episode has ended in 3 x 8 steps: Train/ holds the episodes under way (24 steps long at the last iteration)
    assert [e.value for e in acc.Scalars("Train/mean_episode_length")] == [8.0, 16.0, 24.0]
    assert all(abs(e.value) < 1e3 for e in acc.Scalars("Train/mean_reward"))
    # the event file holds the store's curve: same learning rate and action std at each iteration
    rows = read_curve_csv(Store(os.environ["MORFIC_STORE"]).read_file("runs/film-smoke-s0", "curve.csv"))
    lr = acc.Scalars("Loss/learning_rate")
    assert [e.step for e in lr] == [0, 1, 2]
    assert [e.value for e in lr] == pytest.approx([r["learning_rate"] for r in rows], rel=1e-6)
    std = acc.Scalars("Policy/mean_std")
    assert [e.value for e in std] == pytest.approx([r["action_std"] for r in rows], rel=1e-6)
    ev = acc.Scalars("PPO/explained_variance")
    assert [e.value for e in ev] == pytest.approx([r["explained_variance"] for r in rows], rel=1e-5, abs=1e-6)
    # rsl-rl's /time tags: the same values, at the whole seconds of the run's wall clock (the curve's wall_time_s)
    timed = acc.Scalars("Train/mean_episode_length/time")
    assert [e.value for e in timed] == [8.0, 16.0, 24.0]
    assert [e.step for e in timed] == [int(r["wall_time_s"]) for r in rows]

    # a resumed run continues the same folder at the next step
    code, _, err = run_cli("train", "--resume", "runs/film-smoke-s0", "--set", "max_iterations=4", "-q")
    assert code == 0, err
    assert [e.step for e in _scalars(folder).Scalars("Loss/learning_rate")] == [0, 1, 2, 3]
    assert json.loads(out)["iteration"] == 3


class _Writer:
    def __init__(self):
        self.scalars: dict[str, list[tuple[int, float]]] = {}

    def add_scalar(self, tag, value, step):
        self.scalars.setdefault(tag, []).append((step, value))


def test_tags_follow_rsl_rl_and_isaac_lab():
    from morfic_cli.rl.live_log import write_iteration

    w = _Writer()
    losses = {
        "value": 0.5,
        "value_loss": 0.5,
        "surrogate": -0.01,
        "entropy": 17.0,
        "adaptation_error": 0.2,
        "explained_variance": 0.8,
        "kl": 0.004,
        "clip_fraction": 0.1,
    }
    extras = {
        "/episode_reward/track_lin_vel": 0.9,
        "/termination/base_contact": 0.25,
        "/termination/time_out": 0.75,
        "/curriculum/vx_max": 1.5,
        "/curriculum/lin_tracking": 0.7,
        "/tracking/vx_error": 0.3,
        "/episode/length_s": 12.0,
        "/reward/track_lin_vel": 0.01,
        "/reward_raw/track_lin_vel": 0.5,
        "/env/nonfinite_resets": 0.0,
        "plain": 2.0,
    }
    write_iteration(w, 4, 1000, 1.5, 0.5, losses, 1e-3, 0.8, extras, -3.0, 250.0, wall_time_s=75.9)
    assert w.scalars.pop("Train/mean_reward/time") == [(75, -3.0)]  # rsl-rl's: whole seconds of wall time
    assert w.scalars.pop("Train/mean_episode_length/time") == [(75, 250.0)]
    assert {tag: v for tag, [(step, v)] in w.scalars.items() if step == 4} == {
        "Loss/value": 0.5,
        "Loss/surrogate": -0.01,
        "Loss/entropy": 17.0,
        "Loss/adaptation_error": 0.2,
        "PPO/explained_variance": 0.8,
        "PPO/kl": 0.004,
        "PPO/clip_fraction": 0.1,
        "Episode_Reward/track_lin_vel": 0.9,
        "Episode_Termination/base_contact": 0.25,
        "Episode_Termination/time_out": 0.75,
        "Curriculum/vx_max": 1.5,
        "Curriculum/lin_tracking": 0.7,
        "Metrics/vx_error": 0.3,
        "Episode/length_s": 12.0,
        "Step_Reward/track_lin_vel": 0.01,
        "Step_Reward_Raw/track_lin_vel": 0.5,
        "Env/nonfinite_resets": 0.0,
        "Episode/plain": 2.0,
        "Loss/learning_rate": 1e-3,
        "Policy/mean_std": 0.8,
        "Perf/total_fps": 500,
        "Perf/collection_time": 1.5,
        "Perf/learning_time": 0.5,
        "Train/mean_reward": -3.0,
        "Train/mean_episode_length": 250.0,
    }


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


def test_time_tags_are_left_out_without_a_wall_clock():
    """rsl-rl writes the /time tags on TensorBoard only (not on wandb): None leaves them out."""
    from morfic_cli.rl.live_log import write_iteration

    w = _Writer()
    write_iteration(w, 0, 10, 1.0, 1.0, {}, 1e-3, 1.0, {}, 1.0, 2.0)
    assert not any(tag.endswith("/time") for tag in w.scalars)
