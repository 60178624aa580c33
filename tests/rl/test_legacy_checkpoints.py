"""Checkpoints written before issue 16's fields: the shipped bundle loads and evaluates as it was trained."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys

import pytest
import torch
from smoke_runs import LEGACY_BUNDLE

from morfic_cli import __version__
from morfic_cli.envs import observations as O
from morfic_cli.errors import MorficError
from morfic_cli.rl.config import preset_cfg, train_cfg_to_dict
from morfic_cli.rl.load import load_trained
from morfic_cli.store import Store
from morfic_cli.store.transfer import import_tar

BUNDLE = LEGACY_BUNDLE


@pytest.fixture
def bundle_store(tmp_path) -> Store:
    store = Store(tmp_path / "bundle-store")
    import_tar(store, BUNDLE)
    return store


def test_the_shipped_bundle_loads_with_the_method_it_was_trained_with(bundle_store, one_torch_thread):
    models = load_trained(bundle_store, "runs/film-cpu")  # strict state_dict load
    cfg = models.cfg
    assert cfg.model.film_scale == 1.0 and not cfg.model.shared_morphology_encoder
    assert cfg.env.obs.history_includes_current and O.history_frames(cfg.env.obs) == 15
    assert cfg.env.rand.rerandomize_interval_s == 0.0
    assert cfg.env.rewards.w_gaitF == 2.0 and cfg.env.rewards.w_raibert == 5.0  # recorded, so kept
    assert [m.scale for m in models.critic.modulators] == [1.0, 1.0, 1.0]
    assert models.critic.morphology_encoder is not None  # its own encoder, as trained
    assert models.actor.obs_dim == 15 * 48


def test_weights_that_do_not_fit_name_the_version_that_wrote_them(tmp_path):
    store = Store(tmp_path / "s")
    buf = io.BytesIO()
    torch.save({"actor": {"mlp.0.weight": torch.zeros(1)}, "critic": {}}, buf)
    with store.writing():
        ckpt = store.put_manifest(
            "checkpoint",
            config=train_cfg_to_dict(preset_cfg("smoke", "film")),
            meta={},
            files={"model.pt": buf.getvalue()},
        )
    with pytest.raises(MorficError, match=f"written by morfic {__version__}"):
        load_trained(store, ckpt)


@pytest.mark.slow
def test_the_shipped_bundle_evaluates_as_before(tmp_path):
    """`morfic eval runs/film-cpu --robots go2 --command-vx 1.0 --envs 16 --steps 250`: vx 0.936, S 1.0 (the
    numbers docs/results.md gives for it, unchanged by the new defaults)."""
    env = dict(os.environ, MORFIC_STORE=str(tmp_path / "store"), OMP_NUM_THREADS="1")
    morfic = [sys.executable, "-m", "morfic_cli"]
    subprocess.run([*morfic, "store", "import", str(BUNDLE)], env=env, check=True, capture_output=True)
    out = subprocess.run(
        [
            *morfic,
            "eval",
            "runs/film-cpu",
            "--robots",
            "go2",
            "--command-vx",
            "1.0",
            "--envs",
            "16",
            "--steps",
            "250",
            "--format",
            "json",
        ],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    row = json.loads(out.stdout)[0]
    assert row["vx_mean"] == pytest.approx(0.9356, abs=5e-4)
    assert row["survival"] == 1.0
