"""scripts/gpu_check.{sh,py} and scripts/gpu_wheels.{sh,py}: the GPU check's logic, without a GPU.

Fast: the pure functions on hand-made inputs, and the part transfer (split here, stash + join + install
there) on two stub wheels. Slow: the whole check as a dry run on warp's CPU device at tiny sizes
(about 6 minutes on 2 cores), checking the JSON files it leaves under $OUT.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


gc = _load("gpu_check")
gw = _load("gpu_wheels")

JUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest" tests="4">
 <testcase classname="tests.sim.test_warp_backend" name="test_parity_template" time="2.5">
  <properties>
   <property name="worst_one_step" value="{&quot;joint_pos&quot;: 1e-05, &quot;joint_vel&quot;: 0.002}"/>
   <property name="worst_free_run" value="{&quot;joint_pos&quot;: 3e-05}"/>
  </properties>
 </testcase>
 <testcase classname="tests.sim.test_warp_backend" name="test_parity_robot[a1]" time="1.25">
  <properties>
   <property name="worst_one_step_full" value="{&quot;joint_pos&quot;: 4e-05, &quot;joint_vel&quot;: 0.001}"/>
  </properties>
 </testcase>
 <testcase classname="tests.sim.test_warp_backend" name="test_parity_robot[b1]" time="1.0">
  <failure message="AssertionError: beyond the parity tolerance">trace</failure>
 </testcase>
 <testcase classname="tests.sim.test_warp_backend" name="test_other" time="0.5">
  <skipped message="mujoco_warp is not installed"/>
 </testcase>
</testsuite></testsuites>
"""


def test_parity_report_from_junit_counts_outcomes_and_takes_the_worst_per_field():
    doc = gc.parity_from_junit(JUNIT)
    assert (doc["passed"], doc["failed"], doc["skipped"], doc["ok"]) == (2, 1, 1, False)
    assert [t["outcome"] for t in doc["tests"]] == ["passed", "passed", "failed", "skipped"]
    assert doc["tests"][0]["worst"]["worst_free_run"] == {"joint_pos": 3e-05}
    assert doc["tests"][2]["message"].startswith("AssertionError")
    # one-step: joint_pos max(1e-5, 4e-5), joint_vel max(0.002, 0.001); free run only from the template
    assert gc.worst_over_tests(doc, "worst_one_step") == {"joint_pos": 4e-05, "joint_vel": 0.002}
    assert gc.worst_over_tests(doc, "worst_free_run") == {"joint_pos": 3e-05}
    passing = gc.parity_from_junit(
        JUNIT.replace('<failure message="AssertionError: beyond the parity tolerance">trace</failure>', "").replace(
            '<skipped message="mujoco_warp is not installed"/>', ""
        )
    )
    assert passing["ok"] and passing["passed"] == 4
    merged = gc.merge_reports([passing, doc])
    assert (merged["passed"], merged["failed"], merged["skipped"], merged["ok"]) == (6, 1, 1, False)
    assert merged["worst_one_step"] == {"joint_pos": 4e-05, "joint_vel": 0.002}
    assert gc.merge_reports([passing])["ok"] and not gc.merge_reports([passing, None])["ok"]


def test_figures_compare_with_the_paper_and_project_the_400m_run():
    env = [
        {"num_envs": 4096, "env_steps_per_s": 200000.0, "ratio": 0.5, "device": "cuda:0 (NVIDIA H200)"},
        {"num_envs": 8192, "env_steps_per_s": 300000.0, "ratio": 0.6, "device": "cuda:0 (NVIDIA H200)"},
    ]
    bench = {
        "preset": "paper",
        "num_envs": 4096,
        "s_per_iteration": 4.0,
        "collect_s_per_iteration": 3.0,
        "learn_s_per_iteration": 1.0,
        "train_steps_per_s": 24576.0,
        "fraction_of_floor": 0.2,
    }
    train = {
        "iteration": 60,
        "env_steps": 5898240,
        "wall_time_s": 295.0,
        "mean_reward": 1.5,
        "explained_variance": 0.8,
        "interrupted": True,
    }
    f = gc.figures(env, bench, train, (1.98, 2.70), (2.2, 3.0), 4000)
    assert f["env_steps_per_s"] == {"4096": 200000.0, "8192": 300000.0}
    assert f["env_ratio"] == {"4096": 0.5, "8192": 0.6}
    assert f["x_paper_s_per_iteration"] == [round(4.0 / 1.98, 3), round(4.0 / 2.70, 3)] == [2.02, 1.481]
    assert f["projected_hours_400M"] == 4.52  # 400e6 / 24576 / 3600 = 4.521
    assert f["projected_hours_paper_iterations"] == 4.44  # 4000 * 4.0 / 3600
    assert f["train_run"]["steps_per_s"] == 19994.0  # 5898240 / 295
    assert gc.figures(None, None, None, (1.98, 2.70), (2.2, 3.0), 4000) == {
        "paper_s_per_iteration": [1.98, 2.7],
        "paper_hours": [2.2, 3.0],
    }


def test_requirement_problems_name_what_is_missing_or_too_old():
    env = {
        "python_version": "3.12",
        "python_full_version": "3.12.3",
        "sys_platform": "linux",
        "extra": "",
        "platform_machine": "x86_64",
        "implementation_name": "cpython",
        "os_name": "posix",
        "platform_system": "Linux",
        "platform_python_implementation": "CPython",
        "platform_release": "",
        "platform_version": "",
        "implementation_version": "3.12.3",
    }
    installed = {"torch": "2.11.0", "typer": "0.11.0", "mujoco-warp": "4.0.0"}
    problems = gc.requirement_problems(
        [
            "torch>=2.6",
            "typer>=0.12",
            "mcap>=1.2",
            "mujoco-warp>=4.0,<5; python_version >= '3.11'",
            "tomli>=2; python_version < '3.11'",
            "Mujoco_Warp>=4",
        ],
        installed,
        env,
    )
    assert problems == ["typer 0.11.0 does not satisfy typer>=0.12", "mcap: missing (needed by mcap>=1.2)"]


def _item(name, version, requires=(), requested=False):
    return {"requested": requested, "metadata": {"name": name, "version": version, "requires_dist": list(requires)}}


def test_classify_splits_carried_from_device_and_names_what_is_missing():
    report = {
        "install": [
            _item("morfic-dep", "1", requested=True),  # requested, neither carried nor on the device: a problem
            _item("mujoco", "4.0.0", ["numpy", "glfw"]),
            _item("glfw", "2.0"),  # carried at another version than its pin
            _item("numpy", "2.4"),
            _item("typer", "0.29", ["pydantic>=2"]),
            _item("pydantic", "2.14", ["pydantic-core==2.50"]),  # needed only by a device package
            _item("pydantic-core", "2.50"),  # needed only by a package only device packages need
            _item("tzdata", "2026.6"),  # needed by nobody in the report: a problem
        ]
    }
    carried, device, problems, notes = gw.classify(
        report, {"mujoco": "4.0.0", "glfw": "2.11.0", "mcap": "1.6.0"}, {"numpy", "typer"}
    )
    assert carried == {"mujoco": "4.0.0", "glfw": "2.0"} and set(device) == {"numpy", "typer"}
    assert problems == [
        "morfic-dep 1: needed, but neither carried nor on the device; add 'morfic-dep==1' to scripts/gpu_wheels.txt",
        "glfw: resolved 2.0, pinned 2.11.0 (scripts/gpu_wheels.txt)",
        "tzdata 2026.6: needed, but neither carried nor on the device; add 'tzdata==2026.6' to scripts/gpu_wheels.txt",
        "mcap: pinned in scripts/gpu_wheels.txt but not needed",
    ]
    assert [n.split(":")[0] for n in notes] == ["pydantic 2.14", "pydantic-core 2.50"]
    assert gw.stub_requires(["pydantic>=2", "numpy>=2; python_version < '3.14'", "glfw"], {"numpy", "glfw"}) == [
        "numpy>=2; python_version < '3.14'",
        "glfw",
    ]


def test_stub_wheel_is_metadata_only_with_its_requirements(tmp_path):
    path = gw.write_stub(tmp_path, "etils", "1.15.0", ["zipp; extra == 'epath'"], ">=3.10", ["epath"])
    assert path.name == "etils-1.15.0-py3-none-any.whl"
    with zipfile.ZipFile(path) as zf:
        assert sorted(zf.namelist()) == [
            "etils-1.15.0.dist-info/METADATA",
            "etils-1.15.0.dist-info/RECORD",
            "etils-1.15.0.dist-info/WHEEL",
        ]
        meta = zf.read("etils-1.15.0.dist-info/METADATA").decode()
    assert "Name: etils\nVersion: 1.15.0\nRequires-Python: >=3.10\nProvides-Extra: epath\n" in meta
    assert "Requires-Dist: zipp; extra == 'epath'" in meta


def test_plan_sizes_every_call_against_the_limit():
    mib = 1024 * 1024
    lines = gw.plan(12 * mib, [(".gpu/p1", 50 * mib), (".gpu/p2", 53 * mib)])
    assert lines[0] == (
        'call 1: carry [".gpu/p1"]  command: bash scripts/gpu_check.sh stash  timeout_s: 60  '
        "(50.0 MiB + tree 12.0 MiB = 62.0 MiB of 64 MiB)"
    )
    assert lines[1].startswith('call 2: carry [".gpu/p2"]  command: bash scripts/gpu_check.sh run  timeout_s: 600')
    assert lines[1].endswith("(53.0 MiB + tree 12.0 MiB = 65.0 MiB of 64 MiB)  <-- OVER THE LIMIT")


def _checkout(tmp_path: Path, bundle_bytes: int = 0) -> Path:
    """A git checkout holding gpu_wheels.{sh,py} (and, if asked, a tracked bundle of that many bytes), so that
    the split measures this tree, not the size this repository happens to have."""
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    for name in ("gpu_wheels.sh", "gpu_wheels.py"):
        (repo / "scripts" / name).write_bytes((SCRIPTS / name).read_bytes())
    if bundle_bytes:
        (repo / "artifacts" / "bundles").mkdir(parents=True)
        with open(repo / "artifacts" / "bundles" / "film-cpu-s0.tar", "wb") as f:
            f.truncate(bundle_bytes)  # sparse: instant, and stat reports its full size
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "tree"]):
        subprocess.run(git + args, check=True, capture_output=True, timeout=60)
    return repo


def _gpu_wheels(repo: Path, what: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(repo / "scripts" / "gpu_wheels.sh"), what],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_parts_split_here_are_joined_and_installed_there(tmp_path):
    """gpu_wheels.sh split -> parts p1..pN; gpu_check.sh install on 'the device' joins, verifies, installs."""
    g = tmp_path / "g"
    (g / "wheels").mkdir(parents=True)
    for name in ("alpha", "beta"):  # two real (tiny) wheels, installable offline
        gw.write_stub(g / "wheels", name, "1.0", [], None)
    env = {**os.environ, "MORFIC_GPU_DIR": str(g), "PART_SIZE": "1500", "PYTHON": sys.executable}
    split = _gpu_wheels(_checkout(tmp_path), "split", env)
    assert split.returncode == 0, split.stderr
    parts = sorted(p.name for p in g.iterdir() if p.name.startswith("p"))
    assert len(parts) >= 2 and "call 1: carry" in split.stdout
    assert (g / "PLAN.txt").read_text().count("command: bash scripts/gpu_check.sh run") == 1

    def install(work: Path) -> subprocess.CompletedProcess:
        return subprocess.run(
            ["bash", str(SCRIPTS / "gpu_check.sh"), "install"],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
            env={
                **env,
                "MORFIC_GPU_CHECK_CARRIED": str(g),
                "MORFIC_GPU_CHECK_WORK": str(work),
                "OUT": str(work / "out"),
            },
        )

    done = install(tmp_path / "work")
    assert done.returncode == 0, done.stdout + done.stderr
    site = tmp_path / "work" / "site"
    assert {p.name for p in site.glob("*.dist-info")} == {"alpha-1.0.dist-info", "beta-1.0.dist-info"}
    again = install(tmp_path / "work")  # same parts, still warm: no second install
    assert again.returncode == 0 and "already installed" in again.stdout

    last = g / parts[-1]  # a call that never happened: its part is missing there
    for f in last.glob("morfic-wheels.tar.*"):
        f.unlink()
    missing = install(tmp_path / "cold")
    assert missing.returncode == 1
    assert "part(s) missing: morfic-wheels.tar." in missing.stdout and "from call 1" in missing.stdout


def test_a_heavy_tree_is_slimmed_for_the_parts_and_restored(tmp_path):
    """60 MiB of tracked bundles leave no room in a 64 MiB call: split says to slim; slim leaves artifacts/bundles/
    out (sparse checkout), the split then measures the small tree; full brings the bundle back."""
    g = tmp_path / "g"
    (g / "wheels").mkdir(parents=True)
    gw.write_stub(g / "wheels", "alpha", "1.0", [], None)
    repo = _checkout(tmp_path, bundle_bytes=60 * 1024 * 1024)
    env = {**os.environ, "MORFIC_GPU_DIR": str(g), "PYTHON": sys.executable}
    heavy = _gpu_wheels(repo, "split", env)
    assert heavy.returncode == 1
    assert heavy.stderr.startswith("Error: the working tree (60 MiB) leaves no room for parts")
    assert "gpu_wheels.sh slim" in heavy.stderr
    bundle = repo / "artifacts" / "bundles" / "film-cpu-s0.tar"
    slim = _gpu_wheels(repo, "slim", env)
    assert slim.returncode == 0, slim.stderr
    assert not bundle.exists()
    split = _gpu_wheels(repo, "split", env)
    assert split.returncode == 0, split.stderr
    assert "working tree 0.0 MiB" in split.stdout  # the two scripts only (a few KiB)
    full = _gpu_wheels(repo, "full", env)
    assert full.returncode == 0, full.stderr
    assert bundle.stat().st_size == 60 * 1024 * 1024


@pytest.mark.slow
def test_dry_run_on_warps_cpu_device_writes_every_json(tmp_path):
    """The whole check on warp's CPU device at tiny sizes (about 6 minutes on 2 cores)."""
    pytest.importorskip("mujoco_warp", reason="mujoco_warp is not installed (pip install 'morfic[gpu]')")
    out = tmp_path / "out"
    env = {
        **os.environ,
        "MORFIC_GPU_CHECK_DEVICE": "cpu",
        "MORFIC_GPU_CHECK_ENVS": "8,16",
        "MORFIC_GPU_CHECK_STEPS": "3",
        "MORFIC_GPU_CHECK_PRESET": "smoke",
        "MORFIC_GPU_CHECK_ITERATIONS": "1",
        "MORFIC_GPU_CHECK_TRAIN_S": "40",
        "MORFIC_GPU_CHECK_TRAIN_SET": "max_iterations=1000 save_interval=1",
        "MORFIC_GPU_CHECK_PARITY_K": "template",
        "MORFIC_GPU_CHECK_OTHER_K": "",
        "MORFIC_GPU_CHECK_WARMUP": "0",
        "MORFIC_GPU_CHECK_WORK": str(tmp_path / "work"),
        "OUT": str(out),
        "PYTHON": sys.executable,
    }
    done = subprocess.run(
        ["bash", str(SCRIPTS / "gpu_check.sh"), "check"],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-3000:]
    assert sorted(p.name for p in out.iterdir()) == [
        "bench_env.json",
        "bench_train.json",
        "checkpoint.tar",
        "gpu_check.log",
        "parity.json",
        "summary.json",
        "train.json",
    ]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["schema"] == "morfic-gpu-check/1" and summary["device"] == "cpu"
    assert {s: v["status"] for s, v in summary["steps"].items()} == dict.fromkeys(
        ["info", "parity", "bench_env", "bench_train", "train", "export", "show"], "ok"
    )
    assert summary["parity"]["ok"] and summary["parity"]["worst_one_step"]["joint_pos"] < 1e-4
    fig = summary["figures"]
    assert set(fig["env_steps_per_s"]) == {"8", "16"} and fig["preset"] == "smoke"
    assert fig["s_per_iteration"] > 0 and fig["projected_hours_400M"] > 0
    assert fig["train_run"]["interrupted"] is True and fig["train_run"]["iteration"] >= 1
    assert summary["bundle"]["bytes"] == (out / "checkpoint.tar").stat().st_size
    assert summary["bundle"]["manifest"]["kind"] == "checkpoint"
