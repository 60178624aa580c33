"""Argument checks shared by the simulation backends (ids, per-env rows, randomised dynamics).

These guard the backend API against morfic's own callers: a failure is a bug, so it is a ``ValueError`` with its
traceback, not a user error (what a user gives is checked before, in the CLI and the configs).
"""

from __future__ import annotations

import numpy as np
import torch

from morfic_cli.morphology.robots import JOINTS, LEGS

NUM_JOINTS = len(LEGS) * len(JOINTS)
"""Actuated joints of every robot (4 legs x hip, thigh, calf)."""


def as_numpy(value: torch.Tensor | np.ndarray | float) -> np.ndarray:
    """A tensor (any device) or array-like as a numpy array."""
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().numpy()
    return np.asarray(value)


def env_index(env_ids: torch.Tensor | np.ndarray, num_envs: int) -> np.ndarray:
    """Env ids as a flat int64 array. Raises ValueError outside [0, num_envs). Shape: (k,)."""
    ids = as_numpy(env_ids).astype(np.int64).reshape(-1)
    if ids.size and (ids.min() < 0 or ids.max() >= num_envs):
        raise ValueError(f"env ids must be in [0, {num_envs}), got {ids.min()}..{ids.max()}.")
    return ids


def env_rows(value: torch.Tensor | np.ndarray, k: int, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as float64 rows of shape (k, *shape); ValueError naming ``what`` otherwise."""
    arr = as_numpy(value).astype(np.float64)
    if arr.shape != (k, *shape):
        raise ValueError(f"{what}: expected shape {(k, *shape)}, got {tuple(arr.shape)}.")
    return arr


def dynamics_rows(k: int, friction, restitution, com_offset, joint_friction) -> tuple[np.ndarray, ...]:
    """The checked arguments of ``set_dynamics`` for k envs: (mu (k,), e (k,), com (k, 3), joint friction (k, 12)).

    Raises:
        ValueError: wrong shapes, negative friction, restitution outside [0, 1) or a non-finite COM offset.
    """
    mu = env_rows(friction, k, (), "friction")
    e = env_rows(restitution, k, (), "restitution")
    com = env_rows(com_offset, k, (3,), "com_offset")
    jf = env_rows(joint_friction, k, (NUM_JOINTS,), "joint_friction")
    if np.any(~np.isfinite(mu) | (mu < 0)) or np.any(~np.isfinite(jf) | (jf < 0)):
        raise ValueError("friction and joint_friction must be finite and >= 0.")
    if np.any(~np.isfinite(e) | (e < 0) | (e >= 1)) or not np.all(np.isfinite(com)):
        raise ValueError("restitution must be in [0, 1) and com_offset finite.")
    return mu, e, com, jf
