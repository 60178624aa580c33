"""`morfic eval` on a smoke checkpoint: every robot in both modes, stored MCAP logs, table, bad input."""

from __future__ import annotations

import csv
import io
import json
import os

import numpy as np
import pytest
from smoke_runs import train_smoke_runs

from morfic_cli.evaluation.protocol import EvalCfg, evaluate, rollout_role
from morfic_cli.morphology.robots import list_robots
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def smoke_store(tmp_path_factory):
    """One smoke-trained film checkpoint, shared by the tests of this module (copied per test)."""
    root = tmp_path_factory.mktemp("smoke") / "store"
    train_smoke_runs(root)
    return root


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    import shutil

    root = tmp_path / "store"
    shutil.copytree(smoke_store, root)
    monkeypatch.setenv("MORFIC_STORE", str(root))
    return Store(root)


def test_every_robot_in_both_modes_through_the_cli(run_cli, store):
    code, out, err = run_cli("eval", "runs/film-s0", "--robots", "all", "--mode", "both", "--envs", "2",
                             "--steps", "6", "--command-vx", "1.0", "--format", "json", "--quiet")
    assert code == 0, err
    rows = json.loads(out)
    robots = list_robots()
    assert [(r["robot"], r["mode"]) for r in rows] == [(n, m) for n in robots for m in ("descriptor", "full")]
    for row in rows:
        assert {"robot", "mode", "command_vx", "vx_mean", "vx_std", "vx_env_std", "vx_peak_1s_mean", "survival",
                "valid"} <= set(row)
        assert row["command_vx"] == 1.0 and 0.0 <= row["survival"] <= 1.0 and isinstance(row["valid"], bool)
        assert row["num_envs"] == 2 and row["steps"] == 6
        assert " / " in row["cell"]
    assert next(r for r in rows if r["robot"] == "go2")["d"] == 0.0
    manifest = store.read_manifest("evals/film-s0")
    assert manifest.kind == "eval"
    assert manifest.inputs["checkpoint"] == store.resolve("runs/film-s0")
    assert len([k for k in manifest.inputs if k.startswith("rollout/")]) == 2 * len(robots)
    table = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "eval.csv").decode())))
    assert [r["robot"] for r in table] == [r["robot"] for r in rows]


def test_stored_mcap_logs_read_back_to_the_rollout_arrays(store, tmp_path):
    from mcap.reader import make_reader

    from morfic_cli.recording.rollout_log import read_rollout

    cfg = EvalCfg(robots=("a1",), modes=("descriptor",), command_vx=(1.5,), num_envs=3, steps=7, seed=2)
    result = evaluate(store, "runs/film-s0", cfg)
    role = rollout_role("a1", "descriptor", 1.5)
    rollout = result.rollouts[role]
    rid = store.read_manifest(result.id).inputs[role]
    path = tmp_path / "a1.mcap"
    path.write_bytes(store.read_file(rid, "rollout.mcap"))
    log = read_rollout(path)
    for key in ("base_pos", "base_quat", "joint_pos", "action", "reward", "value", "reward_terms"):
        np.testing.assert_array_equal(log.arrays[key], rollout.arrays[key].astype(log.arrays[key].dtype), key)
    np.testing.assert_array_equal(log.arrays["done"], rollout.arrays["done"])
    assert log.term_names == rollout.term_names
    assert log.metadata["robot"] == "a1" and log.metadata["mode"] == "descriptor"
    assert log.metadata["checkpoint"] == store.resolve("runs/film-s0")
    assert log.metadata["command"] == [1.5, 0.0, 0.0] and log.metadata["seed"] == 2
    with open(path, "rb") as fh:  # the mcap library's own reader sees 7 step messages
        assert sum(1 for _ in make_reader(fh).iter_messages()) == 7
    # per-step rewards are the sum of the logged term contributions
    np.testing.assert_allclose(rollout.arrays["reward_terms"].sum(-1), rollout.arrays["reward"], atol=1e-5)


def test_rollout_metrics_follow_the_recorded_arrays(store):
    """The table row is the metrics function applied to the recorded arrays (no second code path)."""
    from morfic_cli.evaluation.metrics import transfer_metrics

    cfg = EvalCfg(robots=("go2",), command_vx=(1.0,), num_envs=4, steps=30, seed=1)
    result = evaluate(store, "runs/film-s0", cfg)
    rollout = result.rollouts[rollout_role("go2", "descriptor", 1.0)]
    a = rollout.arrays
    m = transfer_metrics(a["base_lin_vel"][..., 0], a["done"] & ~a["time_out"], 1.0, 0.02, tilt=a["tilt"],
                         height_ratio=a["height_ratio"], foot_slip=a["foot_slip"])
    row = result.rows[0]
    assert row["vx_mean"] == pytest.approx(m.vx_mean) and row["survival"] == m.survival
    assert not a["time_out"].any()  # the eval episode is longer than the rollout
    np.testing.assert_allclose(a["command"][..., 0], 1.0)
    assert a["base_pos"].shape == (30, 4, 3) and a["value"].shape == (30, 4)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["runs/nothing"], "no artifact 'runs/nothing'"),
        (["runs/film-s0", "--robots", "go3"], "unknown robot 'go3'"),
        (["runs/film-s0", "--command-vx", "fast"], "--command-vx takes"),
        (["runs/film-s0", "--mode", "sideways"], "'sideways' is not one of 'descriptor', 'full', 'both'"),
        (["runs/film-s0", "--envs", "0"], "Invalid value for '--envs'"),
    ],
)
def test_bad_input_is_an_error_and_writes_nothing(run_cli, store, argv, needle):
    refs = store.list_refs()
    code, out, err = run_cli("eval", argv[0], "--steps", "2", "--envs", "2", *argv[1:])  # later flags win
    assert code == 1 and err.startswith("Error: ") and needle in err, err
    assert out == "" and store.list_refs() == refs


def test_eval_of_a_trainer_state_is_refused(run_cli, store):
    state = store.read_manifest("runs/film-s0").inputs["trainer_state"]
    code, _, err = run_cli("eval", state, "--robots", "go2", "--steps", "2", "--envs", "1")
    assert code == 1 and "not a training checkpoint" in err
    assert os.environ["MORFIC_STORE"] == str(store.root)


def test_video_is_stored_and_written_into_out(run_cli, store, tmp_path, gl_backend):
    out = tmp_path / "results"
    code, _, err = run_cli("eval", "runs/film-s0", "--robots", "go2", "--envs", "2", "--steps", "4",
                           "--command-vx", "1.0", "--video", "--out", str(out), "--format", "json", "--quiet")
    assert code == 0, err
    videos = sorted(p.name for p in out.iterdir())
    ext = "mp4" if any(n.endswith(".mp4") for n in videos) else "gif"
    assert videos == ["eval.csv", "go2-descriptor-vx1-frames.png", f"go2-descriptor-vx1.{ext}"]
    media = store.ls("media")
    assert len(media) == 1
    manifest = store.read_manifest(media[0]["id"])
    assert manifest.inputs["eval"] == store.resolve("evals/film-s0")
    assert store.read_manifest(manifest.inputs["rollout"]).kind == "rollout"
    assert store.read_file(manifest.id, f"video.{ext}") == (out / f"go2-descriptor-vx1.{ext}").read_bytes()
