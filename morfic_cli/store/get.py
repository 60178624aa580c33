"""``morfic store get``: an artifact's files out of the store, under names a person would give them.

A manifest's files keep their names (``model.pt``, ``eval.csv``, ``table.csv``, ``policy.onnx``); a rollout's
generic ``rollout.mcap`` is named after what it recorded, ``<robot>-<mode>-vx<vx>.mcap`` (from its meta). The
bytes written are the object's bytes, rehashed on the way out (:meth:`Store.read_file`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from morfic_cli.errors import MorficError
from morfic_cli.store.manifest import Manifest, safe_join


@dataclass(frozen=True)
class GotFile:
    """One file written by :func:`get_files`: its manifest name, where it went, its object id and size."""

    name: str
    path: Path
    id: str
    size: int


def out_name(manifest: Manifest, name: str) -> str:
    """The file name ``store get`` gives file ``name`` of ``manifest``.

    Example: a rollout of go1, mode descriptor, command vx 2 -> ``go1-descriptor-vx2.0.mcap``.
    """
    meta = manifest.meta
    if manifest.kind == "rollout" and name == "rollout.mcap" and {"robot", "mode", "command"} <= set(meta):
        try:
            vx = float(meta["command"][0])
        except (TypeError, ValueError, IndexError):
            return name
        return f"{meta['robot']}-{meta['mode']}-vx{vx:.1f}.mcap"
    return name


def get_files(store, spec: str, out: Path, names: list[str] | None = None) -> list[GotFile]:
    """Write the files of manifest ``spec`` (all, or ``names``) into directory ``out`` (created).

    Raises:
        ArtifactNotFoundError: No such artifact, or no such file in it (the message lists its files).
        MorficError: ``out`` is a file, cannot be written, or the manifest has no files.
    """
    manifest = store.read_manifest(spec)
    wanted = list(names) if names else sorted(manifest.files)
    if not wanted:
        raise MorficError(f"{manifest.kind} artifact '{spec}' holds no files; see `morfic store show {spec}`.")
    entries = [(name, manifest.file(name)) for name in wanted]  # unknown names fail before anything is written
    if out.exists() and not out.is_dir():
        raise MorficError(f"--out {out} is a file; give a directory (it is created if missing).")
    got = []
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, entry in entries:
            path = safe_join(out, out_name(manifest, name))
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(store.read_file(manifest.id, name))
            got.append(GotFile(name, path, entry.id, entry.size))
    except OSError as exc:
        raise MorficError(f"cannot write to {out}: {exc.strerror or exc}.") from exc
    return got
