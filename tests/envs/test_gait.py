"""The gait clock, checked against hand-computed numbers."""

from __future__ import annotations

import math

import pytest
import torch

from morfic_cli.envs.gait import (
    GaitCfg,
    advance_phase,
    desired_contact,
    foot_phases,
    normalized_phase,
    raibert_foot_targets,
    raibert_phase,
)


def _phi(x: float, kappa: float = 0.07) -> float:
    """Normal CDF Phi(x / kappa), for the expected values."""
    return 0.5 * (1.0 + math.erf(x / (kappa * math.sqrt(2.0))))


def test_default_is_a_trot():
    cfg = GaitCfg()
    assert cfg.offsets == (0.0, 0.5, 0.5, 0.0)
    assert cfg.duty == 0.5
    assert cfg.kappa == 0.07


def test_advance_phase_wraps():
    # 0.9 + 3 Hz * 0.05 s = 1.05 -> 0.05; 0.2 + 2 * 0.05 = 0.3
    out = advance_phase(torch.tensor([0.9, 0.2]), torch.tensor([3.0, 2.0]), 0.05)
    torch.testing.assert_close(out, torch.tensor([0.05, 0.3]))


def test_advance_phase_full_period_returns():
    # 50 steps of 0.02 s at 1 Hz is one period.
    phase = torch.tensor([0.3])
    for _ in range(50):
        phase = advance_phase(phase, torch.tensor([1.0]), 0.02)
    torch.testing.assert_close(phase, torch.tensor([0.3]), atol=1e-5, rtol=0)


def test_foot_phases_trot_offsets():
    # phase 0.1 -> FL 0.1, FR 0.6, RL 0.6, RR 0.1; phase 0.7 -> 0.7, 0.2 (1.2 mod 1), 0.2, 0.7
    out = foot_phases(torch.tensor([0.1, 0.7]), GaitCfg())
    torch.testing.assert_close(out, torch.tensor([[0.1, 0.6, 0.6, 0.1], [0.7, 0.2, 0.2, 0.7]]))


def test_normalized_phase_duty_remap():
    # duty 0.25: stance 0.125 -> 0.125 * 0.5 / 0.25 = 0.25; swing 0.625 -> 0.5 + 0.375 * 0.5 / 0.75 = 0.75
    out = normalized_phase(torch.tensor([[0.125, 0.625, 0.0, 0.25]]), 0.25)
    torch.testing.assert_close(out, torch.tensor([[0.25, 0.75, 0.0, 0.5]]))
    # duty 0.5 is the identity
    x = torch.tensor([[0.0, 0.2, 0.5, 0.9]])
    torch.testing.assert_close(normalized_phase(x, 0.5), x)


def test_desired_contact_mid_stance_and_mid_swing():
    cfg = GaitCfg()
    d = desired_contact(torch.tensor([[0.25, 0.75, 0.0, 0.5]]), cfg)
    # mid-stance phi = 0.25: Phi(0.25) (1 - Phi(-0.25)) + Phi(-0.75)(1 - Phi(-1.25)) = Phi(0.25)^2 + ~0
    mid_stance = _phi(0.25) ** 2 + _phi(-0.75) * (1 - _phi(-1.25))
    # mid-swing phi = 0.75: Phi(0.75)(1 - Phi(0.25)) + Phi(-0.25)(1 - Phi(-0.75)) = 2 (1 - Phi(0.25)) (1 - ...)
    mid_swing = _phi(0.75) * (1 - _phi(0.25)) + _phi(-0.25) * (1 - _phi(-0.75))
    # touchdown phi = 0: Phi(0) (1 - Phi(-0.5)) + Phi(-1)(...) = 0.5 (1 - ~0) ~ 0.5; lift-off phi = 0.5 likewise
    touchdown = _phi(0.0) * (1 - _phi(-0.5)) + _phi(-1.0) * (1 - _phi(-1.5))
    lift_off = _phi(0.5) * (1 - _phi(0.0)) + _phi(-0.5) * (1 - _phi(-1.0))
    expected = torch.tensor([[mid_stance, mid_swing, touchdown, lift_off]])
    torch.testing.assert_close(d, expected, atol=1e-6, rtol=0)
    assert d[0, 0] > 0.999  # ~1 mid-stance
    assert d[0, 1] < 1e-3  # ~0 mid-swing
    assert abs(d[0, 2].item() - 0.5) < 1e-3 and abs(d[0, 3].item() - 0.5) < 1e-3


def test_desired_contact_trot_diagonals_in_phase():
    cfg = GaitCfg()
    phase = torch.linspace(0.0, 0.99, 100)
    d = desired_contact(foot_phases(phase, cfg), cfg)
    torch.testing.assert_close(d[:, 0], d[:, 3])  # FL with RR
    torch.testing.assert_close(d[:, 1], d[:, 2])  # FR with RL
    # the two diagonals alternate: half a period apart, and with duty 0.5 they sum to ~1
    torch.testing.assert_close(d[:, 0] + d[:, 1], torch.ones(100), atol=2e-3, rtol=0)
    assert ((d >= 0) & (d <= 1)).all()


def test_desired_contact_continuous_across_wrap():
    cfg = GaitCfg()
    d = desired_contact(torch.tensor([[0.9999, 0.0001, 0.4999, 0.5001]]), cfg)
    assert abs(d[0, 0].item() - d[0, 1].item()) < 1e-2
    assert abs(d[0, 2].item() - d[0, 3].item()) < 1e-2


def test_raibert_phase_values():
    # |1 - 2 phi| - 0.5: 0 -> 0.5 (touchdown), 0.25 -> 0, 0.5 -> -0.5 (lift-off), 0.75 -> 0
    s = raibert_phase(torch.tensor([[0.0, 0.25, 0.5, 0.75]]), 0.5)
    torch.testing.assert_close(s, torch.tensor([[0.5, 0.0, -0.5, 0.0]]))
    # duty 0.25: stance 0.125 is mid-stance (0), swing 0.625 is mid-swing (0)
    s = raibert_phase(torch.tensor([[0.125, 0.625, 0.0, 0.25]]), 0.25)
    torch.testing.assert_close(s, torch.tensor([[0.0, 0.0, 0.5, -0.5]]))


NOMINAL = torch.tensor([[[0.19, 0.14], [0.19, -0.14], [-0.19, 0.14], [-0.19, -0.14]]])


def test_raibert_foot_targets_forward():
    # vx = 1, f = 2 Hz, duty 0.5 -> T_st = 0.25 s; offset_x = s * 1 * 0.25
    # FL s=0.5 -> +0.125, FR s=0 -> 0, RL s=-0.5 -> -0.125, RR s=0 -> 0
    phases = torch.tensor([[0.0, 0.25, 0.5, 0.75]])
    out = raibert_foot_targets(phases, torch.tensor([[1.0, 0.0, 0.0]]), torch.tensor([2.0]), NOMINAL, 0.5)
    expected = NOMINAL.clone()
    expected[0, 0, 0] += 0.125
    expected[0, 2, 0] -= 0.125
    torch.testing.assert_close(out, expected)


def test_raibert_foot_targets_yaw_and_lateral():
    # FL at touchdown (s = 0.5), T_st = 0.25, command vy = 0.2, wz = 1:
    # v_foot = (0 - 1 * 0.14, 0.2 + 1 * 0.19) = (-0.14, 0.39); offset = 0.125 * v = (-0.0175, 0.04875)
    phases = torch.tensor([[0.0, 0.25, 0.25, 0.25]])
    out = raibert_foot_targets(phases, torch.tensor([[0.0, 0.2, 1.0]]), torch.tensor([2.0]), NOMINAL, 0.5)
    expected = NOMINAL.clone()
    expected[0, 0] += torch.tensor([-0.0175, 0.04875])
    torch.testing.assert_close(out, expected)


@pytest.mark.parametrize("freq", [0.0, 1e-9])
def test_raibert_foot_targets_finite_at_zero_frequency(freq):
    out = raibert_foot_targets(torch.zeros(1, 4), torch.tensor([[1.0, 0.0, 0.0]]), torch.tensor([freq]), NOMINAL, 0.5)
    assert torch.isfinite(out).all()
