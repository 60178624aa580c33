"""Batched numpy quaternion helpers, (w, x, y, z) as MuJoCo's: the one numpy copy for morfic's modules.

MuJoCo's ``mju_rotVecQuat`` / ``mju_mulQuat`` / ``mju_negQuat`` do the same for one quaternion at a time; these take
any leading shape, for arrays of envs and bodies. The batched torch versions for the env are in
:mod:`morfic_cli.quaternion_torch`; both compute R(q)^T v as v - 2 w (u x v) + 2 u x (u x v), u = (x, y, z).
"""

from __future__ import annotations

import numpy as np


def quat_rotate_inverse(quat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """Rotate world vectors into the frame of unit quaternions: R(q)^T v.

    Args:
        quat: Unit quaternions (w, x, y, z). Shape: (..., 4).
        vec: Vectors in the world frame. Shape: (..., 3).

    Returns:
        The vectors in the quaternions' frames. Shape: (..., 3).
    """
    w, u = quat[..., :1], quat[..., 1:]
    uv = np.cross(u, vec)
    return vec - 2.0 * w * uv + 2.0 * np.cross(u, uv)


def quat_conj_mul(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """conj(qa) * qb, the rotation of ``qb`` in the frame of ``qa``.

    Args:
        qa: Quaternions (w, x, y, z). Shape: (..., 4).
        qb: Quaternions (w, x, y, z). Shape: (..., 4).

    Returns:
        Shape: (..., 4).
    """
    aw, ax, ay, az = qa[..., 0], -qa[..., 1], -qa[..., 2], -qa[..., 3]
    bw, bx, by, bz = qb[..., 0], qb[..., 1], qb[..., 2], qb[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )
