"""The factory that picks a simulation backend by name (``SimCfg.backend``).

Kept apart from :mod:`morfic_cli.sim.backend` (the protocol and frame types the backends import), so the
backends and the protocol do not import each other. The warp backend module imports mujoco_warp only when a warp
backend is built.
"""

from __future__ import annotations

from morfic_cli.config import SimCfg
from morfic_cli.errors import MorficError
from morfic_cli.morphology.robots import RobotSpec
from morfic_cli.sim.backend import SimBackend
from morfic_cli.sim.cpu import CpuBackend
from morfic_cli.sim.warp import WarpBackend

#: Simulation backends: ``cpu`` (MuJoCo C) and ``warp`` (MuJoCo Warp on ``SimCfg.device``); ``gpu`` is an alias of
#: ``warp``.
BACKENDS: tuple[str, ...] = ("cpu", "warp", "gpu")


def make_backend(cfg: SimCfg, robot: RobotSpec, num_envs: int, *, template: bool) -> SimBackend:
    """Create the backend named by ``cfg.backend``.

    Args:
        cfg: Simulation config (backend name, threads, physics dt, device). ``warp`` (alias ``gpu``)
            runs MuJoCo Warp on ``cfg.device`` ("cpu" or "cuda").
        robot: The robot to build: the Go2 template (training and ``descriptor`` mode) or the
            target's own spec (``full`` mode).
        num_envs: Number of parallel envs N.
        template: True when per-env morphology may be applied (``set_morphology``).

    Returns:
        A :class:`SimBackend`.
    """
    if cfg.backend == "cpu":
        return CpuBackend(cfg, robot, num_envs, template=template)
    if cfg.backend in ("warp", "gpu"):
        return WarpBackend(cfg, robot, num_envs, template=template)
    raise MorficError(f"unknown simulation backend '{cfg.backend}'; valid backends are: {', '.join(BACKENDS)}.")
