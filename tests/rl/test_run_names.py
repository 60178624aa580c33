"""One naming rule for runs, ``<variant>-<preset>-s<seed>``, in ``train``, ``reproduce`` and the shipped bundles;
runs named by an earlier morfic (``film-s0``) still evaluate."""

from __future__ import annotations

import json
from pathlib import Path

from morfic_cli.pipeline import Pipeline, reproduce_cfg
from morfic_cli.rl.config import smoke_preset
from morfic_cli.rl.runner import new_run
from morfic_cli.runs import RUNS_PREFIX, run_name
from morfic_cli.store import Store

BUNDLES = Path(__file__).resolve().parents[2] / "artifacts" / "bundles"
TINY = (
    "--set",
    "max_iterations=1",
    "--set",
    "env.num_envs=8",
    "--set",
    "num_steps_per_env=8",
    "--set",
    "ppo.use_mixed_precision=false",
)


def test_train_and_reproduce_name_runs_alike_and_presets_do_not_collide(run_cli, tmp_path):
    store = str(tmp_path / "store")
    refs = []
    for preset in ("smoke", "cpu"):  # the cpu preset shrunk to seconds: only its name matters here
        code, out, err = run_cli(
            "train",
            "--variant",
            "film",
            "--preset",
            preset,
            *TINY,
            "-q",
            "-f",
            "json",
            "--store",
            store,
            "--logger",
            "none",
        )
        assert code == 0, err  # cpu after smoke: no "already exists"
        refs.append(json.loads(out)["ref"])
    assert refs == ["runs/film-smoke-s0@1", "runs/film-cpu-s0@1"]
    code, _, err = run_cli("train", "--variant", "film", *TINY, "-q", "--store", store, "--logger", "none")
    assert code == 1 and "runs/film-smoke-s0' already exists" in err  # no --preset: smoke, the same run
    for preset in ("smoke", "cpu"):
        specs = Pipeline(Store(store), reproduce_cfg(preset, variants=("film", "ppo"), seeds=2)).run_specs()
        assert [s[2] for s in specs] == [RUNS_PREFIX + run_name(v, s, preset) for v in ("film", "ppo") for s in (0, 1)]
        assert specs[0][2] == f"runs/film-{preset}-s0"


def test_the_shipped_bundles_follow_the_rule():
    names = sorted(p.stem for p in BUNDLES.glob("*-s0.tar"))
    assert "film-cpu-s0" in names
    assert all(n == run_name(n.removesuffix("-cpu-s0"), 0, "cpu") for n in names)


def test_a_run_named_by_an_earlier_morfic_still_evaluates(run_cli, tmp_path):
    store = Store(tmp_path / "store")
    cfg = smoke_preset("film", seed=0)
    run = new_run(store, type(cfg)(**{**cfg.__dict__, "max_iterations": 1}), "film-s0")  # the old `train` default
    run.train()
    run.env.close()
    code, out, err = run_cli(
        "eval",
        "runs/film-s0",
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "5",
        "--scene-envs",
        "0",
        "-q",
        "-f",
        "json",
        "--store",
        str(store.root),
    )
    assert code == 0, err
    (row,) = json.loads(out)
    assert row["robot"] == "go2" and row["survival"] >= 0.0
    assert store.read_manifest("evals/film-s0").meta["run"] == "film-s0"
