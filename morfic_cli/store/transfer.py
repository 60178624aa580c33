"""Move artifacts between stores as one tar file (``morfic store export`` / ``import``).

The tar mirrors the store layout and holds the closure of the named refs::

    morfic-export.json           {"format": 1, "morfic_version": ..., "refs": [...], "objects": N}
    objects/ab/cdef...           every object reachable from any version of those refs
    manifests/<id>               index markers of the manifests among them
    refs/<name>                  the full history of each named ref

Members are written in sorted order with fixed owner, mode and mtime, so exporting the same refs
twice gives the same bytes. Import rehashes every object, adds only what is missing, and merges
each ref history (see :func:`morfic_cli.store.refs.merge_status`); it is idempotent.
"""

from __future__ import annotations

import io
import json
import os
import tarfile
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

from morfic_cli import __version__
from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store.gc import closure
from morfic_cli.store.manifest import parse_manifest
from morfic_cli.store.objects import CHUNK_SIZE, is_object_id, object_relpath, store_os_error, unlink_quiet
from morfic_cli.store.refs import RefEntry, check_ref_name, decode_history, encode_history, merge_status

if TYPE_CHECKING:
    from morfic_cli.store import Store

#: Name of the header member of an export tar.
HEADER = "morfic-export.json"

#: Export format version.
EXPORT_FORMAT = 1


@dataclass
class ExportReport:
    """What ``export_tar`` wrote.

    Attributes:
        path: The tar file.
        refs: The exported ref names.
        objects: Objects in the tar.
        bytes: Their total size.
    """

    path: Path
    refs: list[str]
    objects: int = 0
    bytes: int = 0


@dataclass
class ImportReport:
    """What ``import_tar`` did.

    Attributes:
        objects_added: Objects that were new to this store.
        objects_present: Objects this store already had.
        manifests: Manifests indexed.
        refs: Ref name -> ``created``, ``extended`` or ``unchanged``.
    """

    objects_added: int = 0
    objects_present: int = 0
    manifests: int = 0
    refs: dict[str, str] = field(default_factory=dict)


def _info(name: str, size: int, mode: int) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.size = size
    info.mode = mode
    info.mtime = 0
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    return info


def _add_bytes(tar: tarfile.TarFile, name: str, data: bytes, mode: int = 0o644) -> None:
    tar.addfile(_info(name, len(data), mode), io.BytesIO(data))


def export_tar(store: Store, refs: list[str], out: Path, *, latest: bool = False) -> ExportReport:
    """Write the closure of ``refs`` (objects and ref histories) to the tar file ``out``.

    With ``latest``, only each ref's current version goes in, as a one-version history (version 1 in the
    importing store): a small snapshot, e.g. a trained policy without its earlier checkpoints. Such a
    snapshot and a full export of the same ref do not merge into one store (their histories differ).

    Raises:
        ArtifactNotFoundError: A name that is not a ref.
        StoreError: A reachable object is missing (run ``verify``) or ``out`` cannot be written.
    """
    names = sorted(set(refs))
    if not names:
        raise StoreError("name at least one ref to export, e.g. `morfic store export runs/film-s0 --out x.tar`.")
    for name in names:
        if not store.refs.exists(check_ref_name(name)):
            raise ArtifactNotFoundError(f"no ref '{name}' in store {store.root}; try `morfic store ls`.")
    out = Path(out)
    report = ExportReport(path=out, refs=names)
    with store.reading():
        histories = {name: store.refs.history(name) for name in names}
        if latest:
            histories = {name: [RefEntry(1, h[-1].id, h[-1].time)] for name, h in histories.items()}
        ids = sorted(closure(store, [entry.id for h in histories.values() for entry in h]))
        missing = [oid for oid in ids if not store.objects.has(oid)]
        if missing:
            raise StoreError(f"cannot export: {len(missing)} reachable object(s) are missing (first: "
                             f"{missing[0]}); run `morfic store verify`.")
        _write_tar(store, out, names, histories, ids, report)
    return report


def _write_tar(store: Store, out: Path, names: list[str], histories: dict[str, list[RefEntry]],
               ids: list[str], report: ExportReport) -> None:
    """Write the tar to a temp file next to ``out`` and rename it into place."""
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp")
    os.close(fd)
    try:
        with tarfile.open(tmp, "w", format=tarfile.PAX_FORMAT) as tar:
            header = {"format": EXPORT_FORMAT, "morfic_version": __version__, "objects": len(ids), "refs": names}
            _add_bytes(tar, HEADER, json.dumps(header, sort_keys=True, indent=1).encode())
            for oid in ids:
                path = store.objects.path(oid)
                size = path.stat().st_size
                with open(path, "rb") as fh:
                    tar.addfile(_info(object_relpath(oid), size, 0o444), fh)
                report.objects += 1
                report.bytes += size
            for oid in ids:
                if store.index.has(oid):
                    _add_bytes(tar, f"manifests/{oid}", b"", 0o444)
            for name in names:
                _add_bytes(tar, f"refs/{name}", encode_history(histories[name]))
        os.replace(tmp, out)
        tmp = None
    except OSError as exc:
        raise store_os_error(exc, f"writing the export {out}", store.root) from exc
    finally:
        if tmp is not None:
            unlink_quiet(tmp)


@dataclass
class _Members:
    objects: list[tarfile.TarInfo] = field(default_factory=list)
    manifests: list[str] = field(default_factory=list)
    refs: dict[str, tarfile.TarInfo] = field(default_factory=dict)
    header: tarfile.TarInfo | None = None


def _classify(tar: tarfile.TarFile, path: Path) -> _Members:
    """Sort the tar's members into objects, index markers and refs; refuse anything else."""
    members = _Members()
    for member in tar.getmembers():
        name = member.name
        if member.isdir():
            continue
        if not member.isfile():
            raise StoreError(f"{path} is not a morfic export: member '{name}' is not a regular file.")
        if name == HEADER:
            members.header = member
        elif _object_id_of(name) is not None:
            members.objects.append(member)
        elif name.startswith("manifests/") and is_object_id(name[10:]):
            members.manifests.append(name[10:])
        elif name.startswith("refs/"):
            members.refs[check_ref_name(name[5:])] = member
        else:
            raise StoreError(f"{path} is not a morfic export: unexpected member '{name}'.")
    if members.header is None:
        raise StoreError(f"{path} is not a morfic export (no {HEADER}); make one with `morfic store export`.")
    return members


def _object_id_of(name: str) -> str | None:
    """The id of an ``objects/ab/cdef...`` member name, or ``None``."""
    oid = name[len("objects/"):].replace("/", "", 1)
    return oid if is_object_id(oid) and name == object_relpath(oid) else None


def _chunks(fh: IO[bytes]) -> Iterator[bytes]:
    return iter(lambda: fh.read(CHUNK_SIZE), b"")


def _open_tar(path: Path) -> tarfile.TarFile:
    try:
        return tarfile.open(path, "r:*")
    except FileNotFoundError:
        raise StoreError(f"no such file: {path}.") from None
    except (tarfile.TarError, OSError) as exc:
        raise StoreError(f"{path} is not a readable tar file ({exc}); make one with `morfic store export`.") from exc


def import_tar(store: Store, path: Path) -> ImportReport:
    """Import an export tar: rehash and add its objects, index its manifests, merge its refs.

    Objects go in first, refs last, and every ref merge is checked before any ref is written, so a
    failure leaves the refs untouched (at worst some new unreferenced objects that ``gc`` removes).

    Raises:
        StoreError: Not an export, a corrupt object, or a ref whose history diverged from the local one.
    """
    path = Path(path)
    report = ImportReport()
    with _open_tar(path) as tar, store.writing():
        members = _classify(tar, path)
        for member in members.objects:
            _import_object(store, tar, member, report)
        histories = {name: _read_history(tar, name, member) for name, member in members.refs.items()}
        _index_manifests(store, members.manifests, report)
        _check_history_targets(store, histories)
        with store.refs.locked():
            report.refs = {name: merge_status(name, store.refs.history(name), hist)
                           for name, hist in sorted(histories.items())}
            for name, status in report.refs.items():
                if status in ("created", "extended"):
                    store.refs.write(name, histories[name])
    return report


def _import_object(store: Store, tar: tarfile.TarFile, member: tarfile.TarInfo, report: ImportReport) -> None:
    oid = _object_id_of(member.name)
    assert oid is not None  # checked by _classify
    if store.objects.has(oid):
        report.objects_present += 1
        return
    fh = tar.extractfile(member)
    assert fh is not None  # regular file, checked by _classify
    store.objects.put_stream(_chunks(fh), expected=oid)
    report.objects_added += 1


def _read_history(tar: tarfile.TarFile, name: str, member: tarfile.TarInfo) -> list[RefEntry]:
    fh = tar.extractfile(member)
    assert fh is not None
    return decode_history(name, fh.read())


def _index_manifests(store: Store, ids: list[str], report: ImportReport) -> None:
    for oid in ids:
        if not store.objects.has(oid):
            raise StoreError(f"the export lists manifest {oid} but does not contain it; re-export it.")
        manifest = parse_manifest(oid, store.objects.get_bytes(oid))
        missing = [ref for ref in manifest.referenced_ids() if not store.objects.has(ref)]
        if missing:
            raise StoreError(f"the export is incomplete: manifest {oid} names {missing[0]}, which is neither "
                             "in the export nor in this store; re-export it.")
        store.index.add(oid)
        report.manifests += 1


def _check_history_targets(store: Store, histories: dict[str, list[RefEntry]]) -> None:
    for name, history in histories.items():
        for entry in history:
            if not store.index.has(entry.id):
                raise StoreError(f"ref '{name}@{entry.version}' in the export points at {entry.id}, which "
                                 "is not a manifest in the export; re-export it.")
