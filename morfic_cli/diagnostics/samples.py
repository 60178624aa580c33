"""Diagnostic rollouts: collect once with a run's actor, store (MCAP + the models' inputs), reuse by id.

A diagnostic rollout is :func:`~morfic_cli.evaluation.rollout.run_rollout` in the evaluation env (no randomisation,
pushes or sensor noise; command (vx, 0, 0); no time-out inside the rollout) with two differences from ``morfic eval``:

- actions are *sampled* from the actor's Gaussian (seeded), as PPO's behaviour policy acts: the policy gradient of
  CosGrad is an expectation over sampled actions (at the mean action, grad log pi vanishes for the mean network);
- the observation groups the models saw are kept per step (:data:`OBS_GROUPS`), so that any critic (its own
  history, privileged and morphology inputs, exactly as in training) and the actor can be scored on these samples.

Store layout: one ``rollout`` manifest per (checkpoint, robot, mode, command, envs, steps, seed, batch), config
:func:`rollout_config`, input ``checkpoint``, files ``rollout.mcap`` (the log of docs/mcap.md, with the sampled
actions, rewards, the collecting critic's values, done and time-out flags) and ``obs.npz`` (the observation groups,
see :func:`encode_obs`). Asking again for the same inputs finds that manifest (:func:`find_rollout`) and reads it
back instead of stepping the simulator.
"""

from __future__ import annotations

import dataclasses
import io
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from morfic_cli import __version__
from morfic_cli.store import Store

if TYPE_CHECKING:
    from morfic_cli.evaluation.rollout import Rollout
    from morfic_cli.rl.load import TrainedModels

OBS_GROUPS: tuple[str, ...] = ("history", "critic", "privileged", "morphology")
"""Observation groups a diagnostic rollout keeps: the actor's (history, morphology) and every critic's (critic =
clean history, privileged, morphology); :func:`kept_groups` adds URMA's token groups where the env gives them."""


def kept_groups(env_cfg: Any) -> tuple[str, ...]:
    """The groups a rollout in this env config keeps.

    :data:`OBS_GROUPS`, plus URMA's token groups (:data:`~morfic_cli.envs.observations.BODY_TOKEN_GROUPS`) when
    ``env_cfg.obs.body_tokens``.
    """
    from morfic_cli.envs.observations import BODY_TOKEN_GROUPS

    return OBS_GROUPS + (BODY_TOKEN_GROUPS if env_cfg.obs.body_tokens else ())


ROLLOUT_PURPOSE = "diagnose"
"""Value of ``config["purpose"]`` of diagnostic rollout manifests (eval rollouts have none)."""


@dataclass(frozen=True)
class DiagnoseCfg:
    """What ``morfic diagnose`` collects and which samples count (defaults: docs/metrics.md)."""

    robots: tuple[str, ...] = ("go2",)
    """Target robots."""
    mode: str = "descriptor"
    """descriptor (Go2 template with the target's descriptor) or full (the target's own model)."""
    command_vx: float = 2.0
    """Forward command (m/s), the evaluation protocol's."""
    num_envs: int = 64
    """Envs per rollout (N)."""
    steps: int = 800
    """Policy steps per rollout (T, 50 per second); must exceed H_eps (299 at gamma 0.99, eps 0.05)."""
    seed: int = 0
    """Env seed (reset poses) and action-sampling seed."""
    trunc_eps: float = 0.05
    """eps of I_eps: a truncated return may miss at most this fraction of the return scale."""
    sigma_eps: float = 1e-8
    """eps of sigma_G + eps in NVB and NVE."""
    batch: tuple[str, ...] = ()
    """Robots whose descriptor-mode rollouts are stepped together, as one env of ``len(batch) * num_envs`` envs,
    each robot its slice (:func:`~morfic_cli.evaluation.rollout.run_rollouts`); empty: each robot alone. Same
    per-robot protocol, other random start states and action noise, about half the CPU time for 7 robots. The rollout
    manifests record it (``config["batch"]``), so a batched and an unbatched rollout are distinct artifacts."""


def diagnose_config(cfg: DiagnoseCfg) -> dict[str, Any]:
    """``cfg`` as a manifest config.

    ``batch`` is in it only when set, so an unbatched diagnosis keeps the config (and so the content address) it
    always had.
    """
    config = dataclasses.asdict(cfg)
    if not cfg.batch:
        config.pop("batch")
    return config


def batched(robot: str, cfg: DiagnoseCfg) -> bool:
    """Whether ``robot``'s rollout under ``cfg`` is its slice of a joint one (:attr:`DiagnoseCfg.batch`)."""
    return cfg.mode == "descriptor" and len(cfg.batch) > 1 and robot in cfg.batch


@dataclass
class Samples:
    """A diagnostic rollout of T steps x N envs, as the models saw it.

    Attributes:
        robot: Target robot.
        mode: descriptor or full.
        obs: Group -> (T, N, ...) float32; row t is s_t (e.g. ``critic`` (T, N, 15, 48)).
        action: The sampled actions a_t. Shape: (T, N, 12).
        reward: r_t (dt-scaled, as the env returns it). Shape: (T, N).
        value: V(s_t) of the collecting run's critic. Shape: (T, N).
        done: Shape: (T, N) bool.
        time_out: Shape: (T, N) bool.
        rollout_id: The rollout manifest.
        reused: Read back from the store instead of collected now.
    """

    robot: str
    mode: str
    obs: dict[str, np.ndarray]
    action: np.ndarray
    reward: np.ndarray
    value: np.ndarray
    done: np.ndarray
    time_out: np.ndarray
    rollout_id: str
    reused: bool


def rollout_config(robot: str, cfg: DiagnoseCfg, obs_groups: tuple[str, ...] = OBS_GROUPS) -> dict[str, Any]:
    """The config of a diagnostic rollout manifest: everything that changes the samples.

    ``obs_groups``: the groups it keeps (:func:`kept_groups`).
    """
    return {
        "purpose": ROLLOUT_PURPOSE,
        "robot": robot,
        "mode": cfg.mode,
        "command_vx": float(cfg.command_vx),
        "num_envs": cfg.num_envs,
        "steps": cfg.steps,
        "seed": cfg.seed,
        "actions": "sample",
        "obs_groups": list(obs_groups),
        **({"batch": list(cfg.batch)} if batched(robot, cfg) else {}),
    }


def encode_obs(obs: dict[str, np.ndarray]) -> bytes:
    """The observation groups as a compressed ``.npz`` (numpy's zip of ``.npy`` files).

    Each group is stored env-major, (N, T, ...), where consecutive histories of one env (shifted copies of each
    other) sit next to each other and compress well. A group equal to an earlier one (``history`` and ``critic``
    in the noise-free evaluation env) is stored once and named in the JSON entry ``__aliases__``.
    """
    arrays: dict[str, np.ndarray] = {}
    aliases: dict[str, str] = {}
    for name, a in obs.items():
        same = next((k for k in arrays if obs[k].shape == a.shape and np.array_equal(obs[k], a)), None)
        if same is not None:
            aliases[name] = same
        else:
            arrays[name] = np.ascontiguousarray(np.swapaxes(a, 0, 1))
    buf = io.BytesIO()
    # numpy's stub lets **kwds fill the keyword allow_pickle, so it refuses a dict of arrays here
    np.savez_compressed(buf, __aliases__=np.array(json.dumps(aliases)), **arrays)  # type: ignore[arg-type]
    return buf.getvalue()


def decode_obs(data: bytes) -> dict[str, np.ndarray]:
    """Inverse of :func:`encode_obs`: group -> (T, N, ...) float32."""
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        aliases = json.loads(str(npz["__aliases__"]))
        out = {k: np.swapaxes(npz[k], 0, 1) for k in npz.files if k != "__aliases__"}
    out.update({name: out[target] for name, target in aliases.items()})
    return out


def find_rollout(store: Store, checkpoint_id: str, config: dict[str, Any]) -> str | None:
    """The newest stored rollout manifest with exactly this config and checkpoint, else None.

    A manifest whose rollout log a results-only bundle left out (``store.omitted_files``) does not count: its
    samples cannot be read, so the rollout is collected again.
    """
    found = None
    for row in store.ls("rollout"):  # oldest first
        manifest = store.read_manifest(row["id"])
        if (
            manifest.config == config
            and manifest.inputs == {"checkpoint": checkpoint_id}
            and {"rollout.mcap", "obs.npz"} <= set(manifest.files)
            and not store.omitted_files(manifest)
        ):
            found = manifest.id
    return found


def load_samples(store: Store, rollout_id: str) -> Samples:
    """Read a stored diagnostic rollout back (MCAP log + observation groups)."""
    from morfic_cli.recording.rollout_log import read_rollout

    manifest = store.read_manifest(rollout_id)
    log = read_rollout(store.file_path(manifest.id, "rollout.mcap"))
    a = log.arrays
    obs = decode_obs(store.read_file(manifest.id, "obs.npz"))
    return Samples(
        manifest.config["robot"],
        manifest.config["mode"],
        obs,
        a["action"],
        a["reward"],
        a["value"],
        a["done"],
        a["time_out"],
        manifest.id,
        True,
    )


def collect_samples(
    store: Store,
    trained: TrainedModels,
    robot: str,
    cfg: DiagnoseCfg,
    *,
    on_step: Callable[[int], None] | None = None,
) -> Samples:
    """The diagnostic rollout of ``trained``'s actor on ``robot``: reused from the store if there, else collected.

    A robot of ``cfg.batch`` not in the store is collected with the whole batch (:func:`collect_batch`; every
    robot's slice is stored).

    Args:
        store: Artifact store (a new rollout manifest is written there).
        trained: The checkpoint whose actor acts (:func:`~morfic_cli.rl.load.load_trained`).
        robot: Target robot.
        cfg: Rollout settings (mode, command, envs, steps, seed, batch).
        on_step: Progress callback per policy step (called ``steps`` times at once for a reused rollout).
    """
    config = rollout_config(robot, cfg, kept_groups(trained.cfg.env))
    existing = find_rollout(store, trained.checkpoint_id, config)
    if existing is not None:
        _reused(cfg, on_step)
        return load_samples(store, existing)
    if batched(robot, cfg):
        return collect_batch(store, trained, cfg, on_step=on_step)[robot]
    rollout = _diagnostic_rollouts(trained, cfg, (robot,), on_step)[robot]
    return _store_samples(store, trained, rollout, config, cfg)


def _reused(cfg: DiagnoseCfg, on_step: Callable[[int], None] | None) -> None:
    """Report a reused rollout's progress as complete at once (``cfg.steps`` calls)."""
    if on_step is not None:
        for t in range(cfg.steps):
            on_step(t)


def _diagnostic_rollouts(
    trained: TrainedModels, cfg: DiagnoseCfg, robots: tuple[str, ...], on_step: Callable[[int], None] | None
) -> dict:
    """Robot -> its rollout: the actor's sampled actions, the critic's inputs recorded, ``robots`` as one env."""
    from morfic_cli.evaluation.rollout import run_rollouts

    return run_rollouts(
        trained.actor,
        trained.critic,
        trained.cfg.env,
        robots=robots,
        mode=cfg.mode,
        command_vx=cfg.command_vx,
        num_envs=cfg.num_envs,
        steps=cfg.steps,
        seed=cfg.seed,
        on_step=on_step,
        keep_obs=kept_groups(trained.cfg.env),
        sample_actions=True,
    )


def collect_batch(
    store: Store,
    trained: TrainedModels,
    cfg: DiagnoseCfg,
    *,
    on_step: Callable[[int], None] | None = None,
) -> dict[str, Samples]:
    """The diagnostic rollouts of every robot of ``cfg.batch`` (descriptor mode), stepped as one env.

    When the store holds every robot's slice they are read back; otherwise the joint rollout runs once and each
    robot missing from the store gets its rollout manifest (the stored ones are read back).

    Args:
        store: Artifact store (the new rollout manifests are written there).
        trained: The checkpoint whose actor acts.
        cfg: Rollout settings; ``cfg.batch`` names the robots.
        on_step: Progress per joint policy step (``cfg.steps`` calls).

    Returns:
        Robot -> its samples, in the order of ``cfg.batch``.
    """
    configs = {robot: rollout_config(robot, cfg, kept_groups(trained.cfg.env)) for robot in cfg.batch}
    found = {robot: find_rollout(store, trained.checkpoint_id, c) for robot, c in configs.items()}
    if all(found.values()):
        _reused(cfg, on_step)
        return {robot: load_samples(store, rid) for robot, rid in found.items() if rid}
    rollouts = _diagnostic_rollouts(trained, cfg, tuple(cfg.batch), on_step)
    return {
        robot: load_samples(store, rid)
        if (rid := found[robot])
        else _store_samples(store, trained, rollouts.pop(robot), configs[robot], cfg)
        for robot in cfg.batch
    }


def _store_samples(
    store: Store, trained: TrainedModels, rollout: Rollout, config: dict[str, Any], cfg: DiagnoseCfg
) -> Samples:
    """Store a collected diagnostic rollout (MCAP log + observation groups) as a ``rollout`` manifest."""
    from morfic_cli.evaluation.protocol import write_rollout_log

    meta = {
        "run": trained.meta.get("run"),
        "checkpoint": trained.checkpoint_id,
        "robot": rollout.robot,
        "descriptor": [float(x) for x in rollout.descriptor],
        "mode": cfg.mode,
        "command": [float(cfg.command_vx), 0.0, 0.0],
        "seed": cfg.seed,
        "morfic_version": __version__,
        "actions": "sampled from the actor's Gaussian",
        "term_names": rollout.term_names,
    }
    with tempfile.TemporaryDirectory(prefix="morfic-diagnose-") as tmp:
        path = Path(tmp) / "rollout.mcap"
        write_rollout_log(path, rollout, {k: v for k, v in meta.items() if v is not None})
        rid = store.put_manifest(
            "rollout",
            config=config,
            inputs={"checkpoint": trained.checkpoint_id},
            files={"rollout.mcap": path, "obs.npz": encode_obs(rollout.obs)},
            meta={k: v for k, v in meta.items() if k != "term_names"},
        )
    a = rollout.arrays
    return Samples(
        rollout.robot, cfg.mode, rollout.obs, a["action"], a["reward"], a["value"], a["done"], a["time_out"], rid, False
    )
