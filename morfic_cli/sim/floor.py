"""Batched MuJoCo stepping in C, and the raw physics floor that ``morfic bench env`` compares against.

:class:`BatchStepper` is the stepping mechanism of the CPU backend: ``mujoco.rollout`` with a
persistent thread pool steps N (model, state) pairs, each env with its own ``MjModel``, entirely in
C across ``num_threads`` cores. The whole physics state of every env is one array of shape
(N, nstate) in MuJoCo's ``mjSTATE_FULLPHYSICS`` layout ``[time, qpos, qvel, act, ...]``, so resets
and pushes are array writes.

Why rollout: on the 2-core development machine (Go2 with the simulation sensors, standing, 4
physics steps per call, best of 3) it beat a persistent ``ThreadPoolExecutor`` whose workers call
``mj_step(m, d, 4)`` on per-env ``MjData`` and then gather qpos/qvel/sensordata:

=====  =======  =================  =====================
  N    threads  rollout (steps/s)  thread pool (steps/s)
=====  =======  =================  =====================
   64        1             49 000                 37 000
   64        2             71 000                 72 000
  256        1             43 000                 37 000
  256        2             88 000                 70 000
 1024        1             43 000                 36 000
 1024        2             69 000                 54 000
=====  =======  =================  =====================

Semantics worth knowing:

* Sensors: MuJoCo evaluates sensors inside ``mj_step`` *before* integrating, so the sensor values
  returned for a call belong to the start of its last physics step (position/velocity sensors lag
  the returned state by one physics step; force sensors are the forces applied during that step).
* Warm start: every call starts the constraint solver from a zero warm start (rollout cannot
  return the final warm start), so results depend only on (model, state, control): deterministic and
  independent of the thread count.
* Instability: when MuJoCo flags a warning (NaN/Inf/huge qpos, qvel or qacc, full arenas) inside a
  call it resets that env's data (time back to 0) and rollout stops stepping it. The env's time then
  differs from ``t0 + nsteps * dt``, which is how :meth:`BatchStepper.step` reports it. The one
  ambiguous case (t0 = 0, ``nsteps = 1``: a reset env that diverges in its very first step ends at
  time dt either way) is caught by the warning messages themselves: when MuJoCo warned but no env's
  time is off, every env that started at time 0 is reported (a rare, harmless over-report: those
  envs are merely reset).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import mujoco
import numpy as np
from mujoco import rollout

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
"""The state layout of :class:`BatchStepper`: time, qpos, qvel, act (and history, plugin state)."""


class BatchStepper:
    """Step N envs in C with ``mujoco.rollout`` and a persistent thread pool.

    Args:
        models: One model per env (the same object may repeat); all must have the same sizes.
        num_threads: Worker threads; 1 runs on the calling thread.
    """

    def __init__(self, models: Sequence[mujoco.MjModel], num_threads: int) -> None:
        if not models:
            raise ValueError("BatchStepper needs at least one model.")
        self.models = list(models)
        self.num_threads = max(1, int(num_threads))
        m0 = self.models[0]
        self.nstate = mujoco.mj_stateSize(m0, STATE_SPEC)
        self.nu, self.nv, self.nsensordata = m0.nu, m0.nv, m0.nsensordata
        for m in self.models[1:]:
            if (mujoco.mj_stateSize(m, STATE_SPEC), m.nu, m.nv, m.nsensordata) != (
                self.nstate,
                self.nu,
                self.nv,
                self.nsensordata,
            ):
                raise ValueError("BatchStepper models must have the same state, control and sensor sizes.")
        nthread = self.num_threads if self.num_threads > 1 else 0
        self._rollout: rollout.Rollout | None = rollout.Rollout(nthread=nthread)
        self._datas = [mujoco.MjData(m0) for _ in range(self.num_threads)]
        self._warmstart = np.zeros((len(self.models), self.nv))
        self._dt = np.array([m.opt.timestep for m in self.models])
        self._buffers: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.warnings: list[str] = []
        """MuJoCo warning messages raised during the last :meth:`step` call."""

    @property
    def num_envs(self) -> int:
        """Number of envs N."""
        return len(self.models)

    def _buffers_for(self, nsteps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if nsteps not in self._buffers:
            n = self.num_envs
            self._buffers[nsteps] = (
                np.empty((n, nsteps, self.nu)),
                np.empty((n, nsteps, self.nstate)),
                np.empty((n, nsteps, self.nsensordata)),
            )
        return self._buffers[nsteps]

    def step(self, state: np.ndarray, ctrl: np.ndarray, nsteps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance every env ``nsteps`` physics steps holding ``ctrl``.

        Args:
            state: Initial states (``mjSTATE_FULLPHYSICS``). Shape: (N, nstate), float64.
            ctrl: Controls held for the whole call. Shape: (N, nu).
            nsteps: Physics steps, >= 1.

        Returns:
            ``(state, sensordata, ok)``: the final states, shape (N, nstate); the sensor values of
            the last step, shape (N, nsensordata) (views into internal buffers, valid until the next
            call); and ``ok``, False where MuJoCo flagged a warning (and reset the env) during the
            call, shape (N,).
        """
        if self._rollout is None:
            raise RuntimeError("BatchStepper.step called after close().")
        nsteps = int(nsteps)
        if nsteps < 1:
            raise ValueError(f"nsteps must be >= 1, got {nsteps}.")
        control, out_state, out_sensor = self._buffers_for(nsteps)
        control[:] = np.asarray(ctrl, dtype=np.float64)[:, None, :]
        initial = np.ascontiguousarray(state, dtype=np.float64)
        expected = initial[:, 0].copy()
        for _ in range(nsteps):  # the same float64 additions as MuJoCo's `time += timestep`
            expected = expected + self._dt
        with _collect_warnings() as messages:
            self._rollout.rollout(
                self.models,
                self._datas,
                initial,
                control,
                skip_checks=True,
                nstep=nsteps,
                initial_warmstart=self._warmstart,
                state=out_state,
                sensordata=out_sensor,
            )
        self.warnings = messages
        final = out_state[:, -1]
        ok = final[:, 0] == expected
        if messages and ok.all():  # the t0 = 0, nsteps = 1 case (module docstring)
            ok &= initial[:, 0] != 0.0
        return final, out_sensor[:, -1], ok

    def close(self) -> None:
        """Stop the thread pool."""
        if self._rollout is not None:
            self._rollout.close()
            self._rollout = None


@contextmanager
def _collect_warnings() -> Iterator[list[str]]:
    """Route MuJoCo warnings into a list while stepping (instead of stdout and MUJOCO_LOG.TXT)."""
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


def home_state(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """State and controls of the ``home`` keyframe (or ``qpos0`` when the model has none).

    Args:
        model: The model.
        data: Scratch data for ``model`` (overwritten).

    Returns:
        ``(state, ctrl)``, shapes (nstate,) and (nu,).
    """
    if model.nkey > 0:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    else:
        mujoco.mj_resetData(model, data)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return state, data.ctrl.copy()


def physics_floor(
    models: Sequence[mujoco.MjModel],
    nsteps: int,
    num_threads: int,
    *,
    decimation: int = 4,
    ctrl_noise: float = 0.0,
    seed: int = 0,
) -> float:
    """Raw physics throughput: every model stepped ``nsteps`` physics steps in C, no env logic.

    Each env starts at its ``home`` keyframe holding the keyframe's controls (a standing robot),
    and is stepped ``decimation`` physics steps per call, the same mechanism and granularity as the
    CPU backend. One call is made first to start the thread pool and is not timed. A standing robot
    is the cheapest workload (few contacts, fast solver convergence); ``ctrl_noise`` adds Gaussian
    noise to the targets at every call so the physics work resembles an env driven by random
    actions (the robots stumble and fall), which can halve the rate.

    Args:
        models: One model per env.
        nsteps: Physics steps per env to time (rounded up to a multiple of ``decimation``).
        num_threads: Worker threads.
        decimation: Physics steps per rollout call.
        ctrl_noise: Standard deviation (rad) of the noise added to the home controls per call.
        seed: Seed of that noise.

    Returns:
        Physics steps per second, summed over envs.
    """
    stepper = BatchStepper(models, num_threads)
    rng = np.random.default_rng(seed)
    try:
        data = mujoco.MjData(stepper.models[0])
        homes = [home_state(m, data) for m in stepper.models]
        state = np.stack([s for s, _ in homes])
        home_ctrl = np.stack([c for _, c in homes])
        calls = max(1, -(-int(nsteps) // decimation))
        ctrls = [
            home_ctrl + ctrl_noise * rng.standard_normal(home_ctrl.shape) if ctrl_noise else home_ctrl
            for _ in range(calls + 1)
        ]
        state[:] = stepper.step(state, ctrls[0], decimation)[0]
        start = time.perf_counter()
        for ctrl in ctrls[1:]:
            state[:] = stepper.step(state, ctrl, decimation)[0]
        elapsed = time.perf_counter() - start
    finally:
        stepper.close()
    return stepper.num_envs * calls * decimation / elapsed


class StepRecorder:
    """Record every ``BatchStepper.step`` call (inputs only) so the same physics can be replayed.

    Used by ``morfic bench env``: the env's own calls are recorded during the timed run, then
    :func:`replay_floor` times exactly those calls (same models, states, controls, step counts) with
    no env logic around them: the raw physics floor of that very workload.

    Args:
        stepper: The stepper whose calls to record (its ``step`` is wrapped until :meth:`stop`).
    """

    def __init__(self, stepper: BatchStepper) -> None:
        self.stepper = stepper
        self.calls: list[tuple[np.ndarray, np.ndarray, int]] = []
        self._inner = stepper.step

        def _recording_step(state: np.ndarray, ctrl: np.ndarray, nsteps: int):
            self.calls.append((np.array(state, dtype=np.float64), np.array(ctrl, dtype=np.float64), int(nsteps)))
            return self._inner(state, ctrl, nsteps)

        stepper.step = _recording_step  # type: ignore[method-assign]

    def stop(self) -> None:
        """Stop recording (restore the stepper's own ``step``)."""
        self.stepper.step = self._inner  # type: ignore[method-assign]


def replay_floor(
    models: Sequence[mujoco.MjModel], calls: Sequence[tuple[np.ndarray, np.ndarray, int]], num_threads: int
) -> float:
    """Time recorded stepping calls on a fresh stepper: physics steps per second, summed over envs.

    Args:
        models: The models the calls were made with (one per env).
        calls: ``(state (N, nstate), ctrl (N, nu), nsteps)`` per call, as recorded by :class:`StepRecorder`.
        num_threads: Worker threads.

    Returns:
        Physics steps per second.
    """
    if not calls:
        raise ValueError("replay_floor needs at least one recorded call.")
    stepper = BatchStepper(models, num_threads)
    try:
        stepper.step(*calls[0])  # start the thread pool, untimed
        t0 = time.perf_counter()
        for state, ctrl, nsteps in calls:
            stepper.step(state, ctrl, nsteps)
        wall = time.perf_counter() - t0
    finally:
        stepper.close()
    return sum(s.shape[0] * n for s, _, n in calls) / wall
