"""Model building: the rsl-rl runner config of a TrainCfg and a fresh actor-critic pair, without an env.

Shapes: :func:`dummy_observations` gives each observation group as the env does, batch (B,) first.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
from typing import Any

import torch
from tensordict import TensorDict

from morfic_cli.envs import observations as O
from morfic_cli.errors import MorficError
from morfic_cli.morphology.descriptor import DIM as DESCRIPTOR_DIM
from morfic_cli.morphology.extended import EXTENDED_DIM
from morfic_cli.rl.config import TrainCfg
from morfic_cli.rl.models import link_morphology_encoder
from morfic_cli.rl.ppo import ALGORITHM_CLASS
from morfic_cli.rl.variants import resolve_variant
from morfic_cli.sim.args import NUM_JOINTS


def rsl_rl_cfg(cfg: TrainCfg) -> dict[str, Any]:
    """The rsl-rl runner config (``obs_groups``, ``algorithm``, ``actor``, ``critic``, ...) of a TrainCfg.

    Raises:
        MorficError: A user variant whose module cannot be imported (:func:`~morfic_cli.rl.variants.resolve_variant`),
            or a variant that reads observation groups the env config does not give.
    """
    variant = resolve_variant(cfg.variant)
    actor, critic, obs_groups = variant.model_cfgs()
    given = dummy_observations(cfg).keys()
    missing = [g for groups in obs_groups.values() for g in groups if g not in given]
    if missing:  # e.g. urma with --set env.obs.body_tokens=false
        raise MorficError(
            f"variant {cfg.variant} reads the observation groups {', '.join(dict.fromkeys(missing))}, "
            "which this env config does not give; keep the variant's env settings (for urma "
            "env.obs.body_tokens=true)."
        )
    if "distribution_cfg" in actor:
        actor["distribution_cfg"]["init_std"] = cfg.model.init_std
    if not variant.own_models:  # the external baselines keep their own sizes (model.*_hidden_dims are the MLPs')
        actor["hidden_dims"] = list(cfg.model.actor_hidden_dims)
        if cfg.model.critic_hidden_dims is not None:
            critic["hidden_dims"] = list(cfg.model.critic_hidden_dims)
    if variant.stock and not variant.own_models:  # a user's class takes the config its critic_defaults give
        if critic["conditioning"] == "film":
            critic["conditioning_scale"] = cfg.model.film_scale
        if critic["conditioning"] == "hyper" and cfg.model.hyper_conditions == "head":
            critic["conditioning"] = "hyper_head"
        if cfg.model.shared_morphology_encoder and variant.actor_morphology and variant.critic_morphology:
            critic["shared_morphology_encoder"] = True
    algorithm = {
        "class_name": ALGORITHM_CLASS,
        "optimizer": "adam",
        **dataclasses.asdict(cfg.ppo),
        "rnd_cfg": None,
        "symmetry_cfg": None,
    }
    return {
        "obs_groups": obs_groups,
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": cfg.save_interval,
        "check_for_nan": True,
        "algorithm": algorithm,
        "actor": actor,
        "critic": critic,
        "logger": "tensorboard",
    }


def dummy_observations(cfg: TrainCfg, batch: int = 1) -> TensorDict:
    """Zero observations with the env's group shapes, to build models without an env. Batch shape: (batch,)."""
    h = O.history_frames(cfg.env.obs)
    return TensorDict(
        {
            "policy": torch.zeros(batch, O.POLICY_DIM),
            "history": torch.zeros(batch, h, O.POLICY_DIM),
            "critic": torch.zeros(batch, h, O.POLICY_DIM),
            "privileged": torch.zeros(batch, O.PRIVILEGED_DIM),
            "morphology": torch.zeros(batch, EXTENDED_DIM if cfg.env.obs.extended_morphology else DESCRIPTOR_DIM),
            **(
                {
                    "joint_description": torch.zeros(batch, NUM_JOINTS, O.JOINT_DESCRIPTION_DIM),
                    "foot_description": torch.zeros(batch, 4, O.FOOT_DESCRIPTION_DIM),
                    "foot_state": torch.zeros(batch, 4, O.FOOT_STATE_DIM),
                }
                if cfg.env.obs.body_tokens
                else {}
            ),
        },
        batch_size=[batch],
    )


def build_models(cfg: TrainCfg) -> tuple[torch.nn.Module, torch.nn.Module]:
    """A fresh (actor, critic) pair of a config, on CPU, without an env."""
    from rsl_rl.utils import resolve_class
    from rsl_rl.utils.utils import resolve_obs_groups

    rcfg = rsl_rl_cfg(cfg)
    obs = dummy_observations(cfg)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the resolved groups on stdout
        groups = resolve_obs_groups(obs, rcfg["obs_groups"], ["actor", "critic"])
    actor_class, actor_kwargs = resolve_class(rcfg["actor"])
    critic_class, critic_kwargs = resolve_class(rcfg["critic"])
    actor = actor_class(obs, groups, "actor", NUM_JOINTS, **actor_kwargs)
    critic = critic_class(obs, groups, "critic", 1, **critic_kwargs)
    link_morphology_encoder(actor, critic)
    return actor, critic


def variant_record(cfg: TrainCfg) -> dict[str, Any]:
    """What a checkpoint's meta records of its variant: the actor and critic configs it was built from.

    The variant itself (a stock name or a user's import path) is ``meta.variant``; ``model`` keeps the classes
    and their config as rsl-rl received them, so a reader can see what a user variant's class was given.
    """
    rcfg = rsl_rl_cfg(cfg)
    return {"model": {"actor": rcfg["actor"], "critic": rcfg["critic"], "obs_groups": rcfg["obs_groups"]}}
