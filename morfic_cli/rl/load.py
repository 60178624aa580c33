"""Loading trained runs: a checkpoint's actor and critic, rebuilt from its stored config and weights.

Every ``torch.load`` here is ``weights_only=True`` (:func:`~morfic_cli.rl.trainer_state.load_tensors`): a bundle
from anyone can never run code.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import torch

from morfic_cli import __version__
from morfic_cli.errors import MorficError
from morfic_cli.rl import trainer_state
from morfic_cli.rl.build import build_models
from morfic_cli.rl.config import TrainCfg
from morfic_cli.rl.variants import resolve_variant
from morfic_cli.runs import RUNS_PREFIX, run_of
from morfic_cli.validation import check_stored_cfg

if TYPE_CHECKING:
    from morfic_cli.store import Store


@dataclasses.dataclass
class TrainedModels:
    """A checkpoint's models, ready for evaluation (eval mode, CPU)."""

    actor: torch.nn.Module
    critic: torch.nn.Module
    cfg: TrainCfg
    checkpoint_id: str
    meta: dict[str, Any]


def load_trained(store: Store, spec: str) -> TrainedModels:
    """Load a checkpoint's actor and critic (``spec``: ``runs/NAME``, ``runs/NAME@N``, id or prefix).

    Raises:
        ArtifactNotFoundError: Nothing by that name.
        UntrustedVariantError: Its user variant is neither trusted nor named on this command line (nothing of it
            is imported; :func:`~morfic_cli.rl.variants.require_trusted`).
        MorficError: It is not a training checkpoint, or its user variant cannot be imported or its weights do
            not fit that class.
    """
    manifest = store.read_manifest(spec)
    if manifest.kind != "checkpoint" or "model.pt" not in manifest.files:
        raise MorficError(
            f"'{spec}' is a {manifest.kind} artifact, not a training checkpoint; "
            "pass a run ref such as runs/film-cpu-s0 (see `morfic store ls --kind checkpoint`)."
        )
    check_weights(store, spec, manifest)
    cfg = check_stored_cfg(manifest.config, spec)  # a bundle's config: checked before anything is built
    variant = resolve_variant(cfg.variant, source=spec)  # a user variant: only with the user's consent, else Error
    actor, critic = build_models(cfg)
    state = load_weights(store, manifest.id, "cpu")
    try:
        actor.load_state_dict(state["actor"])
        critic.load_state_dict(state["critic"])
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0]
        if variant.stock:
            raise MorficError(
                f"checkpoint '{spec}' was written by morfic {manifest.morfic_version}, and its weights do not fit "
                f"the '{cfg.variant}' models of this morfic {__version__} ({first}); evaluate it with morfic "
                f"{manifest.morfic_version}, or retrain it with this version."
            ) from exc
        raise MorficError(
            f"checkpoint '{spec}' does not fit variant '{cfg.variant}' ({variant.critic_class}) as "
            f"it is installed now ({first}); install the version of the class it was trained "
            "with."
        ) from exc
    actor.eval()
    critic.eval()
    return TrainedModels(actor, critic, cfg, manifest.id, dict(manifest.meta))


def check_weights(store: Store, spec: str, manifest: Any) -> None:
    """Raise when the checkpoint's weights were left out (a run imported from a results-only bundle).

    Raises:
        MorficError: ``model.pt`` of ``manifest`` is recorded as left out (``shallow/``); names the bundle to import.
    """
    if store.weights_omitted(manifest):
        name = run_of(spec, manifest.meta)
        raise MorficError(
            f"{spec} was imported from a results-only bundle: its weights (model.pt) and trainer state "
            "were left out, so it cannot be evaluated, played, exported, diagnosed or resumed (its "
            "tables, curves and config are here, for `morfic report`). Import a bundle with its weights "
            f"first: its weights-only bundle (made by `morfic store export {RUNS_PREFIX}{name} --latest "
            "--without-trainer-state` in the store that trained it; shipped ones are under "
            "artifacts/bundles/), or its full bundle to resume it."
        )


def load_weights(store: Store, ckpt_id: str, device: str) -> dict[str, Any]:
    """``model.pt`` of a checkpoint: ``{"actor": state dict, "critic": state dict}``, loaded as tensors only."""
    state = trainer_state.load_tensors(
        store.read_file(ckpt_id, "model.pt"), f"model.pt of checkpoint {ckpt_id[:12]}", map_location=device
    )
    if not (isinstance(state, dict) and isinstance(state.get("actor"), dict) and isinstance(state.get("critic"), dict)):
        raise MorficError(
            f"model.pt of checkpoint {ckpt_id[:12]} is not {{'actor': ..., 'critic': ...}} weights; "
            "use a checkpoint written by `morfic train`."
        )
    return state
