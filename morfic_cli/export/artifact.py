"""``morfic export`` as library calls: export a checkpoint's policy into the store, and re-check an export.

One export = one ``export`` manifest (input ``checkpoint``) holding the model file (``policy.onnx`` or
``policy.pt``) and ``policy.json`` (:mod:`morfic_cli.export.metadata`); ref ``exports/<run>/<robot>-<format>``
(``exports/<run>/<format>`` when the descriptor stays a model input). Nothing is stored unless the runtime
reproduces the torch actor (:func:`~morfic_cli.export.verify.verify_outputs`) and the metadata matches every
described robot's MuJoCo model (:func:`~morfic_cli.export.verify.model_mismatches`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from morfic_cli.errors import ArtifactNotFoundError, MorficError, UnknownNameError
from morfic_cli.export import metadata as M
from morfic_cli.export.policy import DescriptorInputPolicy, FixedDescriptorPolicy, JointTargetPolicy
from morfic_cli.export.runtime import (
    FORMATS,
    MODEL_FILES,
    ONNX_OPSET,
    load_runner,
    onnxruntime_version,
    read_metadata,
    require_onnx,
    to_onnx,
    to_torchscript,
    with_metadata,
)
from morfic_cli.export.verify import TOLERANCE, Verification, model_mismatches, verify_outputs
from morfic_cli.morphology.robots import list_robots, load_robot
from morfic_cli.rl.load import TrainedModels, load_trained
from morfic_cli.runs import run_of
from morfic_cli.store import Store
from morfic_cli.store.manifest import safe_join

EXPORTS_PREFIX = "exports/"
METADATA_FILE = "policy.json"

#: Metadata keys that may differ between the writer and a later --check (everything else must be equal).
_VOLATILE_KEYS = frozenset({"morfic_version", "model_sha256"})


@dataclass(frozen=True)
class ExportCfg:
    """What to export (the ``morfic export`` options)."""

    robot: str | None = None
    """Bake this robot's descriptor into the model; None keeps ``morphology`` as an input."""
    fmt: str = "onnx"
    """``onnx`` or ``torchscript``."""
    targets: bool = False
    """Also output the joint position targets (needs ``robot``: q0 and the limits are the robot's)."""
    opset: int = ONNX_OPSET
    """ONNX opset (>= 17)."""
    samples: int = 256
    """Random inputs of the verification."""
    seed: int = 0
    """Seed of those inputs."""
    tolerance: float = TOLERANCE
    """Largest accepted |runtime - torch|."""


@dataclass
class ExportResult:
    """A stored export.

    Attributes:
        id: The export manifest id.
        ref: ``exports/<run>/...`` and version.
        files: File name -> bytes (the model and ``policy.json``).
        metadata: The parsed ``policy.json``.
        verification: Runtime vs torch.
        written: Files written to ``--out``.
    """

    id: str
    ref: str
    files: dict[str, bytes]
    metadata: dict[str, Any]
    verification: Verification
    written: list[Path] = field(default_factory=list)


@dataclass
class CheckResult:
    """A re-verified export (``--check``).

    Attributes:
        source: The store spec or path that was checked.
        metadata: Its ``policy.json``.
        verification: Runtime vs the torch actor of the checkpoint it names.
        problems: Everything that is wrong (empty: the export is good).
    """

    source: str
    metadata: dict[str, Any]
    verification: Verification
    problems: list[str]

    @property
    def ok(self) -> bool:
        """No problems and a passed verification."""
        return not self.problems and self.verification.ok


def export_ref(run: str, robot: str | None, fmt: str) -> str:
    """``exports/<run>/<robot>-<format>``, or ``exports/<run>/<format>`` without a baked robot."""
    return f"{EXPORTS_PREFIX}{run}/{robot}-{fmt}" if robot else f"{EXPORTS_PREFIX}{run}/{fmt}"


def check_cfg(cfg: ExportCfg) -> None:
    """Reject bad options before anything is loaded.

    Raises:
        MorficError: Unknown format or robot, ``--targets`` without ``--robot``, opset < 17, missing packages.
    """
    if cfg.fmt not in FORMATS:
        raise UnknownNameError("format", cfg.fmt, FORMATS)
    if cfg.robot is not None:
        load_robot(cfg.robot)
    if cfg.targets and cfg.robot is None:
        raise MorficError("--targets needs --robot: the joint targets use that robot's default pose and limits.")
    if cfg.opset < 17:
        raise MorficError(f"--opset {cfg.opset} is too old; use 17 or newer.")
    if cfg.samples < 1:
        raise MorficError("--samples must be a positive integer.")
    if cfg.fmt == "onnx":
        require_onnx()


def plan_export(trained: TrainedModels, robot: str | None, targets: bool) -> tuple[torch.nn.Module, dict[str, Any]]:
    """The module to serialise and its metadata (without the model-file fields).

    Args:
        trained: The loaded checkpoint.
        robot: Robot to bake in, or None.
        targets: Add the ``joint_targets`` output.

    Returns:
        ``(module, metadata)``; the module takes the metadata's inputs in order.

    Raises:
        MorficError: The actor reads the extended descriptor (not exportable yet).
    """
    actor = trained.actor
    env = trained.cfg.env
    if env.obs.extended_morphology and actor.morphology_encoder is not None:
        raise MorficError(
            f"run '{trained.meta.get('run')}' reads the extended descriptor "
            "(env.obs.extended_morphology, variant film-act); export bakes the 11-D one only, so it "
            "is not supported yet. Evaluate it with `morfic eval` instead."
        )
    morphology_input = actor.morphology_encoder is not None and robot is None
    robots = {robot: load_robot(robot)} if robot else {name: load_robot(name) for name in list_robots()}
    source = {
        "run": trained.meta.get("run"),
        "checkpoint": trained.checkpoint_id,
        "variant": trained.cfg.variant,
        "preset": trained.cfg.preset,
        "seed": trained.cfg.seed,
        "iteration": trained.meta.get("iteration"),
    }
    meta = M.build_metadata(
        env=env,
        robots=robots,
        baked_robot=robot,
        morphology_input=morphology_input,
        targets=targets,
        model={},
        source=source,
    )
    if morphology_input:
        module: torch.nn.Module = DescriptorInputPolicy(actor)
    else:
        baked = meta["robots"][robot]["morphology"] if robot else None
        module = FixedDescriptorPolicy(actor, baked)
        if targets:
            section = meta["robots"][robot]
            module = JointTargetPolicy(
                module, section["default_joint_pos"], section["joint_limits"], env.action_scale, env.action_clip
            )
    return module.eval(), meta


def serialise(module: torch.nn.Module, meta: dict[str, Any], fmt: str, opset: int = ONNX_OPSET) -> bytes:
    """The model file's bytes in ``fmt`` (example batch of 2 so the batch axis stays symbolic)."""
    if fmt == "torchscript":
        return to_torchscript(module)
    example = tuple(torch.zeros(2, *spec["shape"][1:]) for spec in meta["inputs"])
    return to_onnx(module, example, [s["name"] for s in meta["inputs"]], [s["name"] for s in meta["outputs"]], opset)


def runtime_name(fmt: str) -> str:
    """What runs the format: ``onnxruntime <version>`` or ``torch <version> (TorchScript)``."""
    return onnxruntime_version() if fmt == "onnx" else f"torch {torch.__version__} (TorchScript)"


def export_policy(
    store: Store,
    spec: str,
    cfg: ExportCfg,
    out: Path | None = None,
    trained: TrainedModels | None = None,
    on_phase: Callable[[str], None] | None = None,
) -> ExportResult:
    """Export checkpoint ``spec``'s deployed actor path, verify it, store it, and optionally write it to ``out``.

    Args:
        store: The artifact store.
        spec: A run ref (``runs/film-cpu-s0``), ``ref@N``, or checkpoint id.
        cfg: What to export.
        out: Also write the model and ``policy.json`` into this directory.
        trained: The checkpoint already loaded (else loaded from ``spec``).
        on_phase: Called with a short description as each phase starts (the CLI's progress line).

    Raises:
        MorficError: Bad options, not a checkpoint, or a failed verification (then nothing is stored).
    """
    check_cfg(cfg)
    phase = on_phase or (lambda _text: None)
    phase("loading the checkpoint")
    trained = trained or load_trained(store, spec)
    module, meta = plan_export(trained, cfg.robot, cfg.targets)
    model_file = MODEL_FILES[cfg.fmt]
    meta.update(format=cfg.fmt, model_file=model_file, onnx_opset=cfg.opset if cfg.fmt == "onnx" else None)
    phase(f"exporting {'ONNX (torch.export)' if cfg.fmt == 'onnx' else 'TorchScript'}")
    model_bytes = serialise(module, meta, cfg.fmt, cfg.opset)
    if cfg.fmt == "onnx":
        model_bytes = with_metadata(model_bytes, M.onnx_props(meta))
    meta["model_sha256"] = hashlib.sha256(model_bytes).hexdigest()
    phase(f"verifying on {cfg.samples} random inputs")
    verification = verify_outputs(
        load_runner(cfg.fmt, model_bytes),
        runtime_name(cfg.fmt),
        trained.actor,
        meta,
        samples=cfg.samples,
        seed=cfg.seed,
        tolerance=cfg.tolerance,
    )
    if not verification.ok:
        raise MorficError(f"export verification failed, nothing stored: {verification.summary()}.")
    phase("checking the metadata against the robot models")
    problems = robot_model_problems(meta)
    if problems:
        raise MorficError("export metadata disagrees with the robot model, nothing stored: " + "; ".join(problems))
    files = {model_file: model_bytes, METADATA_FILE: metadata_bytes(meta)}
    run = run_of(spec, meta)
    ref = export_ref(run, cfg.robot, cfg.fmt)
    config = {"spec": spec, **dataclasses.asdict(cfg)}
    pub = store.publish(
        "export",
        ref,
        config=config,
        inputs={"checkpoint": trained.checkpoint_id},
        files=files,
        meta={
            "run": run,
            "robot": cfg.robot,
            "format": cfg.fmt,
            "targets": cfg.targets,
            "model_sha256": meta["model_sha256"],
            "verification": verification.to_dict(),
        },
    )
    result = ExportResult(pub.id, f"{ref}@{pub.version}", files, meta, verification)
    if out is not None:
        result.written = write_files(out, files)
    return result


@dataclass
class RslRlExport:
    """A stored rsl-rl checkpoint export (``morfic export RUN --to rsl-rl``).

    Attributes:
        id: The export manifest id.
        ref: ``exports/<run>/rsl-rl`` and version.
        files: File name -> bytes (``model_<it>.pt``, ``agent.json``, ``train.json``).
        checkpoint: The morfic checkpoint id it was made from.
        optimizer: ``trained`` (the run's optimiser state) or ``fresh`` (a weights-only checkpoint).
        reused: The store already held this export (no new manifest).
        written: Files written to ``--out``.
    """

    id: str
    ref: str
    files: dict[str, bytes]
    checkpoint: str
    optimizer: str
    reused: bool
    written: list[Path] = field(default_factory=list)


def export_rsl_rl(store: Store, spec: str, out: Path | None = None) -> RslRlExport:
    """Export checkpoint ``spec`` in rsl-rl's checkpoint layout (:mod:`morfic_cli.export.rsl_rl`), store it, write it.

    The weights are checked to load back into freshly built models with identical actions before anything is
    stored. Ref ``exports/<run>/rsl-rl``; an identical export already in the store is reused (no new version).

    Raises:
        MorficError: Not a checkpoint, or its user variant cannot be imported.
    """
    from morfic_cli.export import rsl_rl

    trained = load_trained(store, spec)
    files, infos = rsl_rl.rsl_rl_files(store, trained)
    name = next(n for n in files if n.endswith(".pt"))
    _check_rsl_rl_weights(trained, files[name])
    run = run_of(spec, trained.meta)
    ref = export_ref(run, None, "rsl-rl")
    optimizer = infos["optimizer"]
    pub = store.publish(
        "export",
        ref,
        config={"to": "rsl-rl"},
        inputs={"checkpoint": trained.checkpoint_id},
        files=files,
        meta={"run": run, "format": "rsl-rl", "model_file": name, "optimizer": optimizer},
        reuse=True,
    )
    result = RslRlExport(pub.id, f"{ref}@{pub.version}", files, trained.checkpoint_id, optimizer, pub.reused)
    if out is not None:
        result.written = write_files(out, files)
    return result


def _check_rsl_rl_weights(trained: TrainedModels, data: bytes) -> None:
    """Load the exported weights into fresh models and compare actions on random inputs (an internal invariant)."""
    from morfic_cli.rl.build import build_models, dummy_observations

    state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    actor, critic = build_models(trained.cfg)
    actor.load_state_dict(state["actor_state_dict"])
    critic.load_state_dict(state["critic_state_dict"])
    actor.eval()
    obs = dummy_observations(trained.cfg, batch=8)
    gen = torch.Generator().manual_seed(0)
    for key in obs.keys():
        obs[key] = torch.randn(obs[key].shape, generator=gen)
    with torch.no_grad():
        if not torch.equal(actor(obs), trained.actor(obs)):
            raise RuntimeError("the rsl-rl export's actor weights do not reproduce the checkpoint's actions")


def metadata_bytes(meta: dict[str, Any]) -> bytes:
    """``policy.json``: indented, key order as built, trailing newline."""
    return (json.dumps(meta, indent=2) + "\n").encode()


def write_files(out: Path, files: dict[str, bytes]) -> list[Path]:
    """Write ``files`` into directory ``out`` (created); returns the paths.

    Raises:
        MorficError: ``out`` exists and is not a directory, or cannot be written.
    """
    if out.exists() and not out.is_dir():
        raise MorficError(f"--out {out} is a file; give a directory (it is created if missing).")
    try:
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, data in files.items():
            path = safe_join(out, name)
            path.write_bytes(data)
            paths.append(path)
    except OSError as exc:
        raise MorficError(f"cannot write the export to {out}: {exc.strerror or exc}.") from exc
    return paths


def robot_model_problems(meta: dict[str, Any]) -> list[str]:
    """:func:`~morfic_cli.export.verify.model_mismatches` for every robot the metadata describes."""
    from morfic_cli.morphology.builder import build_model

    problems = []
    for name in meta["robots"]:
        try:
            spec = load_robot(name)
        except UnknownNameError:
            problems.append(f"robot '{name}' is not in this robot library")
            continue
        problems += model_mismatches(meta, name, build_model(spec, floor=False))
    return problems


def read_export(store: Store, source: str) -> tuple[dict[str, Any], bytes]:
    """The metadata and model bytes of an export in the store (id, ``exports/...`` ref) or on disk.

    ``source`` on disk: a directory written with ``--out`` (holding ``policy.json``) or the ``policy.json`` itself.

    Raises:
        MorficError: Not an export, or unreadable files.
    """
    path = Path(source)
    if path.exists():
        meta_path = path / METADATA_FILE if path.is_dir() else path
        try:
            meta = json.loads(meta_path.read_text())
            model = (meta_path.parent / meta["model_file"]).read_bytes()
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise MorficError(
                f"{source} is not an export written by `morfic export --out` (needs {METADATA_FILE} "
                f"and the model file it names): {exc}"
            ) from exc
        return meta, model
    manifest = store.read_manifest(source)
    if manifest.kind == "export" and METADATA_FILE not in manifest.files:
        raise MorficError(
            f"'{source}' is an rsl-rl checkpoint export; --check verifies ONNX and TorchScript "
            "exports (load it with rsl-rl's OnPolicyRunner.load, docs/deploy.md)."
        )
    if manifest.kind != "export":
        raise MorficError(
            f"'{source}' is a {manifest.kind} artifact; --check takes an export (an exports/... ref "
            "or id, see `morfic store ls --kind export`) or a directory written with --out."
        )
    meta = json.loads(store.read_file(manifest.id, METADATA_FILE))
    return meta, store.read_file(manifest.id, meta["model_file"])


def check_export(
    store: Store, source: str, *, samples: int = 256, seed: int = 0, tolerance: float = TOLERANCE
) -> CheckResult:
    """Re-verify an export against the checkpoint it was made from (``morfic export SOURCE --check``).

    Checks: the model file's sha256 against the metadata; the metadata against what this morfic writes for that
    checkpoint (all but the version fields); the robots' MuJoCo models; and the runtime against the torch actor
    on random inputs.

    Raises:
        MorficError: Not an export, or its checkpoint is not in ``store``.
    """
    meta, model = read_export(store, source)
    if meta.get("schema") != M.SCHEMA:
        raise MorficError(f"{source}: metadata schema {meta.get('schema')!r} is not {M.SCHEMA!r}.")
    problems = []
    if hashlib.sha256(model).hexdigest() != meta.get("model_sha256"):
        problems.append(f"{meta['model_file']} does not match the model_sha256 in the metadata (file changed)")
    try:
        trained = load_trained(store, meta["checkpoint"])
    except ArtifactNotFoundError as exc:
        raise MorficError(
            f"checkpoint {meta['checkpoint'][:12]} of this export is not in {store.root}; import its "
            "run (`morfic store import`) or point --store at the store it came from."
        ) from exc
    _, expected = plan_export(trained, meta["baked_robot"], len(meta["outputs"]) > 1)
    for key in sorted(set(expected) | set(meta)):
        if key in _VOLATILE_KEYS or key in ("format", "model_file", "onnx_opset"):
            continue
        if expected.get(key) != meta.get(key):
            problems.append(f"metadata '{key}' differs from what checkpoint {trained.checkpoint_id[:12]} gives")
    if meta.get("format") == "onnx":
        try:
            props = read_metadata(model)
        except Exception:  # onnx raises its own decode errors; the sha256 check above names the file
            props = None
        if props != M.onnx_props(meta):
            problems.append("the ONNX metadata_props disagree with policy.json")
    problems += robot_model_problems(meta)
    verification = verify_outputs(
        load_runner(meta["format"], model),
        runtime_name(meta["format"]),
        trained.actor,
        meta,
        samples=samples,
        seed=seed,
        tolerance=tolerance,
    )
    return CheckResult(source, meta, verification, problems)
