"""Copy one experiment run's result tables out of the store: its eval, calibration and training-conditions CSVs.

The eval and diagnosis are the ones `morfic reproduce --preset cpu` stored for the run (found as the pipeline finds
them, so a table is never another run's); written as ``<out>/<run>-eval.csv`` and ``<out>/<run>-calibration.csv``.

Usage: python scripts/experiment_tables.py RUN_NAME [--out docs/results] [--store STORE]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    """Write the tables; 1 with ``Error:`` when the store has no paper-protocol eval or diagnosis of the run."""
    from morfic_cli.pipeline import Pipeline, reproduce_cfg
    from morfic_cli.store import Store

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="run name, e.g. concat-cpu-s0")
    p.add_argument("--out", type=Path, default=Path("docs/results"))
    p.add_argument("--store", default=os.environ.get("MORFIC_STORE", "artifacts"))
    args = p.parse_args(argv)
    store = Store(args.store)
    spec = f"runs/{args.run}"
    manifest = store.read_manifest(spec)
    variant = manifest.config["variant"]
    pipe = Pipeline(store, reproduce_cfg("cpu", variants=(variant,), seeds=int(manifest.config["seed"]) + 1))
    found = {"eval": (pipe.stored_eval(spec), "eval.csv"),
             "calibration": (pipe.stored_diagnosis(spec), "calibration.csv")}
    args.out.mkdir(parents=True, exist_ok=True)
    for what, (step, file) in found.items():
        if step is None:
            print(f"Error: no {what} of {spec} with the paper's protocol in {store.root}; run "
                  f"`morfic reproduce --preset cpu --variants {variant}` first.", file=sys.stderr)
            return 1
        path = args.out / f"{args.run}-{what}.csv"
        path.write_bytes(store.read_file(step.id, file))
        print(f"{path} (artifact {step.id[:12]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
