"""Smoke-trained runs shared by the tests that need a real checkpoint (eval, diagnose, export, deploy)."""

from __future__ import annotations

from pathlib import Path

from morfic_cli.store import Store


def train_smoke_runs(root: Path, variants: tuple[str, ...] = ("film",), seed: int = 0,
                     name: str = "{variant}-s{seed}") -> Store:
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


#: The first shipped policy (`film`, cpu preset, trained by morfic 0.1.0 before the method fixes of issue 16; ref
#: runs/film-cpu): the fixture of every test about checkpoints an older morfic wrote (artifacts/README.md).
LEGACY_BUNDLE = Path(__file__).resolve().parents[1] / "artifacts" / "bundles" / "film-cpu-legacy.tar"


def copy_store(src: Path, tmp_path: Path, monkeypatch) -> Store:
    """A test's own copy of a module's smoke store at ``tmp_path/store``, made the default store (MORFIC_STORE)."""
    import shutil

    root = tmp_path / "store"
    shutil.copytree(src, root)
    monkeypatch.setenv("MORFIC_STORE", str(root))
    return Store(root)
