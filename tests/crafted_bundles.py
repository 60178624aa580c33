"""Hand-made (hostile) export tars for the import tests: any manifest bytes, any members, any header."""

from __future__ import annotations

import hashlib
import io
import json
import tarfile
from pathlib import Path
from typing import Any

GOOD_TIME = "2025-01-02T03:04:05.000000Z"


def oid_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def manifest_bytes(**fields: Any) -> bytes:
    """A manifest document with defaults for every key (canonical JSON unless ``allow_nan`` is needed)."""
    doc = {"schema": 1, "kind": "report", "morfic_version": "0.1.0", "created": GOOD_TIME, "config": {},
           "inputs": {}, "files": {}, "meta": {}}
    doc.update(fields)
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode("ascii")


def history_bytes(ids: list[str], times: list[str] | None = None) -> bytes:
    """A legacy (unchained) ref history, as every morfic before the hash chain wrote it."""
    times = times or [GOOD_TIME] * len(ids)
    lines = [json.dumps({"id": oid, "time": t, "version": n}, sort_keys=True, separators=(",", ":"))
             for n, (oid, t) in enumerate(zip(ids, times, strict=True), start=1)]
    return "".join(line + "\n" for line in lines).encode()


def write_bundle(path: Path, *, blobs: list[bytes] = (), manifests: list[bytes] = (),
                 refs: dict[str, bytes] | None = None, header: dict | None = None,
                 extra: dict[str, bytes] | None = None) -> Path:
    """An export tar holding ``blobs`` and ``manifests`` as objects (manifests indexed) and ``refs`` histories."""
    refs = refs or {}
    objects = {oid_of(b): b for b in [*blobs, *manifests]}
    head = {"format": 1, "morfic_version": "0.1.0", "objects": len(objects), "refs": sorted(refs)}
    if header is not None:
        head = header
    members: dict[str, bytes] = {"morfic-export.json": json.dumps(head).encode()}
    for oid, data in sorted(objects.items()):
        members[f"objects/{oid[:2]}/{oid[2:]}"] = data
    for data in manifests:
        members[f"manifests/{oid_of(data)}"] = b""
    for name, data in refs.items():
        members[f"refs/{name}"] = data
    members.update(extra or {})
    with tarfile.open(path, "w") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return path


def report_bundle(path: Path, files: dict[str, bytes], **fields: Any) -> tuple[Path, str]:
    """A one-ref bundle (``reports/evil``) whose report manifest names ``files`` (any names, true sizes)."""
    entries = {name: {"id": oid_of(data), "size": len(data)} for name, data in files.items()}
    manifest = manifest_bytes(files=entries, **fields)
    write_bundle(path, blobs=list(files.values()), manifests=[manifest],
                 refs={"reports/evil": history_bytes([oid_of(manifest)])})
    return path, oid_of(manifest)


def listing(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (relative path -> bytes), to compare a store before and after."""
    if not root.exists():
        return {}
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
