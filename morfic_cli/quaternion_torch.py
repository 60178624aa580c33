"""Batched torch quaternion rotation, (w, x, y, z) as MuJoCo's: the one torch copy, shared by sim/ and envs/.

The numpy versions are in :mod:`morfic_cli.quaternion`; both compute R(q)^T v as v - 2 w (u x v) + 2 u x (u x v),
u = (x, y, z). The env's other torch helpers (yaw, projected gravity) are in :mod:`morfic_cli.envs.math`.
"""

from __future__ import annotations

import torch


def quat_rotate_inverse(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors into the frame of ``q``: R(q)^T v.

    Args:
        q: Unit quaternions (w, x, y, z). Shape: (N, 4).
        v: Vectors in the world frame. Shape: (N, 3).

    Returns:
        The vectors in the body frame. Shape: (N, 3).
    """
    w, xyz = q[:, :1], q[:, 1:]
    t = 2.0 * torch.cross(xyz, v, dim=1)
    return v - w * t + torch.cross(xyz, t, dim=1)
