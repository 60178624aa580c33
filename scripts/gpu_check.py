"""Helper of scripts/gpu_check.sh: environment facts, kernel warm-up, parity report, and the summary of figures.

Run by the shell script, one sub-command per step (``python3 scripts/gpu_check.py SUB ...``):

- ``info OUT.json``: Python, torch, warp, mujoco, the GPU, and whether every requirement of morfic and of
  the carried wheels is met by what is installed (the device machine mixes its own packages with carried ones).
- ``warmup DEVICE OUT.json``: import MuJoCo Warp and compile (or load from warp's kernel cache) all its modules for
  DEVICE in parallel, so that the timed steps after it do not compile one module at a time.
- ``parity OUT.json JUNIT.xml...``: the warp tests' outcomes and worst differences (recorded by
  tests/sim/test_warp_backend.py through ``record_property``) from pytest's JUnit XML.
- ``summary TMPDIR OUT.json``: every step's status and time, the figures docs/gpu.md asks for (env steps/s
  per env count, s/iteration at the preset against the paper's, projected hours of a 400M-transition run).

The pure functions (:func:`parity_from_junit`, :func:`figures`, :func:`requirement_problems`) are tested in
tests/scripts/test_gpu_check.py. Everything here uses the standard library plus ``packaging`` (present on
the device machine and wherever pip is), and morfic itself for the paper's numbers.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # morfic_cli from this checkout (on the device machine it is not installed)
    sys.path.append(str(ROOT))
SCHEMA = "morfic-gpu-check/1"
TRANSITIONS_400M = 400e6
"""The paper's transition budget (Training Compute Methodology: GPU-hours normalised to 400M transitions)."""


# ---------------------------------------------------------------------------- pure functions


def parity_from_junit(xml_text: str) -> dict[str, Any]:
    """The parity tests of a pytest JUnit XML report.

    Args:
        xml_text: ``pytest --junitxml`` output of tests/sim/test_warp_backend.py.

    Returns:
        ``{"passed": int, "failed": int, "skipped": int, "ok": bool, "tests": [{"name", "outcome",
        "seconds", "message", "worst": {property: {field: max abs difference}}}]}``. ``ok`` is true when
        at least one test ran and none failed or was skipped (a skip on the GPU means the backend is missing).
    """
    root = ET.fromstring(xml_text)
    tests: list[dict[str, Any]] = []
    for case in root.iter("testcase"):
        outcome, message = "passed", ""
        for tag in ("failure", "error", "skipped"):
            node = case.find(tag)
            if node is not None:
                outcome = "skipped" if tag == "skipped" else "failed"
                message = (node.get("message") or node.text or "").strip()[:500]
                break
        worst = {
            p.get("name"): json.loads(p.get("value") or "{}")
            for p in case.iter("property")
            if (p.get("name") or "").startswith("worst")
        }
        tests.append(
            {
                "name": case.get("name"),
                "outcome": outcome,
                "seconds": round(float(case.get("time") or 0), 2),
                "message": message,
                "worst": worst,
            }
        )
    counts = {k: sum(t["outcome"] == k for t in tests) for k in ("passed", "failed", "skipped")}
    return {**counts, "ok": counts["passed"] > 0 and counts["failed"] == 0 and counts["skipped"] == 0, "tests": tests}


def worst_over_tests(parity: dict[str, Any], kind: str) -> dict[str, float]:
    """Largest difference per frame field over every recorded property whose name starts with ``kind``.

    Args:
        parity: :func:`parity_from_junit`'s result.
        kind: ``"worst_one_step"`` or ``"worst_free_run"``.
    """
    out: dict[str, float] = {}
    for test in parity["tests"]:
        for name, fields in test["worst"].items():
            if name.startswith(kind):
                for field, value in fields.items():
                    out[field] = max(out.get(field, 0.0), float(value))
    return out


def figures(
    bench_env: list[dict[str, Any]] | None,
    bench_train: dict[str, Any] | None,
    train: dict[str, Any] | None,
    paper_s_per_iteration: tuple[float, float],
    paper_hours: tuple[float, float],
    paper_iterations: float,
) -> dict[str, Any]:
    """The numbers docs/gpu.md and docs/benchmarks.md report, from the steps' JSON outputs.

    Args:
        bench_env: ``morfic bench env --format json`` rows (a list), or None if the step failed.
        bench_train: ``morfic bench train --format json`` (one object), or None.
        train: ``morfic train --format json`` (one object), or None.
        paper_s_per_iteration: The paper's seconds per iteration (low, high), laptop RTX 4090.
        paper_hours: The paper's GPU-hours of its run (low, high).
        paper_iterations: PPO iterations of the paper's run.

    Returns:
        ``env_steps_per_s`` (env count as a string -> env steps/s), ``env_ratio`` (-> fraction of the
        physics floor), and, with bench_train: ``s_per_iteration``, its ``collect``/``learn`` parts,
        ``train_steps_per_s`` (transitions/s including learning), ``x_paper_s_per_iteration`` (ours / the
        paper's, low and high), ``projected_hours_400M`` (400M transitions at that rate),
        ``projected_hours_paper_iterations`` (the paper's iteration count at our s/iteration and
        transitions per iteration of the preset measured); with train: its transitions/s over the run.
    """
    out: dict[str, Any] = {"paper_s_per_iteration": list(paper_s_per_iteration), "paper_hours": list(paper_hours)}
    if bench_env:
        out["env_steps_per_s"] = {str(r["num_envs"]): r["env_steps_per_s"] for r in bench_env}
        out["env_ratio"] = {str(r["num_envs"]): r["ratio"] for r in bench_env}
        out["env_device"] = bench_env[0].get("device")
    if bench_train:
        spi = float(bench_train["s_per_iteration"])
        sps = float(bench_train["train_steps_per_s"])
        out.update(
            {
                "preset": bench_train["preset"],
                "num_envs": bench_train["num_envs"],
                "s_per_iteration": spi,
                "collect_s_per_iteration": bench_train["collect_s_per_iteration"],
                "learn_s_per_iteration": bench_train["learn_s_per_iteration"],
                "train_steps_per_s": sps,
                "fraction_of_floor": bench_train["fraction_of_floor"],
                "x_paper_s_per_iteration": [
                    round(spi / paper_s_per_iteration[0], 3),
                    round(spi / paper_s_per_iteration[1], 3),
                ],
                "projected_hours_400M": round(TRANSITIONS_400M / sps / 3600, 2) if sps > 0 else None,
                "projected_hours_paper_iterations": round(paper_iterations * spi / 3600, 2),
            }
        )
    if train and train.get("wall_time_s"):
        out["train_run"] = {
            k: train.get(k)
            for k in ("iteration", "env_steps", "wall_time_s", "mean_reward", "explained_variance", "interrupted")
        }
        out["train_run"]["steps_per_s"] = round(float(train["env_steps"]) / float(train["wall_time_s"]), 1)
    return out


def requirement_problems(requirements: list[str], installed: dict[str, str], env: dict[str, str]) -> list[str]:
    """Requirements not met by the installed distributions.

    Args:
        requirements: PEP 508 strings (``"torch>=2.6"``, ``"pkg; python_version >= '3.11'"``).
        installed: Normalised distribution name -> version.
        env: Marker environment (``packaging.markers.default_environment()`` plus ``extra``).

    Returns:
        One line per unmet requirement: ``"NAME: missing (needed by REQ)"`` or ``"NAME VERSION does not
        satisfy REQ"``; empty when all are met.
    """
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    problems = []
    for text in requirements:
        req = Requirement(text)
        if req.marker is not None and not req.marker.evaluate(env):
            continue
        name = canonicalize_name(req.name)
        if name not in installed:
            problems.append(f"{req.name}: missing (needed by {text})")
        elif req.specifier and not req.specifier.contains(installed[name], prereleases=True):
            problems.append(f"{req.name} {installed[name]} does not satisfy {text}")
    return problems


# ---------------------------------------------------------------------------- sub-commands


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _write_json(path: Path, doc: Any) -> None:
    path.write_text(json.dumps(doc, indent=2, sort_keys=False) + "\n")


def _version(name: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _morfic_requirements(extras: tuple[str, ...] = ("gpu",)) -> list[str]:
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = list(project["dependencies"])
    for extra in extras:
        reqs += project["optional-dependencies"][extra]
    return reqs


def cmd_info(out: Path) -> None:
    """Environment facts and the requirement check, as JSON."""
    from importlib import metadata

    from packaging.markers import default_environment
    from packaging.utils import canonicalize_name

    installed = {
        canonicalize_name(d.metadata["Name"]): d.version for d in metadata.distributions() if d.metadata["Name"]
    }
    env = {**default_environment(), "extra": ""}
    problems = requirement_problems(_morfic_requirements(), installed, env)
    carried = [
        ln.split("==")[0].strip()
        for ln in (ROOT / "scripts" / "gpu_wheels.txt").read_text().splitlines()
        if ln.strip() and not ln.startswith("#")
    ]
    for name in carried:  # the carried wheels' own needs, met by the device's packages or other carried ones
        dist = metadata.distribution(name) if canonicalize_name(name) in installed else None
        problems += [] if dist is None else requirement_problems(dist.requires or [], installed, env)
    doc: dict[str, Any] = {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "executable": sys.executable,
        "cores": os.cpu_count(),
        "versions": {
            n: _version(n)
            for n in (
                "torch",
                "numpy",
                "mujoco",
                "mujoco-warp",
                "warp-lang",
                "rsl-rl-lib",
                "tensordict",
                "mcap",
                "typer",
                "rich",
                "pandas",
                "matplotlib",
            )
        },
        "requirement_problems": sorted(set(problems)),
    }
    try:
        import torch

        doc["torch_cuda"] = torch.version.cuda
        doc["cuda_available"] = torch.cuda.is_available()
        if torch.cuda.is_available():
            doc["gpu"] = torch.cuda.get_device_name(0)
    except ImportError as exc:
        doc["torch_error"] = str(exc)
    try:
        smi = subprocess.run(
            ["nvidia-smi", "--query-gpu=name,driver_version,memory.total,clocks.max.sm", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
        doc["nvidia_smi"] = smi.stdout.strip() or smi.stderr.strip()
    except (OSError, subprocess.TimeoutExpired) as exc:
        doc["nvidia_smi"] = f"not available: {exc}"
    _write_json(out, doc)
    print(json.dumps(doc, indent=2))


def cmd_warmup(device: str, out: Path) -> None:
    """Compile (or load from the kernel cache) every MuJoCo Warp module for ``device``, in parallel."""
    import mujoco_warp  # noqa: F401  (imports its kernels' modules)
    import warp as wp

    wp.init()
    t0 = time.perf_counter()
    wp.force_load(device=device, max_workers=os.cpu_count() or 1)
    doc = {
        "device": device,
        "seconds": round(time.perf_counter() - t0, 1),
        "warp": wp.config.version,
        "kernel_cache": wp.config.kernel_cache_dir,
    }
    _write_json(out, doc)
    print(json.dumps(doc))


def merge_reports(reports: list[dict[str, Any] | None]) -> dict[str, Any]:
    """One report of several :func:`parity_from_junit` results; ``None`` (no XML: pytest was killed) fails it."""
    tests = [t for r in reports if r for t in r["tests"]]
    counts = {k: sum(t["outcome"] == k for t in tests) for k in ("passed", "failed", "skipped")}
    ok = all(r is not None and r["ok"] for r in reports) and bool(reports)
    doc = {**counts, "ok": ok, "tests": tests}
    doc["worst_one_step"] = worst_over_tests(doc, "worst_one_step")
    doc["worst_free_run"] = worst_over_tests(doc, "worst_free_run")
    return doc


def cmd_parity(out: Path, *junits: Path) -> None:
    """The parity report from pytest's JUnit XML files (a missing one counts as a failure)."""
    doc = merge_reports([parity_from_junit(j.read_text()) if j.exists() else None for j in junits])
    doc["missing_reports"] = [str(j) for j in junits if not j.exists()]
    doc["device"] = os.environ.get("MORFIC_WARP_TEST_DEVICE", "cpu")
    _write_json(out, doc)
    print(f"parity on {doc['device']}: {doc['passed']} passed, {doc['failed']} failed, {doc['skipped']} skipped")


def _steps(path: Path) -> dict[str, Any]:
    steps: dict[str, Any] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                steps[row.pop("step")] = row
    return steps


def cmd_summary(tmp: Path, out_dir: Path) -> None:
    """Assemble summary.json from the steps' files (whatever exists: a failed step leaves its entry out)."""
    from morfic_cli.report.paper import TRAINING_COMPUTE

    paper = next(r for r in TRAINING_COMPUTE if r.method == "film")
    bench_env = _read_json(out_dir / "bench_env.json")
    if isinstance(bench_env, dict):  # a single --envs value prints one object
        bench_env = [bench_env]
    bench_train = _read_json(out_dir / "bench_train.json")
    train = _read_json(out_dir / "train.json")
    parity = _read_json(out_dir / "parity.json")
    doc = {
        "schema": SCHEMA,
        "device": os.environ.get("MORFIC_GPU_CHECK_DEVICE", "cuda"),
        "info": _read_json(tmp / "info.json"),
        "warmup": _read_json(tmp / "warmup.json"),
        "steps": _steps(tmp / "steps.jsonl"),
        "parity": None
        if parity is None
        else {
            k: parity.get(k)
            for k in ("ok", "passed", "failed", "skipped", "worst_one_step", "worst_free_run", "missing_reports")
        },
        "figures": figures(
            bench_env,
            bench_train if isinstance(bench_train, dict) else None,
            train if isinstance(train, dict) else None,
            paper.sec_per_iter,
            paper.gpu_hours,
            paper.iterations,
        ),
        "bundle": None,
    }
    bundle = out_dir / "checkpoint.tar"
    if bundle.exists():
        doc["bundle"] = {
            "file": bundle.name,
            "bytes": bundle.stat().st_size,
            "manifest": _read_json(tmp / "bundle.json"),
        }
    _write_json(out_dir / "summary.json", doc)
    print(json.dumps(doc, indent=2))


def main(argv: list[str]) -> None:
    """Dispatch a sub-command (see the module docstring)."""
    commands = {
        "info": (cmd_info, 1),
        "warmup": (cmd_warmup, 2),
        "parity": (cmd_parity, -2),
        "summary": (cmd_summary, 2),
    }  # -2: at least 2
    if (
        not argv
        or argv[0] not in commands
        or not (
            len(argv) - 1 == commands[argv[0]][1] or (commands[argv[0]][1] < 0 and len(argv) > -commands[argv[0]][1])
        )
    ):
        sys.exit(f"usage: gpu_check.py {{{'|'.join(commands)}}} ARGS (see the docstring)")
    fn, _ = commands[argv[0]]
    args = [Path(a) for a in argv[1:]]
    fn(*([argv[1], *args[1:]] if fn is cmd_warmup else args))


if __name__ == "__main__":
    main(sys.argv[1:])
