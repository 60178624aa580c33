"""Issue 16 items 4, 8, 9 in the env: observable reward terms, periodic re-randomisation, h_t = {o_{t-k}}."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from morfic_cli.config import EnvCfg, ObsCfg, RewardCfg, SimCfg
from morfic_cli.envs import observations as O
from morfic_cli.envs.locomotion import LocomotionEnv
from morfic_cli.envs.rewards import TERMS
from morfic_cli.envs.state import CLOCK, FIELD_SOURCES, OBSERVED, EnvState
from morfic_cli.rl.build import rsl_rl_cfg
from morfic_cli.rl.config import preset_cfg


def _env(n: int = 2, **parts) -> LocomotionEnv:
    cfg = dataclasses.replace(EnvCfg(num_envs=n, sim=SimCfg(num_threads=1)), **parts)
    return LocomotionEnv(cfg, mode="train", seed=3)


# ---------------------------------------------------------------------------------------------- item 4
class _Recorder:
    """Stands in for an EnvState: records the fields a term reads, returns the real values."""

    def __init__(self, state: EnvState) -> None:
        self._state, self.read = state, set()

    def __getattr__(self, name: str):
        self.read.add(name)
        return getattr(self._state, name)


def _state(n: int = 3) -> EnvState:
    g = torch.Generator().manual_seed(0)
    fields = {}
    shapes = {
        "base_pos_w": (3,),
        "base_quat_w": (4,),
        "foot_pos_w": (4, 3),
        "foot_vel_w": (4, 3),
        "foot_vel_w_prev": (4, 3),
        "foot_force_w": (4, 3),
        "body_contact_force": (9,),
        "command": (3,),
        "gait_phase": (4,),
        "desired_contact": (4,),
        "gait_frequency": (),
        "nominal_foot_pos_b": (4, 2),
        "nominal_height": (),
        "total_mass": (),
        "base_lin_vel_b": (3,),
        "base_ang_vel_b": (3,),
        "projected_gravity_b": (3,),
    }
    for f in dataclasses.fields(EnvState):
        if f.name == "dt":
            fields["dt"] = 0.02
        elif f.name == "foot_contact":
            fields[f.name] = torch.rand(n, 4, generator=g) > 0.5
        else:
            fields[f.name] = torch.rand((n, *shapes.get(f.name, (12,))), generator=g) + 0.1
    return EnvState(**fields)


def test_every_env_state_field_has_a_source():
    assert set(FIELD_SOURCES) == {f.name for f in dataclasses.fields(EnvState)}
    layout = {name for name, _, _ in O.POLICY_LAYOUT}
    for field, (source, term) in FIELD_SOURCES.items():
        assert (term in layout) if source == OBSERVED else term is None, field


def test_every_default_weighted_term_reads_only_what_the_critic_observes():
    cfg = RewardCfg()
    critic_groups = rsl_rl_cfg(preset_cfg("cpu", "film"))["obs_groups"]["critic"]
    assert critic_groups == ["critic", "privileged", "morphology"]  # o_t history, p_t, m
    clocked = set()
    for term in TERMS:
        rec = _Recorder(_state())
        term.func(rec, cfg)  # type: ignore[arg-type]
        assert rec.read, term.name
        sources = {FIELD_SOURCES[f][0] for f in rec.read}
        if CLOCK in sources:
            clocked.add(term.name)
            assert term.weight_of(cfg) == 0.0, f"{term.name} follows the unobserved gait clock"
        else:
            assert term.weight_of(cfg) > 0.0, term.name
    assert clocked == {"r_gaitF", "r_gaitV", "r_raibert"}  # the three clock terms, off by default


# ---------------------------------------------------------------------------------------------- item 9
@pytest.mark.parametrize(("includes_current", "frames"), [(False, 4), (True, 3)])
def test_history_is_the_previous_observations_then_o_t(includes_current, frames):
    obs_cfg = ObsCfg(history_len=3, history_includes_current=includes_current)
    env = _env(obs=obs_cfg)
    seen = [env.get_observations()["policy"].clone()]
    for _ in range(5):
        obs, *_ = env.step(torch.zeros(2, 12))
        seen.append(obs["policy"].clone())
    history = env.get_observations()["history"]
    assert history.shape == (2, frames, 48) and O.history_frames(obs_cfg) == frames
    # with |h_t| = 3: [o_{t-3}, o_{t-2}, o_{t-1}, o_t] (paper), or [o_{t-2}, o_{t-1}, o_t] (old runs)
    torch.testing.assert_close(history, torch.stack(seen[-frames:], dim=1))


# ---------------------------------------------------------------------------------------------- item 8
@pytest.mark.parametrize(("interval_s", "changes"), [(0.04, True), (0.0, False)])
def test_dynamics_are_drawn_again_every_interval(interval_s, changes):
    env = _env(rand=dataclasses.replace(EnvCfg().rand, rerandomize_interval_s=interval_s, pushes=False))
    before = env.params.friction.clone()
    env.step(torch.zeros(2, 12))  # t = 0.02 s: not a multiple of the 0.04 s interval (2 steps)
    assert torch.equal(env.params.friction, before)
    obs, *_ = env.step(torch.zeros(2, 12))  # t = 0.04 s
    friction = env.params.friction
    assert (not torch.equal(friction, before)) == changes
    assert ((friction >= 0.5) & (friction <= 1.25)).all()
    torch.testing.assert_close(obs["privileged"][:, 0], friction.float())  # p_t follows


def test_the_paper_interval_is_the_default():
    assert EnvCfg().rand.rerandomize_interval_s == 10.0
