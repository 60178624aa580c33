"""Move artifacts between stores as one tar file (``morfic store export`` / ``import``).

The tar mirrors the store layout and holds the closure of the named refs::

    morfic-export.json           {"format": 1, "morfic_version": ..., "refs": [...], "objects": N}
                                 (+ "omitted": {id: "trainer_state"} in a weights-only export,
                                  + "omitted_files": {id: "model.pt"} in a results-only one,
                                    "speed.png" for a rendered figure)
    objects/ab/cdef...           every object reachable from any version of those refs
    manifests/<id>               index markers of the manifests among them
    refs/<name>                  the full history of each named ref

Members are written in sorted order with fixed owner, mode and mtime, so exporting the same refs
twice gives the same bytes. Import treats the tar as untrusted: it checks everything before anything
becomes visible (see :func:`import_tar`), adds only what is missing or corrupt here, and merges each
ref history (see :func:`morfic_cli.store.refs.merge_status`); it is idempotent and all or nothing.

A weights-only export (``without_trainer_state``) leaves out the ``trainer_state`` inputs of the checkpoints
and lists them under ``omitted``; a results-only export (``results_only``, refs chosen by
:mod:`morfic_cli.store.results`) also leaves out the weight and rollout-log files, the rendered figures (and
other runs' curves) and lists them under ``omitted_files``. Their manifests are the store's, byte for byte.
Importing one records the omitted ids the store lacks under ``shallow/`` (:mod:`morfic_cli.store.shallow`);
exporting from such a store leaves them out (and lists them) by itself.
"""

from __future__ import annotations

import bz2
import gzip
import hashlib
import io
import json
import lzma
import os
import re
import shutil
import tarfile
import tempfile
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

from morfic_cli import __version__
from morfic_cli.errors import ArtifactNotFoundError, MorficError, StoreError, printable
from morfic_cli.runs import RUNS_PREFIX
from morfic_cli.store.gc import walk
from morfic_cli.store.manifest import MAX_MANIFEST_BYTES, clashing_names, parse_manifest, plain_name_problem
from morfic_cli.store.objects import CHUNK_SIZE, is_object_id, object_relpath, store_os_error, unlink_quiet
from morfic_cli.store.refs import (
    RefEntry,
    check_ref_name,
    decode_history,
    encode_history,
    is_ref_name,
    merge_status,
    next_entry,
)
from morfic_cli.store.results import results_histories
from morfic_cli.store.shallow import (
    FIGURE_KINDS,
    FIGURE_SUFFIXES,
    NOTHING,
    OMITTABLE_FILES,
    OMITTABLE_ROLES,
    RESULTS_ONLY,
    WEIGHTS_ONLY,
    is_figure,
    omittable_file,
)
from morfic_cli.validation import stored_cfg_problem
from morfic_cli.variant_names import stored_variants

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
        omitted: Inputs left out (id -> role ``trainer_state``), listed in the header; empty for a full export.
        omitted_files: Files left out (id -> file name: ``model.pt``, ``rollout.mcap``, ``obs.npz``, a figure such
            as ``speed.png``), listed in the header; empty but for a results-only export.
    """

    path: Path
    refs: list[str]
    objects: int = 0
    bytes: int = 0
    omitted: dict[str, str] = field(default_factory=dict)
    omitted_files: dict[str, str] = field(default_factory=dict)


@dataclass
class ImportReport:
    """What ``import_tar`` did.

    Attributes:
        objects_added: Objects that were new to this store.
        objects_present: Objects this store already had.
        objects_repaired: Of those, copies that were corrupt here and were replaced by the export's.
        manifests: Manifests indexed.
        refs: Ref name -> ``created``, ``extended`` or ``unchanged``.
        omitted: Inputs the (weights-only) export left out and this store lacks, now recorded under ``shallow/``.
        omitted_files: Files the (results-only) export left out and this store lacks, recorded the same way.
        filled: Inputs and files this store had recorded as left out and that this import brought.
        variants: Variant -> the refs (or manifest ids) of the bundle whose manifests name it, stock ones
            included (the store knows no registry); a user variant among them is code that commands on those runs
            import, with the user's consent (docs/extending.md), which ``morfic store import`` says.
    """

    objects_added: int = 0
    objects_present: int = 0
    objects_repaired: int = 0
    manifests: int = 0
    refs: dict[str, str] = field(default_factory=dict)
    omitted: list[str] = field(default_factory=list)
    omitted_files: list[str] = field(default_factory=list)
    filled: list[str] = field(default_factory=list)
    variants: dict[str, list[str]] = field(default_factory=dict)


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


#: At most this many refs are named in a default tar name; more give ``<first>+<N-1>-more``.
MAX_NAMED_REFS = 3

_TAR_NAME = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9._+-]*")


def bundle_name(refs: list[str]) -> str:
    """The file name ``morfic store export --out DIR`` gives the tar of ``refs`` when no ``--name`` is given.

    One ref: its last part (``runs/film-cpu-s0`` -> ``film-cpu-s0.tar``). Several: the last parts of the sorted
    refs joined by ``+`` (``runs/film-cpu-s0 runs/film-cpu-s1`` -> ``film-cpu-s0+film-cpu-s1.tar``); more than
    :data:`MAX_NAMED_REFS`: the first one and how many more (``film-cpu-s0+4-more.tar``).
    """
    parts = [name.rsplit("/", 1)[-1] for name in sorted(set(refs))]
    if len(parts) > MAX_NAMED_REFS:
        parts = [parts[0], f"{len(parts) - 1}-more"]
    return "+".join(parts) + ".tar"


def export_path(out_dir: Path, refs: list[str], name: str | None = None, *, force: bool = False) -> Path:
    """Where ``morfic store export REFS --out DIR [--name NAME]`` writes: ``DIR/NAME.tar``.

    ``NAME`` defaults to :func:`bundle_name`; a trailing ``.tar`` in ``name`` is not doubled. Nothing is created
    here (the export creates ``DIR`` once the refs are known to exist).

    Raises:
        StoreError: ``name`` is not a plain file name, or the tar exists and ``force`` is not set.
    """
    if name is None:
        file_name = bundle_name(refs)
    else:
        stem = name[:-4] if name.endswith(".tar") else name
        if not _TAR_NAME.fullmatch(stem):
            raise StoreError(
                f"--name {name!r} is not a file name: use letters, digits, '.', '_', '+' and '-' (not "
                "first: '.'), no '/' or spaces, e.g. --name film-cpu (writes film-cpu.tar)."
            )
        file_name = stem + ".tar"
    path = Path(out_dir) / file_name
    if path.is_dir():
        raise StoreError(f"{path} is a folder; choose another --name or --out.")
    if path.exists() and not force:
        raise StoreError(f"{path} exists; pass --force to overwrite it, or choose another --name or --out.")
    return path


def export_tar(
    store: Store,
    refs: list[str],
    out: Path,
    *,
    latest: bool = False,
    without_trainer_state: bool = False,
    results_only: bool = False,
) -> ExportReport:
    """Write the closure of ``refs`` (objects and ref histories) to the tar file ``out``.

    With ``latest``, only each ref's current version goes in, as a one-version history (version 1 in the
    importing store): a small snapshot, e.g. a trained policy without its earlier checkpoints. Such a
    snapshot and a full export of the same ref do not merge into one store (their histories differ).

    With ``without_trainer_state``, the ``trainer_state`` inputs (and what only they reach) stay out and
    the header lists them (``"omitted"``): a weights-only bundle that evaluates and exports but cannot be
    resumed. Inputs this store itself lacks because it imported such a bundle are left out (and listed) in
    any case.

    With ``results_only``, ``refs`` are runs and the tar holds their results
    (:func:`morfic_cli.store.results.results_histories` picks the refs and history prefixes; ``latest`` changes
    nothing) without the trainer states, weights, rollout logs, rendered figures and the training curves of
    checkpoints other than the runs' own (listed under ``omitted`` and ``omitted_files``): a bundle that ``morfic
    report`` reads (it draws the figures from the tables), but that cannot evaluate, diagnose or resume.

    Raises:
        ArtifactNotFoundError: A name that is not a ref.
        StoreError: A reachable object is missing (run ``verify``), ``out`` cannot be written, or (results only)
            a ref that is not a run or a run without results.
    """
    names = sorted(set(refs))
    out = Path(out)
    if out.is_dir() or not out.name:
        raise StoreError(f"{out} is a folder; give the tar file to write, e.g. {out / 'export.tar'}.")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise StoreError(f"{out}: {parent} is a file, so the tar cannot be written there.")
            break
    if not names:
        raise StoreError("name at least one ref to export, e.g. `morfic store export runs/film-cpu-s0 --out bundles/`.")
    for name in names:
        if not store.refs.exists(check_ref_name(name)):
            raise ArtifactNotFoundError(f"no ref '{name}' in store {store.root}; try `morfic store ls`.")
    with store.reading():
        if results_only:
            histories = results_histories(store, names)
            names = sorted(histories)
        else:
            histories = {name: store.refs.history(name) for name in names}
            if latest:
                histories = {name: [RefEntry(1, h[-1].id, h[-1].time)] for name, h in histories.items()}
        report = ExportReport(path=out, refs=names)
        if results_only:  # the runs' own curves stay in; other checkpoints' are in their runs' bundles
            leave_out = RESULTS_ONLY.keeping(frozenset(histories[name][-1].id for name in set(refs)))
        else:
            leave_out = WEIGHTS_ONLY if without_trainer_state else NOTHING
        reached = walk(store, [entry.id for h in histories.values() for entry in h], leave_out=leave_out)
        ids = sorted(reached.ids)
        missing = [oid for oid in ids if not store.objects.has(oid)]
        if missing:
            raise StoreError(
                f"cannot export: {len(missing)} reachable object(s) are missing (first: "
                f"{missing[0]}); run `morfic store verify`."
            )
        report.omitted = dict(sorted(reached.absent.items()))
        report.omitted_files = dict(sorted(reached.absent_files.items()))
        _write_tar(store, out, names, histories, ids, report)
    return report


def _umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _write_tar(
    store: Store,
    out: Path,
    names: list[str],
    histories: dict[str, list[RefEntry]],
    ids: list[str],
    report: ExportReport,
) -> None:
    """Write the tar to a temp file next to ``out`` and rename it into place."""
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp")
    tmp: str | None = tmp_name
    os.close(fd)
    try:
        with tarfile.open(tmp_name, "w", format=tarfile.PAX_FORMAT) as tar:
            header = {"format": EXPORT_FORMAT, "morfic_version": __version__, "objects": len(ids), "refs": names}
            if report.omitted:  # a full export's header (and bytes) stay what they always were
                header["omitted"] = report.omitted
            if report.omitted_files:
                header["omitted_files"] = report.omitted_files
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
        os.chmod(tmp_name, 0o666 & ~_umask())  # mkstemp makes 0600; a bundle is a file to share, as `cp` would make it
        os.replace(tmp_name, out)
        tmp = None
    except OSError as exc:
        raise store_os_error(exc, f"writing the export {out}", store.root) from exc
    finally:
        if tmp is not None:
            unlink_quiet(tmp)


#: Largest accepted header member and ref history member of an export (bytes).
MAX_SMALL_MEMBER = 16 << 20

_HEADER_KEYS = frozenset({"format", "morfic_version", "objects", "refs"})
_OPTIONAL_HEADER_KEYS = frozenset({"omitted", "omitted_files"})


@dataclass
class _Members:
    objects: list[tarfile.TarInfo] = field(default_factory=list)
    manifests: list[str] = field(default_factory=list)
    refs: dict[str, tarfile.TarInfo] = field(default_factory=dict)
    header: tarfile.TarInfo | None = None


def _classify(tar: tarfile.TarFile, path: Path) -> _Members:
    """Sort the tar's members into objects, index markers and refs; refuse anything else."""
    members = _Members()
    names: set[str] = set()
    for member in tar.getmembers():
        name, shown = member.name, _shown(member.name)
        if member.isdir():  # nothing is ever extracted: a folder entry (as `tar` writes one) is ignored
            continue
        if not member.isfile():
            raise StoreError(f"{path} is not a morfic export: member {shown} is not a regular file.")
        if member.sparse is not None or member.size < 0:  # a sparse file's holes read as zeros: a bomb in a plain tar
            raise StoreError(f"{path} is not a morfic export: member {shown} is a sparse file or has a negative size.")
        if name in names:
            raise StoreError(f"{path} is not a morfic export: member {shown} appears twice.")
        names.add(name)
        if name == HEADER:
            members.header = member
        elif _object_id_of(name) is not None:
            members.objects.append(member)
        elif name.startswith("manifests/") and is_object_id(name[10:]):
            if member.size != 0:
                raise StoreError(f"{path} is not a morfic export: index marker '{name}' is not empty.")
            members.manifests.append(name[10:])
        elif name.startswith("refs/") and is_ref_name(name[5:]):
            members.refs[name[5:]] = member
        else:
            raise StoreError(f"{path} is not a morfic export: unexpected member {shown}.")
    if members.header is None:
        raise StoreError(f"{path} is not a morfic export (no {HEADER}); make one with `morfic store export`.")
    return members


def _shown(name: str) -> str:
    """A member name for a message: quoted, cut at 200 characters, control characters and bad bytes escaped."""
    return repr(name[:200])


def _object_id_of(name: str) -> str | None:
    """The id of an ``objects/ab/cdef...`` member name, or ``None``."""
    oid = name[len("objects/") :].replace("/", "", 1)
    return oid if is_object_id(oid) and name == object_relpath(oid) else None


def _chunks(fh: IO[bytes]) -> Iterator[bytes]:
    return iter(lambda: fh.read(CHUNK_SIZE), b"")


#: A compressed bundle (gzip, bzip2, xz: ``foo.tar.gz``) may expand to at most this many times its own size
#: when read (a shipped bundle expands about 2 times), or to :data:`MIN_EXPANDED_BYTES`, whichever is more;
#: past that it is refused as a compression bomb while streaming, before its bytes fill memory or disk. A plain
#: tar (what ``morfic store export`` writes) cannot expand: import never reads more than the file holds.
MAX_EXPANSION = 32

#: Every compressed bundle may expand to this many bytes (so small ones always import), see :data:`MAX_EXPANSION`.
MIN_EXPANDED_BYTES = 64 << 20

#: Import reads a bundle about three times over (list, check, stage); a tar that makes it read (decompress) more
#: than this many times its limit (the file's size, or a compressed bundle's expansion limit) is refused: its
#: member headers point backwards or loop.
MAX_READ_PASSES = 8

_COMPRESSED = (
    (b"\x1f\x8b", "gzip", lambda fh: gzip.GzipFile(fileobj=fh, mode="rb")),
    (b"BZh", "bzip2", bz2.BZ2File),
    (b"\xfd7zXZ\x00", "xz", lzma.LZMAFile),
)

_READ_ERRORS = (tarfile.TarError, EOFError, zlib.error, lzma.LZMAError, gzip.BadGzipFile, ValueError)
"""What a hostile or damaged tar makes :mod:`tarfile` raise while reading (ValueError: e.g. a bad sparse map)."""


class _BoundedReader:
    """A bundle's bytes as :mod:`tarfile` reads them (decompressed), with a bomb and a loop refused while streaming.

    ``limit``: the largest offset a compressed bundle may reach (None for a plain tar). Every byte read, skipped
    forward or (compressed) decompressed again after a backward seek counts towards ``MAX_READ_PASSES`` times
    the limit (the file's size for a plain tar), and a single read is at most what a morfic member needs.
    """

    def __init__(self, stream: io.BufferedIOBase, path: Path, size: int, limit: int | None, kind: str) -> None:
        self._stream, self._path, self._size, self._limit, self._kind = stream, path, size, limit, kind
        self._budget = MAX_READ_PASSES * max(limit or size, 1 << 20)
        self._pos = 0

    def _spend(self, n: int) -> None:
        self._budget -= n
        if self._budget < 0:
            raise StoreError(
                f"{self._path} makes import read it more than {MAX_READ_PASSES} times over (its tar "
                "headers point backwards or loop); it was not made by `morfic store export`, nothing "
                "was imported. Re-export it."
            )

    def _bomb(self) -> StoreError:
        return StoreError(
            f"{self._path} is {self._kind}-compressed and expands to more than {self._limit} bytes, "
            f"over {MAX_EXPANSION} times its {self._size} bytes (a compression bomb?); nothing was "
            "imported. `morfic store export` writes plain tars: decompress a bundle you trust first "
            "and import the .tar (a plain tar has no such limit)."
        )

    def read(self, size: int | None = -1) -> bytes:
        if size is None or size < 0:  # (tarfile always asks for a size)
            size = max((self._limit if self._limit is not None else self._size) - self._pos + 1, 0)
        elif size > MAX_SMALL_MEMBER + tarfile.BLOCKSIZE:  # import reads 1 MiB chunks; tarfile reads headers whole
            raise StoreError(
                f"{self._path} has a tar header of more than {MAX_SMALL_MEMBER} bytes; it was not made "
                "by `morfic store export`, nothing was imported."
            )
        data = self._stream.read(size)
        self._pos += len(data)
        self._spend(len(data))
        if self._limit is not None and self._pos > self._limit:
            raise self._bomb()
        return data

    def seek(self, offset: int, whence: int = 0) -> int:
        target = offset + (self._pos if whence == 1 else 0)
        if whence not in (0, 1) or target < 0 or (self._limit is None and target > self._size):
            raise tarfile.ReadError(f"a member runs to offset {target}, the file has {self._size} bytes")
        if self._limit is not None and target > self._limit:  # a member header claims bytes past the limit
            raise self._bomb()
        if target >= self._pos:
            self._spend(target - self._pos)
        elif self._limit is not None:  # a compressed stream decompresses again from its start
            self._spend(target)
        self._pos = self._stream.seek(target)
        return self._pos

    def tell(self) -> int:
        return self._pos

    def seekable(self) -> bool:
        return True

    def readable(self) -> bool:
        return True


class _ForwardTarFile(tarfile.TarFile):
    """A tar read forwards only: a member whose header moves the next one back (a negative size) ends the read."""

    def next(self) -> tarfile.TarInfo | None:
        # (the first member is read when opening; typeshed lacks the undocumented TarFile.firstmember)
        cached, before = self.firstmember is not None, self.offset  # type: ignore[attr-defined]
        info = super().next()
        if info is not None and not cached and self.offset <= before:  # tarfile would read them forever
            raise tarfile.ReadError(f"the member header at offset {before} points backwards")
        return info


@contextmanager
def _open_tar(path: Path) -> Iterator[tarfile.TarFile]:
    """The tar at ``path``, plain or gzip/bzip2/xz-compressed, read through :class:`_BoundedReader`."""
    try:
        raw = open(path, "rb")  # noqa: SIM115 (closed below, after the tar)
    except FileNotFoundError:
        raise StoreError(f"no such file: {path}.") from None
    except IsADirectoryError:
        raise StoreError(f"{path} is a folder; give the tar file made by `morfic store export`.") from None
    except OSError as exc:
        raise StoreError(f"{path} is not a readable tar file ({exc}); make one with `morfic store export`.") from exc
    stream: io.BufferedIOBase = raw
    try:
        try:
            size = os.fstat(raw.fileno()).st_size
            magic = raw.read(6)
            raw.seek(0)
            kind, opener = next(((k, o) for m, k, o in _COMPRESSED if magic.startswith(m)), ("plain", None))
            stream = raw if opener is None else opener(raw)
            limit = None if opener is None else max(MIN_EXPANDED_BYTES, MAX_EXPANSION * size)
            reader = _BoundedReader(stream, path, size, limit, kind)
            # typeshed's tarfile fileobj protocol also asks for write() and close(), which mode "r" never calls
            tar = _ForwardTarFile(fileobj=reader, mode="r")  # type: ignore[arg-type]
        except (*_READ_ERRORS, OSError) as exc:
            raise StoreError(
                f"{path} is not a readable tar file ({exc}); make one with `morfic store export`."
            ) from exc
        with tar:
            yield tar
    finally:
        stream.close()
        raw.close()


@dataclass
class _Plan:
    """Everything an import will write, checked before anything is written."""

    staged: dict[str, Path] = field(default_factory=dict)
    """Object id -> staged temp file (new objects, and good copies of locally corrupt ones)."""
    present: int = 0
    contents: dict[str, bytes] = field(default_factory=dict)
    """Bytes of the exported manifests (read while hashing)."""
    manifests: list[str] = field(default_factory=list)
    histories: dict[str, list[RefEntry]] = field(default_factory=dict)
    omitted: list[str] = field(default_factory=list)
    """Ids the export declares left out (``trainer_state`` inputs of its manifests)."""
    omitted_files: list[str] = field(default_factory=list)
    """Ids of the files the export declares left out (weights and rollout logs of its manifests)."""
    objects: list[str] = field(default_factory=list)
    """Every object id the tar holds."""
    variants: dict[str, list[str]] = field(default_factory=dict)
    """Manifest id -> the variants it names (stock ones too) (checked well-formed, never imported)."""


#: Which refs an import appends to instead of merging: all (``True``), none (``False``), or those a predicate names.
AppendRule = bool | Callable[[str], bool]


def appends_results(name: str) -> bool:
    """Every ref but a run's: ``morfic store import --append``'s rule.

    A result ref (``evals/NAME``, ``diagnoses/calibration``) is a log that bundles of several stores may each have
    begun; a run's history (``runs/NAME``) is one training, and a diverged one is another run of that name, which
    an import still refuses.
    """
    return not name.startswith(RUNS_PREFIX)


def _appends(append: AppendRule, name: str) -> bool:
    return append(name) if callable(append) else append


def import_tar(store: Store, path: Path, *, append: AppendRule = False) -> ImportReport:
    """Import an export tar, all or nothing.

    With ``append``, a ref's history is not merged but extended: the import's versions whose ids this ref
    never pointed at are appended, in the import's order (how ``reproduce --executor ray`` brings home jobs
    that each add one version to a ref all of them share, such as ``diagnoses/calibration``). ``True``: every
    ref; a predicate (:func:`appends_results`): the refs it names, the others merged.

    Everything is checked before anything becomes visible: the header, every object against its
    hash and declared size (objects this store already has are rehashed, and a corrupt local copy is
    replaced by the export's good one), every manifest against the schema (safe file names, sizes
    that match the objects, inputs that are manifests or, in a weights-only export, declared left out under
    their own role ``trainer_state``), every ref history (entries, hash chain,
    targets that are manifests) and how it merges with the local one. Only then are objects renamed
    into place, manifests indexed, left-out inputs recorded under ``shallow/`` (and those this import brings
    unrecorded) and refs written (under the ref lock; a failure while writing refs puts the old histories back).

    Raises:
        StoreError: Not an export, a damaged or truncated tar, a corrupt object, an invalid manifest or
            history, or a ref whose history diverged from the local one. Nothing was imported.
    """
    path = Path(path)
    report = ImportReport()
    with _open_tar(path) as tar:
        # a first pass that writes nothing, not even a new store's folders
        _checked_stage(store, tar, path, None, append)
        with store.writing():
            staging = Path(tempfile.mkdtemp(dir=store.root / "tmp", prefix="import-"))
            try:
                _commit(store, _checked_stage(store, tar, path, staging, append), report, append)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
    return report


def _checked_stage(
    store: Store, tar: tarfile.TarFile, path: Path, staging: Path | None, append: AppendRule = False
) -> _Plan:
    try:
        return _stage(store, tar, path, staging, append)
    except _READ_ERRORS as exc:
        raise StoreError(
            f"{path} is damaged or truncated ({exc}); nothing was imported. Copy the whole file again, or re-export it."
        ) from exc
    except OSError as exc:
        raise store_os_error(exc, f"reading {path}", store.root) from exc


def _stage(store: Store, tar: tarfile.TarFile, path: Path, staging: Path | None, append: AppendRule = False) -> _Plan:
    """Read and check the whole tar; stage the objects this store lacks or has corrupt (none without ``staging``)."""
    members = _classify(tar, path)
    header = _read_header(tar, members, path)
    plan = _Plan()
    sizes: dict[str, int] = {}
    listed = set(members.manifests)
    for member in members.objects:
        oid = _object_id_of(member.name)
        assert oid is not None  # checked by _classify
        fh = tar.extractfile(member)
        assert fh is not None  # regular file, checked by _classify
        if oid in listed and member.size <= MAX_MANIFEST_BYTES:
            plan.contents[oid] = fh.read()
            fh = io.BytesIO(plan.contents[oid])
        if staging is None or store.objects.intact(oid, member.size):
            actual, size = _hash_stream(_chunks(fh))
            plan.present += 1
        else:
            tmp, actual, size = store.objects.stage(_chunks(fh), staging)
            plan.staged[oid] = tmp
        if actual != oid or size != member.size:
            raise StoreError(
                f"object {oid} in {path} is corrupt (its bytes hash to {actual}); nothing was "
                "imported. Re-export it from an intact store."
            )
        sizes[oid] = size
    if header["objects"] != len(sizes):
        raise StoreError(
            f"{path} is incomplete: its header lists {header['objects']} objects, it holds "
            f"{len(sizes)}; nothing was imported. Re-export it."
        )
    exported = set(members.manifests)
    omitted: dict[str, str] = header["omitted"]
    omitted_files: dict[str, str] = header["omitted_files"]
    both = sorted((set(omitted) | set(omitted_files)) & (exported | set(sizes)))
    if both:
        raise StoreError(
            f"{path} is inconsistent: its header lists {both[0]} as left out, yet it holds it; "
            "nothing was imported. Re-export it."
        )
    named: set[str] = set()
    for oid in sorted(exported):
        named |= _check_manifest(store, oid, plan, sizes, exported, omitted, omitted_files)
    unnamed = sorted((set(omitted) | set(omitted_files)) - named)
    if unnamed:
        what = ("trainer state", "input") if unnamed[0] in omitted else (omitted_files[unnamed[0]], "file")
        raise StoreError(
            f"{path} is inconsistent: its header lists {unnamed[0]} as a left-out {what[0]}, but "
            f"no manifest in it names that {what[1]}; nothing was imported. Re-export it."
        )
    plan.manifests = sorted(exported)
    plan.omitted = sorted(omitted)
    plan.omitted_files = sorted(omitted_files)
    plan.objects = sorted(sizes)
    for name, member in sorted(members.refs.items()):
        history = decode_history(name, _read_small(tar, member, f"ref '{name}'", path))
        if not history:
            raise StoreError(f"ref '{name}' in {path} has an empty history; nothing was imported.")
        for entry in history:
            if entry.id not in exported and not store.index.has(entry.id):
                raise StoreError(
                    f"ref '{name}@{entry.version}' in {path} points at {entry.id}, which is not a "
                    "manifest in the export; nothing was imported. Re-export it."
                )
        plan.histories[name] = history
    if sorted(plan.histories) != header["refs"]:
        raise StoreError(
            f"{path} is inconsistent: its header lists refs {header['refs'][:5]}, it holds "
            f"{sorted(plan.histories)[:5]}; nothing was imported. Re-export it."
        )
    _check_ref_folders(store, sorted(plan.histories), path)
    for name, history in plan.histories.items():
        if not _appends(append, name):
            merge_status(name, store.refs.history(name), history)  # diverged: refuse before writing anything
    return plan


def _check_ref_folders(store: Store, names: list[str], path: Path) -> None:
    """Refuse a ref of the bundle that is a folder of refs, or inside a ref, here or in the bundle (before writing)."""
    taken = set(names)
    for name in names:
        parts = name.split("/")
        clash = next(
            (p for p in ("/".join(parts[:i]) for i in range(1, len(parts))) if p in taken or store.refs.exists(p)), None
        )
        if clash is None and store.refs.path(name).is_dir():
            clash = next(n for n in store.refs.names() if n.startswith(name + "/"))
        if clash is not None:
            raise StoreError(
                f"{path} holds ref '{name}', but ref '{clash}' exists here or in it, and a name cannot "
                "be both a ref and a folder of refs; nothing was imported. Rename the local ref, or "
                "import into another store."
            )


def _appended(local: list[RefEntry], incoming: list[RefEntry]) -> list[RefEntry]:
    """``local`` extended by the entries of ``incoming`` whose ids it never pointed at (re-chained)."""
    out, seen = list(local), {e.id for e in local}
    for entry in incoming:
        if entry.id not in seen:
            out.append(next_entry(out, entry.id, entry.time))
            seen.add(entry.id)
    return out


def _read_small(tar: tarfile.TarFile, member: tarfile.TarInfo, what: str, path: Path) -> bytes:
    if member.size > MAX_SMALL_MEMBER:
        raise StoreError(
            f"{what} in {path} is {member.size} bytes, more than {MAX_SMALL_MEMBER}; it was not "
            "made by `morfic store export`."
        )
    fh = tar.extractfile(member)
    assert fh is not None
    return fh.read()


def _read_header(tar: tarfile.TarFile, members: _Members, path: Path) -> dict:
    assert members.header is not None
    bad = StoreError(
        f"{path} has an invalid {HEADER}; it was not made by `morfic store export` (or by a "
        "newer morfic: upgrade morfic)."
    )
    try:
        header = json.loads(_read_small(tar, members.header, HEADER, path), parse_constant=_no_constant)
    except (ValueError, RecursionError):  # RecursionError: JSON nested too deep
        raise bad from None
    if not isinstance(header, dict) or not _HEADER_KEYS <= set(header) <= _HEADER_KEYS | _OPTIONAL_HEADER_KEYS:
        raise bad
    if header["format"] != EXPORT_FORMAT or isinstance(header["format"], bool):
        raise bad
    count, refs = header["objects"], header["refs"]
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise bad
    if not (isinstance(refs, list) and all(isinstance(r, str) and is_ref_name(r) for r in refs)):
        raise bad
    if not isinstance(header["morfic_version"], str) or len(header["morfic_version"]) > 100:
        raise bad
    header["refs"] = sorted(refs)
    header["omitted"] = _read_omitted(
        header.get("omitted", {}), bad, path, OMITTABLE_ROLES.__contains__, "input", ", ".join(sorted(OMITTABLE_ROLES))
    )
    header["omitted_files"] = _read_omitted(
        header.get("omitted_files", {}), bad, path, _omittable_label, "file", _OMITTABLE_FILES_TEXT
    )
    return header


_OMITTABLE_FILES_TEXT = (
    f"{', '.join(sorted(OMITTABLE_FILES))} and rendered figures "
    f"({'/'.join(s.lstrip('.') for s in FIGURE_SUFFIXES)} of {', '.join(sorted(FIGURE_KINDS))} "
    "artifacts)"
)
"""What a bundle may leave out of a manifest's files, for messages."""


def _omittable_label(label: str) -> bool:
    """Whether a header's ``omitted_files`` label may name a left-out file: an omittable name, or a plain figure name.

    Which manifest kind the figure belongs to is checked with the manifest (:func:`_check_manifest`).
    """
    return label in OMITTABLE_FILES or (is_figure(label) and plain_name_problem(label) is None)


def _read_omitted(
    omitted: object, bad: StoreError, path: Path, allowed: Callable[[str], bool], what: str, allowed_text: str
) -> dict[str, str]:
    """The header's ``omitted`` (id -> role) or ``omitted_files`` (id -> file name) map, checked.

    Full ids, and only the roles or file names (``allowed``, described by ``allowed_text``) a bundle may leave out.
    """
    if not (isinstance(omitted, dict) and all(isinstance(k, str) and is_object_id(k) for k in omitted)):
        raise bad
    for oid, label in omitted.items():
        if not isinstance(label, str) or not allowed(label):
            shown = label[:40] if isinstance(label, str) else type(label).__name__
            raise StoreError(
                f"{path} leaves out {what} {oid} as {shown!r}, but a bundle may only leave out "
                f"{allowed_text} {what}s; nothing was imported. Export it again with everything it "
                "needs."
            )
    return dict(omitted)


def _no_constant(name: str) -> None:
    raise ValueError(name)


def _hash_stream(chunks: Iterator[bytes]) -> tuple[str, int]:
    digest = hashlib.sha256()
    size = 0
    for chunk in chunks:
        digest.update(chunk)
        size += len(chunk)
    return digest.hexdigest(), size


def _check_manifest(
    store: Store,
    oid: str,
    plan: _Plan,
    sizes: dict[str, int],
    exported: set[str],
    omitted: dict[str, str],
    omitted_files: dict[str, str],
) -> set[str]:
    """Parse an exported manifest strictly and check that everything it names is there, with the right size.

    An input may instead be declared left out (``omitted``), under its own role, which must be ``trainer_state``;
    a file (``omitted_files``) under a name its manifest's kind may lack (:func:`~morfic_cli.store.shallow.
    omittable_file`: ``OMITTABLE_FILES``, or a rendered figure of a result).
    Returns the declared-omitted ids this manifest names.
    """
    if oid in plan.staged:
        data = plan.staged[oid].read_bytes()
    elif oid in plan.contents:
        data = plan.contents[oid]
    elif oid in sizes:
        raise StoreError(
            f"manifest {oid} in the export is {sizes[oid]} bytes, more than the {MAX_MANIFEST_BYTES} a "
            "manifest may have; nothing was imported."
        )
    elif store.objects.intact(oid):
        data = store.objects.get_bytes(oid)
    else:
        raise StoreError(
            f"the export lists manifest {oid} but does not contain it; nothing was imported. Re-export it."
        )
    manifest = parse_manifest(oid, data)
    try:  # a variant names code that commands would import: refuse any string that is not a well-formed name
        variants = stored_variants(manifest.config, manifest.meta)  # stock ones too: the store knows no registry
    except MorficError as exc:
        raise StoreError(
            f"manifest {oid} in the export names a variant that is not well-formed ({exc}); nothing was "
            "imported. morfic records a stock name, an entry-point name or module.path:Class: the bundle "
            "was not made by morfic, or was edited."
        ) from None
    if variants:
        plan.variants[oid] = variants
    if manifest.kind == "checkpoint" and "model.pt" in manifest.files:  # a run: commands rebuild models from it
        problem = stored_cfg_problem(manifest.config)
        if problem is not None:
            raise StoreError(
                f"manifest {oid} in the export is a run's checkpoint with an invalid config "
                f"({printable(problem)}); nothing was imported. `morfic train` never writes one: the "
                "bundle was not made by morfic, or was edited."
            )
    clash = clashing_names(manifest.files)
    if clash is not None:
        raise StoreError(
            f"manifest {oid} in the export names the files {ascii(clash[0][:80])} and "
            f"{ascii(clash[1][:80])}, which cannot both be files of one folder (equal but for case, or "
            "one a folder of the other); nothing was imported. The bundle was not made by morfic."
        )
    named: set[str] = set()
    for name, entry in manifest.files.items():
        problem = plain_name_problem(name)  # e.g. .config/morfic/trusted-variants, sitecustomize.py, x.pth
        if problem is not None:
            raise StoreError(
                f"manifest {oid} in the export names the file {ascii(name[:80])}: it {problem}; nothing "
                'was imported. morfic writes only plain file names (docs/concepts.md, "File names"): '
                "the bundle was not made by morfic, or was edited."
            )
        size = sizes.get(entry.id)
        if size is None and store.objects.intact(entry.id):
            size = store.objects.size(entry.id)
        if entry.id in omitted_files:
            if not omittable_file(manifest.kind, name):
                raise StoreError(
                    f"manifest {oid} in the export names the left-out file {entry.id} as '{name}' (a "
                    f"{manifest.kind} artifact), but only {_OMITTABLE_FILES_TEXT} files may be left "
                    "out; nothing was imported. Export it again with everything it needs."
                )
            named.add(entry.id)
            if size is None:
                continue
        if size is None:
            raise StoreError(
                f"the export is incomplete: manifest {oid} names {entry.id} (file '{name}'), which "
                "is neither in the export nor intact in this store; nothing was imported. Re-export it."
            )
        if size != entry.size:
            raise StoreError(
                f"manifest {oid} declares file '{name}' as {entry.size} bytes, but its object has "
                f"{size}; nothing was imported. It was not made by morfic."
            )
    for role, input_id in manifest.inputs.items():
        if input_id in omitted:
            if omitted[input_id] != role:
                raise StoreError(
                    f"manifest {oid} in the export names the left-out input {input_id} as '{role}', "
                    f"but only its {omitted[input_id]} may be left out; nothing was imported. Export it "
                    "again with everything it needs."
                )
            named.add(input_id)
        elif input_id not in exported and not store.index.has(input_id):
            raise StoreError(
                f"the export is incomplete: manifest {oid} input '{role}' {input_id} is not a "
                "manifest in the export or in this store; nothing was imported. Re-export it."
            )
    return named


def _commit(store: Store, plan: _Plan, report: ImportReport, append: AppendRule = False) -> None:
    """Make a checked import visible: objects, then index markers, then refs (rolled back on failure)."""
    with store.refs.locked():
        previous = {name: store.refs.history(name) for name in plan.histories}
        plan.histories = {
            name: _appended(previous[name], hist) if _appends(append, name) else hist
            for name, hist in plan.histories.items()
        }
        statuses = {name: merge_status(name, previous[name], hist) for name, hist in sorted(plan.histories.items())}
        try:
            for oid, tmp in sorted(plan.staged.items()):
                if store.objects.has(oid):
                    report.objects_repaired += int(store.objects.commit_staged(tmp, oid))
                    report.objects_present += 1
                elif store.objects.commit_staged(tmp, oid):
                    report.objects_added += 1
            report.objects_present += plan.present
            for oid in plan.manifests:
                store.index.add(oid)
            report.manifests = len(plan.manifests)
            for oid in plan.objects:
                if store.omitted.has(oid):  # a fuller bundle after a weights- or results-only one: the gap is filled
                    store.omitted.remove(oid)
                    report.filled.append(oid)
            for oids, recorded in ((plan.omitted, report.omitted), (plan.omitted_files, report.omitted_files)):
                for oid in oids:
                    if not store.objects.has(oid):
                        store.omitted.add(oid)
                        recorded.append(oid)
        except OSError as exc:
            raise store_os_error(exc, "importing objects", store.root) from exc
        written: list[str] = []
        try:
            for name, status in statuses.items():
                if status in ("created", "extended"):
                    store.refs.write(name, plan.histories[name])
                    written.append(name)
        except BaseException:
            for name in written:
                if previous[name]:
                    store.refs.write(name, previous[name])
                else:
                    store.refs.remove(name)
            raise
        report.refs = statuses
        report.variants = _named_variants(plan)


def _named_variants(plan: _Plan) -> dict[str, list[str]]:
    """Variant -> the bundle's refs whose versions name it (a manifest no ref points at: its short id)."""
    out: dict[str, list[str]] = {}
    pointed: set[str] = set()
    for name, history in sorted(plan.histories.items()):
        for entry in history:
            pointed.add(entry.id)
            for variant in plan.variants.get(entry.id, ()):
                refs = out.setdefault(variant, [])
                if name not in refs:
                    refs.append(name)
    for oid, names in sorted(plan.variants.items()):
        for variant in names if oid not in pointed else ():
            out.setdefault(variant, []).append(oid[:12])
    return dict(sorted(out.items()))
