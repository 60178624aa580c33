"""The warp backend (MuJoCo Warp) on warp's CPU device: parity with the CPU backend, per-world model fields.

Everything here runs without a GPU. ``MORFIC_WARP_TEST_DEVICE=cuda`` runs the same tests with the warp
backend on the GPU (``scripts/gpu_check.sh`` does; docs/gpu.md); the CPU backend is the reference either way.
The module is skipped, with the reason, where mujoco_warp is not
installed (``pip install 'morfic[gpu]'``). The first test in a fresh warp kernel cache compiles
MuJoCo Warp's kernels for the CPU (about 40 s on a 2-core machine; cached in ~/.cache/warp).

Parity (docs/gpu.md), the same model, state and joint targets on both backends:

* :data:`STEP_TOL`, one policy step (4 physics steps) from the *same* state, re-synchronised from
  the CPU backend before every step, along a 50-step gait-like trajectory: the dynamics agree at
  every state visited. Measured worst cases over the seven robots are 5-10x below these bounds.
* :data:`RUN_TOL`, free-running for 25 policy steps (0.5 s) of a slow sway. MuJoCo Warp computes in
  float32 (the CPU backend in float64), so free runs drift apart, and a foot that touches down
  within float32 rounding of the floor makes or misses its contact in one backend only: over long
  runs with chattering contacts the two trajectories then part for good (chaos, not a model
  difference). The sway keeps the contact set steady so the drift itself is measured.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp", reason="mujoco_warp is not installed (pip install 'morfic[gpu]')")

from morfic_cli.config import EnvCfg, SimCfg  # noqa: E402
from morfic_cli.envs.locomotion import LocomotionEnv  # noqa: E402
from morfic_cli.errors import MorficError  # noqa: E402
from morfic_cli.morphology.descriptor import TRAIN_MAX, TRAIN_MIN  # noqa: E402
from morfic_cli.morphology.robots import list_robots, load_robot  # noqa: E402
from morfic_cli.sim.backend import SimFrame  # noqa: E402
from morfic_cli.sim.cpu import CpuBackend  # noqa: E402
from morfic_cli.sim.factory import make_backend  # noqa: E402
from morfic_cli.sim.warp import PER_WORLD_FIELDS, WarpBackend  # noqa: E402

DECIMATION = 4
STEP_TOL: dict[str, float] = {
    "base_pos_w": 1e-5,  # m
    "base_quat_w": 1e-5,
    "base_lin_vel_b": 1e-4,  # m/s
    "base_ang_vel_b": 1e-3,  # rad/s
    "joint_pos": 1e-4,  # rad
    "joint_vel": 1e-2,  # rad/s
    "joint_torque": 2e-2,  # N m
    "foot_pos_w": 1e-5,  # m
    "foot_vel_w": 2e-3,  # m/s
    "foot_force_w": 1.0,  # N (of 100-300 N per stance foot)
    "body_contact_force": 1.0,  # N
}
"""Largest difference allowed after one policy step from the same state, per frame field (its units)."""

RUN_TOL: dict[str, float] = {
    "base_pos_w": 1e-3,
    "base_quat_w": 1e-3,
    "base_lin_vel_b": 1e-2,
    "base_ang_vel_b": 5e-2,
    "joint_pos": 2e-3,
    "joint_vel": 5e-2,
    "joint_torque": 0.1,
    "foot_pos_w": 1e-3,
    "foot_vel_w": 2e-2,
    "foot_force_w": 1.0,
    "body_contact_force": 1.0,
}
"""Largest difference allowed over 25 free-running policy steps (0.5 s), per frame field (its units)."""

CFG = SimCfg(num_threads=1, device="cpu")
"""The CPU backend's config (the reference)."""
DEVICE = os.environ.get("MORFIC_WARP_TEST_DEVICE", "cpu")
"""Where the warp backend runs here: warp's CPU device (default, CI) or the GPU ("cuda", scripts/gpu_check.sh)."""
WARP_CFG = dataclasses.replace(CFG, device=DEVICE)


def _pair(robot: str, n: int, *, template: bool, seed: int = 0) -> tuple[WarpBackend, CpuBackend]:
    """Both backends with the same random morphology (template), dynamics and initial state."""
    spec = load_robot(robot)
    warp, cpu = WarpBackend(WARP_CFG, spec, n, template=template), CpuBackend(CFG, spec, n, template=template)
    ids, gen = torch.arange(n), torch.Generator().manual_seed(seed)
    if template:
        lo, hi = torch.tensor(TRAIN_MIN, dtype=torch.float64), torch.tensor(TRAIN_MAX, dtype=torch.float64)
        desc = lo + (hi - lo) * torch.rand(n, 11, generator=gen, dtype=torch.float64)
        for b in (warp, cpu):
            b.set_morphology(ids, desc)
    dyn = (
        0.5 + 0.75 * torch.rand(n, generator=gen),
        0.3 * torch.rand(n, generator=gen),
        0.03 * (2 * torch.rand(n, 3, generator=gen) - 1),
        0.1 * torch.rand(n, 12, generator=gen),
    )
    for b in (warp, cpu):
        b.set_dynamics(ids, *dyn)
    p = cpu.params()
    pos = torch.tensor([[0.0, 0.0, spec.init_height]]).repeat(n, 1)
    yaw = math.pi * (2 * torch.rand(n, generator=gen) - 1)
    quat = torch.stack([torch.cos(yaw / 2), torch.zeros(n), torch.zeros(n), torch.sin(yaw / 2)], dim=1)
    for b in (warp, cpu):
        b.reset_envs(ids, pos, quat, torch.zeros(n, 6), p.default_joint_pos, torch.zeros(n, 12))
    return warp, cpu


def _gait(q0: torch.Tensor, step: int) -> torch.Tensor:
    """Gait-like joint targets: every joint swings 0.25 rad at 2 Hz (rad). Shape: like q0."""
    phase = 2 * math.pi * 2.0 * step * DECIMATION * CFG.physics_dt + torch.arange(12) * 0.7
    return q0 + 0.25 * torch.sin(phase)


def _sway(q0: torch.Tensor, step: int) -> torch.Tensor:
    """A slow sway that keeps every foot on the ground: 0.1 rad at 1 Hz (rad). Shape: like q0."""
    phase = 2 * math.pi * 1.0 * step * DECIMATION * CFG.physics_dt + torch.arange(12) * 0.7
    return q0 + 0.1 * torch.sin(phase)


def _max_diff(a: SimFrame, b: SimFrame) -> dict[str, float]:
    return {k: float((getattr(a, k).cpu().double() - getattr(b, k).cpu().double()).abs().max()) for k in STEP_TOL}


def _assert_parity(warp: WarpBackend, cpu: CpuBackend, policy_steps: int, *, resync: bool) -> dict[str, float]:
    """Step both backends with the same targets; ``resync`` copies the CPU state into warp before each step."""
    q0 = cpu.params().default_joint_pos.float()
    targets, tol = (_gait, STEP_TOL) if resync else (_sway, RUN_TOL)
    start = cpu.state_dict()
    worst = dict.fromkeys(tol, 0.0)
    for step in range(policy_steps):
        if resync:
            warp.load_state_dict(cpu.state_dict())
        tw, tc = warp.step(targets(q0, step), DECIMATION), cpu.step(targets(q0, step), DECIMATION)
        assert not tw.bad.any() and not tc.bad.any()
        worst = {k: max(v, d) for (k, v), d in zip(worst.items(), _max_diff(tw, tc).values(), strict=True)}
    cpu.load_state_dict(start)
    warp.load_state_dict(start)
    over = {k: v for k, v in worst.items() if v > tol[k]}
    how = "one step from the same state" if resync else f"{policy_steps} free-running steps"
    assert not over, f"beyond the parity tolerance ({how}): {over} (all: {worst})"
    return worst


def _record(record_property, name: str, worst: dict[str, float]) -> None:
    """The worst differences into the JUnit XML report (``pytest --junitxml``; scripts/gpu_check.py reads them)."""
    record_property(name, json.dumps(worst))


def test_parity_with_the_cpu_backend_on_the_template(record_property):
    """Go2 template, a different random morphology and randomised dynamics in each of 4 worlds."""
    warp, cpu = _pair("go2", 4, template=True)
    try:
        assert torch.equal(warp.params().default_joint_pos.cpu(), cpu.params().default_joint_pos)
        _record(record_property, "worst_free_run", _assert_parity(warp, cpu, 25, resync=False))
        _record(record_property, "worst_one_step", _assert_parity(warp, cpu, 50, resync=True))
    finally:
        warp.close()
        cpu.close()


@pytest.mark.slow
@pytest.mark.parametrize("robot", list_robots())
def test_parity_with_the_cpu_backend_for_each_robot(robot, record_property):
    """Each robot's own model (full mode) and, on the template, its descriptor in every world."""
    for template in (False, True):
        mode = "descriptor" if template else "full"
        warp, cpu = _pair(robot, 3, template=template, seed=1)
        if template:
            desc = torch.as_tensor(load_robot(robot).descriptor, dtype=torch.float64).expand(3, -1).clone()
            for b in (warp, cpu):
                b.set_morphology(torch.arange(3), desc)
        try:
            _record(record_property, f"worst_free_run_{mode}", _assert_parity(warp, cpu, 25, resync=False))
            _record(record_property, f"worst_one_step_{mode}", _assert_parity(warp, cpu, 50, resync=True))
        finally:
            warp.close()
            cpu.close()


def test_per_world_morphology_really_differs_and_matches_mj_setconst():
    """Masses, inertias, limits, ranges and derived constants read back per world = the CPU backend's models."""
    warp, cpu = _pair("go2", 3, template=True, seed=2)
    try:
        warp.frame()  # the derived constants are recomputed lazily: a frame does not need them ...
        warp.step(cpu.params().default_joint_pos, 1)  # ... a step does
        cpu.step(cpu.params().default_joint_pos, 1)
        for name in PER_WORLD_FIELDS:
            got = warp.fields[name].cpu().numpy().astype(np.float64)
            want = np.stack([getattr(m, name) for m in cpu.models]).reshape(got.shape)
            np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6, err_msg=name)
        base = warp.info.base_body
        masses = warp.fields["body_mass"][:, base]
        assert len(set(masses.tolist())) == 3, "every world has its own base mass"
        hip = warp.info.joint_ids[0, 0]
        assert len({tuple(r) for r in warp.fields["jnt_range"][:, hip].tolist()}) == 3, "and its own hip limits"
        p = warp.params()
        torch.testing.assert_close(masses.double().cpu(), p.base_mass.cpu(), rtol=1e-6, atol=0)
        joints = torch.tensor(warp.info.joint_ids.reshape(-1))
        torch.testing.assert_close(
            warp.fields["jnt_range"][:, joints].double().cpu(), p.joint_range.cpu(), rtol=1e-6, atol=1e-7
        )
        for name in (
            "joint_range",
            "default_joint_pos",
            "total_mass",
            "base_mass",
            "nominal_height",
            "friction",
            "restitution",
            "com_offset",
            "joint_friction",
            "descriptor",
        ):
            torch.testing.assert_close(getattr(p, name).cpu(), getattr(cpu.params(), name), rtol=1e-12, atol=1e-12)
    finally:
        warp.close()
        cpu.close()


def test_a_heavier_base_sinks_further_in_its_own_world_only():
    """Per-world masses act on the physics: the same world-0 state, a much heavier base in world 1."""
    warp = WarpBackend(WARP_CFG, load_robot("go2"), 2, template=True)
    try:
        desc = torch.as_tensor(load_robot("go2").descriptor, dtype=torch.float64).repeat(2, 1)
        desc[1, 4] *= 1.6
        warp.set_morphology(torch.arange(2), desc)
        q0 = warp.params().default_joint_pos
        for _ in range(25):
            frame = warp.step(q0, DECIMATION)
        assert frame.base_pos_w[1, 2] < frame.base_pos_w[0, 2] - 1e-3
        assert frame.foot_force_w[1, :, 2].sum() > 1.3 * frame.foot_force_w[0, :, 2].sum()
    finally:
        warp.close()


def test_state_dict_moves_between_backends():
    warp, cpu = _pair("go2", 2, template=True, seed=3)
    try:
        q0 = cpu.params().default_joint_pos
        for _ in range(5):
            cpu.step(q0, DECIMATION)
        warp.load_state_dict(cpu.state_dict())
        fw, fc = warp.frame(), cpu.frame()
        for k in STEP_TOL:  # the same state, rounded to float32
            torch.testing.assert_close(getattr(fw, k).cpu(), getattr(fc, k).cpu(), rtol=1e-5, atol=1e-5, msg=k)
        assert warp.state_dict()["state"].shape == cpu.state_dict()["state"].shape
        with pytest.raises(ValueError, match="shape"):
            warp.load_state_dict({"state": torch.zeros(3, 38), "sensordata": torch.zeros(3, 1)})
    finally:
        warp.close()
        cpu.close()


def test_a_nonfinite_env_is_flagged_and_restored_alone():
    warp = WarpBackend(WARP_CFG, load_robot("go2"), 3, template=True)
    try:
        q0 = warp.params().default_joint_pos
        warp.step(q0, DECIMATION)
        state = warp.state_dict()
        state["state"][1, 5] = float("nan")
        warp.load_state_dict(state)
        reference = WarpBackend(WARP_CFG, load_robot("go2"), 3, template=True)
        reference.step(q0, DECIMATION)
        frame, ref = warp.step(q0, DECIMATION), reference.step(q0, DECIMATION)
        assert frame.bad.tolist() == [False, True, False]
        assert set(warp.bad_states) == {1} and np.isnan(warp.bad_states[1][5])
        assert torch.isfinite(frame.joint_pos).all() and torch.isfinite(frame.foot_force_w).all()
        for k in STEP_TOL:  # the other worlds never noticed
            torch.testing.assert_close(getattr(frame, k)[[0, 2]], getattr(ref, k)[[0, 2]], rtol=0, atol=1e-6)
        targets = q0.clone()
        targets[2, 0] = float("inf")
        assert warp.step(targets, DECIMATION).bad.tolist() == [False, False, True]
        reference.close()
    finally:
        warp.close()


def test_factory_full_mode_and_bad_input():
    backend = make_backend(SimCfg(backend="warp", device=DEVICE), load_robot("a1"), 2, template=False)
    try:
        assert isinstance(backend, WarpBackend) and not backend.morphology_mutable
        with pytest.raises(MorficError, match="full mode"):
            backend.set_morphology(torch.arange(2), torch.zeros(2, 11))
        with pytest.raises(ValueError, match="restitution"):
            backend.set_dynamics(torch.arange(1), torch.ones(1), torch.ones(1), torch.zeros(1, 3), torch.zeros(1, 12))
        with pytest.raises(ValueError, match="env ids"):
            backend.push(torch.tensor([5]), torch.zeros(1, 2))
    finally:
        backend.close()
    assert isinstance(
        make_backend(SimCfg(backend="gpu", device=DEVICE), load_robot("go2"), 1, template=True), WarpBackend
    )


@pytest.mark.slow
def test_the_env_is_the_same_code_on_both_backends():
    """LocomotionEnv on warp vs cpu: same seed, same random draws, observations within the parity tolerance."""
    envs = [
        LocomotionEnv(EnvCfg(num_envs=4, sim=SimCfg(num_threads=1, backend=b, device=d)), mode="train", seed=0)
        for b, d in (("warp", DEVICE), ("cpu", "cpu"))
    ]
    try:
        gen = torch.Generator().manual_seed(0)
        for _ in range(10):
            a = 0.5 * (2 * torch.rand(4, 12, generator=gen) - 1)
            (ow, rw, dw, _), (oc, rc, dc, _) = envs[0].step(a), envs[1].step(a)
            assert torch.equal(dw, dc)
            torch.testing.assert_close(ow["critic"], oc["critic"], rtol=0, atol=2e-2)
            torch.testing.assert_close(ow["privileged"], oc["privileged"], rtol=0, atol=1e-6)
            torch.testing.assert_close(ow["morphology"], oc["morphology"], rtol=0, atol=1e-6)
            torch.testing.assert_close(rw, rc, rtol=0, atol=1e-2)
    finally:
        for env in envs:
            env.close()
