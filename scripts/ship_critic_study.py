"""Ship the store's critic study: its results-only bundle, its rows and its id under docs/results.

Writes, from the study at ``diagnoses/critic-study`` of the store (``--store`` or ``$MORFIC_STORE``):

- ``artifacts/bundles/results/critic-study.tar``: the study as a results-only bundle (its tables; no rollouts, no
  figures), what ``morfic reproduce --preset shipped`` imports (replaced when there);
- ``<out>/critic-study.csv``: its ``critic_study.csv``, verbatim (a row per command, robot, variant, actor, fit seed);
- ``<out>/critic-study.json``: its id, actors and their checkpoints, settings, timings (the study's own split and,
  with ``--wall-seconds``, the whole command's wall time as ``/usr/bin/time`` measured it), the machine, a note.

Then regenerate the tables and the generated answer: ``python scripts/results_tables.py --write docs/results.md
--figures docs/img --readme README.md``.

Usage: python scripts/ship_critic_study.py [--store STORE] [--out docs/results] [--bundles artifacts/bundles]
       [--wall-seconds S] [--note TEXT]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

STUDY_REF = "diagnoses/critic-study"


def study_record(doc: dict, wall_seconds: float | None, machine: str, note: str) -> dict:
    """``critic-study.json`` of a study's manifest ``doc`` (``morfic store show -f json``'s document)."""
    actors = {ref.split("/", 1)[1]: oid[:12] for ref, oid in doc["inputs"].items() if ref.startswith("actor/")}
    record = {
        "id": doc["id"][:12],
        "full_id": doc["id"],
        "actor": ", ".join(actors) or doc["meta"].get("actor", ""),  # layout 1: one actor, named in meta
        "actor_checkpoints": actors,
        "seconds": doc["meta"]["seconds"],
        "config": doc["config"],
        "machine": machine,
        "note": note,
    }
    if wall_seconds is not None:
        record["wall_seconds"] = wall_seconds
    return record


def machine() -> str:
    """This machine in words: CPU model, cores, whether oneDNN has bf16 matrix kernels on it."""
    from morfic_cli.benchmarks import cpu_model
    from morfic_cli.rl.precision import cpu_bf16_kernels

    kernels = {True: "bf16 kernels", False: "no bf16 kernels (AVX2 only)", None: "bf16 kernels unknown"}
    return f"{cpu_model()}, {os.cpu_count()} cores, {kernels[cpu_bf16_kernels()]}"


def main(argv: list[str] | None = None) -> int:
    """Export the study, write its rows and record; 1 with an ``Error:`` when the store holds no study."""
    from morfic_cli.store import Store

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--store", default=os.environ.get("MORFIC_STORE"))
    p.add_argument("--out", type=Path, default=Path("docs/results"))
    p.add_argument("--bundles", type=Path, default=Path("artifacts/bundles"))
    p.add_argument("--wall-seconds", type=float, default=None, help="The whole command's wall time (/usr/bin/time).")
    p.add_argument("--note", default="", help="How it was run (machine load, options).")
    a = p.parse_args(argv)
    if not a.store:
        print("Error: give the study's store with --store or MORFIC_STORE", file=sys.stderr)
        return 1
    store = Store(a.store)
    if not store.has_ref(STUDY_REF):
        print(f"Error: {a.store} has no {STUDY_REF}; run `morfic critic-study` into it first", file=sys.stderr)
        return 1
    doc = store.describe(STUDY_REF)
    tar = a.bundles / "results" / "critic-study.tar"
    tar.parent.mkdir(parents=True, exist_ok=True)
    tar.unlink(missing_ok=True)
    store.export_tar([STUDY_REF], tar, latest=True, results_only=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "critic-study.csv").write_bytes(store.read_file(STUDY_REF, "critic_study.csv"))
    record = study_record(doc, a.wall_seconds, machine(), a.note)
    (a.out / "critic-study.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"shipped {record['id']}: {tar} ({tar.stat().st_size / 2**20:.2f} MiB), {a.out}/critic-study.csv, .json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
