"""``morfic play``: a trained policy walking in real time, shown live in Foxglove (or MuJoCo's viewer).

The env is the evaluation env (:func:`~morfic_cli.evaluation.rollout.rollout_env_cfg`: no randomisation, the
command fixed to (vx, 0, 0), episodes reset at falls and time-outs), the actor's mean action, one policy step per
``dt`` of wall-clock time (slower when the machine cannot keep up: :class:`PaceCheck` says so once). Each step goes
to the sinks: a :class:`~morfic_cli.recording.live.LiveView` (Foxglove WebSocket server), a rollout log
(``--record``, the same channels as ``morfic eval``'s logs) and/or MuJoCo's passive viewer (``--viewer``, env 0).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from morfic_cli.errors import MorficError

if TYPE_CHECKING:
    from morfic_cli.rl.load import TrainedModels


@dataclass(frozen=True)
class PlayCfg:
    """What ``morfic play`` runs and where it shows it."""

    robot: str = "go2"
    mode: str = "descriptor"
    command_vx: float = 1.0
    num_envs: int = 1
    seed: int = 0
    steps: int = 0
    """Policy steps to run; 0 = until Ctrl-C."""
    host: str = "127.0.0.1"
    port: int = 8765
    record: Path | None = None
    viewer: bool = False


class PaceCheck:
    """Whether a real-time loop keeps up: the achieved steps/s over windows of ``window_s``, reported once.

    ``update(steps, now)`` after each step (``steps`` run so far, ``now`` a ``time.perf_counter()`` reading) returns
    the achieved rate the first time a whole window ran below ``tolerance`` x the target ``1 / dt``, else None. The
    first window starts at the first call (after the first step, which opens the sinks).
    """

    def __init__(self, dt: float, window_s: float = 2.0, tolerance: float = 0.9) -> None:
        self.target = 1.0 / dt
        """Steps per second of real time."""
        self.window_s, self.tolerance = window_s, tolerance
        self.reported = False
        self._start: tuple[int, float] | None = None

    def update(self, steps: int, now: float) -> float | None:
        """The achieved steps/s of the window just ended, if it is the first one behind real time; else None."""
        if self._start is None:
            self._start = (steps, now)
            return None
        n0, t0 = self._start
        if now - t0 < self.window_s:
            return None
        self._start = (steps, now)
        rate = (steps - n0) / (now - t0)
        if self.reported or rate >= self.tolerance * self.target:
            return None
        self.reported = True
        return rate


def has_display() -> bool:
    """Whether a window can open (an X11 or Wayland display on Linux; assumed elsewhere)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def play(
    trained: TrainedModels,
    cfg: PlayCfg,
    *,
    on_ready: Callable[[Any], None] | None = None,
    on_step: Callable[[int], None] | None = None,
    on_behind: Callable[[float, float], None] | None = None,
) -> int:
    """Run the policy until ``cfg.steps`` steps or Ctrl-C.

    Ctrl-C (SIGINT) only asks the loop to stop after the current step, so the simulation, the server and the
    recording close cleanly whatever the step was doing; a second Ctrl-C interrupts at once.

    Args:
        trained: The checkpoint (:func:`~morfic_cli.rl.load.load_trained`).
        cfg: What to run and where to show it.
        on_ready: Called once the sinks are open, with the :class:`~morfic_cli.recording.live.LiveView`
            (None with ``--viewer``), e.g. to print the URL.
        on_step: Called with each step index.
        on_behind: Called once, with (achieved steps/s, real-time steps/s), when the machine cannot keep up
            (:class:`PaceCheck`: a 2 s window below 90 % of real time).

    Returns:
        The number of policy steps run.

    Raises:
        MorficError: ``--viewer`` without a display.
    """
    import torch

    from morfic_cli.envs.locomotion import LocomotionEnv
    from morfic_cli.evaluation.rollout import rollout_env_cfg, step_record
    from morfic_cli.recording.rollout_log import ROLLOUT_FIELDS, RolloutLogWriter
    from morfic_cli.recording.scene import RolloutScene
    from morfic_cli.sim.cpu import CpuBackend

    if cfg.viewer and not has_display():
        raise MorficError(
            "--viewer opens MuJoCo's window and needs a display (DISPLAY is not set); without "
            "--viewer, `morfic play` serves the live view to Foxglove instead."
        )
    env_cfg = rollout_env_cfg(trained.cfg.env, cfg.num_envs, 1, cfg.command_vx)
    env = LocomotionEnv(env_cfg, mode=cfg.mode, robot=cfg.robot, seed=cfg.seed)
    live = log = viewer = None
    steps_run = 0
    stop = threading.Event()

    def on_sigint(signum, frame) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_sigint) if in_main else None
    try:
        backend = env.backend
        assert isinstance(backend, CpuBackend)  # evaluation always simulates on the CPU backend (eval_env_cfg)
        models, info = backend.models[: cfg.num_envs], backend.info
        scene = RolloutScene(models, range(len(models)), info.qpos_adr)
        nominal = env.params.nominal_height.float()
        obs = env.get_observations()
        term_names = None
        pace = PaceCheck(env.dt)
        start = time.perf_counter()
        with torch.no_grad():
            while not stop.is_set() and (cfg.steps <= 0 or steps_run < cfg.steps):
                action = trained.actor(obs)
                value = trained.critic(obs).reshape(-1)
                obs, reward, done, extras = env.step(action)
                if term_names is None:
                    term_names = list(env.last_reward_terms)
                rec = step_record(env, action, value, reward, done, extras, nominal, term_names)
                data = {k: rec[k].detach().cpu().numpy() for k in ROLLOUT_FIELDS}
                t_s = (steps_run + 1) * env.dt
                if steps_run == 0:  # sinks open once the term names are known
                    meta = {
                        "run": trained.meta.get("run") or "",
                        "checkpoint": trained.checkpoint_id,
                        "robot": cfg.robot,
                        "mode": cfg.mode,
                        "command": [cfg.command_vx, 0.0, 0.0],
                        "seed": cfg.seed,
                        "source": "morfic play",
                    }
                    if cfg.record is not None:
                        log = RolloutLogWriter(
                            cfg.record, num_envs=cfg.num_envs, term_names=term_names, metadata=meta, scene=scene
                        )
                    if cfg.viewer:
                        viewer = _open_viewer(models[0])
                    else:
                        from morfic_cli.recording.live import LiveView

                        live = LiveView(
                            num_envs=cfg.num_envs, term_names=term_names, scene=scene, host=cfg.host, port=cfg.port
                        )
                    if on_ready is not None:
                        on_ready(live)
                if live is not None:
                    live.publish(steps_run, t_s, data)
                if log is not None:
                    log.write_step(steps_run, t_s, data)
                if viewer is not None:
                    if not viewer[0].is_running():
                        break
                    _sync_viewer(viewer, scene.qpos(data["base_pos"], data["base_quat"], data["joint_pos"])[0])
                steps_run += 1
                if on_step is not None:
                    on_step(steps_run - 1)
                now = time.perf_counter()
                behind = pace.update(steps_run, now)
                if behind is not None and on_behind is not None:
                    on_behind(behind, pace.target)
                delay = start + steps_run * env.dt - now
                if delay > 0:
                    stop.wait(delay)
    except KeyboardInterrupt:
        pass
    finally:
        if in_main:
            signal.signal(signal.SIGINT, previous)
        for closer in (live, log):
            if closer is not None:
                closer.close()
        if viewer is not None:
            viewer[0].close()
        env.close()
    return steps_run


def _open_viewer(model) -> tuple[Any, Any, Any]:
    """MuJoCo's passive viewer on ``model`` with its own data -> (handle, model, data)."""
    import mujoco
    import mujoco.viewer

    data = mujoco.MjData(model)
    return mujoco.viewer.launch_passive(model, data), model, data


def _sync_viewer(viewer: tuple[Any, Any, Any], qpos: np.ndarray) -> None:
    """Show ``qpos`` (nq,) in the passive viewer."""
    import mujoco

    handle, model, data = viewer
    with handle.lock():
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
    handle.sync()
