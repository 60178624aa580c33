"""``morfic store get``: an artifact's files out of the store, under names a person would give them.

A manifest's files keep their names (``model.pt``, ``eval.csv``, ``table.csv``, ``policy.onnx``); a rollout's
generic ``rollout.mcap`` is named after what it recorded, ``<robot>-<mode>-vx<vx>.mcap`` (from its meta). The
bytes written are the object's bytes, rehashed on the way out (:meth:`Store.read_file`).

A manifest may come from anyone's bundle, so nothing it names may act as configuration wherever ``--out`` points
(docs/concepts.md, "File names"): every output name is a plain name (no hidden ``.config`` part, no ``.py`` or
``.pth``: :func:`~morfic_cli.store.manifest.plain_name_problem`), no two files go to one path, and no file that
exists is replaced without ``force``. Everything is checked before the first file is written.
"""

from __future__ import annotations

import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from morfic_cli.errors import MorficError, printable
from morfic_cli.store.manifest import Manifest, clashing_names, plain_name_problem, safe_join


@dataclass(frozen=True)
class GotFile:
    """One file written by :func:`get_files`: its manifest name, where it went, its object id and size."""

    name: str
    path: Path
    id: str
    size: int


def out_name(manifest: Manifest, name: str) -> str:
    """The file name ``store get`` gives file ``name`` of ``manifest``.

    Example: a rollout of go1, mode descriptor, command vx 2 -> ``go1-descriptor-vx2.0.mcap``. A rollout whose
    meta would give no plain name keeps ``rollout.mcap``.
    """
    meta = manifest.meta
    if manifest.kind == "rollout" and name == "rollout.mcap" and {"robot", "mode", "command"} <= set(meta):
        try:
            vx = float(meta["command"][0])
        except (TypeError, ValueError, IndexError, KeyError):
            return name
        named = f"{meta['robot']}-{meta['mode']}-vx{vx:.1f}.mcap"
        return named if plain_name_problem(named) is None else name
    return name


def _plan(manifest: Manifest, wanted: list[str], out: Path, force: bool) -> list[tuple[str, Path]]:
    """(manifest name, path) of each file to write, all checked before anything is written.

    Raises:
        MorficError: A name that is not plain, two files that would go to one path (also when they differ only in
            case, or one is a folder of the other), or a path that exists (a folder, or a file without ``force``).
    """
    names = {name: out_name(manifest, name) for name in wanted}
    clash = clashing_names(list(names.values()))
    if clash is not None:
        first = next(n for n, o in names.items() if o == clash[0])
        second = next(n for n, o in names.items() if o == clash[1] and n != first)
        raise MorficError(
            f"files '{first}' and '{second}' of artifact {manifest.id[:12]} would both be written to "
            f"{clash[0]!r} (names equal but for case, or a file where the other needs a folder); "
            "nothing was written. morfic never stores such an artifact: fetch one of them with --file "
            "NAME."
        )
    plan = [(name, safe_join(out, names[name])) for name in wanted]
    base = out.resolve()
    blocked = next(
        (
            parent
            for _, path in plan
            for parent in path.parents
            if parent != base and base in parent.parents and (parent.is_file() or parent.is_symlink())
        ),
        None,
    )
    if blocked is not None:
        raise MorficError(
            f"{printable(blocked)} is a file, where store get needs a folder; nothing was written. "
            "Choose another --out."
        )
    there = [path for _, path in plan if path.exists() or path.is_symlink()]
    folders = [p for p in there if p.is_dir() and not p.is_symlink()]
    if folders:
        raise MorficError(
            f"{printable(folders[0])} is a folder, where store get would write a file; nothing was "
            "written. Choose another --out."
        )
    if there and not force:
        shown = ", ".join(printable(p) for p in there[:3]) + (f" and {len(there) - 3} more" if len(there) > 3 else "")
        raise MorficError(
            f"{shown} exist{'s' if len(there) == 1 else ''}; nothing was written. Pass --force to "
            "replace them, or choose another --out."
        )
    return plan


def get_files(store, spec: str, out: Path, names: list[str] | None = None, *, force: bool = False) -> list[GotFile]:
    """Write the files of manifest ``spec`` (all, or ``names``) into directory ``out`` (created).

    Each file is written to a temporary file beside its path and renamed into place, so an existing file (with
    ``force``) is replaced, never written through (a symlink there is replaced, not followed).

    Raises:
        ArtifactNotFoundError: No such artifact, or no such file in it (the message lists its files).
        MorficError: ``out`` is a file or cannot be written, the manifest has no files, or :func:`_plan` refuses.
    """
    manifest = store.read_manifest(spec)
    wanted = list(dict.fromkeys(names)) if names else sorted(manifest.files)
    if not wanted:
        raise MorficError(
            f"{manifest.kind} artifact '{printable(spec)}' holds no files; see `morfic store show {printable(spec)}`."
        )
    entries = {name: manifest.file(name) for name in wanted}  # unknown names fail before anything is written
    if out.exists() and not out.is_dir():
        raise MorficError(f"--out {out} is a file; give a directory (it is created if missing).")
    plan = _plan(manifest, wanted, out, force)
    got = []
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, path in plan:
            data = store.read_file(manifest.id, name)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".morfic-get-{os.getpid()}-{secrets.token_hex(4)}")
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies, as for any file
                with os.fdopen(fd, "wb") as fh:
                    fh.write(data)
                os.replace(tmp, path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                raise
            got.append(GotFile(name, path, entries[name].id, entries[name].size))
    except OSError as exc:
        raise MorficError(f"cannot write to {out}: {exc.strerror or exc}.") from exc
    return got
