"""The ``genloco`` baseline: ppo's networks trained on procedurally generated robots, end to end through the CLI."""

from __future__ import annotations

import json
import os

import pytest

from morfic_cli.rl import variants as V
from morfic_cli.rl.config import apply_overrides, preset_cfg
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_genloco_is_an_external_baseline_with_ppos_networks():
    g, ppo = V.STOCK["genloco"], V.STOCK["ppo"]
    assert g.label == "GenLoco" and g.tables == ("external",)
    assert "genloco" not in V.table_variants("main") + V.table_variants("ablation")
    assert not g.actor_morphology and not g.critic_morphology and not g.multiplicative
    assert g.model_cfgs() == ppo.model_cfgs()  # the same actor (15-step history, no z_m) and unconditioned critic
    assert g.env_overrides == {"rand.geometry.enabled": True}


def test_its_presets_turn_procedural_geometry_on_and_set_can_turn_it_off():
    for preset in ("smoke", "cpu", "paper"):
        cfg = preset_cfg(preset, "genloco")
        assert cfg.env.rand.geometry.enabled
        base = preset_cfg(preset, "ppo")
        assert not base.env.rand.geometry.enabled  # every other variant unchanged
        assert cfg.env == type(cfg.env)(**{**base.env.__dict__, "rand": cfg.env.rand})
        pool = 8 if preset == "smoke" else 256  # the smoke preset compiles 8 generated robots, not GenLoco's 256
        assert base.env.rand.geometry.pool_size == 256  # and only where geometry is on: ppo's config is as before
        assert cfg.env.rand.geometry == type(base.env.rand.geometry)(enabled=True, pool_size=pool)
    off = apply_overrides(preset_cfg("smoke", "genloco"), ["env.rand.geometry.enabled=false"])
    assert not off.env.rand.geometry.enabled


def test_train_genloco_smoke_and_evaluate_it_on_one_robot(run_cli):
    code, out, err = run_cli("train", "--variant", "genloco", "--preset", "smoke", "--format", "json", "--quiet")
    assert code == 0, err
    assert json.loads(out)["ref"] == "runs/genloco-smoke-s0@1"
    store = Store(os.environ["MORFIC_STORE"])
    config = store.read_manifest("runs/genloco-smoke-s0").config
    assert config["variant"] == "genloco" and config["env"]["rand"]["geometry"]["enabled"] is True
    code, out, err = run_cli(
        "eval",
        "runs/genloco-smoke-s0",
        "--robots",
        "go1",
        "--envs",
        "2",
        "--steps",
        "20",
        "--mode",
        "both",
        "--format",
        "json",
        "--quiet",
    )
    assert code == 0, err
    rows = json.loads(out)
    assert sorted((r["robot"], r["mode"]) for r in rows) == [("go1", "descriptor"), ("go1", "full")]
    assert all(r["num_envs"] == 2 and r["steps"] == 20 and 0.0 <= r["survival"] <= 1.0 for r in rows)


def test_a_run_recorded_before_procedural_geometry_is_the_same_experiment(tmp_path):
    from types import SimpleNamespace

    from morfic_cli.errors import MorficError
    from morfic_cli.pipeline import Pipeline, ReproduceCfg
    from morfic_cli.rl.config import train_cfg_to_dict

    def manifest(variant):  # a manifest written before env.rand.geometry existed
        doc = train_cfg_to_dict(preset_cfg("smoke", variant))
        del doc["env"]["rand"]["geometry"]
        return SimpleNamespace(config=doc, meta={"finished": True, "iteration": 2}, id="abc")

    store = SimpleNamespace(
        root=tmp_path, has_ref=lambda spec: True, read_manifest=lambda spec: manifest(spec.split("/")[1].split("-")[0])
    )
    pipeline = Pipeline(store, ReproduceCfg(preset="smoke", variants=("film", "genloco")))
    assert pipeline.stored_train("film", 0, "runs/film-smoke-s0").status == "skipped"
    with pytest.raises(MorficError, match="another config"):  # it reads as geometry off: not genloco's experiment
        pipeline.stored_train("genloco", 0, "runs/genloco-smoke-s0")
