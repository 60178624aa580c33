"""The batched numpy quaternion helpers agree with MuJoCo's one-at-a-time mju_* functions."""

from __future__ import annotations

import mujoco
import numpy as np

from morfic_cli.quaternion import quat_conj_mul, quat_rotate_inverse


def test_batched_helpers_match_mujoco():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(5, 3, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    qb = rng.normal(size=(5, 3, 4))
    qb /= np.linalg.norm(qb, axis=-1, keepdims=True)
    v = rng.normal(size=(5, 3, 3))
    rot, mul = quat_rotate_inverse(q, v), quat_conj_mul(q, qb)
    assert rot.shape == (5, 3, 3) and mul.shape == (5, 3, 4)
    for i in np.ndindex(5, 3):
        neg, want_v, want_q = np.zeros(4), np.zeros(3), np.zeros(4)
        mujoco.mju_negQuat(neg, q[i])
        mujoco.mju_rotVecQuat(want_v, v[i], neg)
        mujoco.mju_mulQuat(want_q, neg, qb[i])
        np.testing.assert_allclose(rot[i], want_v, atol=1e-12)
        np.testing.assert_allclose(mul[i], want_q, atol=1e-12)
