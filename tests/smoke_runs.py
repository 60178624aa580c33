"""Smoke-trained runs shared by the tests that need a real checkpoint (eval, diagnose, export, deploy)."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

from filelock import FileLock

from morfic_cli.store import Store


def train_smoke_runs(
    root: Path, variants: tuple[str, ...] = ("film",), seed: int = 0, name: str = "{variant}-s{seed}"
) -> Store:
    """Train each variant with the smoke preset into the store at ``root`` as ``runs/<name>``, in order.

    ``name`` is formatted with ``variant`` and ``seed``: the default is an older store's name (``film-s0``, which
    must keep loading); ``"{variant}-smoke-s{seed}"`` is today's rule (``reproduce``'s fixed-rollout actor).
    """
    from morfic_cli.rl.config import smoke_preset
    from morfic_cli.rl.runner import new_run

    store = Store(root)
    for variant in variants:
        run = new_run(store, smoke_preset(variant, seed=seed), name.format(variant=variant, seed=seed))
        run.train()
        run.env.close()
    return store


#: One ``train_smoke_runs`` call: (variants, seed, name).
SmokeCall = tuple[tuple[str, ...], int, str]
DEFAULT_NAME = "{variant}-s{seed}"


class SmokeRuns:
    """Smoke-trained stores made once per test session and handed out as copies (the ``smoke_runs`` fixture).

    A store is keyed by its ``train_smoke_runs`` calls, in order: the first request trains it into a template under
    ``root`` that no test sees; every request (the first included) gets its own ``shutil.copytree`` of it, so a
    test or module that writes into its store never reaches another's. Training is the slow part (about 8-20 s a
    run on 2 cores); a copy of a 20 MB store takes a fraction of a second.

    ``root`` may be shared by the session's pytest-xdist workers (tests/conftest.py): a template's folder is named
    by its calls and trained under a file lock, so the first worker to ask trains it and the others wait for it and
    copy it. A worker that failed half-way leaves no ``fingerprint.json``: the next one trains it anew.
    """

    def __init__(self, root: Path) -> None:
        self.root = root
        self.templates: dict[tuple[SmokeCall, ...], Path] = {}
        self.fingerprints: dict[Path, list[tuple[str, int, int]]] = {}

    def template(self, *calls: SmokeCall) -> Path:
        """The read-only template store of ``calls`` (trained on first use); copy it, never write into it."""
        if not calls:
            calls = ((("film",), 0, DEFAULT_NAME),)
        key = tuple((tuple(v), s, n) for v, s, n in calls)
        if key not in self.templates:
            folder = self.root / hashlib.sha256(repr(key).encode()).hexdigest()[:16]
            folder.parent.mkdir(parents=True, exist_ok=True)
            with FileLock(folder.with_suffix(".lock")):  # across the xdist workers
                done = folder / "fingerprint.json"
                if not done.exists():
                    shutil.rmtree(folder, ignore_errors=True)  # what a failed worker left
                    for variants, seed, name in key:
                        train_smoke_runs(folder / "store", variants, seed, name)
                    done.write_text(json.dumps(_fingerprint(folder / "store")))
            self.templates[key] = folder / "store"
            self.fingerprints[folder / "store"] = [tuple(f) for f in json.loads(done.read_text())]
        path = self.templates[key]
        assert _fingerprint(path) == self.fingerprints[path], f"a test wrote into the smoke template {path}"
        return path

    def store(self, root: Path, *calls: SmokeCall) -> Store:
        """A fresh copy at ``root`` of the store ``train_smoke_runs`` makes with ``calls`` (default: film seed 0,
        ``runs/film-s0``)."""
        shutil.copytree(self.template(*calls), root)
        return Store(root)


def _fingerprint(root: Path) -> list[tuple[str, int, int]]:
    """Every file under ``root``: (relative path, size, mtime in ns), sorted."""
    return sorted(
        (str(p.relative_to(root)), p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()
    )


#: The first shipped policy (`film`, cpu preset, trained by morfic 0.1.0 before the method fixes of issue 16; ref
#: runs/film-cpu): the fixture of every test about checkpoints an older morfic wrote (artifacts/README.md).
LEGACY_BUNDLE = Path(__file__).resolve().parents[1] / "artifacts" / "bundles" / "film-cpu-legacy.tar"


def copy_store(src: Path, tmp_path: Path, monkeypatch) -> Store:
    """A test's own copy of a module's smoke store at ``tmp_path/store``, made the default store (MORFIC_STORE)."""
    root = tmp_path / "store"
    shutil.copytree(src, root)
    monkeypatch.setenv("MORFIC_STORE", str(root))
    return Store(root)
