"""Issue 36: an imported bundle does not choose what code morfic imports.

A stored run names its critic variant; a user variant (``module:Class``) is imported only with the user's consent
(``--trust-variant`` on the command, or the allow-list of ``morfic trust``), checked before anything is imported.
``store import`` names the user variants a bundle's runs need and refuses names that are not well-formed. The
sentinel module here leaves a marker file when its top-level code runs; the runs are crafted (no training): the
refusal comes before the weights are read. tests/rl/test_user_variant.py runs a real trained user variant.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from crafted_bundles import history_bytes, listing, manifest_bytes, oid_of, write_bundle

from morfic_cli.store import Store

SENTINEL = "sentinel_consent:Critic"
RUN = "runs/x"
REFUSED = (
    f"Error: run {RUN} needs the user variant {SENTINEL}; morfic will not import code named by a stored run "
    f"without --trust-variant {SENTINEL}"
)


@pytest.fixture
def sentinel(tmp_path, monkeypatch):
    """The sentinel module on sys.path (a MorficCritic under another name); returns its marker file."""
    marker = tmp_path / "sentinel-imported"
    mods = tmp_path / "mods"
    mods.mkdir()
    (mods / "sentinel_consent.py").write_text(
        "import pathlib\n"
        f"pathlib.Path({str(marker)!r}).write_text('imported')\n"
        "from morfic_cli.rl.models import MorficCritic\n\n\n"
        "class Critic(MorficCritic):\n    critic_defaults = {'conditioning': 'film'}\n"
    )
    monkeypatch.syspath_prepend(str(mods))
    monkeypatch.delitem(sys.modules, "sentinel_consent", raising=False)
    return marker


def imported(marker: Path) -> bool:
    return marker.exists() or "sentinel_consent" in sys.modules


def run_bundle(tmp_path: Path, variant: str, ref: str = RUN) -> Path:
    """A bundle of one finished checkpoint run (``ref``) whose config and meta name ``variant``."""
    src = Store(tmp_path / "src")
    src.publish(
        "checkpoint",
        ref,
        config={"variant": variant},
        meta={"variant": variant, "finished": True},
        files={"model.pt": b"not weights"},
    )
    out = tmp_path / "x.tar"
    src.export_tar([ref], out)
    return out


#: Every command that loads a stored run's models (it must refuse before importing the run's user variant).
LOADERS = {
    "eval": ["eval", RUN, "--robots", "go2", "--envs", "1", "--steps", "2"],
    "diagnose": ["diagnose", RUN, "--robots", "go2", "--envs", "1", "--steps", "2"],
    "fixed-rollout": ["diagnose", "--fixed-rollout", "go2", "--actor", RUN, "--critics", RUN, "--envs", "1"],
    "export": ["export", RUN, "--robot", "go2"],
    "play": ["play", RUN, "--steps", "1"],
    "critic-study": ["critic-study", "--actor", RUN, "--variants", "film", "--seeds", "1"],
    "train --resume": ["train", "--resume", RUN],
}


def test_a_bundles_user_variant_is_named_at_import_and_never_imported_without_consent(run_cli, sentinel, tmp_path):
    tar = run_bundle(tmp_path, SENTINEL)
    code, out, err = run_cli("store", "import", str(tar))
    assert code == 0, err
    assert f"needs the user variant {SENTINEL}" in err and f"for {RUN}; NOT trusted here" in err
    assert f"--trust-variant {SENTINEL}" in err and f"morfic trust {SENTINEL}" in err
    for name, argv in LOADERS.items():
        code, out, err = run_cli(*argv, "--out", str(tmp_path / "o")) if name == "export" else run_cli(*argv)
        assert code == 1, (name, err)
        assert err.startswith(REFUSED), (name, err)
        assert f"morfic trust {SENTINEL}" in err and "Traceback" not in err
        assert not imported(sentinel), name
    for argv in (["report"], ["compare-baselines"], ["store", "show", RUN]):  # they read the store, import nothing
        run_cli(*argv)
        assert not imported(sentinel), argv


def test_trust_variant_or_the_allow_list_lets_the_same_run_load(run_cli, sentinel, tmp_path):
    tar = run_bundle(tmp_path, SENTINEL)
    assert run_cli("store", "import", str(tar))[0] == 0
    code, _, err = run_cli(*LOADERS["eval"], "--trust-variant", SENTINEL)
    assert imported(sentinel)  # consent given: the class is imported and the models built ...
    assert code == 1 and "needs the user variant" not in err and "model.pt" in err  # ... the crafted weights fail
    # consent ends with the command: the next one (same process) is refused again, before the weights
    sys.modules.pop("sentinel_consent")
    sentinel.unlink()
    code, _, err = run_cli(*LOADERS["eval"])
    assert err.startswith(REFUSED) and not imported(sentinel)
    # the allow-list: `morfic trust` once, every command after
    code, _, err = run_cli("trust", SENTINEL)
    assert code == 0 and f"trusted: {SENTINEL}" in err
    code, out, _ = run_cli("trust", "--list", "-f", "json")
    assert code == 0 and SENTINEL in out
    code, _, err = run_cli(*LOADERS["eval"])
    assert imported(sentinel) and "needs the user variant" not in err
    code, _, err = run_cli("store", "import", str(tar))
    assert (
        f"needs the user variant {SENTINEL} (code morfic imports to rebuild the models) for {RUN}; trusted here" in err
    )
    assert run_cli("trust", "--remove", SENTINEL)[0] == 0
    sys.modules.pop("sentinel_consent")
    sentinel.unlink()
    assert run_cli(*LOADERS["diagnose"])[2].startswith(REFUSED) and not imported(sentinel)


def test_this_is_not_imported_from_a_stored_run(run_cli, tmp_path):
    """The issue's example: variant "this:x" would import the stdlib module `this`, which prints the Zen of Python."""
    assert "this" not in sys.modules
    tar = run_bundle(tmp_path, "this:x")
    assert run_cli("store", "import", str(tar))[0] == 0
    code, out, err = run_cli(*LOADERS["eval"])
    assert code == 1 and err.startswith(f"Error: run {RUN} needs the user variant this:x;")
    assert "this" not in sys.modules and "Zen" not in out + err


def test_the_allow_list_is_in_the_config_folder_not_the_store(run_cli, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert run_cli("trust", "pkg.mod:Critic")[0] == 0
    assert (tmp_path / "xdg" / "morfic" / "trusted-variants").read_text().splitlines()[-1] == "pkg.mod:Critic"
    assert not (tmp_path / "store").exists()
    code, out, _ = run_cli("trust", "-f", "csv")
    assert code == 0 and out.splitlines() == ["variant", "pkg.mod:Critic"]
    code, _, err = run_cli("trust", "--remove", "other.mod:Critic")
    assert code == 1 and err.startswith("Error: other.mod:Critic is not on the allow-list")
    code, _, err = run_cli("trust", ".rel:Critic")
    assert code == 1 and err.startswith("Error: variant '.rel:Critic' is not an import path")
    code, _, err = run_cli("trust", "--remove")
    assert code == 1 and err.startswith("Error: --remove needs the variants")


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["eval", RUN, "--trust-variant", "pkg..mod:C"], "--trust-variant: variant 'pkg..mod:C' is not an import path"),
        (["eval", RUN, "--trust-variant", "film"], "--trust-variant film: film is a stock variant"),
        (["diagnose", RUN, "--trust-variant", "a:b c"], "--trust-variant: variant 'a:b c' is not an import path"),
    ],
)
def test_a_bad_trust_variant_is_an_error_before_any_work(run_cli, argv, needle):
    code, _, err = run_cli(*argv)
    assert code == 1 and err.startswith(f"Error: {needle}")


BAD_NAMES = [
    ".rel:Critic",
    "..up:Critic",
    "pkg..mod:Critic",
    "pkg:",
    ":Critic",
    "pkg:Cri tic",
    "pkg:C\n",
    "pkg:C\x1b[2J",
    "pkg/mod:C",
    "a:b:c",
    "x" * 300 + ":C",
    42,
    None,
    "film xl",
    "-film",
]


@pytest.mark.parametrize("where", ["config", "meta"])
@pytest.mark.parametrize("bad", BAD_NAMES, ids=lambda b: ascii(b)[:20])
def test_import_refuses_a_variant_that_is_not_well_formed(run_cli, tmp_path, where, bad):
    model = b"weights"
    fields = {"config": {"variant": "film"}, "meta": {"variant": "film"}}
    fields[where] = {"variant": bad}
    manifest = manifest_bytes(
        kind="checkpoint", files={"model.pt": {"id": oid_of(model), "size": len(model)}}, **fields
    )
    tar = write_bundle(
        tmp_path / "bad.tar", blobs=[model], manifests=[manifest], refs={RUN: history_bytes([oid_of(manifest)])}
    )
    store = tmp_path / "store"
    before = listing(store)
    code, out, err = run_cli("store", "import", str(tar))
    assert code == 1, err
    assert (
        err.startswith(f"Error: manifest {oid_of(manifest)} in the export names a variant that is not well-formed")
        and "nothing was imported" in err
    )
    assert "\x1b" not in err and len(err.splitlines()) == 1
    assert listing(store) == before


def test_a_well_formed_user_variant_in_a_study_list_imports(run_cli, tmp_path):
    """A critic study's `variants` list is checked the same way and names no code to import (no line)."""
    src = Store(tmp_path / "src")
    src.publish(
        "diagnosis",
        "diagnoses/critic-study",
        config={"variants": ["film", "my_lab.critics:Gated"]},
        meta={"variants": ["film", "my_lab.critics:Gated"]},
        files={"critic_study.csv": b"x\n"},
    )
    src.export_tar(["diagnoses/critic-study"], tmp_path / "s.tar")
    code, _, err = run_cli("store", "import", str(tmp_path / "s.tar"))
    assert code == 0, err


def test_a_cluster_worker_imports_only_what_the_driver_trusts(sentinel, tmp_path):
    """``reproduce --executor ray``: a job re-resolves its input run's variant with the driver's consent only.

    The input run has the name of a stock run of the pipeline but names the sentinel (a hostile store).
    """
    from morfic_cli import __version__
    from morfic_cli.cluster.jobs import Job
    from morfic_cli.cluster.worker import execute
    from morfic_cli.pipeline import reproduce_cfg

    run = "runs/film-smoke-s0"
    tar = run_bundle(tmp_path, SENTINEL, run).read_bytes()
    cfg = reproduce_cfg("smoke", variants=("film",))
    job = Job("eval", run, needs=(run,))
    refused = execute(job, cfg, __version__, tar)
    assert refused.error.startswith(f"run {run} needs the user variant {SENTINEL};") and not imported(sentinel)
    trusted = execute(job, cfg, __version__, tar, trusted=(SENTINEL,))
    assert imported(sentinel) and "needs the user variant" not in trusted.error


def test_a_trusted_name_that_is_not_a_critic_class_is_an_error(run_cli, tmp_path, monkeypatch):
    """Issue 53, item 4: `class Critic: pass`, consented to: `Error:` naming the protocol, not a TypeError."""
    mods = tmp_path / "mods"
    mods.mkdir()
    (mods / "notcritic_consent.py").write_text("class Critic:\n    pass\n")
    monkeypatch.syspath_prepend(str(mods))
    monkeypatch.delitem(sys.modules, "notcritic_consent", raising=False)
    name = "notcritic_consent:Critic"
    assert run_cli("store", "import", str(run_bundle(tmp_path, name)))[0] == 0
    for argv in (LOADERS["eval"], LOADERS["diagnose"], LOADERS["train --resume"]):
        code, _, err = run_cli(*argv, "--trust-variant", name)
        assert code == 1 and "Traceback" not in err and err.count("\n") == 1, err
        assert err.startswith(
            f"Error: variant '{name}': class Critic is not a critic model: a torch.nn.Module "
            "subclass with forward and encode_privileged"
        ), err


def test_the_example_variant_installs_as_its_own_package(tmp_path):
    """docs/extending.md: the example travels as a package (examples/pyproject.toml), installed, no PYTHONPATH.

    Built offline from a copy of examples/ and installed into a folder that a subprocess adds as a site directory
    (as site-packages is); the variant resolves and its models build with consent, and only with it.
    """
    import shutil
    import subprocess

    repo = Path(__file__).resolve().parents[2]
    shutil.copytree(repo / "examples", tmp_path / "src")
    site = tmp_path / "site"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--quiet",
            "--target",
            str(site),
            str(tmp_path / "src"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert (site / "custom_variant.py").read_bytes() == (repo / "examples" / "custom_variant.py").read_bytes()
    script = (
        f"import site; site.addsitedir({str(site)!r})\n"
        "from morfic_cli.rl import variants as V\n"
        "from morfic_cli.rl.config import smoke_preset\n"
        "from morfic_cli.rl.build import build_models\n"
        "name = 'custom_variant:GatedCritic'\n"
        "try:\n    V.resolve_variant(name)\nexcept V.UntrustedVariantError:\n    print('refused')\n"
        "with V.consent_scope([name]):\n"
        "    cfg = smoke_preset(name)\n"
        "    actor, critic = build_models(cfg)\n"
        "    label = V.resolve_variant(name).label\n"
        "print(type(critic).__name__, type(critic).__module__, label)\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=tmp_path,
        env={**env, "OMP_NUM_THREADS": "1"},
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["refused", "GatedCritic", "custom_variant", "Gated"]


def test_names_that_look_like_emoji_codes_print_as_written(run_cli, tmp_path, monkeypatch):
    """rich turns ``:x:`` into an emoji unless told not to: a variant named ``evil.mod:X`` next to a colon must print
    as those characters, in the table and in the message that the hand-added line voids the list."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert run_cli("trust", "smile.mod:Smile")[0] == 0
    code, out, _ = run_cli("trust", "--list")
    assert code == 0 and "smile.mod:Smile" in out
    path = tmp_path / "xdg" / "morfic" / "trusted-variants"
    path.write_text(path.read_text() + "evil.mod:X\n")
    code, out, err = run_cli("trust", "--list")
    assert code == 0 and "evil.mod:X" in out + err and "\N{CROSS MARK}" not in out + err
