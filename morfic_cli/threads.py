"""Thread settings of a morfic process: OpenMP threads sleep when idle instead of spinning.

torch runs its CPU kernels on an OpenMP (GNU libgomp) thread pool, one thread per core. At the end of every parallel
region a thread that has finished its share spins (busy-waits, up to ~300,000 iterations) for the others before it
sleeps. On an idle machine that saves a wake-up; on a shared one it is ruinous: when another process holds one of the
cores, the thread the others wait for is descheduled while they spin through their own time slices, and every one
of the thousands of parallel regions in a PPO update pays for it. Measured on the 2-core development machine under
a load average of ~10 (docs/benchmarks-history.md, "Competing load"): the cpu preset's PPO update took 31-36 s with the
default policy and 5-7 s with ``OMP_WAIT_POLICY=PASSIVE``.

libgomp reads the variable once, when it is loaded (the first ``import torch``), so :func:`configure_openmp` must run
before that; the ``morfic`` entry point calls it first thing. A value the user set is kept.
"""

from __future__ import annotations

import os

#: The OpenMP wait policy morfic uses unless ``OMP_WAIT_POLICY`` is already set.
OMP_WAIT_POLICY = "PASSIVE"


_SET_HERE = "_MORFIC_SET_OMP_WAIT_POLICY"
"""Marks (in the environment) that morfic, not the user, chose ``OMP_WAIT_POLICY``."""


def configure_openmp(environ: dict[str, str] | None = None) -> str:
    """Set ``OMP_WAIT_POLICY`` to :data:`OMP_WAIT_POLICY` unless it is set; returns the policy in effect.

    Args:
        environ: The environment to edit (default ``os.environ``; child processes inherit it).
    """
    env = os.environ if environ is None else environ
    if "OMP_WAIT_POLICY" not in env:
        env["OMP_WAIT_POLICY"] = OMP_WAIT_POLICY
        env[_SET_HERE] = "1"
    return env["OMP_WAIT_POLICY"]


def user_environment(environ: dict[str, str] | None = None) -> dict[str, str]:
    """A copy of the environment without what :func:`configure_openmp` added (for a child running other code)."""
    env = dict(os.environ if environ is None else environ)
    if env.pop(_SET_HERE, None):
        env.pop("OMP_WAIT_POLICY", None)
    return env
