"""The environment's configuration in one module: :class:`EnvCfg` and every part of it.

Parts: simulation (:class:`SimCfg`), velocity commands and their curriculum (:class:`CommandCfg`), domain
randomisation (:class:`DomainRandCfg`, procedural geometry :class:`GeometryRandCfg`), observations
(:class:`ObsCfg`), terminations (:class:`TerminationCfg`), the gait clock (:class:`GaitCfg`) and the reward weights
and parameters (:class:`RewardCfg`; the terms that read them are the objects of :data:`morfic_cli.envs.rewards.TERMS`).
Every config is a frozen dataclass with documented attributes (unit, default); this module imports nothing of
morfic's, so every module may import it.
The resolved config is serialised as sorted-key JSON into run manifests (:func:`to_dict`); training presets are
factory functions in :mod:`morfic_cli.rl.config`, where ``--set`` overrides fail on unknown keys.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from _typeshed import DataclassInstance


def _default_threads() -> int:
    return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class SimCfg:
    """Physics backend settings (docs/concepts.md)."""

    backend: str = "cpu"
    """"cpu" (MuJoCo C, one MjModel per env, all cores) or "warp" (MuJoCo Warp, per-world model fields, on
    ``device``; alias "gpu"). ``--device cuda`` selects "warp" on the GPU."""
    num_threads: int = field(default_factory=_default_threads)
    """Worker threads of the CPU backend (default: every core)."""
    physics_dt: float = 0.005
    """Physics time step (s)."""
    device: str = "cpu"
    """Torch device of the tensors the backend returns ("cpu", "cuda", "cuda:N"); the warp backend also
    simulates on it."""


def to_dict(cfg: DataclassInstance) -> dict:
    """A config as a plain, JSON-serialisable dict (nested dataclasses included)."""
    return dataclasses.asdict(cfg)


@dataclass(frozen=True)
class CommandCfg:
    """Velocity commands c = (vx, vy, yaw rate) and their curriculum (docs/concepts.md)."""

    resample_time_s: float = 10.0
    """Commands are resampled every this many seconds (and at reset)."""
    vx_init: tuple[float, float] = (-1.0, 1.0)
    """Initial forward-velocity range (m/s)."""
    vx_limit: tuple[float, float] = (-1.0, 3.0)
    """Widest forward-velocity range the curriculum reaches (m/s); 2.0 and 2.5 m/s evaluations lie inside."""
    vy: tuple[float, float] = (-0.6, 0.6)
    """Lateral-velocity range (m/s)."""
    yaw_rate: tuple[float, float] = (-1.0, 1.0)
    """Yaw-rate range (rad/s)."""
    curriculum_step: float = 0.5
    """How much each end of the vx range widens per curriculum update (m/s)."""
    curriculum_threshold: float = 0.8
    """Widen (checked once per max episode length) when the finished episodes' r_lin, summed and divided by the
    max episode length, reaches this fraction of its maximum (legged_gym's rule: a fall counts as poor tracking)."""
    zero_fraction: float = 0.1
    """Fraction of envs commanded to stand still, so standing is learned too."""
    small_command: float = 0.1
    """Planar commands below this norm (m/s) are set to zero."""
    fixed: tuple[float, float, float] | None = None
    """When set, every env is always commanded exactly this (vx, vy, yaw rate) (evaluation); ranges are ignored."""


@dataclass(frozen=True)
class GeometryRandCfg:
    """Procedural geometry: robots generated around the template (docs/robots.md, "Procedural geometry").

    GenLoco's generator (Feng et al. 2022), by :mod:`morfic_cli.morphology.procedural`. Off by default. On
    (training only, the CPU backend), ``pool_size`` robots are generated and compiled when the env is built and
    every env draws one of them, uniformly, at each reset; the descriptor each env reports (and z_m) is its
    robot's. Ranges are (low, high) factors, uniform; lengths are also multiplied by ``scale`` and
    masses by ``scale``^3. The defaults are GenLoco's.
    """

    enabled: bool = False
    """Generate robots (train mode with ``DomainRandCfg.enabled``; evaluation never does)."""
    pool_size: int = 256
    """K, the robots generated and compiled once per env construction."""
    scale: tuple[float, float] = (0.8, 1.2)
    """Global scale s of every length (GenLoco U(0.8, 1.2))."""
    base_size: tuple[float, float] = (0.5, 1.5)
    """Factor of each base box dimension, drawn per dimension (GenLoco: A1's box +-50 %)."""
    base_density: tuple[float, float] = (0.5, 1.5)
    """Factor of the base density; base mass = nominal x density factor x volume ratio (GenLoco +-50 %)."""
    hip_pos: tuple[float, float] = (0.9, 1.1)
    """Extra factor of the hip joints' x and y (which follow the box) and of the lateral hip-to-thigh offset
    (GenLoco U(0.9, 1.1))."""
    link_length: tuple[float, float] = (0.5, 1.5)
    """Factor of the calf (lower leg) length (GenLoco +-50 %)."""
    thigh_length_ratio: tuple[float, float] = (0.75, 1.25)
    """Thigh length factor over the calf's (GenLoco: upper = lower x U(0.75, 1.25))."""
    link_radius: tuple[float, float] = (0.5, 1.5)
    """Factor of the calf capsule radius; the foot sphere follows it (GenLoco +-50 %)."""
    thigh_radius_ratio: tuple[float, float] = (0.75, 1.25)
    """Thigh radius factor over the calf's (GenLoco U(0.75, 1.25))."""
    link_mass: tuple[float, float] = (0.5, 1.5)
    """Factor of the hip, thigh, calf and foot masses, one per link type, before x scale^3 (GenLoco +-50 %)."""
    gains_with_mass: bool = True
    """Kp and Kd x total mass / nominal total mass, as GenLoco sets them (a deployer's rule)."""
    torque_with_mass: bool = False
    """Torque limits x total mass / nominal total mass too (GenLoco keeps the motors: off)."""
    min_base_clearance: float = 0.05
    """A robot whose base box bottom would stand lower than this above the ground (m) at the default pose is
    drawn again (it would touch the ground and end every episode)."""
    limits_from_support: bool = False
    """Draw each env's joint limits from the paper's training support at every reset (as train mode does without
    geometry); False keeps the template's limits (GenLoco)."""


@dataclass(frozen=True)
class ActuationRandCfg:
    """Heavier bodies and the actuators that carry them, with a morphology curriculum (docs/training.md, issue 58).

    Off by default. On (train mode with ``DomainRandCfg.enabled``, the CPU backend), at every reset each env's link
    and base masses (the descriptor's five, of the support sample or of its generated robot) are multiplied by one
    factor s_m, log-uniform in [``mass_scale[0]``, the current upper bound]; then Kp and Kd are set as a deployer
    sets them, the template's x (M / M_template) (M: the env's total mass after scaling), and the torque limits the
    template's x (M / M_template)^``torque_mass_exponent``, each times a log-uniform jitter factor
    (:mod:`morfic_cli.envs.actuation`). The curriculum starts the upper bound at ``curriculum_init`` and multiplies
    it by ``curriculum_step`` whenever the finished episodes' tracking (the command curriculum's measure) reaches
    ``curriculum_threshold``, up to ``mass_scale[1]``; without it the whole range is used from the start (the fixed
    wide support).
    """

    enabled: bool = False
    """Scale masses and set gains and torque limits at every reset (train mode only; evaluation never does)."""
    mass_scale: tuple[float, float] = (1.0, 1.0)
    """Range of the total-mass factor s_m, log-uniform (e.g. (0.8, 4.0): B1's 62.6 kg is Go2's 16.1 kg x 3.9)."""
    gains_with_mass: bool = True
    """Kp and Kd = the template's x M / M_template (a deployer's rule: the same stiffness per kilogram)."""
    torque_mass_exponent: float = 0.75
    """Torque limits = the template's x (M / M_template)^this. 0.75: a log-log fit of the seven robots' torque
    limits (robots/*.toml) against their total masses gives 0.72-0.74 (hip, thigh, calf; docs/robots.md, "Extended
    descriptor"), between geometric similarity's 2/3 and the same torque per kilogram (1); 0 keeps the motors."""
    kp_factor: tuple[float, float] = (1.0, 1.0)
    """Log-uniform jitter of Kp around the mass rule (real robots set 1-3x Go2's stiffness per kilogram)."""
    kd_factor: tuple[float, float] = (1.0, 1.0)
    """Log-uniform jitter of Kd around the mass rule."""
    torque_factor: tuple[float, float] = (1.0, 1.0)
    """Log-uniform jitter of the torque limits around the mass rule."""
    curriculum: bool = False
    """Widen the mass range's upper bound as the policy masters it (the paper's suggested morphology curriculum)."""
    curriculum_init: float = 1.25
    """The upper bound of s_m at the start of training (with ``curriculum``)."""
    curriculum_step: float = 1.25
    """Factor by which the upper bound grows per widening (a step of log 1.25 in log-mass width)."""
    curriculum_threshold: float = 0.7
    """Widen (checked once per max episode length, with the command curriculum) when the finished episodes' r_lin
    summed over the max episode length reaches this fraction of its maximum (a fall counts as poor tracking)."""


@dataclass(frozen=True)
class DomainRandCfg:
    """Domain randomisation (docs/concepts.md; paper appendix "Domain Randomization")."""

    enabled: bool = True
    """Master switch (evaluation turns it off)."""
    friction: tuple[float, float] = (0.5, 1.25)
    """Ground friction coefficient, uniform (paper)."""
    restitution: tuple[float, float] = (0.0, 0.4)
    """Contact restitution, uniform; mapped to the contact damping ratio by the backend."""
    com_offset: float = 0.03
    """Base centre-of-mass offset, uniform in [-x, x] per axis (m)."""
    joint_friction: tuple[float, float] = (0.0, 0.2)
    """Joint dry friction (N m), uniform per joint."""
    rerandomize_interval_s: float = 10.0
    """Friction, restitution, COM offset and joint friction are drawn again every this many seconds of an episode
    (and at reset), as the paper re-randomises rigid-body and contact properties periodically "with the interval
    10 s". 0 draws them at reset only (morfic before this field; runs recorded without it read as 0)."""
    push_interval_s: float = 15.0
    """Seconds between pushes (paper: 15 s)."""
    push_vel: float = 1.0
    """Maximum planar push velocity per axis (m/s) (paper: 1.0)."""
    pushes: bool = True
    """Whether pushes happen at all (evaluation turns them off)."""
    max_latency_steps: int = 6
    """Action latency sampled per episode in 0..max policy steps (paper: up to 6)."""
    init_joint_scale: tuple[float, float] = (0.5, 1.5)
    """Reset joint positions are the default pose times this uniform factor (clamped into limits)."""
    random_reset_pose: bool = True
    """Apply ``init_joint_scale`` at reset even when ``enabled`` is off, so evaluation envs start apart (else
    the N envs of an evaluation would be identical copies and their spread meaningless)."""
    geometry: GeometryRandCfg = field(default_factory=GeometryRandCfg)
    """Procedural geometry (off by default)."""
    actuation: ActuationRandCfg = field(default_factory=ActuationRandCfg)
    """Heavier masses, gains and torque limits with mass, and the morphology curriculum (off by default)."""


@dataclass(frozen=True)
class ObsCfg:
    """Observation scales and noise (legged_gym conventions)."""

    lin_vel_scale: float = 2.0
    ang_vel_scale: float = 0.25
    joint_pos_scale: float = 1.0
    joint_vel_scale: float = 0.05
    command_scale: tuple[float, float, float] = (2.0, 2.0, 0.25)
    noise: bool = True
    """Add uniform sensor noise to the actor's observations (the critic's are clean)."""
    noise_lin_vel: float = 0.1
    noise_ang_vel: float = 0.2
    noise_gravity: float = 0.05
    noise_joint_pos: float = 0.01
    noise_joint_vel: float = 1.5
    history_len: int = 15
    """|h_t|, the number of past observations in the history (paper: 15)."""
    history_includes_current: bool = False
    """False (the paper's h_t = {o_{t-k}}, k = 1..15, Table "Observation streams"): the ``history`` and ``critic``
    groups hold [o_{t-15}, ..., o_{t-1}, o_t], the 15 previous observations followed by the current one, so the
    networks see both of the paper's streams o_t and h_t (16 x 48). True: the groups hold o_{t-14..t}, 15 entries
    with o_t the newest (morfic before this field; runs recorded without it read as True)."""
    clip: float = 100.0
    """Observations are clipped to [-clip, clip]."""
    extended_morphology: bool = False
    """The ``morphology`` group carries the extended descriptor (N, 28: the 11-D descriptor, total mass, Kp, Kd,
    torque limits and geometry), log-scaled and bounded (:func:`morfic_cli.envs.observations.extended_morphology_obs`,
    docs/robots.md, "Extended descriptor") instead of the paper's normalised 11-D descriptor (False)."""
    body_tokens: bool = False
    """Also give URMA's per-joint and per-foot groups ``joint_description``, ``foot_description`` and ``foot_state``
    (:mod:`morfic_cli.envs.observations`; variant ``urma`` turns it on; CPU backend only)."""


@dataclass(frozen=True)
class TerminationCfg:
    """When an episode ends early (docs/concepts.md)."""

    contact_force: float = 1.0
    """Ground force (N) on the base or a thigh that ends the episode."""
    max_tilt_rad: float = 1.0
    """Tilt of the base (angle between its z axis and world up) that ends the episode."""
    min_height_fraction: float = 0.35
    """Episode ends when the base falls below this fraction of its nominal height."""


@dataclass(frozen=True)
class GaitCfg:
    """A periodic gait schedule (default: trot)."""

    frequency: float = 3.0
    """Gait frequency f (Hz). Default 3 Hz: walk-these-ways' default trot (its range is 2-4 Hz); at
    duty 0.5 the stance lasts 1/6 s, a stride of v/6 m at speed v (0.42 m at 2.5 m/s)."""
    offsets: tuple[float, float, float, float] = (0.0, 0.5, 0.5, 0.0)
    """Phase offset of each foot, FL, FR, RL, RR (periods). Trot: FL and RR together, FR and RL
    half a period later."""
    duty: float = 0.5
    """Duty factor: fraction of the period each foot is in stance, in (0, 1)."""
    kappa: float = 0.07
    """Smoothing width of the desired-contact indicator, in (normalised) periods
    (walk-these-ways' ``kappa_gait_probs``)."""


@dataclass(frozen=True)
class RewardCfg:
    """Weights and parameters of every reward term (the paper gives no weights; these are ours).

    Weights are non-negative; the group in :data:`TERMS` gives the sign (penalties subtracted).
    A weight of 0 skips the term. Defaults are set so that a quadruped learns to trot on flat
    ground with PPO: velocity tracking dominates (r_lin at most 4 w_lin = 4 per second, r_yaw 2),
    the stability terms add a bounded positive bonus (at most 2), and every penalty is small at
    a normal trot, so the per-step reward stays positive and falling over (which ends the
    episode) is never attractive. Magnitudes follow legged_gym /
    walk-these-ways / mjlab for the terms they share (docs/rewards.md gives the source of each weight).
    """

    # ---- task / tracking (added) ----
    w_lin: float = 1.0
    """r_lin, linear-velocity tracking (task, +). 1.0 like legged_gym / walk-these-ways; with the
    paper's factor 4 the term is worth up to 4, the largest in the sum."""
    w_yaw: float = 2.0
    """r_yaw, yaw-rate tracking (task, +). Half of r_lin's maximum (4), the 2:1 lin/yaw ratio of
    legged_gym (1.0 / 0.5)."""
    w_gaitF: float = 0.0
    """r_gaitF, no force on swing feet (task, +; the term itself is <= 0). Off (0) by default: it follows the
    gait clock, which no observation group carries, so no critic could predict it (docs/rewards.md, "Gait-clock
    terms"). Runs before this default trained with 2.0 (walk-these-ways' 4 halved) and record it."""
    w_gaitV: float = 0.0
    """r_gaitV, no velocity of stance feet (task, +; term <= 0). Off by default like ``w_gaitF`` (was 2.0)."""
    w_jump: float = 10.0
    """r_jump, base-height tracking with h_cmd = 0 (task, +; term <= 0). walk-these-ways' 10: a
    5 cm height error costs 0.025."""

    # ---- penalties (subtracted) ----
    w_vz: float = 2.0
    """p_vz, vertical base velocity (penalty, -). legged_gym's lin_vel_z 2.0."""
    w_omega_xy: float = 0.05
    """p_omega_xy, roll/pitch rate (penalty, -). legged_gym's ang_vel_xy 0.05."""
    w_ori: float = 1.0
    """p_ori, base tilt ||g_xy||^2 (penalty, -). Mild (Playground 5, legged_gym 0) because
    r_upright already rewards an upright base; a 0.3 rad tilt costs 0.087."""
    w_tau: float = 1e-4
    """p_tau, joint torques (penalty, -). walk-these-ways' 1e-4 (legged_gym Go2 2e-4): ~0.06 at
    a trot with ~7 N m per joint."""
    w_qddot: float = 2.5e-7
    """p_qddot, joint accelerations (penalty, -). legged_gym's dof_acc 2.5e-7."""
    w_da: float = 0.01
    """p_da, action rate (penalty, -). legged_gym's action_rate 0.01 (same 0.25 action scale)."""
    w_coll: float = 1.0
    """p_coll, number of base/thigh/calf bodies touching the ground (penalty, -). legged_gym's
    collision 1.0; base and thigh contacts also end the episode."""
    w_jl: float = 10.0
    """p_jl, joint-limit excess in rad (penalty, -). legged_gym A1/Go2 and walk-these-ways 10:
    excesses are small numbers of radians, so the weight is large."""
    w_slip: float = 0.05
    """p_slip, planar speed^2 of contact feet (penalty, -). walk-these-ways' feet_slip 0.04,
    mjlab / Playground 0.1."""
    w_impact: float = 0.05
    """p_impact, downward foot speed^2 just before contact (penalty, -). Same size as ``w_slip``
    (walk-these-ways ships 0): a 0.7 m/s touchdown costs 0.025 per foot."""
    w_f: float = 0.01
    """p_f, foot force above ``f_max_factor`` body weights, in N (penalty, -). legged_gym's
    feet_contact_forces term (its weight is 0 there); 0.01 makes a 50 N excess cost 0.5."""
    w_q: float = 0.05
    """p_q, deviation from the default pose (penalty, -). Small (mjlab / Playground reward the pose
    with weight 0.5-1): keeps the hips near default without forbidding the trot's joint swing."""
    w_qdot: float = 1e-4
    """p_qdot, joint speeds (penalty, -). walk-these-ways' dof_vel 1e-4."""
    w_raibert: float = 0.0
    """r_raibert, squared distance of the feet from the Raibert footholds (penalty, -: the table
    defines it as a non-negative distance, so it is subtracted). Off by default like ``w_gaitF``: its
    footholds follow the unobserved gait clock (was 5.0, walk-these-ways' 10 halved)."""

    # ---- stability shaping (added) ----
    w_upright: float = 1.0
    """r_upright, eq. (upright_stability) (stability, +). mjlab's upright 1.0."""
    w_cop: float = 0.5
    """r_cop, eq. (cop_stability) (stability, +). Half of r_upright: in a trot the CoP sits between
    the two diagonal feet, so this rewards an even load split without dominating."""
    w_width: float = 0.5
    """r_width, eq. (stance_width) (stability, +). Constant 1 unless the gate is on, so it only
    matters when tilted or fast; 0.5 like r_cop."""

    # ---- term parameters ----
    sigma_lin: float = 0.25
    """sigma_lin of r_lin ((m/s)^2): legged_gym's tracking_sigma."""
    sigma_yaw: float = 0.25
    """sigma_yaw of r_yaw ((rad/s)^2): legged_gym's tracking_sigma."""
    theta0: float = 0.3
    """theta0 of r_upright (rad), the paper's value: a tilt of theta0 gives exp(-1)."""
    tau_cop: float = 0.10
    """tau of r_cop (m), the paper's value."""
    eta: float = 0.05
    """eta of the width gate, eq. (width_gate): the gate opens when ||g_xy||^2 > eta (a tilt of
    about 0.23 rad, 13 degrees)."""
    v_th: float = 1.0
    """v_th of the width gate (m/s): the gate opens when the planar base speed exceeds it."""
    w_min_ratio: float = 0.8
    """w_min of r_width as a fraction of the nominal stance width (from ``nominal_foot_pos_b``), so
    it follows each robot's geometry; 0.8 lets the feet come 20% inside the hips for free."""
    sigma_w: float = 0.05
    """sigma_w of r_width (m): 5 cm narrower than w_min gives exp(-1)."""
    sigma_F: float = 100.0
    """sigma_F of r_gaitF (N^2): walk-these-ways' gait_force_sigma."""
    sigma_V: float = 10.0
    """sigma_V of r_gaitV ((m/s)^2): walk-these-ways' gait_vel_sigma."""
    f_max_factor: float = 1.5
    """f_max of p_f as a multiple of body weight (total_mass * g), so it scales with morphology
    mass; a trotting foot carries about half to one body weight."""
    collision_force: float = 0.1
    """Force (N) above which a body counts as colliding in p_coll (the paper's table: 0.1)."""
    impact_clip: float = 100.0
    """p_impact clips the previous foot z-velocity to [-impact_clip, 0] (m/s), the table's 100."""
    h_cmd: float = 0.0
    """h_cmd of r_jump (m): the commanded extra height; 0 (no jumping) as in the paper."""
    gait_duty: float = 0.5
    """Duty factor of the gait r_raibert assumes; must match ``GaitCfg.duty``."""
    raibert_kv: float = 0.0
    """Raibert's velocity-feedback gain k_v (s): x_des += k_v (v - v_cmd). 0 = walk-these-ways
    (pure feed-forward footholds)."""


@dataclass(frozen=True)
class EnvCfg:
    """The locomotion environment (docs/concepts.md)."""

    num_envs: int = 64
    decimation: int = 4
    """Physics steps per policy step (50 Hz policy at dt 0.005)."""
    episode_length_s: float = 20.0
    """Episode length (s): 1000 policy steps."""
    action_scale: float = 0.25
    """Joint target = q0 + action_scale * a."""
    action_clip: float = 100.0
    """Actions are clipped to [-clip, clip] before scaling."""
    sim: SimCfg = field(default_factory=SimCfg)
    commands: CommandCfg = field(default_factory=CommandCfg)
    rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    obs: ObsCfg = field(default_factory=ObsCfg)
    terminations: TerminationCfg = field(default_factory=TerminationCfg)
    rewards: RewardCfg = field(default_factory=RewardCfg)
    gait: GaitCfg = field(default_factory=GaitCfg)


def eval_env_cfg(cfg: EnvCfg) -> EnvCfg:
    """The evaluation variant of an env config: no pushes, no randomisation, no sensor noise (docs/eval.md).

    Evaluation simulates on the CPU backend whatever the run trained on (a run trained with
    ``--device cuda`` stores the warp backend on a GPU), so its numbers and rollout logs come from
    one simulator and the machine evaluating needs no GPU.
    """
    return dataclasses.replace(
        cfg,
        rand=dataclasses.replace(cfg.rand, enabled=False, pushes=False, max_latency_steps=0),
        obs=dataclasses.replace(cfg.obs, noise=False),
        sim=dataclasses.replace(cfg.sim, backend="cpu", device="cpu"),
    )
