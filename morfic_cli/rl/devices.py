"""Devices: where a training runs (cpu, cuda) and this process's place in a torchrun job."""

from __future__ import annotations

import dataclasses
import os

import torch

from morfic_cli.errors import MorficError
from morfic_cli.rl.config import TrainCfg, apply_overrides


def check_device(device: str) -> None:
    """Raise MorficError when ``device`` cannot train here.

    ``cuda`` needs a CUDA build of torch that sees a GPU and the optional warp backend
    (``pip install 'morfic[gpu]'``); under torchrun with more than one process it is the only choice
    (rsl-rl's distributed training uses NCCL).
    """
    dist = distributed_info()
    if device == "cpu":
        if dist.world_size > 1:
            raise MorficError(
                f"distributed training (torchrun, WORLD_SIZE={dist.world_size}) needs --device cuda: "
                "rsl-rl reduces gradients with NCCL; run a single process for --device cpu."
            )
        return
    if device == "cuda":
        if not torch.cuda.is_available():
            raise MorficError(
                "--device cuda: no CUDA device is available on this machine (or torch is a CPU "
                "build); train with --device cpu, or on a GPU machine with a CUDA build of torch and "
                "`pip install 'morfic[gpu]'`."
            )
        from morfic_cli.sim.warp import import_warp

        import_warp()  # MorficError with the install hint when mujoco_warp is missing
        return
    raise MorficError(f"unknown device '{device}'; valid devices are: cpu, cuda.")


@dataclasses.dataclass(frozen=True)
class DistributedInfo:
    """This process's place in a torchrun job (world size 1, rank 0 outside torchrun).

    Attributes:
        world_size: Processes in the job (``WORLD_SIZE``).
        rank: Global rank (``RANK``); only rank 0 writes to the store.
        local_rank: Rank on this node (``LOCAL_RANK``); the GPU ``cuda:LOCAL_RANK`` is this process's.
    """

    world_size: int
    rank: int
    local_rank: int


def distributed_info() -> DistributedInfo:
    """Read torchrun's environment variables (the ones rsl-rl's OnPolicyRunner reads too)."""
    return DistributedInfo(
        int(os.environ.get("WORLD_SIZE", "1")), int(os.environ.get("RANK", "0")), int(os.environ.get("LOCAL_RANK", "0"))
    )


def torch_device(device: str) -> str:
    """The torch device of this process: ``cuda`` becomes ``cuda:LOCAL_RANK`` (what rsl-rl expects under torchrun)."""
    return f"cuda:{distributed_info().local_rank}" if device == "cuda" else device


def for_device(cfg: TrainCfg, device: str) -> TrainCfg:
    """Place the simulation on ``device``.

    ``cuda`` selects the warp backend (MuJoCo Warp) on this process's GPU, so that simulation,
    observations and the policy share the device; ``cpu`` keeps the configured backend and puts its
    tensors on the CPU (``--set env.sim.backend=warp`` runs MuJoCo Warp on warp's CPU device).
    """
    if device == "cuda":
        return apply_overrides(cfg, ["env.sim.backend=warp", f"env.sim.device={torch_device(device)}"])
    return apply_overrides(cfg, ["env.sim.device=cpu"])
