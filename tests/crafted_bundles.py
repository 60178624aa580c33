"""Hand-made (hostile) export tars for the import tests: any manifest bytes, any members, any header.

Three levels: :func:`write_bundle` (a bundle from blobs, manifests and histories), :func:`write_members` (any
``TarInfo`` members, links and devices included, plain or compressed), and :func:`ustar_block` / :func:`raw_tar`
(header blocks byte by byte: lying size fields, bad checksums, raw name bytes). :func:`stream` and
:func:`zeros_stream` build compression bombs by concatenating compressed streams, without ever holding the
expanded bytes.
"""

from __future__ import annotations

import bz2
import functools
import gzip
import hashlib
import io
import json
import lzma
import os
import tarfile
from pathlib import Path
from typing import Any

GOOD_TIME = "2025-01-02T03:04:05.000000Z"


def oid_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def manifest_bytes(**fields: Any) -> bytes:
    """A manifest document with defaults for every key (canonical JSON unless ``allow_nan`` is needed)."""
    doc = {
        "schema": 1,
        "kind": "report",
        "morfic_version": "0.1.0",
        "created": GOOD_TIME,
        "config": {},
        "inputs": {},
        "files": {},
        "meta": {},
    }
    doc.update(fields)
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode("ascii")


def history_bytes(ids: list[str], times: list[str] | None = None) -> bytes:
    """A legacy (unchained) ref history, as every morfic before the hash chain wrote it."""
    times = times or [GOOD_TIME] * len(ids)
    lines = [
        json.dumps({"id": oid, "time": t, "version": n}, sort_keys=True, separators=(",", ":"))
        for n, (oid, t) in enumerate(zip(ids, times, strict=True), start=1)
    ]
    return "".join(line + "\n" for line in lines).encode()


def write_bundle(
    path: Path,
    *,
    blobs: list[bytes] = (),
    manifests: list[bytes] = (),
    refs: dict[str, bytes] | None = None,
    header: dict | None = None,
    extra: dict[str, bytes] | None = None,
) -> Path:
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
    write_bundle(
        path, blobs=list(files.values()), manifests=[manifest], refs={"reports/evil": history_bytes([oid_of(manifest)])}
    )
    return path, oid_of(manifest)


def listing(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (relative path -> bytes), to compare a store before and after."""
    if not root.exists():
        return {}
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def tree(root: Path, *, skip: Path | None = None) -> dict[str, object]:
    """Every entry under ``root`` but ``skip``: files by bytes and mode, folders, symlinks by target, others by type."""
    out: dict[str, object] = {}
    for folder, dirs, files in os.walk(root):
        here = Path(folder)
        if skip is not None and here == skip:
            dirs[:] = []
            continue
        for name in [*dirs, *files]:
            path = here / name
            if skip is not None and path == skip:
                out[path.relative_to(root).as_posix()] = "<skipped>"
                continue
            st = path.lstat()
            rel = path.relative_to(root).as_posix()
            if path.is_symlink():
                out[rel] = ("link", os.readlink(path))
            elif path.is_file():
                out[rel] = ("file", st.st_mode, path.read_bytes())
            elif path.is_dir():
                out[rel] = ("dir",)
            else:
                out[rel] = ("other", st.st_mode)
    return out


# ---------------------------------------------------------------------------------------------- members

DATA = b"a,b\n1,2\n"


def header_bytes(objects: int, refs: list[str], **extra: Any) -> bytes:
    """An export header (``morfic-export.json``) declaring ``objects`` and ``refs``."""
    return json.dumps(
        {"format": 1, "morfic_version": "0.1.0", "objects": objects, "refs": sorted(refs), **extra}
    ).encode()


def member(
    name: str,
    data: bytes = b"",
    *,
    kind: bytes = tarfile.REGTYPE,
    linkname: str = "",
    size: int | None = None,
    pax: dict[str, str] | None = None,
) -> tuple[tarfile.TarInfo, bytes]:
    """A tar member: ``kind`` is a tarfile type (``SYMTYPE``, ``LNKTYPE``, ``CHRTYPE``, ``FIFOTYPE``, ...)."""
    info = tarfile.TarInfo(name)
    info.type = kind
    info.linkname = linkname
    info.size = len(data) if size is None else size
    info.mode = 0o644
    if pax:
        info.pax_headers = dict(pax)
    return info, data


def good_members(ref: str = "runs/x", blob: bytes = DATA) -> list[tuple[tarfile.TarInfo, bytes]]:
    """The members of a well-formed one-ref bundle: header, a blob, a report manifest naming it, its marker, the ref."""
    manifest = manifest_bytes(files={"t.csv": {"id": oid_of(blob), "size": len(blob)}})
    return [
        member("morfic-export.json", header_bytes(2, [ref])),
        *[member(f"objects/{oid_of(d)[:2]}/{oid_of(d)[2:]}", d) for d in sorted([blob, manifest], key=oid_of)],
        member(f"manifests/{oid_of(manifest)}"),
        member(f"refs/{ref}", history_bytes([oid_of(manifest)])),
    ]


def object_name(data: bytes) -> str:
    """The member name of ``data`` as an object."""
    oid = oid_of(data)
    return f"objects/{oid[:2]}/{oid[2:]}"


def write_members(
    path: Path, members: list[tuple[tarfile.TarInfo, bytes]], *, fmt: int = tarfile.PAX_FORMAT, compression: str = ""
) -> Path:
    """A tar of exactly ``members`` (in order, duplicates kept); ``compression``: ``gz``, ``bz2``, ``xz`` or ``""``."""
    with tarfile.open(path, f"w:{compression}" if compression else "w", format=fmt) as tar:
        for info, data in members:
            tar.addfile(info, io.BytesIO(data) if info.size else None)
    return path


# ---------------------------------------------------------------------------------------------- raw blocks

BLOCK = 512


def ustar_block(
    name: bytes,
    size: int | bytes = 0,
    *,
    typeflag: bytes = b"0",
    linkname: bytes = b"",
    checksum: bool = True,
    extra: dict[int, bytes] | None = None,
) -> bytes:
    """One ustar header block, byte by byte: ``size`` as a number or as the raw 12-byte field, ``extra``: raw bytes
    at offsets (e.g. the GNU sparse fields), ``checksum=False``: a wrong checksum."""
    buf = bytearray(BLOCK)
    buf[0 : len(name[:100])] = name[:100]
    buf[100:108] = b"0000644\0"
    buf[108:116] = buf[116:124] = b"0000000\0"
    buf[124:136] = size if isinstance(size, bytes) else b"%011o\0" % size
    buf[136:148] = b"00000000000\0"
    buf[156:157] = typeflag
    buf[157 : 157 + len(linkname[:100])] = linkname[:100]
    buf[257:265] = b"ustar\x0000"
    for offset, raw in (extra or {}).items():
        buf[offset : offset + len(raw)] = raw
    buf[148:156] = b" " * 8
    total = sum(buf) + (0 if checksum else 1)
    buf[148:156] = b"%06o\0 " % total
    return bytes(buf)


def base256(value: int) -> bytes:
    """A 12-byte GNU base-256 number field (negative values too)."""
    return bytes([0xFF if value < 0 else 0x80]) + (value & ((1 << 88) - 1)).to_bytes(11, "big")


def padded(data: bytes) -> bytes:
    return data + b"\0" * (-len(data) % BLOCK)


def file_blocks(name: str, data: bytes) -> bytes:
    """A regular member with a truthful header, as blocks."""
    return ustar_block(name.encode(), len(data)) + padded(data)


def raw_tar(path: Path, *parts: bytes, end: bool = True) -> Path:
    """Concatenate header and data blocks (and the two zero blocks that end an archive)."""
    path.write_bytes(b"".join(parts) + (b"\0" * 2 * BLOCK if end else b""))
    return path


# ---------------------------------------------------------------------------------------------- compression

_COMPRESS = {"gz": lambda d: gzip.compress(d, mtime=0), "bz2": bz2.compress, "xz": lambda d: lzma.compress(d, preset=0)}


def stream(kind: str, data: bytes) -> bytes:
    """``data`` as one complete gzip, bzip2 or xz stream; concatenated streams read back as one file."""
    return _COMPRESS[kind](data)


@functools.cache
def zeros_stream(kind: str, size: int) -> bytes:
    """``size`` zero bytes as one compressed stream (16 MiB: 16 KiB as gzip, 45 bytes as bzip2, 2.5 KiB as xz)."""
    return stream(kind, bytes(size))


def member_header(name: str, size: int) -> bytes:
    """The header block(s) of a regular member of ``size`` bytes (a pax header first when it needs one)."""
    info = tarfile.TarInfo(name)
    info.size = size
    return info.tobuf(tarfile.PAX_FORMAT)


# ---------------------------------------------------------------------------------------------- runs (issue 53)


def run_config(variant: str = "film", **changes: Any) -> dict:
    """A run's stored training config (the smoke preset), with dotted ``changes`` (``{"env.obs.history_len": -3}``;
    the value ``DROP`` removes a key)."""
    import copy

    from morfic_cli.rl.config import smoke_preset, train_cfg_to_dict

    doc = copy.deepcopy(train_cfg_to_dict(smoke_preset("film")))
    doc["variant"] = variant
    for key, value in changes.items():
        *parents, leaf = key.split(".")
        node = doc
        for part in parents:
            node = node[part]
        if value is DROP:
            node.pop(leaf)
        else:
            node[leaf] = value
    return doc


DROP = object()


def trainer_state(num_envs: int = 2, **changes: Any) -> dict:
    """A trainer state of the structure ``morfic train`` writes (tiny tensors, ``num_envs`` rows), with top-level
    ``changes``; what :func:`morfic_cli.rl.trainer_state.trainer_state_problems` accepts."""
    import torch

    from morfic_cli.envs.locomotion import LocomotionEnv

    n = num_envs
    rows = {"a": torch.zeros(n), "b": torch.zeros(n, 3)}
    state = {
        "iteration": 1,
        "learning_rate": 1e-3,
        "torch_rng": torch.get_rng_state(),
        "alg": {"optimizer_state_dict": {"state": {}, "param_groups": [{"lr": 1e-3, "params": []}]}},
        "env": {
            "num_envs": n,
            "mode": "train",
            "tensors": {k: torch.zeros(n) for k in LocomotionEnv._TENSORS},
            "episode_sums": dict(rows),
            "obs": dict(rows),
            "params": dict(rows),
            "backend": dict(rows),
            "counters": {"common_step_counter": 8, "nonfinite_resets": 0, "tracking_sum": 0.0, "tracking_count": 0},
            "command_vx": (-1.0, 1.0),
            "generator": torch.Generator().manual_seed(0).get_state(),
        },
        "logger": {
            "rewbuffer": [1.5],
            "lenbuffer": [20.0],
            "cur_reward_sum": torch.zeros(n),
            "cur_episode_length": torch.zeros(n),
            "tot_timesteps": 64,
            "tot_time": 0.1,
            "wall_time_s": 1.0,
        },
    }
    state.update(changes)
    return state
