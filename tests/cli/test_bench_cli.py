"""``morfic bench env``: keys, the floor comparison, and the table artifact (no timing assertions)."""

from __future__ import annotations

import json
import os

import pytest
import torch


def test_bench_env_json_has_the_required_keys_and_is_stored(run_cli):
    code, out, err = run_cli("bench", "env", "--envs", "8", "--steps", "3", "--format", "json")
    assert code == 0, err
    row = json.loads(out)
    for key in ("env_steps_per_s", "physics_floor_steps_per_s", "ratio", "cores", "cpu_model", "num_envs"):
        assert key in row, key
    assert row["num_envs"] == 8 and row["env_steps_per_s"] > 0 and row["physics_floor_steps_per_s"] > 0
    # ratio is env steps/s over the floor expressed in env steps (physics steps / decimation 4)
    assert abs(row["ratio"] - row["env_steps_per_s"] / (row["physics_floor_steps_per_s"] / 4)) < 1e-2 * row["ratio"]

    from morfic_cli.store import Store

    store = Store(os.environ["MORFIC_STORE"])
    assert store.read_manifest("tables/bench-env").config["num_envs"] == [8]
    assert store.read_file("tables/bench-env", "bench_env.csv").startswith(b"num_envs,steps,")


def test_bench_bad_input_is_an_error(run_cli):
    code, _, err = run_cli("bench", "env", "--envs", "many")
    assert code == 1 and err.startswith("Error: ") and "--envs" in err
    code, _, err = run_cli("bench", "physics")
    assert code == 1 and "'physics' is not one of 'env', 'train'" in err


def test_bench_backend_and_device_errors(run_cli):
    code, _, err = run_cli("bench", "env", "--envs", "8", "--backend", "physx")
    assert code == 1 and err.startswith("Error: ") and "'physx' is not one of 'cpu', 'warp', 'gpu'" in err
    code, _, err = run_cli("bench", "env", "--envs", "8", "--backend", "cpu", "--device", "cuda")
    assert code == 1 and "--backend warp" in err


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
def test_bench_on_cuda_without_cuda_is_an_error(run_cli):
    for argv in (("env", "--backend", "warp"), ("train", "--preset", "smoke")):
        code, out, err = run_cli("bench", *argv, "--device", "cuda")
        assert code == 1 and err.startswith("Error: ") and "no CUDA device" in err and out == ""


def test_bench_env_on_warp_cpu_is_stored_with_its_device(run_cli):
    pytest.importorskip("mujoco_warp", reason="mujoco_warp is not installed (pip install 'morfic[gpu]')")
    code, out, err = run_cli("bench", "env", "--backend", "warp", "--device", "cpu", "--envs", "4", "--steps", "2",
                             "--format", "json")
    assert code == 0, err
    row = json.loads(out)
    assert (row["backend"], row["device"]) == ("warp", "cpu")
    assert row["env_steps_per_s"] > 0 and row["physics_floor_steps_per_s"] > 0
