"""Resume: the checkpoint ``--resume`` continues from, with its trainer state, in the current or a legacy layout.

Runs written before the one-ref layout kept the trainer state apart, under ref ``resume/NAME`` (``trainer.pt``,
input ``checkpoint`` = the weights); they still resume when that file holds only tensors and plain containers,
and give a clear error otherwise.
"""

from __future__ import annotations

import dataclasses
import re
from typing import TYPE_CHECKING, Any

from morfic_cli.errors import ArtifactNotFoundError, MorficError
from morfic_cli.rl import trainer_state
from morfic_cli.rl.load import check_weights
from morfic_cli.rl.variants import resolve_variant
from morfic_cli.runs import RESUME_PREFIX, RUNS_PREFIX, run_of
from morfic_cli.store.refs import is_ref_name
from morfic_cli.store.shallow import TRAINER_STATE_ROLE  # defined by the store: weights-only bundles leave it out
from morfic_cli.validation import check_stored_cfg

if TYPE_CHECKING:
    from morfic_cli.store import Store


@dataclasses.dataclass
class ResumePoint:
    """What ``--resume`` continues from: the checkpoint, its run name, trainer state and curve so far."""

    manifest: Any
    name: str
    trainer: dict[str, Any]
    rows: list[dict[str, float]]


def load_resume_point(store: Store, spec: str) -> ResumePoint:
    """The checkpoint ``spec`` names with its trainer state, loaded without building an env (``--resume``)."""
    from morfic_cli.recording.curves import read_curve_csv

    try:
        manifest = store.read_manifest(spec)
    except ArtifactNotFoundError as exc:
        if not spec.startswith(RUNS_PREFIX) and store.has_ref(RUNS_PREFIX + spec):
            manifest = store.read_manifest(RUNS_PREFIX + spec)
        elif "@" not in spec and is_ref_name(spec) and not store.has_ref(spec) and not _HEX.fullmatch(spec):
            name = spec.removeprefix(RUNS_PREFIX)
            raise ArtifactNotFoundError(
                f"{exc} A run killed before its first checkpoint (written every save_interval iterations) leaves "
                f"nothing to resume: start it afresh with `morfic train --name {name}` and its --variant, --preset, "
                "--seed and --set."
            ) from exc
        else:
            raise
    if manifest.kind != "checkpoint" or "model.pt" not in manifest.files:
        raise MorficError(f"--resume '{spec}' is not a training checkpoint; pass a run ref like runs/film-cpu-s0.")
    name = run_of(spec, manifest.meta)
    resolve_variant(check_stored_cfg(manifest.config, spec).variant, source=spec)  # checked, then consent
    check_weights(store, spec, manifest)
    state_id = manifest.inputs.get(TRAINER_STATE_ROLE)
    if state_id is not None and store.is_omitted(state_id):
        raise MorficError(
            f"{spec} was imported without its trainer state (a weights-only bundle); it evaluates and "
            "exports, but cannot be resumed. Import the full bundle (made by `morfic store export "
            f"{RUNS_PREFIX}{name} --latest`, without --without-trainer-state, in the store that trained "
            "it) to resume it, or start a new run with `morfic train`."
        )
    if state_id is not None:
        state = store.read_manifest(state_id)
        trainer = trainer_state.decode(
            store.read_file(state.id, trainer_state.JSON_FILE),
            store.read_file(state.id, trainer_state.TENSORS_FILE),
            f"checkpoint '{spec}'",
        )
    else:
        trainer = _legacy_trainer_state(store, spec, manifest.id, name)
    trainer_state.check_trainer_state(trainer, f"checkpoint '{spec}'", TRAINER_KEYS)  # keys, types, sizes
    rows = read_curve_csv(store.read_file(manifest.id, "curve.csv"))
    return ResumePoint(manifest, name, trainer, rows)


_HEX = re.compile(r"[0-9a-f]{4,64}")

#: Keys every trainer state holds.
TRAINER_KEYS = frozenset({"iteration", "alg", "learning_rate", "env", "logger", "torch_rng"})


def _legacy_trainer_state(store: Store, spec: str, ckpt_id: str, name: str) -> dict[str, Any]:
    """The ``resume/NAME`` trainer state of a checkpoint written before the one-ref layout (tensors only)."""
    legacy = RESUME_PREFIX + name
    states = {}
    if store.has_ref(legacy):
        for entry in store.ref_history(legacy):
            states[store.read_manifest(entry.id).inputs.get("checkpoint")] = entry.id
    if ckpt_id not in states:
        older = (
            [e for e in store.ref_history(RUNS_PREFIX + name) if e.id in states]
            if store.has_ref(RUNS_PREFIX + name)
            else []
        )
        hint = (
            f" Its last resumable checkpoint is {RUNS_PREFIX}{name}@{older[-1].version}: `morfic train --resume "
            f"{RUNS_PREFIX}{name}@{older[-1].version}`."
            if older
            else " Start a new run with `morfic train`."
        )
        raise MorficError(
            f"checkpoint '{spec}' has no trainer state in {store.root} (policy bundles of older morfic "
            f"versions carry weights only, as does a checkpoint cut short by a kill), so it cannot be "
            f"resumed.{hint}"
        )
    return trainer_state.load_tensors(
        store.read_file(states[ckpt_id], "trainer.pt"),
        f"the trainer state (trainer.pt, an older format) of checkpoint '{spec}'",
    )
