"""Helper of scripts/gpu_wheels.sh: the resolution check of the carried wheels, and the transfer plan.

- ``stubs REPORT.json STUBDIR``: classify pip's online resolution (``pip install --dry-run --report``) of
  morfic + its gpu extra for CPython 3.12: every package is either carried (scripts/gpu_wheels.txt, at its
  pinned version) or on the device (scripts/gpu_device_packages.txt); anything else is an error that names
  it. For each device package, write a metadata-only stub wheel (its real ``Requires-Dist``) into STUBDIR,
  so that an offline resolution can stand in the device's packages without downloading them.
- ``verify REPORT.json WHEELDIR``: the offline resolution (``--no-index --find-links WHEELDIR
  --find-links STUBDIR``) chose every carried pin from WHEELDIR, and nothing else but stubs.
- ``plan TREE_BYTES PART_BYTES PARTDIR...``: the device calls, one per part, with the size each carries.

Standard library plus ``packaging``.
"""

from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
MIB = 1024 * 1024
CALL_LIMIT = 64 * MIB
"""What one device call may carry: the working tree plus the carried paths."""


def _names(path: Path) -> list[str]:
    return [ln.strip() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]


def carried_pins() -> dict[str, str]:
    """scripts/gpu_wheels.txt as canonical name -> pinned version."""
    from packaging.utils import canonicalize_name

    return {canonicalize_name(n.split("==")[0]): n.split("==")[1] for n in _names(HERE / "gpu_wheels.txt")}


def device_packages() -> set[str]:
    """scripts/gpu_device_packages.txt as canonical names."""
    from packaging.utils import canonicalize_name

    return {canonicalize_name(n) for n in _names(HERE / "gpu_device_packages.txt")}


def _requirers(report: dict) -> dict[str, set[str]]:
    """Canonical name -> the canonical names of the report's packages whose Requires-Dist names it (any marker)."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    out: dict[str, set[str]] = {}
    for item in report["install"]:
        who = canonicalize_name(item["metadata"]["name"])
        for text in item["metadata"].get("requires_dist") or []:
            out.setdefault(canonicalize_name(Requirement(text).name), set()).add(who)
    return out


def classify(report: dict, carried: dict[str, str], device: set[str]) -> tuple[dict, dict, list[str], list[str]]:
    """Split a pip report's install list into carried and device packages.

    A package that is neither, but that only device packages require, is the device's business: its own
    version of that package (which this resolution did not pick) is installed and consistent there; it is
    reported as a note, and its stubs leave it out (:func:`stub_requires`).

    Args:
        report: ``pip install --report`` JSON.
        carried: Canonical name -> pinned version of the carried wheels.
        device: Canonical names of the device's packages.

    Returns:
        (carried name -> version, device name -> report item, problems, notes): a problem for a carried
        package resolved at another version than its pin, a pin the resolution did not need, and a package
        that is neither carried nor on the device that morfic or a carried package requires.
    """
    from packaging.utils import canonicalize_name

    requirers = _requirers(report)
    names = {canonicalize_name(i["metadata"]["name"]): i for i in report["install"]}
    device_only: set[str] = set()  # neither carried nor device, and required only by device packages or such
    changed = True
    while changed:
        changed = False
        for name, item in names.items():
            if (
                name not in carried
                and name not in device
                and name not in device_only
                and not item.get("requested")
                and requirers.get(name)
                and requirers[name] <= device | device_only
            ):
                device_only.add(name)
                changed = True
    got_carried, got_device, problems, notes = {}, {}, [], []
    for item in report["install"]:
        name, version = canonicalize_name(item["metadata"]["name"]), item["metadata"]["version"]
        if name in carried:
            got_carried[name] = version
            if version != carried[name]:
                problems.append(f"{name}: resolved {version}, pinned {carried[name]} (scripts/gpu_wheels.txt)")
        elif name in device:
            got_device[name] = item
        elif name in device_only:
            notes.append(
                f"{name} {version}: needed only by device packages (or by packages only they need) "
                f"({', '.join(sorted(requirers[name]))}) in the versions resolved here;"
                " the device has its own"
            )
        else:
            problems.append(
                f"{name} {version}: needed, but neither carried nor on the device; add "
                f"'{name}=={version}' to scripts/gpu_wheels.txt"
            )
    problems += [
        f"{name}: pinned in scripts/gpu_wheels.txt but not needed" for name in carried if name not in got_carried
    ]
    return got_carried, got_device, problems, notes


def stub_requires(requires: list[str], keep: set[str]) -> list[str]:
    """The Requires-Dist lines of a device package's stub: those naming a carried or device package."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    return [r for r in requires if canonicalize_name(Requirement(r).name) in keep]


def write_stub(
    directory: Path,
    name: str,
    version: str,
    requires: list[str],
    requires_python: str | None,
    extras: list[str] | None = None,
) -> Path:
    """A metadata-only wheel ``NAME-VERSION-py3-none-any.whl`` (no files) standing in for an installed package."""
    dist = f"{name.replace('-', '_')}-{version}"
    meta = ["Metadata-Version: 2.1", f"Name: {name}", f"Version: {version}"]
    meta += [f"Requires-Python: {requires_python}"] if requires_python else []
    meta += [f"Provides-Extra: {e}" for e in extras or []]
    meta += [f"Requires-Dist: {r}" for r in requires]
    files = {
        f"{dist}.dist-info/METADATA": "\n".join(meta) + "\n",
        f"{dist}.dist-info/WHEEL": "Wheel-Version: 1.0\nGenerator: morfic-gpu-wheels\nRoot-Is-Purelib: true\n"
        "Tag: py3-none-any\n",
    }
    files[f"{dist}.dist-info/RECORD"] = "".join(f"{p},,\n" for p in [*files, f"{dist}.dist-info/RECORD"])
    path = directory / f"{dist}-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as zf:
        for arc, text in files.items():
            zf.writestr(arc, text)
    return path


def cmd_stubs(report_path: Path, stub_dir: Path) -> None:
    """Classify the online resolution and write the device packages' stubs (exit 1 on a problem)."""
    report = json.loads(report_path.read_text())
    got_carried, got_device, problems, notes = classify(report, carried_pins(), device_packages())
    stub_dir.mkdir(parents=True, exist_ok=True)
    keep = set(got_carried) | set(got_device)
    for name, item in sorted(got_device.items()):
        md = item["metadata"]
        requires = [] if name == "torch" else stub_requires(list(md.get("requires_dist") or []), keep)
        write_stub(stub_dir, name, md["version"], requires, md.get("requires_python"), md.get("provides_extra"))
    print(
        f"resolved for CPython 3.12: {len(got_carried)} carried ({', '.join(sorted(got_carried))}); "
        f"{len(got_device)} from the device ({', '.join(sorted(got_device))})"
    )
    for note in notes:
        print(f"  note: {note}")
    if problems:
        sys.exit("Error: the carried set does not close:\n  " + "\n  ".join(problems))


def cmd_verify(report_path: Path, wheel_dir: Path) -> None:
    """The offline resolution took every carried pin from ``wheel_dir`` (exit 1 otherwise)."""
    from packaging.utils import canonicalize_name

    report = json.loads(report_path.read_text())
    pins, problems, chosen = carried_pins(), [], {}
    for item in report["install"]:
        name = canonicalize_name(item["metadata"]["name"])
        url = item.get("download_info", {}).get("url", "")
        chosen[name] = url
        if name in pins and (
            Path(url.removeprefix("file://")).parent != wheel_dir.resolve() or item["metadata"]["version"] != pins[name]
        ):
            problems.append(f"{name}: took {item['metadata']['version']} from {url}, not the carried wheel")
    problems += [f"{name}: carried but not chosen" for name in pins if name not in chosen]
    if problems:
        sys.exit("Error: offline resolution:\n  " + "\n  ".join(problems))
    print(
        f"offline resolution (--no-index, CPython 3.12, manylinux x86_64) OK: {len(pins)} carried wheels chosen, "
        f"{len(chosen) - len(pins)} device packages (stubs)"
    )


def plan(tree_bytes: int, parts: list[tuple[str, int]]) -> list[str]:
    """One line per device call: what it carries, the command, and the size against the 64 MiB limit.

    Args:
        tree_bytes: Size of the working tree that travels with every call.
        parts: (carried folder, its bytes) in order.
    """
    lines = []
    for k, (folder, size) in enumerate(parts, start=1):
        last = k == len(parts)
        command = "bash scripts/gpu_check.sh run" if last else "bash scripts/gpu_check.sh stash"
        total = tree_bytes + size
        lines.append(
            f'call {k}: carry ["{folder}"]  command: {command}'
            f"{'  timeout_s: 600' if last else '  timeout_s: 60'}"
            f"  ({size / MIB:.1f} MiB + tree {tree_bytes / MIB:.1f} MiB = {total / MIB:.1f} MiB"
            f" of {CALL_LIMIT // MIB} MiB){'  <-- OVER THE LIMIT' if total > CALL_LIMIT else ''}"
        )
    return lines


def cmd_plan(tree_bytes: str, *folders: str) -> None:
    """Print the call plan for the part folders."""
    parts = [(f, sum(p.stat().st_size for p in Path(f).iterdir())) for f in folders]
    lines = plan(int(tree_bytes), parts)
    print("\n".join(lines))
    if any(line.endswith("OVER THE LIMIT") for line in lines):
        sys.exit(1)


def main(argv: list[str]) -> None:
    """Dispatch a sub-command (see the module docstring)."""
    if argv[:1] == ["stubs"] and len(argv) == 3:
        cmd_stubs(Path(argv[1]), Path(argv[2]))
    elif argv[:1] == ["verify"] and len(argv) == 3:
        cmd_verify(Path(argv[1]), Path(argv[2]))
    elif argv[:1] == ["plan"] and len(argv) >= 3:
        cmd_plan(argv[1], *argv[2:])
    else:
        sys.exit("usage: gpu_wheels.py stubs REPORT STUBDIR | verify REPORT WHEELDIR | plan TREE_BYTES DIR...")


if __name__ == "__main__":
    main(sys.argv[1:])
