"""What a store holds, for comparing two stores made by the same command (local vs ray, faulted vs not)."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path
from typing import Any

import pandas as pd

from morfic_cli.store import Store


def differences(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """Where two :func:`comparable` differ: one line per differing leaf (path, then both values); empty when equal."""
    out: list[str] = []

    def walk(x: Any, y: Any, path: str) -> None:
        if isinstance(x, dict) and isinstance(y, dict):
            for key in sorted(set(x) | set(y), key=str):
                walk(x.get(key, "<missing>"), y.get(key, "<missing>"), f"{path}/{key}")
        elif isinstance(x, list | tuple) and isinstance(y, list | tuple) and len(x) == len(y):
            for i, (p, q) in enumerate(zip(x, y, strict=True)):
                walk(p, q, f"{path}[{i}]")
        elif x != y:
            if isinstance(x, str) and isinstance(y, str):
                lines = [(p, q) for p, q in zip(x.splitlines(), y.splitlines(), strict=False) if p != q][:2]
                out.append(f"{path}: {lines or (x[:200], y[:200])}")
            else:
                out.append(f"{path}: {str(x)[:300]} != {str(y)[:300]}")

    walk(a, b, "")
    return out


#: CSV columns that are wall-clock measurements (training curves, compute tables) contain one of these.
TIMING_WORDS = ("wall_time", "steps_per_s", "collect_s", "learn_s", "s_per_iteration", "hours")
_HEX64 = re.compile(r"\b[0-9a-f]{12}(?:[0-9a-f]{52})?\b")


def _csv(data: bytes) -> str:
    frame = pd.read_csv(io.BytesIO(data))
    frame = frame[[c for c in frame.columns if not any(w in c for w in TIMING_WORDS)]]
    header, *rows = _HEX64.sub("<id>", frame.to_csv(index=False)).splitlines()
    return "\n".join([header, *sorted(rows)])  # some tables (provenance.csv) list rows in manifest-id order


def comparable(root: Path) -> dict[str, Any]:
    """``{ref: [version, ...]}`` reduced to what the same command must reproduce on CPU.

    Each version is its kind, its config, its inputs (recursively, by content) and its files: a ``.pt`` file
    (weights, trainer state) by its id, which must match bit for bit; a CSV by its rows (as a set: some list
    theirs in manifest-id order) without the wall-clock columns and with every manifest id (full or 12-digit)
    written as ``<id>`` (a manifest id hashes its ``created`` time, so no two runs share one); every other file
    (figures, MCAP logs, report text, which render timings or ids) by its name. Versions keep their order.
    """
    store = Store(root)
    cache: dict[str, Any] = {}

    def describe(oid: str) -> Any:
        if oid not in cache:
            m = store.read_manifest(oid)
            files = {}
            for name, entry in sorted(m.files.items()):
                if name.endswith(".pt"):
                    files[name] = entry.id
                elif name.endswith(".csv"):
                    files[name] = _csv(store.read_file(oid, name))
                else:
                    files[name] = "present"
            cache[oid] = {
                "kind": m.kind,
                "config": json.loads(_HEX64.sub("<id>", json.dumps(m.config))),
                "files": files,
                "inputs": sorted(((_HEX64.sub("<id>", role), describe(i)) for role, i in m.inputs.items()), key=repr),
            }
        return cache[oid]

    return {name: [describe(e.id) for e in store.ref_history(name)] for name in store.list_refs()}
