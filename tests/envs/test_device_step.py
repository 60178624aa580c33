"""The env step on the warp backend makes no host round trip (docs/gpu.md, "Device-resident step").

Run on warp's CPU device (no GPU needed): every way of reading a tensor or a warp array back to Python
(``.cpu()``, ``.numpy()``, ``.item()``, ``.tolist()``, numpy conversion, ``bool()``/``int()``/``float()`` of a
tensor, ``nonzero()``, ``wp.array.numpy()``) is patched to raise while ``LocomotionEnv.step`` runs, except inside
:mod:`morfic_cli.sim.sync` (the counted reads of a count or a flag). On a GPU each of those would be a transfer and a
wait for the device. The config makes every part of the step happen within a few dozen steps: resets (short
episodes), re-randomisation, pushes, command resampling, the curriculum, and a diverged world.
``MORFIC_WARP_TEST_DEVICE=cuda`` runs it with the warp backend on the GPU (without the CPU-backend comparison:
the GPU's generator draws other numbers), where the patched reads would be real device-to-host transfers.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp", reason="mujoco_warp is not installed (pip install 'morfic[gpu]')")

from morfic_cli.config import EnvCfg, SimCfg  # noqa: E402
from morfic_cli.envs.locomotion import LocomotionEnv  # noqa: E402
from morfic_cli.sim import sync  # noqa: E402

N = 6
DEVICE = os.environ.get("MORFIC_WARP_TEST_DEVICE", "cpu")
"""Where the warp backend runs: warp's CPU device (default, CI) or the GPU ("cuda")."""
READS_PER_STEP = 4
"""Counted reads per step: resets, command resampling, re-randomisation (env) and 'did a world diverge' (backend)."""


class HostRead(AssertionError):
    """A host read inside the step."""


@contextlib.contextmanager
def no_host_reads():
    """Make every host read of a tensor or warp array raise :class:`HostRead`, except inside :mod:`sync`."""
    import warp as wp

    targets = [
        (torch.Tensor, name)
        for name in (
            "cpu",
            "numpy",
            "item",
            "tolist",
            "__array__",
            "__bool__",
            "__int__",
            "__float__",
            "__index__",
            "nonzero",
        )
    ]
    targets += [(torch, "nonzero"), (wp.array, "numpy"), (wp.array, "list")]
    saved = [(owner, name, getattr(owner, name)) for owner, name in targets]

    def guard(name, original):
        def patched(*args, **kwargs):
            if not sync._inside:
                raise HostRead(f"host read inside the step: {name}")
            return original(*args, **kwargs)

        return patched

    for owner, name, original in saved:
        setattr(owner, name, guard(name, original))
    try:
        yield
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)


def _cfg(backend: str) -> EnvCfg:
    cfg = EnvCfg(num_envs=N, sim=SimCfg(num_threads=1, backend=backend, device=DEVICE if backend == "warp" else "cpu"))
    return dataclasses.replace(
        cfg,
        episode_length_s=0.4,  # 20 steps: time-outs and resets
        rand=dataclasses.replace(cfg.rand, push_interval_s=0.1, rerandomize_interval_s=0.14),
        commands=dataclasses.replace(cfg.commands, resample_time_s=0.1, curriculum_threshold=0.0),
    )


def test_the_guard_catches_host_reads():
    t = torch.ones(3)
    with no_host_reads():
        for read in (
            t.cpu,
            t.numpy,
            t[0].item,
            t.tolist,
            lambda: bool(t[0]),
            lambda: float(t[0]),
            lambda: np.asarray(t),
            t.nonzero,
        ):
            with pytest.raises(HostRead):
                read()
        assert sync.any_true(t > 0) and len(sync.nonzero_ids(t > 0)) == 3  # the counted reads go through
    assert t.tolist() == [1.0, 1.0, 1.0]


def test_the_warp_step_reads_nothing_back_and_matches_the_cpu_backend():
    warp_env, cpu_env = LocomotionEnv(_cfg("warp"), seed=0), LocomotionEnv(_cfg("cpu"), seed=0)
    try:
        gen = torch.Generator().manual_seed(0)
        dones = torch.zeros(N, dtype=torch.long)
        for step in range(45):
            a = 0.5 * (2 * torch.rand(N, 12, generator=gen) - 1)
            if step == 30:  # a diverged world: flagged, restored and reset on the device
                warp_env.backend._qpos[2, 2] = float("nan")
            reads = sync.reads
            with no_host_reads():
                obs, rew, done, extras = warp_env.step(a)
            assert sync.reads - reads <= READS_PER_STEP
            assert all(isinstance(v, torch.Tensor) and v.device == warp_env.device for v in extras["log"].values())
            assert obs["policy"].device == rew.device == done.device == warp_env.device
            dones += done.cpu()
            if step < 10 and DEVICE == "cpu":  # before the first reset: the same draws, the CPU backend's numbers
                oc, rc, dc, _ = cpu_env.step(a)
                assert torch.equal(done, dc)
                torch.testing.assert_close(obs["critic"], oc["critic"], rtol=0, atol=2e-2)
                torch.testing.assert_close(obs["privileged"], oc["privileged"], rtol=0, atol=1e-6)
                torch.testing.assert_close(obs["morphology"], oc["morphology"], rtol=0, atol=1e-6)
                torch.testing.assert_close(rew, rc, rtol=0, atol=1e-2)
        assert (dones >= 2).all(), "every env was reset in the step at least twice"
        assert warp_env.nonfinite_resets == 1
        assert float(warp_env.command_ranges.vx[1]) > warp_env.cfg.commands.vx_init[1], "the curriculum ran"
        for key in ("policy", "history", "critic", "privileged", "morphology"):
            assert torch.isfinite(obs[key]).all().cpu(), key
    finally:
        warp_env.close()
        cpu_env.close()
