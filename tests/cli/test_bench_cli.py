"""``morfic bench env``: keys, the floor comparison, and the table artifact (no timing assertions)."""

from __future__ import annotations

import json
import os

import pytest
import torch


def test_bench_env_json_has_the_required_keys_and_is_stored(run_cli):
    code, out, err = run_cli("bench", "env", "--envs", "8", "--steps", "3", "--repeats", "1", "--format", "json")
    assert code == 0, err
    row = json.loads(out)
    for key in ("env_steps_per_s", "physics_floor_steps_per_s", "ratio", "cores", "cpu_model", "num_envs"):
        assert key in row, key
    assert row["num_envs"] == 8 and row["env_steps_per_s"] > 0 and row["physics_floor_steps_per_s"] > 0
    # one repetition: ratio is env steps/s over the floor expressed in env steps (physics steps / decimation 4)
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
    code, out, err = run_cli(
        "bench", "env", "--backend", "warp", "--device", "cpu", "--envs", "4", "--steps", "2", "--format", "json"
    )
    assert code == 0, err
    row = json.loads(out)
    assert (row["backend"], row["device"]) == ("warp", "cpu")
    assert row["env_steps_per_s"] > 0 and row["physics_floor_steps_per_s"] > 0


def test_a_ratio_above_the_credible_limit_is_not_reported():
    from morfic_cli.benchmarks import MAX_CREDIBLE_RATIO, credible

    assert MAX_CREDIBLE_RATIO == 1.05
    assert credible(0.91234) == 0.9123
    assert credible(1.05) == 1.05
    assert credible(1.31) is None  # the env cannot be faster than its own physics: noise, not a result


def test_noisy_rows_are_announced_with_a_rerun_hint(capsys):
    from morfic_cli.cli.bench import _warn_noisy

    _warn_noisy([{"num_envs": 256, "ratio_spread": [1.1, 1.4], "load_before": 6.0, "load_after": 7.5}], "env")
    err = capsys.readouterr().err
    assert "256 envs" in err and "1.10-1.40" in err and "too noisy" in err and "rerun" in err and "6.0 -> 7.5" in err


def test_bench_env_repeats_are_alternated_and_summarised(run_cli):
    code, out, err = run_cli("bench", "env", "--envs", "8", "--steps", "2", "--repeats", "3", "--format", "json")
    assert code == 0, err
    row = json.loads(out)
    assert row["repeats"] == 3 and row["noisy"] is False
    lo, hi = row["ratio_spread"]
    assert lo <= row["ratio"] <= hi  # the median of three lies within their range
    lo, hi = row["env_steps_per_s_spread"]
    assert lo <= row["env_steps_per_s"] <= hi
    assert row["load_before"] >= 0 and row["load_after"] >= 0


def test_bench_compare_needs_a_known_commit(run_cli):
    code, out, err = run_cli("bench", "train", "--preset", "smoke", "--compare", "no-such-branch-xyz")
    assert code == 1 and err.startswith("Error: ") and "no-such-branch-xyz" in err and out == ""
    code, _, err = run_cli("bench", "env", "--envs", "8", "--compare", "HEAD")
    assert code == 1 and "bench train" in err


@pytest.mark.slow
def test_bench_compare_times_both_sides_in_alternation(run_cli):
    code, out, err = run_cli(
        "bench",
        "train",
        "--preset",
        "smoke",
        "--iterations",
        "1",
        "--compare",
        "HEAD",
        "--rounds",
        "2",
        "--format",
        "json",
        "-q",
    )
    assert code == 0, err
    result = json.loads(out)
    assert result["rounds"] == 2 and len(result["this_runs"]) == len(result["ref_runs"]) == 2
    ratios = sorted(
        a["s_per_iteration"] / b["s_per_iteration"]
        for a, b in zip(result["this_runs"], result["ref_runs"], strict=True)
    )
    assert result["s_per_iteration_ratio"] == pytest.approx(sum(ratios) / 2, abs=1e-4)  # median of two = mean
    assert result["ratio_spread"] == pytest.approx(ratios, abs=1e-4)


def test_bench_train_applies_set_and_records_the_precision(run_cli):
    from morfic_cli.rl.precision import bf16_matmul, cpu_bf16_kernels

    for mixed in (True, False):
        code, out, err = run_cli(
            "bench",
            "train",
            "--preset",
            "smoke",
            "--iterations",
            "1",
            "--set",
            f"ppo.use_mixed_precision={str(mixed).lower()}",
            "--format",
            "json",
            "-q",
        )
        assert code == 0, err
        row = json.loads(out)
        assert row["mixed_precision"] is mixed and row["bf16_kernels"] is cpu_bf16_kernels()
        assert row["bf16_matmul"] == (bf16_matmul("cpu", cpu_bf16_kernels()) if mixed else None)
        assert row["iterations"] == 1 and row["transitions"] == 8 * 8  # the smoke preset: 8 envs x 8 steps
    code, _, err = run_cli("bench", "train", "--preset", "smoke", "--compare", "HEAD", "--set", "max_iterations=3")
    assert code == 1 and err.startswith("Error: ") and "--set" in err
