"""scripts/experiment_tables.py's evaluations: each run in its variant's modes (morfic_cli.rl.variants.eval_modes),
the paper's runs with the configs, and so the content addresses, of their shipped evals."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from morfic_cli.evaluation.protocol import eval_config
from morfic_cli.pipeline import Pipeline, _json, reproduce_cfg
from morfic_cli.store import Store

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("experiment_tables", ROOT / "scripts" / "experiment_tables.py")
et = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(et)

D, F, A = "descriptor", "full", "actuation-matched"


def _plan(store: Store, variant: str) -> list[tuple[str, float]]:
    """(mode, command) of every rollout the queue's evaluation of ``variant``'s seed-0 run makes, in order."""
    spec = f"runs/{variant}-cpu-s0"
    pipe = et.one_run_pipeline(store, variant, 0, spec)
    cfgs = (pipe.eval_cfg(spec), et.trained_regime_cfg(variant))
    return [(m, v) for cfg in cfgs for m in cfg.modes for v in cfg.command_vx]


@pytest.mark.parametrize(
    ("variant", "plan"),
    [
        ("film", [(D, 2.0), (D, 2.5), (F, 2.0), (F, 2.5), (D, 1.0)]),  # the paper's: as shipped
        ("adaln", [(D, 2.0), (D, 2.5), (F, 2.0), (F, 2.5), (D, 1.0)]),
        ("genloco", [(D, 2.0), (D, 2.5), (F, 2.0), (F, 2.5), (D, 1.0), (F, 1.0)]),  # issue 57: full mode at 1.0
        (
            "film-act",
            [(D, 2.0), (D, 2.5), (F, 2.0), (F, 2.5), (A, 2.0), (A, 2.5), (D, 1.0), (F, 1.0), (A, 1.0)],
        ),
        (
            "film-act-light",
            [(D, 2.0), (D, 2.5), (F, 2.0), (F, 2.5), (A, 2.0), (A, 2.5), (D, 1.0), (F, 1.0), (A, 1.0)],
        ),
    ],
)
def test_each_run_is_evaluated_in_its_variants_modes_at_every_command(tmp_path, variant, plan):
    assert _plan(Store(tmp_path / "store"), variant) == plan


def test_the_papers_evals_keep_the_configs_of_the_shipped_runs(tmp_path):
    # written out by hand: the config of film-cpu-s0's eval ba87775fde1e (docs/results/film-cpu-s0-artifacts.json)
    # and of the shipped preset's quick eval; the 1.0 m/s one is tests/scripts/test_results_tables.py's
    store = Store(tmp_path / "store")
    pipe = et.one_run_pipeline(store, "film", 0, "runs/film-cpu-s0")
    robots = ["go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c"]
    paper = {
        "spec": "runs/film-cpu-s0",
        "robots": robots,
        "modes": ["descriptor", "full"],
        "command_vx": [2.0, 2.5],
        "num_envs": 64,
        "steps": 500,
        "seed": 0,
        "scene_envs": 4,
    }
    assert _json(eval_config("runs/film-cpu-s0", pipe.eval_cfg("runs/film-cpu-s0"))) == paper
    quick = Pipeline(store, reproduce_cfg("shipped", bundles=ROOT / "artifacts" / "bundles", variants=("film",)))
    assert _json(eval_config("runs/film-cpu-s0", quick.eval_cfg("runs/film-cpu-s0"))) == {
        **paper,
        "modes": ["descriptor"],
        "command_vx": [2.0],
        "num_envs": 16,
        "batch_robots": True,
    }


def test_the_shipped_film_runs_evals_are_found_so_none_is_made_again(tmp_path):
    """reproduce and the queue skip a step whose config and inputs the store holds (``find_manifest``)."""
    store = Store(tmp_path / "store")
    store.import_tar(ROOT / "artifacts" / "bundles" / "results" / "film-cpu-s0.tar")
    shipped = json.loads((ROOT / "docs" / "results" / "film-cpu-s0-artifacts.json").read_text())
    pipe = et.one_run_pipeline(store, "film", 0, "runs/film-cpu-s0")
    found = pipe.stored_eval("runs/film-cpu-s0")
    assert found is not None and found.id == shipped["eval"]
    assert et.trained_regime_eval(pipe, "runs/film-cpu-s0", run_missing=False) == shipped["eval-1.0"]


def test_the_eval_command_of_the_1_0_eval_where_one_choice_of_mode_makes_it():
    assert et.trained_regime_command("runs/film-cpu-s0", (D,)) == "morfic eval runs/film-cpu-s0 --command-vx 1.0"
    assert (
        et.trained_regime_command("runs/genloco-cpu-s0", (D, F))
        == "morfic eval runs/genloco-cpu-s0 --command-vx 1.0 --mode both"
    )
    assert et.trained_regime_command("runs/x", (A,)) == "morfic eval runs/x --command-vx 1.0 --mode actuation-matched"
    assert et.trained_regime_command("runs/film-act-cpu-s0", (D, F, A)) is None  # only --run-missing makes it


def test_an_evals_termination_counts_are_copied_verbatim_and_an_older_eval_writes_none(tmp_path):
    from morfic_cli.evaluation.terminations import TERMINATIONS_CSV

    store = Store(tmp_path / "store")
    counts = b"robot,mode,command_vx,term,envs\ngo2,full,1.0,illegal_contact,12\ngo2,full,1.0,excessive_tilt,3\n"
    new = store.put_manifest("eval", files={"eval.csv": b"robot\ngo2\n", TERMINATIONS_CSV: counts})
    old = store.put_manifest("eval", files={"eval.csv": b"robot\ngo1\n"})
    assert et.terminations_path(tmp_path, "film-act-cpu-s0").name == "film-act-cpu-s0-terminations.csv"
    path = et.terminations_path(tmp_path, "film-act-cpu-s0", 1.0)
    assert path.name == "film-act-cpu-s0-terminations-1.0.csv"
    assert et.write_terminations(store, new, path) and path.read_bytes() == counts
    assert not et.write_terminations(store, old, path) and not path.exists()  # no empty file, no other eval's counts


def test_films_goal_eval_is_full_mode_at_1_0_beside_its_unchanged_1_0_eval():
    # written out by hand: `morfic eval runs/film-cpu-s0 --command-vx 1.0 --mode full` (the CLI's robot order);
    # the 1.0 m/s eval film's runs already have stays descriptor mode (its shipped id, the plan test above)
    goal = et.goal_eval_cfg(1.0)
    assert _json(eval_config("runs/film-cpu-s0", goal)) == {
        "spec": "runs/film-cpu-s0",
        "robots": ["go2", "a1", "aliengo", "anymal_c", "b1", "go1", "mini_cheetah"],
        "modes": ["full"],
        "command_vx": [1.0],
        "num_envs": 64,
        "steps": 500,
        "seed": 0,
        "scene_envs": 4,
    }
    assert et.trained_regime_cfg("film").modes == (D,)
    assert et.goal_eval_command("runs/film-cpu-s0", 1.0) == "morfic eval runs/film-cpu-s0 --command-vx 1.0 --mode full"


def _film_with_goal_eval(tmp_path: Path, variant: str = "film") -> tuple[Store, str, bytes, bytes]:
    """A store with run ``<variant>-cpu-s0`` (no weights) and its stored goal eval: (store, eval id, csv, counts)."""
    from morfic_cli.evaluation.terminations import TERMINATIONS_CSV

    store = Store(tmp_path / "store")
    spec = f"runs/{variant}-cpu-s0"
    ckpt = store.put_manifest("checkpoint", config={"variant": variant, "seed": 0}, files={"x": b"x"})
    store.set_ref(spec, ckpt)
    rows = b"robot,mode,command_vx,vx_mean,survival,verdict\ngo2,full,1.0,0.93,1.0,ok\n"
    counts = b"robot,mode,command_vx,term,envs\ngo2,full,1.0,illegal_contact,0\n"
    config = _json(eval_config(spec, et.goal_eval_cfg(1.0)))
    ev = store.put_manifest(
        "eval", config=config, inputs={"checkpoint": ckpt}, files={"eval.csv": rows, TERMINATIONS_CSV: counts}
    )
    return store, ev, rows, counts


def test_films_goal_eval_is_found_and_copied_with_its_counts_and_id(tmp_path):
    store, ev, rows, counts = _film_with_goal_eval(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    pipe = et.one_run_pipeline(store, "film", 0, "runs/film-cpu-s0")
    ids: dict = {}
    assert et.write_goal_evals(store, pipe, "runs/film-cpu-s0", "film-cpu-s0", out, ids, run_missing=False) == []
    assert (out / "film-cpu-s0-eval-1.0-full.csv").read_bytes() == rows
    assert (out / "film-cpu-s0-terminations-1.0-full.csv").read_bytes() == counts
    assert ids == {"eval-1.0-full": ev}
    # the script alone: --goal-evals-only copies it (the store lacks the run's weights: nothing to run)
    other = tmp_path / "other"
    assert et.main(["film-cpu-s0", "--goal-evals-only", "--out", str(other), "--store", str(store.root)]) == 0
    assert (other / "film-cpu-s0-eval-1.0-full.csv").read_bytes() == rows
    assert json.loads((other / "film-cpu-s0-artifacts.json").read_text())["eval-1.0-full"] == ev


def test_a_missing_goal_eval_is_a_note_and_a_variant_that_needs_none_an_error(tmp_path, capsys):
    store = Store(tmp_path / "store")
    ckpt = store.put_manifest("checkpoint", config={"variant": "film", "seed": 1}, files={"x": b"x"})
    store.set_ref("runs/film-cpu-s1", ckpt)
    pipe = et.one_run_pipeline(store, "film", 1, "runs/film-cpu-s1")
    assert et.write_goal_evals(store, pipe, "runs/film-cpu-s1", "film-cpu-s1", tmp_path, {}, run_missing=False) == [1.0]
    assert "note: no full-mode eval of runs/film-cpu-s1 at 1.0 m/s" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.csv"))
    act, *_ = _film_with_goal_eval(tmp_path / "act", "film-act")
    assert et.main(["film-act-cpu-s0", "--goal-evals-only", "--out", str(tmp_path), "--store", str(act.root)]) == 1
    assert "Error: film-act-cpu-s0 is a run of film-act; issue 58's goal needs extra evals of film's" in (
        capsys.readouterr().err
    )
