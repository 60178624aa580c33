"""The only places where the env step reads device data back to the host (docs/gpu.md, "Device-resident step").

On a GPU every read of a device value from Python (``.item()``, ``.cpu()``, ``bool(t)``, ``nonzero()``, boolean-mask
indexing) waits for the device to finish the work queued so far. The step of :class:`~morfic_cli.envs.locomotion.
LocomotionEnv` on the warp backend keeps observations, rewards, terminations, resets, randomisation and logs on the
device; what it must know on the host to decide *how much* work to queue (how many envs reset, whether a world
diverged) it reads through these two functions, and nowhere else. Each reads a count or a flag, never a batch of
values. ``tests/envs/test_device_step.py`` patches every other host read to raise inside the step and counts these.
"""

from __future__ import annotations

import torch

reads = 0
"""How many device reads these functions made since the process started (tests count them per step)."""

_inside = False
"""True while one of these functions reads (the no-transfer test lets reads through then)."""


def nonzero_ids(mask: torch.Tensor) -> torch.Tensor:
    """The indices where ``mask`` is true, on ``mask``'s device (one read: their count).

    Args:
        mask: Boolean mask. Shape: (N,).

    Returns:
        int64 indices in increasing order. Shape: (k,).
    """
    global reads, _inside
    reads += 1
    _inside = True
    try:
        return mask.nonzero(as_tuple=False).flatten()
    finally:
        _inside = False


def any_true(mask: torch.Tensor) -> bool:
    """Whether any element of ``mask`` is true (one read: one flag).

    Args:
        mask: Boolean mask. Shape: any.
    """
    global reads, _inside
    reads += 1
    _inside = True
    try:
        return bool(mask.any())
    finally:
        _inside = False
