"""A user's own critic, named by import path, through every command — in subprocesses, as a user runs them.

The user module is examples/custom_variant.py copied into a temporary folder under another name; the
subprocesses see it only through PYTHONPATH (nothing is installed, morfic is not changed).
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
VARIANT = "gated_lab:GatedCritic"
RUN = "runs/gated_lab.GatedCritic-smoke-s0"


def morfic(tmp: Path, *args: str, pythonpath: Path | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MORFIC_DEBUG")}
    env.update(MORFIC_STORE=str(tmp / "store"), OMP_NUM_THREADS="1")
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    return subprocess.run([sys.executable, "-m", "morfic_cli", *args], env=env, cwd=tmp, capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A store with the gated critic trained at the smoke preset, and the folder holding the user module."""
    tmp = tmp_path_factory.mktemp("user_variant")
    mods = tmp / "mods"
    mods.mkdir()
    shutil.copy(REPO / "examples" / "custom_variant.py", mods / "gated_lab.py")
    proc = morfic(tmp, "train", "--variant", VARIANT, "--preset", "smoke", "-q", "-f", "json", pythonpath=mods)
    assert proc.returncode == 0, proc.stderr
    return tmp, mods, json.loads(proc.stdout)


def test_a_user_variant_trains_evaluates_diagnoses_exports_and_compares(trained):
    tmp, mods, result = trained
    assert result["variant"] == VARIANT and result["ref"] == f"{RUN}@2"
    show = morfic(tmp, "store", "show", RUN, "-f", "json", pythonpath=mods)
    manifest = json.loads(show.stdout)
    assert manifest["config"]["variant"] == VARIANT and manifest["meta"]["variant"] == VARIANT
    critic = manifest["meta"]["model"]["critic"]
    assert critic["class_name"] == "gated_lab:GatedCritic" and critic["conditioning"] == "gated"

    ev = morfic(tmp, "eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10", "-f", "json", "-q",
                pythonpath=mods)
    assert ev.returncode == 0, ev.stderr
    assert json.loads(ev.stdout)[0]["robot"] == "go2"

    diag = morfic(tmp, "diagnose", RUN, "--robots", "go2", "--envs", "2", "--steps", "30", "--trunc-eps", "0.8",
                  "-f", "json", "-q", pythonpath=mods)
    assert diag.returncode == 0, diag.stderr
    row = json.loads(diag.stdout)[0]
    assert row["variant"] == VARIANT and row["robot"] == "go2"

    exp = morfic(tmp, "export", RUN, "--robot", "go2", "--out", str(tmp / "deploy"), "-q", pythonpath=mods)
    assert exp.returncode == 0, exp.stderr
    assert (tmp / "deploy" / "policy.onnx").is_file()

    cmp = morfic(tmp, "compare-baselines", "-f", "csv", "-q", pythonpath=mods)
    assert cmp.returncode == 0, cmp.stderr
    rows = list(csv.DictReader(io.StringIO(cmp.stdout)))
    assert {r["table"] for r in rows if r["variant"] == VARIANT} == {"transfer", "calibration", "compute"}


def test_a_missing_user_module_is_an_error_naming_the_path(trained):
    tmp, _, _ = trained
    for argv in (("eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10"),
                 ("train", "--variant", VARIANT, "--preset", "smoke", "--name", "other")):
        proc = morfic(tmp, *argv, pythonpath=None)
        assert proc.returncode == 1
        assert proc.stderr.startswith("Error: ") and "Traceback" not in proc.stderr
        assert "gated_lab:GatedCritic" in proc.stderr and "PYTHONPATH" in proc.stderr


def test_weights_that_no_longer_fit_the_class_are_an_error(trained, tmp_path):
    tmp, mods, _ = trained
    changed = tmp_path / "mods"
    changed.mkdir()
    source = (mods / "gated_lab.py").read_text()
    # the user's class changed after training: a wider gate generator
    source = source.replace('c["generator_hidden_dim"], c["activation"])',
                            '2 * c["generator_hidden_dim"], c["activation"])')
    (changed / "gated_lab.py").write_text(source)
    proc = morfic(tmp, "eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10", pythonpath=changed)
    assert proc.returncode == 1
    assert proc.stderr.startswith("Error: ") and "Traceback" not in proc.stderr
    assert "does not fit variant 'gated_lab:GatedCritic'" in proc.stderr


def test_a_module_without_the_class_is_an_error(trained):
    tmp, mods, _ = trained
    proc = morfic(tmp, "train", "--variant", "gated_lab:NoSuchCritic", "--preset", "smoke", pythonpath=mods)
    assert proc.returncode == 1 and "has no 'NoSuchCritic'" in proc.stderr
    assert not (tmp / "store" / "refs" / "runs" / "gated_lab.NoSuchCritic-smoke-s0").exists()
