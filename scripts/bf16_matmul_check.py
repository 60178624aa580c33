"""bf16 products in float32 (morfic_cli/rl/precision.py) against the native bf16 kernels and float32, in training.

Trains ITER (default 2) cpu-preset iterations of concat, seed 1, from the same start three times: bf16 autocast with
its matrix products computed in float32, float32, and bf16 with the native kernels (slow on a CPU without bf16
kernels: ~1 minute per iteration on an AVX2-only 2-core EPYC). Prints each run's curve rows and how far the weights'
change from the start differs from the native run's; writes the rows as JSON to OUT (default bf16_matmul_check.json).
docs/benchmarks-history.md, "The fix: bf16 products computed in float32", quotes its output.

Usage: python scripts/bf16_matmul_check.py [ITER] [OUT]
"""

from __future__ import annotations

import io
import json
import sys
import tempfile
import time

import torch

from morfic_cli.rl import ppo as ppo_module
from morfic_cli.rl.config import apply_overrides, preset_cfg
from morfic_cli.rl.rsl_rl_patches import raw_models
from morfic_cli.rl.runner import new_run
from morfic_cli.store import Store

#: (label, ppo.use_mixed_precision, what MorficPPO is told about the CPU's bf16 kernels)
SETTINGS = (("float32-emulated", True, False), ("float32", False, False), ("native", True, True))
CURVE_KEYS = ("iteration", "mean_reward", "value_loss", "surrogate", "explained_variance", "kl")


def flat_weights(modules) -> torch.Tensor:
    """Every parameter and buffer of ``modules``, float64, in one vector."""
    return torch.cat([v.flatten().double() for m in modules for v in m.state_dict().values()])


def train(mixed: bool, kernels: bool, iterations: int) -> tuple[torch.Tensor, list[dict], float, str | None]:
    """-> (the weights' change from the start, curve rows, wall seconds, the checkpoint's ``meta.bf16_matmul``)."""
    ppo_module.cpu_bf16_kernels = lambda: kernels  # what MorficPPO asks when it is built
    cfg = apply_overrides(
        preset_cfg("cpu", "concat", 1),
        [f"ppo.use_mixed_precision={str(mixed).lower()}", f"max_iterations={iterations}", "save_interval=100"],
    )
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(tmp)
        run = new_run(store, cfg, "check", "cpu")
        start = flat_weights(raw_models(run.runner.alg))
        t0 = time.perf_counter()
        last = run.train()
        wall = time.perf_counter() - t0
        run.env.close()
        weights = torch.load(io.BytesIO(store.read_file(last.id, "model.pt")), weights_only=True)
        meta = store.read_manifest(last.id).meta
    end = torch.cat([v.flatten().double() for part in ("actor", "critic") for v in weights[part].values()])
    rows = [{k: r[k] for k in CURVE_KEYS if k in r} for r in run.rows]
    return end - start, rows, wall, meta.get("bf16_matmul")


def relative(a: torch.Tensor, b: torch.Tensor) -> float:
    """||a - b|| / ||b||."""
    return float((a - b).norm() / b.norm())


def main() -> None:
    """Train the three settings, print their curves and differences, write the JSON."""
    iterations = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    out = sys.argv[2] if len(sys.argv) > 2 else "bf16_matmul_check.json"
    runs = {}
    for label, mixed, kernels in SETTINGS:
        runs[label] = train(mixed, kernels, iterations)
        _, rows, wall, matmul = runs[label]
        print(label, f"{wall:.0f} s", f"bf16_matmul={matmul}", rows, flush=True)
    native = runs["native"][0]
    for label in ("float32-emulated", "float32"):
        print(f"weights' change, relative difference {label} vs native: {relative(runs[label][0], native):.4f}")
    with open(out, "w") as fh:
        json.dump({k: {"rows": v[1], "wall_s": v[2], "bf16_matmul": v[3]} for k, v in runs.items()}, fh, indent=1)


if __name__ == "__main__":
    main()
