"""Small batched quaternion helpers (w, x, y, z convention, MuJoCo's)."""

from __future__ import annotations

import torch

from morfic_cli.quaternion_torch import quat_rotate_inverse


def quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate body vectors into the world frame: R(q) v. Shapes: (N, 4), (N, 3) -> (N, 3)."""
    w, xyz = q[:, :1], q[:, 1:]
    t = 2.0 * torch.cross(xyz, v, dim=1)
    return v + w * t + torch.cross(xyz, t, dim=1)


def yaw_from_quat(q: torch.Tensor) -> torch.Tensor:
    """Heading (yaw) angle of each quaternion (rad). Shape: (N, 4) -> (N,)."""
    w, x, y, z = q.unbind(dim=1)
    return torch.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_quat(yaw: torch.Tensor) -> torch.Tensor:
    """Quaternion of a pure rotation about world z. Shape: (N,) -> (N, 4)."""
    half = 0.5 * yaw
    zeros = torch.zeros_like(yaw)
    return torch.stack([torch.cos(half), zeros, zeros, torch.sin(half)], dim=1)


def projected_gravity(q: torch.Tensor) -> torch.Tensor:
    """g_proj: the unit gravity direction (0, 0, -1) in the base frame. Shape: (N, 4) -> (N, 3)."""
    g = torch.zeros((q.shape[0], 3), dtype=q.dtype, device=q.device)
    g[:, 2] = -1.0
    return quat_rotate_inverse(q, g)
