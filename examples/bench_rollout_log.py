"""Write and read one real 64 x 500 rollout as an MCAP log: sizes and times, before (format 1) and after.

Usage (from a checkout, with a trained run in the store, e.g. the shipped bundle)::

    morfic store import artifacts/bundles/film-cpu-legacy.tar --store /tmp/s
    git show 21fb091:morfic_cli/recording/rollout_log.py > /tmp/rollout_log_v1.py   # the JSON writer (format 1)
    python examples/bench_rollout_log.py --store /tmp/s --run runs/film-cpu --before /tmp/rollout_log_v1.py

Prints the rollout's own time, then per layout: size, bytes per env-step, write time (and its share of the
rollout) and the time of ``read_rollout`` back to arrays; checks that every layout reads back to the same arrays.
Results are in docs/mcap.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

FIELDS = (
    "base_pos",
    "base_quat",
    "base_lin_vel",
    "base_ang_vel",
    "command",
    "joint_pos",
    "joint_vel",
    "action",
    "reward",
    "reward_terms",
    "value",
    "done",
    "time_out",
)


def main() -> None:
    """Run the rollout once, then write and read it in each layout."""
    from morfic_cli.evaluation.protocol import write_rollout_log
    from morfic_cli.evaluation.rollout import run_rollout
    from morfic_cli.recording.rollout_log import read_rollout
    from morfic_cli.rl.load import load_trained
    from morfic_cli.store import Store

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--store", required=True)
    p.add_argument("--run", default="runs/film-cpu")
    p.add_argument("--robot", default="go1")
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--before", help="path of the format-1 rollout_log.py (JSON), to measure it too")
    args = p.parse_args()
    torch.set_num_threads(1)
    trained = load_trained(Store(args.store), args.run)
    t0 = time.perf_counter()
    ro = run_rollout(
        trained.actor,
        trained.critic,
        trained.cfg.env,
        robot=args.robot,
        mode="descriptor",
        command_vx=2.0,
        num_envs=args.envs,
        steps=args.steps,
        keep_models=args.envs,
    )
    t_roll = time.perf_counter() - t0
    n = args.envs * args.steps
    print(f"rollout {args.envs} x {args.steps} on {args.robot}: {t_roll:.1f} s; load average {os.getloadavg()}")
    meta = {"robot": args.robot, "term_names": ro.term_names}
    a = ro.arrays
    ref = None
    with tempfile.TemporaryDirectory() as tmp:
        if args.before:
            spec = importlib.util.spec_from_file_location("rollout_log_v1", args.before)
            v1 = importlib.util.module_from_spec(spec)
            sys.modules["rollout_log_v1"] = v1
            spec.loader.exec_module(v1)
            path = Path(tmp) / "v1.mcap"
            t0 = time.perf_counter()
            with v1.RolloutLogWriter(path, num_envs=args.envs, term_names=ro.term_names, metadata=meta) as log:
                for t in range(args.steps):
                    log.write_step(t, (t + 1) * ro.dt, {k: a[k][t] for k in FIELDS})
            w = time.perf_counter() - t0
            t0 = time.perf_counter()
            ref = v1.read_rollout(path).arrays
            r = time.perf_counter() - t0
            size = path.stat().st_size
            print(
                f"before (format 1, JSON): {size / 1e6:.2f} MB, {size / n:.0f} B/env-step, write {w:.2f} s "
                f"({100 * w / t_roll:.1f} % of the rollout), read {r:.2f} s"
            )
        for scene in (0, 4, args.envs):
            path = Path(tmp) / f"v2-{scene}.mcap"
            t0 = time.perf_counter()
            write_rollout_log(path, ro, meta, scene)
            w = time.perf_counter() - t0
            t0 = time.perf_counter()
            arrays = read_rollout(path).arrays
            r = time.perf_counter() - t0
            size = path.stat().st_size
            for k in FIELDS:
                np.testing.assert_array_equal(arrays[k], (ref or arrays)[k], err_msg=k)
                np.testing.assert_array_equal(arrays[k], a[k].astype(arrays[k].dtype), err_msg=k)
            print(
                f"after (format 2, protobuf), scene of {scene} envs: {size / 1e6:.2f} MB, {size / n:.0f} B/env-step, "
                f"write {w:.2f} s ({100 * w / t_roll:.1f} % of the rollout), read {r:.2f} s"
            )


if __name__ == "__main__":
    main()
