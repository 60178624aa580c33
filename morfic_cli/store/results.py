"""Results-only bundles: which refs (and how much of each history) hold the results of a set of runs.

``morfic store export runs/NAME --results-only`` names *runs*; the export finds their results itself (a named
ref whose current version is itself a result, e.g. ``diagnoses/critic-study``, goes in at that version only, as
version 1, with the checkpoints it names reduced like every other run's: no weights, curves or rollout logs):

- each run ``runs/NAME`` goes in at its current version only, as version 1 (as ``--latest`` does), so it merges
  with the run's weights-only bundle (``--latest --without-trainer-state``), which holds the same one-entry history;
- every other ref with a version whose manifest is a result of one of those checkpoints goes in with its history
  up to its last such version. A result is an ``eval``, ``diagnosis`` or ``table`` manifest that names the
  checkpoint among its inputs and is made from no other result (``evals/NAME``, ``diagnoses/calibration``,
  ``diagnoses/fixed-rollout/<robot>``, ``checks/training-conditions/NAME``). That is the ref as it was when the
  run's last result was added. A prefix of a history merges with any longer one (import says ``unchanged`` or
  ``extended``), so the results bundles of several runs of one store import in any order, and the refs shared
  between runs come out as the source store had them. Earlier versions of a shared ref (other runs' diagnoses)
  come along, without their heavy files like everything else; so do other runs' checkpoint manifests (the frozen
  actor of a fixed rollout, the critics of an earlier diagnosis), without their curves too.

Tables made from other results, and reports (``tables/compare-baselines``, ``reports/*``), stay out: ``morfic
report`` rebuilds them from these results, and a local rebuild would diverge from a shipped history. What the
bundle leaves out is :data:`~morfic_cli.store.shallow.RESULTS_ONLY` (weights, trainer states, rollout logs, the
curves of checkpoints other than the runs').
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from morfic_cli.errors import ArtifactNotFoundError, StoreError
from morfic_cli.store.manifest import Manifest, parse_manifest
from morfic_cli.store.refs import RefEntry, check_ref_name

if TYPE_CHECKING:
    from morfic_cli.store import Store

RESULT_KINDS = frozenset({"eval", "diagnosis", "table"})
"""Manifest kinds that are results of the checkpoints they name as inputs (unless made from other results)."""

RUN_FILE = "model.pt"
"""A run ref's current version is a ``checkpoint`` manifest with this file (its weights)."""


def _not_a_run(name: str, manifest: Manifest) -> StoreError:
    return StoreError(
        f"--results-only exports runs or results, and '{name}' is neither (it is a {manifest.kind} "
        "artifact): name the runs (runs/NAME, see `morfic store ls --kind checkpoint`) and the export "
        "finds the evals and diagnoses made from them, e.g. `morfic store export runs/film-cpu-s0 "
        "--results-only --out bundles/`."
    )


def results_histories(store: Store, runs: list[str]) -> dict[str, list[RefEntry]]:
    """Ref name -> the history a results-only export of ``runs`` writes (see the module docstring). Read-only.

    Raises:
        ArtifactNotFoundError: A name that is not a ref.
        StoreError: A ref that is neither a run nor a result, or a run without any eval or diagnosis in this store.
    """
    cache: dict[str, Manifest] = {}

    def manifest(oid: str) -> Manifest:
        if oid not in cache:
            cache[oid] = parse_manifest(oid, store.objects.get_bytes(oid))
        return cache[oid]

    out: dict[str, list[RefEntry]] = {}
    results: set[str] = set()  # named refs that are results themselves, not runs
    for name in sorted(set(runs)):
        history = store.refs.history(check_ref_name(name))
        if not history:
            raise ArtifactNotFoundError(f"no ref '{name}' in store {store.root}; try `morfic store ls`.")
        head = manifest(history[-1].id)
        if head.kind in RESULT_KINDS:
            results.add(name)
        elif head.kind != "checkpoint" or RUN_FILE not in head.files:
            raise _not_a_run(name, head)
        out[name] = [RefEntry(1, history[-1].id, history[-1].time)]
    checkpoints = {h[-1].id for name, h in out.items() if name not in results}
    found: set[str] = set()
    for ref in store.refs.names():
        if ref in out:
            continue
        history = store.refs.history(ref)
        last = None
        for i, entry in enumerate(history):
            doc = manifest(entry.id)
            hits = checkpoints & set(doc.inputs.values()) if doc.kind in RESULT_KINDS else set()
            others = [oid for oid in set(doc.inputs.values()) - hits if store.objects.has(oid)]
            if hits and any(manifest(oid).kind in RESULT_KINDS for oid in others):
                hits = set()  # made from other results (a comparison table): `morfic report` rebuilds it
            if hits:
                last = i
                found |= hits
        if last is not None:
            out[ref] = history[: last + 1]
    bare = sorted(name for name in runs if name not in results and out[name][0].id not in found)
    if bare:
        raise StoreError(
            f"{bare[0]} has no eval, diagnosis or check in store {store.root}, so a results-only "
            f"bundle of it would hold no results; evaluate and diagnose it first (`morfic eval "
            f"{bare[0]}`, `morfic diagnose {bare[0]}`, or `morfic reproduce`), or export it without "
            "--results-only."
        )
    return out
