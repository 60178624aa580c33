"""A checkpoint as rsl-rl writes one: ``morfic export RUN --to rsl-rl --out DIR`` (docs/deploy.md).

rsl-rl's ``OnPolicyRunner.load(path)`` (rsl-rl-lib 5.5.1) reads a ``torch.save`` dict with
``actor_state_dict``, ``critic_state_dict``, ``optimizer_state_dict``, ``iter`` and ``infos``, and hands it to
the algorithm's ``load``. morfic's store keeps ``model.pt`` as ``{"actor": ..., "critic": ...}`` and the
optimiser in the trainer state (:mod:`morfic_cli.rl.trainer_state`), so this module joins them into rsl-rl's
layout. The files of the export:

- ``model_<iteration>.pt``: rsl-rl's checkpoint dict (plus, from a trainer state, ``adaptation_optimizer_state_dict``,
  which :class:`~morfic_cli.rl.ppo.MorficPPO` loads). A checkpoint without a trainer state (a weights-only policy
  bundle, old or made by ``store export --without-trainer-state``) gets the state of a fresh, never-stepped
  optimiser of the config's type and learning rate, no ``adaptation_optimizer_state_dict``, and
  ``infos["optimizer"] == "fresh"``; otherwise ``"trained"``.
- ``agent.json``: the runner config ``OnPolicyRunner(env, train_cfg)`` takes (:func:`~morfic_cli.rl.build.rsl_rl_cfg`);
  its ``class_name`` entries name morfic's classes, so morfic must be installed to load it.
- ``train.json``: morfic's full :class:`~morfic_cli.rl.config.TrainCfg` (env config included), to rebuild the env.
"""

from __future__ import annotations

import io
import json
from itertools import chain
from typing import Any

import torch

from morfic_cli.rl import trainer_state
from morfic_cli.rl.build import rsl_rl_cfg
from morfic_cli.rl.config import train_cfg_to_dict
from morfic_cli.rl.load import TrainedModels
from morfic_cli.store import Store
from morfic_cli.store.shallow import TRAINER_STATE_ROLE

AGENT_FILE = "agent.json"
TRAIN_FILE = "train.json"


def model_file(iteration: int) -> str:
    """rsl-rl's checkpoint file name, ``model_<iteration>.pt``."""
    return f"model_{iteration}.pt"


def _trained_optimizer(store: Store, checkpoint_id: str) -> dict[str, Any] | None:
    """The ``alg`` part of the checkpoint's trainer state (optimiser states), or None when it has none."""
    manifest = store.read_manifest(checkpoint_id)
    state_id = manifest.inputs.get(TRAINER_STATE_ROLE)
    if state_id is None or store.is_omitted(state_id):  # an older policy bundle, or a weights-only one
        return None
    state = trainer_state.decode(
        store.read_file(state_id, trainer_state.JSON_FILE),
        store.read_file(state_id, trainer_state.TENSORS_FILE),
        f"checkpoint {checkpoint_id[:12]}",
    )
    alg = state.get("alg") if isinstance(state, dict) else None
    return alg if isinstance(alg, dict) and "optimizer_state_dict" in alg else None


def _fresh_optimizer(trained: TrainedModels, agent: dict[str, Any]) -> dict[str, Any]:
    """The state dict of the optimiser rsl-rl's PPO builds (over actor then critic parameters), never stepped."""
    from rsl_rl.utils import resolve_optimizer

    optimizer = resolve_optimizer(agent["algorithm"].get("optimizer", "adam"))(
        chain(trained.actor.parameters(), trained.critic.parameters()), lr=agent["algorithm"]["learning_rate"]
    )
    return optimizer.state_dict()


def rsl_rl_checkpoint(store: Store, trained: TrainedModels) -> dict[str, Any]:
    """The dict ``OnPolicyRunner.load`` expects for a loaded checkpoint (see the module docstring)."""
    agent = rsl_rl_cfg(trained.cfg)
    saved = _trained_optimizer(store, trained.checkpoint_id)
    iteration = int(trained.meta.get("iteration") or 0)
    out: dict[str, Any] = {
        "actor_state_dict": trained.actor.state_dict(),
        "critic_state_dict": trained.critic.state_dict(),
    }
    if saved is not None:
        out.update({k: v for k, v in saved.items() if k.endswith("optimizer_state_dict")})
    else:
        out["optimizer_state_dict"] = _fresh_optimizer(trained, agent)
    out["iter"] = iteration
    out["infos"] = {
        "morfic_checkpoint": trained.checkpoint_id,
        "run": trained.meta.get("run"),
        "variant": trained.cfg.variant,
        "optimizer": "trained" if saved is not None else "fresh",
    }
    return out


def rsl_rl_files(store: Store, trained: TrainedModels) -> tuple[dict[str, bytes], dict[str, Any]]:
    """``({model_<it>.pt, agent.json, train.json} -> bytes, the checkpoint's infos)``: the export's files."""
    ckpt = rsl_rl_checkpoint(store, trained)
    buf = io.BytesIO()
    torch.save(ckpt, buf)
    agent = rsl_rl_cfg(trained.cfg)
    return {
        model_file(ckpt["iter"]): buf.getvalue(),
        AGENT_FILE: (json.dumps(agent, indent=2, sort_keys=True) + "\n").encode(),
        TRAIN_FILE: (json.dumps(train_cfg_to_dict(trained.cfg), indent=2, sort_keys=True) + "\n").encode(),
    }, ckpt["infos"]
