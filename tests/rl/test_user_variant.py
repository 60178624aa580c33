"""A user's own critic, named by import path, through every command — in subprocesses, as a user runs them.

The user module is examples/custom_variant.py copied into a temporary folder under another name; the
subprocesses see it only through PYTHONPATH (nothing is installed, morfic is not changed). Its copy leaves a marker
file when imported (``GATED_LAB_MARKER``), to show when a command imported it. Each test folder has its own config
folder (``XDG_CONFIG_HOME``: the allow-list of trusted variants, issue 36).
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
SENTINEL = (
    "import os as _os, pathlib as _pathlib\n"
    "if _os.environ.get('GATED_LAB_MARKER'):\n"
    "    _pathlib.Path(_os.environ['GATED_LAB_MARKER']).write_text('imported')\n"
)
"""Top-level code put after the example's: the marker that says the module was imported."""


def morfic(tmp: Path, *args: str, pythonpath: Path | None, marker: Path | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MORFIC_DEBUG", "GATED_LAB_MARKER")}
    env.update(MORFIC_STORE=str(tmp / "store"), OMP_NUM_THREADS="1", XDG_CONFIG_HOME=str(tmp / "config"))
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    if marker is not None:
        env["GATED_LAB_MARKER"] = str(marker)
    return subprocess.run(
        [sys.executable, "-m", "morfic_cli", *args],
        env=env,
        cwd=tmp,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A store with the gated critic trained at the smoke preset, and the folder holding the user module."""
    tmp = tmp_path_factory.mktemp("user_variant")
    mods = tmp / "mods"
    mods.mkdir()
    (mods / "gated_lab.py").write_text((REPO / "examples" / "custom_variant.py").read_text() + SENTINEL)
    proc = morfic(tmp, "train", "--variant", VARIANT, "--preset", "smoke", "-q", "-f", "json", pythonpath=mods)
    assert proc.returncode == 0, proc.stderr
    return tmp, mods, json.loads(proc.stdout)


def test_a_user_variant_trains_evaluates_diagnoses_exports_and_compares(trained):
    tmp, mods, result = trained
    assert result["variant"] == VARIANT and result["ref"] == f"{RUN}@1"
    show = morfic(tmp, "store", "show", RUN, "-f", "json", pythonpath=mods)
    manifest = json.loads(show.stdout)
    assert manifest["config"]["variant"] == VARIANT and manifest["meta"]["variant"] == VARIANT
    critic = manifest["meta"]["model"]["critic"]
    assert critic["class_name"] == "gated_lab:GatedCritic" and critic["conditioning"] == "gated"

    ev = morfic(
        tmp, "eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10", "-f", "json", "-q", pythonpath=mods
    )
    assert ev.returncode == 0, ev.stderr
    assert json.loads(ev.stdout)[0]["robot"] == "go2"

    diag = morfic(
        tmp,
        "diagnose",
        RUN,
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "30",
        "--trunc-eps",
        "0.8",
        "-f",
        "json",
        "-q",
        pythonpath=mods,
    )
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
    for argv in (
        ("eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10"),
        ("train", "--variant", VARIANT, "--preset", "smoke", "--name", "other"),
    ):
        proc = morfic(tmp, *argv, pythonpath=None)
        assert proc.returncode == 1
        assert proc.stderr.startswith("Error: ") and "Traceback" not in proc.stderr
        assert "gated_lab:GatedCritic" in proc.stderr and "Install the package that provides it" in proc.stderr


def test_weights_that_no_longer_fit_the_class_are_an_error(trained, tmp_path):
    tmp, mods, _ = trained
    changed = tmp_path / "mods"
    changed.mkdir()
    source = (mods / "gated_lab.py").read_text()
    # the user's class changed after training: a wider gate generator
    source = source.replace(
        'c["generator_hidden_dim"], c["activation"])', '2 * c["generator_hidden_dim"], c["activation"])'
    )
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


def test_train_trusts_the_variant_it_names(trained):
    """`train --variant` is the user naming the code: it goes on their allow-list; the commands above need no more."""
    tmp, _, _ = trained
    assert VARIANT in (tmp / "config" / "morfic" / "trusted-variants").read_text().splitlines()
    listed = morfic(tmp, "trust", "--list", "-f", "json", pythonpath=None)
    assert listed.returncode == 0 and json.loads(listed.stdout) == [{"variant": VARIANT}]


def test_an_imported_user_variant_run_evaluates_only_with_consent(trained, tmp_path):
    """Another user imports the run's bundle: nothing of gated_lab is imported until they name it (issue 36)."""
    tmp, mods, _ = trained
    exp = morfic(
        tmp,
        "store",
        "export",
        RUN,
        "--latest",
        "--without-trainer-state",
        "--out",
        str(tmp_path / "b"),
        pythonpath=None,
    )
    assert exp.returncode == 0, exp.stderr
    tar = tmp_path / "b" / "gated_lab.GatedCritic-smoke-s0.tar"
    other, marker = tmp_path / "other", tmp_path / "imported"  # their own store and config folder
    other.mkdir()
    imp = morfic(other, "store", "import", str(tar), pythonpath=mods, marker=marker)
    assert imp.returncode == 0, imp.stderr
    assert (
        f"needs the user variant {VARIANT} (code morfic imports to rebuild the models) for {RUN}; NOT trusted "
        "here" in imp.stderr
    )
    ev = ("eval", RUN, "--robots", "go2", "--envs", "2", "--steps", "10", "-q")
    for argv in (
        ev,
        ("diagnose", RUN, "--robots", "go2", "--envs", "2", "--steps", "30", "--trunc-eps", "0.8"),
        ("export", RUN, "--robot", "go2", "--out", str(other / "deploy")),
    ):
        proc = morfic(other, *argv, pythonpath=mods, marker=marker)
        assert proc.returncode == 1, proc.stderr
        assert proc.stderr.startswith(
            f"Error: run {RUN} needs the user variant {VARIANT}; morfic will not import code "
            f"named by a stored run without --trust-variant {VARIANT}"
        ), proc.stderr
        assert not marker.exists() and not (other / "deploy").exists()
    proc = morfic(other, *ev, "--trust-variant", VARIANT, pythonpath=mods, marker=marker)
    assert proc.returncode == 0, proc.stderr
    assert marker.exists()
    marker.unlink()
    assert morfic(other, "trust", VARIANT, pythonpath=None).returncode == 0
    proc = morfic(other, *ev, "-f", "json", pythonpath=mods, marker=marker)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)[0]["robot"] == "go2" and marker.exists()


def test_reproduce_with_a_user_variant_needs_no_other_consent(trained, tmp_path):
    """`reproduce --variants` names the variant: its steps (train, eval, diagnose, in one process) import it, and it
    is remembered; a fresh config folder, so nothing else trusted it."""
    tmp, mods, _ = trained
    other = tmp_path / "other"
    shutil.copytree(tmp / "store", other / "store")  # the run is there, finished: the train step is skipped
    proc = morfic(other, "reproduce", "--preset", "smoke", "--variants", VARIANT, "-f", "json", pythonpath=mods)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["work_done"] >= 2
    for line in (f"train {RUN}: skipped", f"eval {RUN}: done", f"diagnose {RUN}: done"):
        assert line in proc.stderr, proc.stderr
    assert f"trusted {VARIANT} for later commands" in proc.stderr
    assert VARIANT in (other / "config" / "morfic" / "trusted-variants").read_text().splitlines()
