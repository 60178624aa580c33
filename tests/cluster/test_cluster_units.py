"""The cluster pieces that need no Ray: the job graph, the worker body, append-import, the CLI's errors."""

from __future__ import annotations

import sys

import pytest

from morfic_cli import __version__
from morfic_cli.cluster.jobs import Job, plan_jobs, stored
from morfic_cli.cluster.worker import Outcome, check_version, execute, input_bundle
from morfic_cli.errors import MorficError, StoreError
from morfic_cli.pipeline import Pipeline, reproduce_cfg
from morfic_cli.store import Store


def _pipeline(tmp_path, **kw) -> Pipeline:
    return Pipeline(Store(tmp_path / "store"), reproduce_cfg("smoke", variants=("film", "ppo"), **kw))


def test_plan_jobs_is_the_pipeline_in_dependency_order(tmp_path):
    jobs = plan_jobs(_pipeline(tmp_path, seeds=2))
    keys = [j.key for j in jobs]
    runs = ["runs/film-smoke-s0", "runs/film-smoke-s1", "runs/ppo-smoke-s0", "runs/ppo-smoke-s1"]
    assert keys == (
        [f"train {r}" for r in runs]
        + [f"eval {r}" for r in runs]
        + [f"diagnose {r}" for r in runs]
        + ["fixed-rollout aliengo", "fixed-rollout mini_cheetah"]
    )
    assert [j.seed for j in jobs[:4]] == [0, 1, 0, 1] and jobs[2].variant == "ppo"
    assert next(j for j in jobs if j.key == "eval runs/ppo-smoke-s1").needs == ("runs/ppo-smoke-s1",)
    assert jobs[-1].needs == tuple(runs)  # every critic is scored on the frozen actor's rollout


def test_the_fixed_rollout_freezes_films_actor_or_does_not_run(tmp_path):
    """Without film among the variants, the analysis freezes film's seed-0 run from the store, never another actor."""
    p = Pipeline(Store(tmp_path / "store"), reproduce_cfg("smoke", variants=("ppo", "concat")))
    assert p.fixed_rollout_models() == ("runs/film-smoke-s0", ["runs/ppo-smoke-s0", "runs/concat-smoke-s0"])
    assert "runs/film-smoke-s0 is neither reproduced here nor in the store" in p.fixed_rollout_unavailable()
    assert [j.kind for j in plan_jobs(p)].count("fixed-rollout") == 0
    result = p.fixed_rollout("aliengo")
    assert (result.status, result.id) == ("not run", None) and "add film to --variants" in result.detail
    p.store.publish("checkpoint", "runs/film-smoke-s0", config={"variant": "film"}, files={"model.pt": b"w"})
    assert p.fixed_rollout_unavailable() is None
    fixed = [j for j in plan_jobs(p) if j.kind == "fixed-rollout"]
    assert [j.label for j in fixed] == ["aliengo", "mini_cheetah"]
    assert fixed[0].needs == ("runs/film-smoke-s0", "runs/ppo-smoke-s0", "runs/concat-smoke-s0")


def test_nothing_is_stored_in_an_empty_store(tmp_path):
    p = _pipeline(tmp_path)
    assert [stored(p, j) for j in plan_jobs(p)] == [None] * 8


def test_version_mismatch_is_a_clear_error():
    check_version(__version__)
    with pytest.raises(MorficError, match=r"runs morfic .* the driver morfic 0\.0\.0.*same morfic on every node"):
        check_version("0.0.0")


def test_a_user_error_comes_back_once_as_a_message(tmp_path):
    """A bad --set key on a worker is an Outcome.error (Ray does not retry a returned value), not an exception."""
    import dataclasses

    cfg = dataclasses.replace(reproduce_cfg("smoke", variants=("film",)), train_overrides=("no_such_key=1",))
    out = execute(Job("train", "runs/film-smoke-s0", variant="film", seed=0), cfg, __version__)
    assert "no_such_key" in out.error and out.bundle == b"" and out.step is None
    mismatch = execute(Job("train", "runs/film-smoke-s0", variant="film", seed=0), cfg, "0.0.0")
    assert "0.0.0" in mismatch.error


def test_a_failed_input_fails_its_dependents():
    with pytest.raises(MorficError, match="its input job train runs/x failed: boom"):
        input_bundle(Outcome("train runs/x", "host", 1, error="boom"))
    assert input_bundle(b"tar") == b"tar"


def test_append_import_adds_each_jobs_version_to_a_shared_ref(tmp_path):
    """Two workers each publish version 1 of one ref: merging diverges, appending keeps both, in import order."""
    user = Store(tmp_path / "user")
    ids = []
    for i in (1, 2):
        worker = Store(tmp_path / f"w{i}")
        ids.append(worker.put_manifest("diagnosis", files={"calibration.csv": f"row {i}".encode()}))
        worker.set_ref("diagnoses/calibration", ids[-1])
        worker.export_tar(["diagnoses/calibration"], tmp_path / f"w{i}.tar")
    user.import_tar(tmp_path / "w1.tar", append=True)
    with pytest.raises(StoreError, match="diverged"):
        user.import_tar(tmp_path / "w2.tar")
    report = user.import_tar(tmp_path / "w2.tar", append=True)
    assert report.refs == {"diagnoses/calibration": "extended"}
    assert [(e.version, e.id) for e in user.ref_history("diagnoses/calibration")] == [(1, ids[0]), (2, ids[1])]
    again = user.import_tar(tmp_path / "w2.tar", append=True)  # a duplicated job adds nothing
    assert again.refs == {"diagnoses/calibration": "unchanged"}
    assert user.verify().problems == []


def test_executor_ray_without_ray_says_what_to_install(run_cli, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    store = tmp_path / "store"
    code, _, err = run_cli(
        "reproduce", "--preset", "smoke", "--variants", "film", "--executor", "ray", "--store", str(store)
    )
    assert code == 1
    assert err.startswith("Error:") and "pip install 'morfic[cluster]'" in err
    assert not store.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--address", "127.0.0.1:6379"], "use it with --executor ray"),
        (["--executor", "ray", "--address", "nohost"], "is not HOST:PORT"),
        (["--executor", "ray", "--retries", "-1"], "--retries must be 0 or more"),
    ],
)
def test_bad_executor_options_are_error_lines(run_cli, tmp_path, args, message):
    store = tmp_path / "store"
    code, _, err = run_cli("reproduce", "--preset", "smoke", "--variants", "film", *args, "--store", str(store))
    assert code == 1 and err.startswith("Error:") and message in err, err
    assert not store.exists()


def test_an_address_where_nothing_listens_is_an_error_line(run_cli, tmp_path):
    pytest.importorskip("ray")
    import socket

    with socket.socket() as s:  # a port that was free a moment ago
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code, _, err = run_cli(
        "reproduce",
        "--preset",
        "smoke",
        "--variants",
        "film",
        "--executor",
        "ray",
        "--address",
        f"127.0.0.1:{port}",
        "--store",
        str(tmp_path / "store"),
    )
    assert code == 1 and "\nError: cannot reach a Ray cluster at --address 127.0.0.1:" in err, err
    assert not (tmp_path / "store" / "refs").exists()
