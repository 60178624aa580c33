"""The CPU backend: standing, determinism, NaN isolation, per-env DR, pushes and contact sensors."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest
import torch

from morfic_cli.config import SimCfg
from morfic_cli.errors import MorficError
from morfic_cli.morphology.builder import build_model, contact_body_names
from morfic_cli.morphology.descriptor import TRAIN_MAX, TRAIN_MIN, sample_uniform
from morfic_cli.morphology.robots import list_robots, load_robot
from morfic_cli.sim.backend import CONTACT_BODIES, SimBackend, SimFrame
from morfic_cli.sim.cpu import CpuBackend, quat_rotate_inverse, restitution_to_dampratio
from morfic_cli.sim.factory import make_backend
from morfic_cli.sim.floor import physics_floor

DECIMATION = 4


def _backend(name: str = "go2", n: int = 4, *, template: bool = True, threads: int = 2) -> CpuBackend:
    return CpuBackend(SimCfg(num_threads=threads), load_robot(name), n, template=template)


def _reset_home(backend: CpuBackend, height: float | None = None) -> None:
    n, p = backend.num_envs, backend.params()
    z = backend.robot.init_height if height is None else height
    backend.reset_envs(
        torch.arange(n),
        torch.tensor([[0.0, 0.0, z]]).repeat(n, 1),
        torch.tensor([[1.0, 0.0, 0.0, 0.0]]).repeat(n, 1),
        torch.zeros(n, 6),
        p.default_joint_pos,
        torch.zeros(n, 12),
    )


def _stand(backend: CpuBackend, physics_steps: int) -> SimFrame:
    q0 = backend.params().default_joint_pos
    frame = backend.frame()
    for _ in range(physics_steps // DECIMATION):
        frame = backend.step(q0, DECIMATION)
        assert not frame.bad.any()
    return frame


def _assert_standing(frame: SimFrame, nominal_height: torch.Tensor, what: str) -> None:
    assert torch.isfinite(frame.base_pos_w).all(), what
    assert torch.all(frame.base_pos_w[:, 2] > 0.7 * nominal_height), f"{what}: {frame.base_pos_w[:, 2]}"
    x, y = frame.base_quat_w[:, 1], frame.base_quat_w[:, 2]
    assert torch.all(1.0 - 2.0 * (x * x + y * y) > 0.95), f"{what} tilted"


def _frames_equal(a: SimFrame, b: SimFrame, rows: slice | list[int] = slice(None)) -> None:
    for f in fields(SimFrame):
        assert torch.equal(getattr(a, f.name)[rows], getattr(b, f.name)[rows]), f.name


def test_protocol_shapes_and_factory():
    backend = make_backend(SimCfg(num_threads=1), load_robot("go2"), 3, template=True)
    assert isinstance(backend, CpuBackend)
    for name in ("step", "frame", "params", "reset_envs", "set_morphology", "set_dynamics", "push", "close"):
        assert callable(getattr(backend, name)) and hasattr(SimBackend, name)
    assert backend.num_envs == 3 and backend.physics_dt == 0.005 and backend.morphology_mutable
    assert backend.device == torch.device("cpu")
    frame = backend.step(backend.params().default_joint_pos, DECIMATION)
    shapes = {
        "base_pos_w": (3, 3),
        "base_quat_w": (3, 4),
        "base_lin_vel_w": (3, 3),
        "base_lin_vel_b": (3, 3),
        "base_ang_vel_b": (3, 3),
        "joint_pos": (3, 12),
        "joint_vel": (3, 12),
        "joint_torque": (3, 12),
        "foot_pos_w": (3, 4, 3),
        "foot_vel_w": (3, 4, 3),
        "foot_force_w": (3, 4, 3),
        "body_contact_force": (3, len(CONTACT_BODIES)),
        "bad": (3,),
    }
    for name, shape in shapes.items():
        assert tuple(getattr(frame, name).shape) == shape, name
    assert frame.bad.dtype == torch.bool and frame.joint_pos.dtype == torch.float32
    assert backend.params().total_mass.dtype == torch.float64  # params are exact
    assert contact_body_names() == list(CONTACT_BODIES)  # the builder's sensors are the protocol's bodies
    p = backend.params()
    assert tuple(p.joint_range.shape) == (3, 12, 2) and tuple(p.descriptor.shape) == (3, 11)
    np.testing.assert_allclose(p.descriptor[0].numpy(), load_robot("go2").descriptor, rtol=1e-6)
    backend.close()


def test_go2_template_stands_for_1000_physics_steps():
    backend = _backend("go2", 6)
    descriptors = np.vstack(
        [load_robot("go2").descriptor, TRAIN_MIN, TRAIN_MAX, sample_uniform(3, np.random.default_rng(0))]
    )
    backend.set_morphology(torch.arange(6), torch.as_tensor(descriptors))
    _reset_home(backend)
    frame = _stand(backend, 1000)
    _assert_standing(frame, backend.params().nominal_height, "go2 template")
    backend.close()


@pytest.mark.parametrize("name", list_robots())
def test_every_robot_stands_in_full_mode(name):
    backend = _backend(name, 2, template=False)
    p = backend.params()
    np.testing.assert_allclose(p.descriptor[0].numpy(), load_robot(name).descriptor, rtol=1e-6)
    np.testing.assert_allclose(p.joint_range[0].numpy(), load_robot(name).ctrl_range, rtol=1e-6)
    frame = _stand(backend, 1000)
    _assert_standing(frame, p.nominal_height, name)
    backend.close()


def test_set_morphology_needs_the_template():
    backend = _backend("go1", 2, template=False)
    with pytest.raises(MorficError, match="full mode"):
        backend.set_morphology(torch.arange(1), torch.as_tensor(load_robot("b1").descriptor)[None])
    backend.close()


def test_set_morphology_changes_only_its_envs_and_params_follow():
    backend = _backend("go2", 3)
    b1 = load_robot("b1")
    backend.set_morphology(torch.tensor([1]), torch.as_tensor(b1.descriptor)[None])
    p = backend.params()
    assert p.base_mass[1].item() == pytest.approx(29.45) and p.base_mass[0].item() == pytest.approx(6.921)
    assert p.total_mass[1].item() == pytest.approx(60.718, rel=1e-6)
    np.testing.assert_allclose(p.joint_range[1, :3].numpy(), [[-0.75, 0.75], [-1.0, 3.5], [-2.6, -0.6]], rtol=1e-6)
    np.testing.assert_allclose(backend.models[1].actuator_ctrlrange[:3], [[-0.75, 0.75], [-1.0, 3.5], [-2.6, -0.6]])
    np.testing.assert_array_equal(backend.models[0].body_mass, backend.models[2].body_mass)
    np.testing.assert_allclose(p.descriptor[1].numpy(), b1.descriptor, rtol=1e-6)
    # joint targets are clipped to each env's own range
    targets = p.default_joint_pos.clone()
    targets[:, 2] = 10.0  # far beyond every calf max
    for _ in range(50):
        frame = backend.step(targets, DECIMATION)
    assert frame.joint_pos[1, 2].item() < -0.6 + 0.05
    assert frame.joint_pos[0, 2].item() < -0.838 + 0.05
    backend.close()


def _scenario(threads: int, nan_env: int | None = None) -> list[SimFrame]:
    """A fixed sequence of morphology, DR, resets, pushes and random targets on 5 envs."""
    backend = _backend("go2", 5, threads=threads)
    rng = np.random.default_rng(7)
    backend.set_morphology(torch.arange(5), torch.as_tensor(sample_uniform(5, rng)))
    backend.set_dynamics(
        torch.arange(5),
        torch.as_tensor(rng.uniform(0.5, 1.25, 5)),
        torch.as_tensor(rng.uniform(0.0, 0.4, 5)),
        torch.as_tensor(rng.uniform(-0.03, 0.03, (5, 3))),
        torch.as_tensor(rng.uniform(0.0, 0.2, (5, 12))),
    )
    _reset_home(backend)
    q0 = backend.params().default_joint_pos
    frames = []
    for t in range(30):
        if t == 10:
            backend.push(torch.tensor([3]), torch.tensor([[0.5, -0.5]]))
        if nan_env is not None and t == 12:
            backend.state[nan_env, 5] = np.nan
        frames.append(backend.step(q0 + 0.2 * torch.as_tensor(rng.uniform(-1, 1, (5, 12))), DECIMATION))
    backend.close()
    return frames


def test_same_inputs_give_bitwise_identical_frames_with_one_and_two_threads():
    one, two = _scenario(threads=1), _scenario(threads=2)
    for a, b in zip(one, two, strict=True):
        _frames_equal(a, b)
    assert not any(f.bad.any() for f in one)


def test_nan_in_one_env_flags_only_that_env_and_leaves_the_others_untouched():
    clean, poisoned = _scenario(threads=2), _scenario(threads=2, nan_env=2)
    for t, (a, b) in enumerate(zip(clean, poisoned, strict=True)):
        assert b.bad.tolist() == ([False, False, True, False, False] if t == 12 else [False] * 5)
        _frames_equal(a, b, rows=[0, 1, 3, 4])
        for f in fields(SimFrame):
            assert torch.isfinite(getattr(b, f.name).float()).all(), f.name


def test_bad_targets_and_diverging_states_are_flagged():
    backend = _backend("go2", 3)
    _reset_home(backend)
    q0 = backend.params().default_joint_pos
    targets = q0.clone()
    targets[1, 4] = float("nan")
    assert backend.step(targets, DECIMATION).bad.tolist() == [False, True, False]
    backend.state[0, backend._qvel0 + 7] = 1e12  # a joint velocity MuJoCo calls unstable
    frame = backend.step(q0, DECIMATION)
    assert frame.bad.tolist() == [True, False, False]
    _reset_home(backend)  # a reset clears the backend's flags, not those of a frame already handed out
    assert frame.bad.tolist() == [True, False, False] and not backend.frame().bad.any()
    assert 0 in backend.bad_states and backend.bad_states[0][backend._qvel0 + 7] == 1e12
    assert backend.warnings  # MuJoCo's message was captured, not printed
    assert torch.isfinite(frame.joint_vel).all()
    assert not backend.step(q0, DECIMATION).bad.any()  # restored to its home state
    # a freshly reset env (time 0) diverging in a single physics step is caught too
    p = backend.params()
    backend.reset_envs(
        torch.tensor([2]),
        torch.tensor([[0.0, 0.0, 0.34]]),
        torch.tensor([[1.0, 0.0, 0.0, 0.0]]),
        torch.zeros(1, 6),
        p.default_joint_pos[2:],
        torch.zeros(1, 12),
    )
    backend.state[2, backend._qvel0 + 8] = 1e12
    assert backend.step(q0, 1).bad.tolist() == [False, False, True]
    backend.close()


def test_restitution_maps_to_the_damping_ratio_by_hand():
    np.testing.assert_allclose(
        restitution_to_dampratio(np.array([0.0, math.exp(-math.pi), 1e-300])),
        [1.0, 1.0 / math.sqrt(2.0), 1.0],
        rtol=1e-3,
    )
    e = 0.3
    assert restitution_to_dampratio(np.array(e)) == pytest.approx(
        -math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2)
    )


def test_set_dynamics_changes_only_that_envs_model():
    backend = _backend("go2", 3)
    before = [m.__copy__() for m in backend.models]
    com = torch.tensor([[0.01, -0.02, 0.03]])
    backend.set_dynamics(
        torch.tensor([1]), torch.tensor([0.6]), torch.tensor([math.exp(-math.pi)]), com, torch.full((1, 12), 0.15)
    )
    m0, m1, base = backend.models[0], backend.models[1], backend.info.base_body
    np.testing.assert_allclose(m1.geom_friction[:, 0], 0.6, rtol=1e-6)  # geom_friction is float32
    np.testing.assert_allclose(m1.geom_solref[:, 1], 1.0 / math.sqrt(2.0))
    np.testing.assert_allclose(m1.body_ipos[base], before[1].body_ipos[base] + com[0].numpy())
    np.testing.assert_allclose(m1.dof_frictionloss[6:], 0.15)
    assert np.all(m1.dof_frictionloss[:6] == 0.0)
    for env in (0, 2):
        for field in ("geom_friction", "geom_solref", "body_ipos", "dof_frictionloss", "body_mass"):
            np.testing.assert_array_equal(getattr(backend.models[env], field), getattr(before[env], field))
    assert m0.geom_friction[0, 0] == 1.0
    p = backend.params()
    assert p.friction.tolist() == pytest.approx([1.0, 0.6, 1.0])
    assert p.restitution[1].item() == pytest.approx(math.exp(-math.pi))
    np.testing.assert_allclose(p.com_offset[1].numpy(), com[0].numpy(), rtol=1e-6)
    assert p.joint_friction[1].tolist() == pytest.approx([0.15] * 12) and p.joint_friction[0].abs().sum() == 0
    with pytest.raises(ValueError):
        backend.set_dynamics(
            torch.tensor([0]), torch.tensor([1.0]), torch.tensor([1.0]), torch.zeros(1, 3), torch.zeros(1, 12)
        )
    backend.close()


def test_push_adds_to_that_envs_base_velocity():
    backend = _backend("go2", 3)
    _reset_home(backend)
    before = backend.frame().base_lin_vel_w.clone()
    backend.push(torch.tensor([2]), torch.tensor([[0.7, -0.4]]))
    after = backend.frame().base_lin_vel_w
    np.testing.assert_allclose((after - before)[2].numpy(), [0.7, -0.4, 0.0], atol=1e-6)
    assert torch.equal(after[:2], before[:2])
    frame = backend.step(backend.params().default_joint_pos, DECIMATION)
    assert frame.base_lin_vel_w[2, 0] > 0.3 and abs(frame.base_lin_vel_w[0, 0]) < 0.1
    backend.close()


def test_reset_envs_writes_the_given_state():
    backend = _backend("go2", 3)
    pos, quat = torch.tensor([[0.5, -0.2, 0.4]]), torch.tensor([[math.cos(0.3), 0.0, 0.0, math.sin(0.3)]])
    vel, q = torch.tensor([[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]]), backend.params().default_joint_pos[:1].float() + 0.05
    backend.reset_envs(torch.tensor([1]), pos, quat, vel, q, torch.full((1, 12), 0.25))
    frame = backend.frame()
    torch.testing.assert_close(frame.base_pos_w[1], pos[0])
    torch.testing.assert_close(frame.base_quat_w[1], quat[0])
    torch.testing.assert_close(frame.base_lin_vel_w[1], vel[0, :3])
    torch.testing.assert_close(frame.base_ang_vel_b[1], vel[0, 3:])
    torch.testing.assert_close(frame.joint_pos[1], q[0])
    torch.testing.assert_close(frame.joint_vel[1], torch.full((12,), 0.25))
    # base-frame velocity: yaw 0.6 rad, so the world velocity is rotated by -0.6 rad about z
    expected = quat_rotate_inverse(quat.double().numpy(), vel[:, :3].double().numpy())[0]
    c, s = math.cos(0.6), math.sin(0.6)
    np.testing.assert_allclose(expected, [c * 0.1 + s * 0.2, -s * 0.1 + c * 0.2, 0.3], atol=1e-7)
    torch.testing.assert_close(frame.base_lin_vel_b[1], torch.as_tensor(expected, dtype=torch.float32))
    # foot sensors were recomputed at the new pose
    assert frame.foot_pos_w[1, 0, 0] > 0.5 and frame.foot_pos_w[0, 0, 0] < 0.3
    backend.close()


def test_foot_forces_carry_the_weight_and_body_forces_are_zero_when_standing():
    backend = _backend("go2", 2)
    backend.set_morphology(torch.tensor([1]), torch.as_tensor(load_robot("go1").descriptor)[None])
    _reset_home(backend)
    frame = _stand(backend, 400)
    weight = backend.params().total_mass.float() * 9.81
    fz = frame.foot_force_w[..., 2].sum(dim=1)
    torch.testing.assert_close(fz, weight, rtol=0.1, atol=0.0)
    assert torch.all(frame.foot_force_w[..., 2] > 0)  # every foot pushed up by the floor
    assert torch.all(frame.body_contact_force == 0)
    assert torch.all(frame.joint_torque[:, 2::3].abs() > 0.5)  # the knees hold the weight
    backend.close()


def test_body_contact_force_when_dropped_upside_down():
    backend = _backend("go2", 2)
    _reset_home(backend)
    n = 2
    p = backend.params()
    upside_down = torch.tensor([[0.0, 1.0, 0.0, 0.0]])  # 180 degrees about x
    backend.reset_envs(
        torch.tensor([1]),
        torch.tensor([[0.0, 0.0, 0.3]]),
        upside_down,
        torch.zeros(1, 6),
        p.default_joint_pos[:1],
        torch.zeros(1, 12),
    )
    peak = torch.zeros(n, len(CONTACT_BODIES))
    for _ in range(40):
        frame = backend.step(p.default_joint_pos, DECIMATION)
        peak = torch.maximum(peak, frame.body_contact_force)
    assert peak[1, 0] > 10.0  # the base hit the floor
    assert torch.all(peak[0] == 0.0)  # the standing robot never touched it with base, thighs or calves
    backend.close()


def test_physics_floor_reports_steps_per_second():
    model = build_model(load_robot("go2"), sim_sensors=True)
    rate = physics_floor([model] * 4, 40, num_threads=2)
    assert 1e3 < rate < 1e8
    assert 1e3 < physics_floor([model] * 4, 40, num_threads=1, ctrl_noise=0.25) < 1e8
