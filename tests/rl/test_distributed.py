"""Multi-GPU training under torchrun: the environment variables, the device rules, and a world-size-1 launch.

rsl-rl's OnPolicyRunner turns distributed on only when WORLD_SIZE > 1, and then insists on NCCL and
``cuda:LOCAL_RANK``; a CPU machine can therefore only launch the world-size-1 case (the same code path
as a single process, started by torchrun), which is what the subprocess test does.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from morfic_cli.errors import MorficError
from morfic_cli.rl.config import smoke_preset
from morfic_cli.rl.devices import check_device, distributed_info, for_device, torch_device
from morfic_cli.store import Store


def test_outside_torchrun_it_is_one_process(monkeypatch):
    for var in ("WORLD_SIZE", "RANK", "LOCAL_RANK"):
        monkeypatch.delenv(var, raising=False)
    info = distributed_info()
    assert (info.world_size, info.rank, info.local_rank) == (1, 0, 0)
    assert torch_device("cuda") == "cuda:0" and torch_device("cpu") == "cpu"


def test_each_rank_gets_its_own_gpu_and_cpu_is_refused_for_several(monkeypatch):
    monkeypatch.setenv("WORLD_SIZE", "4")
    monkeypatch.setenv("RANK", "3")
    monkeypatch.setenv("LOCAL_RANK", "1")
    assert distributed_info().rank == 3
    assert torch_device("cuda") == "cuda:1"
    cfg = for_device(smoke_preset(), "cuda")
    assert (cfg.env.sim.backend, cfg.env.sim.device) == ("warp", "cuda:1")
    with pytest.raises(MorficError, match="needs --device cuda"):
        check_device("cpu")


def test_cpu_keeps_the_configured_backend():
    cfg = for_device(smoke_preset(), "cpu")
    assert (cfg.env.sim.backend, cfg.env.sim.device) == ("cpu", "cpu")


def test_torchrun_world_size_1_trains_and_rank_0_writes_the_checkpoint(tmp_path):
    store = tmp_path / "store"
    env = {k: v for k, v in os.environ.items() if k not in ("WORLD_SIZE", "RANK", "LOCAL_RANK")}
    env["OMP_NUM_THREADS"] = "1"
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nnodes",
        "1",
        "--nproc_per_node",
        "1",
        "-m",
        "morfic_cli",
        "train",
        "--preset",
        "smoke",
        "--set",
        "max_iterations=1",
        "--store",
        str(store),
        "--format",
        "json",
        "-q",
    ]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    assert result["iteration"] == 1 and result["ref"] == "runs/film-smoke-s0@1"
    assert Store(store).read_manifest("runs/film-smoke-s0").meta["iteration"] == 1


def test_a_gpu_trained_run_evaluates_on_the_cpu_backend():
    from morfic_cli.config import eval_env_cfg

    cfg = eval_env_cfg(for_device(smoke_preset(), "cuda").env)
    assert (cfg.sim.backend, cfg.sim.device) == ("cpu", "cpu")
