"""The curve logger: rsl-rl's ``Logger`` turned into one training-curve row per iteration.

:class:`CurveLogger` replaces the runner's logger (:func:`~morfic_cli.rl.rsl_rl_patches.replace_logger`); each
iteration's row goes to a callback (the training run), optionally mirrored to a live writer
(:mod:`morfic_cli.rl.live_log`). Its state travels in the trainer state, so curves continue exactly on resume.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from rsl_rl.utils.logger import Logger


class _NullWriter:
    """Stands in for rsl-rl's log writer so its Logger keeps its episode buffers; writes nothing."""


class CurveLogger(Logger):
    """rsl-rl's Logger, but each iteration becomes a curve row handed to ``on_iteration`` (no console dump).

    Its clock (:attr:`wall_time_s`) is the wall time the user waited for: from :meth:`start_clock` (the start of
    rsl-rl's ``learn``) on, checkpoints and logging included, added to the wall time of the run before a resume.
    rsl-rl's own ``tot_time`` (collection + learning only) is kept for what rsl-rl computes from it.
    """

    def __init__(
        self,
        *args: Any,
        dt: float,
        on_iteration: Callable[[dict[str, float]], None],
        live: tuple[str, Path] | None = None,
        **kwargs: Any,
    ):
        super().__init__(*args, **kwargs)
        self.dt = dt
        self.on_iteration = on_iteration
        self.wall_time_s = 0.0
        """Wall seconds of the run so far (over resumes), as of the last :meth:`clock` reading."""
        self._clock_start: float | None = None
        self._clock_base = 0.0
        self.live_cfg = live
        self.live: Any = None

    def start_clock(self, since: float | None = None) -> None:
        """Start counting wall time on top of :attr:`wall_time_s` (the time of the run before this process).

        Args:
            since: A ``time.perf_counter()`` reading to count from (``morfic train``: the command's start, so the
                imports and the env's construction count too); None: now.
        """
        self._clock_base = self.wall_time_s
        self._clock_start = time.perf_counter() if since is None else since

    def clock(self) -> float:
        """The run's wall seconds now (:attr:`wall_time_s` updated); before :meth:`start_clock`, the stored value."""
        if self._clock_start is not None:
            self.wall_time_s = self._clock_base + time.perf_counter() - self._clock_start
        return self.wall_time_s

    def stop_clock(self) -> float:
        """Read the clock a last time and stop it; returns the run's wall seconds."""
        wall = self.clock()
        self._clock_start = None
        return wall

    def init_logging_writer(self) -> None:
        """No rsl-rl writer, no git snapshot (the store keeps the run); the live writer, if one is configured."""
        self.writer = _NullWriter()
        if self.live_cfg is not None and self.live is None and not self.disable_logs:
            from morfic_cli.rl.live_log import open_writer

            kind, log_dir = self.live_cfg
            self.live = open_writer(kind, log_dir, self.cfg)

    def close_live(self) -> None:
        """Flush and close the live writer (reopened by the next :meth:`init_logging_writer`)."""
        if self.live is not None:
            (self.live.stop if hasattr(self.live, "stop") else self.live.close)()
            self.live = None

    def log(
        self,
        it: int,
        start_it: int,
        total_it: int,
        collect_time: float,
        learn_time: float,
        loss_dict: dict,
        learning_rate: float,
        action_std: torch.Tensor,
        rnd_weight: float | None,
        **_: Any,
    ) -> None:
        """Build the curve row of iteration ``it`` (0-based) and pass it on."""
        size = self.cfg["num_steps_per_env"] * self.num_envs
        self.tot_timesteps += size
        self.tot_time += collect_time + learn_time
        row: dict[str, float] = {
            "iteration": it + 1,
            "env_steps": self.tot_timesteps,
            "wall_time_s": self.clock(),
            "steps_per_s": size / max(collect_time + learn_time, 1e-9),
            "collect_s": collect_time,
            "learn_s": learn_time,
            "mean_reward": sum(self.rewbuffer) / len(self.rewbuffer) if self.rewbuffer else float("nan"),
            "episode_length_s": (sum(self.lenbuffer) / len(self.lenbuffer) * self.dt)
            if self.lenbuffer
            else float("nan"),
            "learning_rate": learning_rate,
            "action_std": float(action_std.detach().mean()),
        }
        row.update({k: float(v) for k, v in loss_dict.items()})
        by_key: dict[str, list[float]] = {}  # each log key's values over the iteration's steps
        for step_log in host_values(self.ep_extras):  # one device -> host read for the iteration's logs
            for key, value in step_log.items():
                by_key.setdefault(key, []).append(value)
        means = {key: sum(values) / len(values) for key, values in by_key.items()}
        for key, values in by_key.items():
            name = key.strip("/").replace("/", ".")
            if name.startswith("reward.") or name == "env.nonfinite_resets":
                continue  # per-step means; the episode means below are what the curve shows
            row[name] = max(values) if name == "curriculum.vx_max" else means[key]
        if self.live is not None:
            from morfic_cli.rl.live_log import write_iteration

            extras = means
            # before the first episode ends: the mean return and length so far of the episodes under way
            reward = (
                sum(self.rewbuffer) / len(self.rewbuffer)
                if self.rewbuffer
                else float(self.cur_reward_sum.float().mean())
            )
            length = (
                sum(self.lenbuffer) / len(self.lenbuffer)
                if self.lenbuffer
                else float(self.cur_episode_length.float().mean())
            )
            wall = None if self.live_cfg is not None and self.live_cfg[0] == "wandb" else self.wall_time_s  # as rsl-rl
            write_iteration(
                self.live,
                it,
                size,
                collect_time,
                learn_time,
                {k: float(v) for k, v in loss_dict.items()},
                learning_rate,
                float(action_std.detach().mean()),
                extras,
                reward,
                length,
                wall,
            )
        self.ep_extras.clear()
        self.on_iteration(row)

    def state_dict(self) -> dict[str, Any]:
        """The episode buffers and counters, for exact curves after a resume."""
        return {
            "rewbuffer": list(self.rewbuffer),
            "lenbuffer": list(self.lenbuffer),
            "cur_reward_sum": self.cur_reward_sum.clone(),
            "cur_episode_length": self.cur_episode_length.clone(),
            "tot_timesteps": self.tot_timesteps,
            "tot_time": self.tot_time,
            "wall_time_s": self.clock(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.rewbuffer = deque(state["rewbuffer"], maxlen=100)
        self.lenbuffer = deque(state["lenbuffer"], maxlen=100)
        self.cur_reward_sum.copy_(state["cur_reward_sum"])
        self.cur_episode_length.copy_(state["cur_episode_length"])
        self.tot_timesteps, self.tot_time = state["tot_timesteps"], state["tot_time"]
        self.wall_time_s = state["wall_time_s"]


def host_values(logs: list[dict[str, Any]]) -> list[dict[str, float]]:
    """Each step's log dict as floats, the tensors among them (0-d, on the env's device) read back in one transfer.

    The warp backend keeps its logs on the device (docs/gpu.md, "Device-resident step"); reading them one
    ``float()`` at a time would wait for the device once per value, about 60 x 24 times per iteration.
    """
    out: list[dict[str, float]] = [{} for _ in logs]
    tensors = []
    for i, log in enumerate(logs):
        for key, value in log.items():
            if isinstance(value, torch.Tensor):
                tensors.append((i, key, value.detach().reshape(()).to(torch.float64)))
            else:
                out[i][key] = float(value)
    if tensors:
        for (i, key, _), value in zip(tensors, torch.stack([t for _, _, t in tensors]).tolist(), strict=True):
            out[i][key] = value
    return out
