"""Training configuration: typed dataclasses, the three presets, and ``--set key=value`` overrides.

A preset is a factory function returning a :class:`TrainCfg`; ``--set`` edits it by dotted path
(``ppo.learning_rate=3e-4``, ``env.num_envs=256``, ``env.rewards.w_lin=2``) and fails on unknown keys
or values of the wrong type. The resolved config is stored in every checkpoint manifest
(:func:`train_cfg_to_dict`) and rebuilt from it on ``--resume`` (:func:`train_cfg_from_dict`).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import types
import typing
from dataclasses import dataclass, field
from typing import Any

from morfic_cli.config import EnvCfg
from morfic_cli.errors import MorficError, UnknownNameError
from morfic_cli.rl.variants import resolve_variant
from morfic_cli.validation import validate_train_cfg

PRESETS: tuple[str, ...] = ("smoke", "cpu", "paper")
HYPER_CONDITIONS: tuple[str, ...] = ("head", "layers")
"""Values of :attr:`ModelCfg.hyper_conditions`."""


@dataclass(frozen=True)
class PPOCfg:
    """rsl-rl PPO hyperparameters (paper Table "PPO hyperparameters") plus the adaptation loss."""

    learning_rate: float = 1.0e-3
    schedule: str = "adaptive"
    """"adaptive" (KL-driven, rsl-rl) or "fixed"."""
    desired_kl: float = 0.01
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    clip_param: float = 0.2
    gamma: float = 0.99
    lam: float = 0.95
    value_loss_coef: float = 1.0
    use_clipped_value_loss: bool = True
    entropy_coef: float = 0.01
    max_grad_norm: float = 1.0
    adaptation_loss_coef: float = 1.0
    """c_adapt of the adaptation regression (0 switches it off)."""
    adaptation_learning_rate: float | None = None
    """Adaptation optimiser learning rate; None = ``learning_rate``."""
    use_mixed_precision: bool = False
    """Forward passes of rollout and update under bf16 autocast, output layers float32 (rsl-rl's flag; the ``cpu``
    preset turns it on: 2.6x faster matrix products on CPUs with AVX512-BF16 or AMX, docs/benchmarks-history.md)."""


@dataclass(frozen=True)
class ModelCfg:
    """Network widths (paper Table "architecture"); None keeps the variant's own critic trunk."""

    actor_hidden_dims: tuple[int, ...] = (512, 256, 128)
    critic_hidden_dims: tuple[int, ...] | None = None
    """None: [512, 256, 128], or [1024, 512, 256] for ``film-scaled``."""
    init_std: float = 1.0
    """Initial action standard deviation of the Gaussian policy."""
    film_scale: float = 0.1
    """s of the residual FiLM update h (1 + s gamma) + s beta of ``film`` and ``film-scaled`` (paper Table
    "architecture": FiLM scale 0.1), so the two differ only in the trunk. 1.0 is the conditioning-variants
    table's other reading (plain FiLM, scale on the scaled variant only), and what ``film`` runs before this
    field used."""
    hyper_conditions: str = "head"
    """What ``hyper``'s hypernetwork generates: "head", eq. (hyper) V = A_m h_t + c_m with (A_m, c_m) = H_eta(z_m)
    (a rank-16, 0.1-scaled delta on a learned base head; the trunk is unconditioned), or "layers", a low-rank
    residual adapter on every hidden layer (the conditioning-variants table's "h <- W h + B_z A_z h"; runs before
    this field)."""
    shared_morphology_encoder: bool = True
    """One morphology encoder f_psi whose z_m feeds both the actor and the critic (paper: "the same z is provided
    to both"), trained by the sum of PPO's losses. False: each network has its own encoder (runs before this
    field). Only variants where both networks see z_m share it."""


@dataclass(frozen=True)
class TrainCfg:
    """One training run (docs/training.md)."""

    variant: str = "film"
    """A stock name of :data:`~morfic_cli.rl.variants.VARIANTS`, or a user critic class as ``module:Class``."""
    preset: str = "cpu"
    seed: int = 0
    max_iterations: int = 1000
    """PPO iterations; each collects ``env.num_envs * num_steps_per_env`` transitions."""
    num_steps_per_env: int = 24
    save_interval: int = 50
    """A checkpoint every this many iterations, and one at the end."""
    init_at_random_ep_len: bool = True
    """Start a fresh run with random episode lengths so time-outs are spread (legged_gym)."""
    env: EnvCfg = field(default_factory=EnvCfg)
    ppo: PPOCfg = field(default_factory=PPOCfg)
    model: ModelCfg = field(default_factory=ModelCfg)


def smoke_preset(variant: str = "film", seed: int = 0) -> TrainCfg:
    """Tiny: 8 envs x 8 steps x 2 iterations, paper-sized networks. Seconds; for tests and CI.

    A checkpoint every 10 iterations (and at the end): one costs more than a smoke iteration (a 6.7 MB store write).
    """
    return TrainCfg(
        variant=variant,
        preset="smoke",
        seed=seed,
        max_iterations=2,
        num_steps_per_env=8,
        save_interval=10,
        env=EnvCfg(num_envs=8),
        ppo=PPOCfg(num_learning_epochs=1, num_mini_batches=2),
    )


def cpu_preset(variant: str = "film", seed: int = 0) -> TrainCfg:
    """Sized for a 2-core machine: 512 envs x 24 steps x 1000 iterations (12.3 M transitions).

    Two learning epochs instead of the paper's five: on 2 cores the update of the 768-input actor dominates the
    iteration (5 epochs: 5.5 s of 7.5 s at 512 envs), so fewer epochs buy more iterations per hour. Action
    latency is sampled in 0..2 policy steps instead of the paper's 0..6: with 3 % of the paper's transitions,
    up to 120 ms of latency is a third of a 3 Hz gait cycle, a hard start for a small budget (docs/training.md);
    the evaluation protocol has no latency either way. Everything else (morphology support, pushes, friction) is
    the paper's. The networks run in bf16 mixed precision (``ppo.use_mixed_precision``; float32 weights and output
    layers), which halves the update on CPUs with bf16 instructions (docs/benchmarks-history.md); on a CPU without them
    ``--set ppo.use_mixed_precision=false`` is faster.
    """
    env = EnvCfg(num_envs=512)
    env = dataclasses.replace(env, rand=dataclasses.replace(env.rand, max_latency_steps=2))
    return TrainCfg(
        variant=variant,
        preset="cpu",
        seed=seed,
        max_iterations=1000,
        num_steps_per_env=24,
        save_interval=25,
        env=env,
        ppo=PPOCfg(num_learning_epochs=2, num_mini_batches=4, use_mixed_precision=True),
    )


def paper_preset(variant: str = "film", seed: int = 0) -> TrainCfg:
    """The paper's budget: 4096 envs x 24 steps x 4000 iterations (393 M transitions), paper PPO."""
    return TrainCfg(
        variant=variant,
        preset="paper",
        seed=seed,
        max_iterations=4000,
        num_steps_per_env=24,
        save_interval=100,
        env=EnvCfg(num_envs=4096),
        ppo=PPOCfg(),
    )


_PRESET_FNS = {"smoke": smoke_preset, "cpu": cpu_preset, "paper": paper_preset}

SMOKE_GEOMETRY_POOL = 8
"""Robots the smoke preset generates for a variant with procedural geometry (GenLoco's 256 elsewhere): its 8 envs
draw few of them, and compiling the pool is nearly all of a smoke env's construction."""


def preset_cfg(preset: str, variant: str = "film", seed: int = 0) -> TrainCfg:
    """The config of a named preset for ``variant``, with the variant's env defaults (:func:`with_env_overrides`).

    Raises:
        UnknownNameError: Unknown preset or variant.
        MorficError: A user variant that cannot be imported.
    """
    if preset not in _PRESET_FNS:
        raise UnknownNameError("preset", preset, PRESETS)
    overrides = resolve_variant(variant).env_overrides
    cfg = with_env_overrides(_PRESET_FNS[preset](variant, seed), overrides)
    if preset == "smoke" and cfg.env.rand.geometry.enabled:
        cfg = with_env_overrides(cfg, {"rand.geometry.pool_size": SMOKE_GEOMETRY_POOL})
    return cfg


def with_env_overrides(cfg: TrainCfg, overrides: dict[str, Any]) -> TrainCfg:
    """``cfg`` with a variant's env defaults set (``cfg`` itself when there are none).

    The keys are dotted paths under ``env`` (:attr:`~morfic_cli.rl.variants.Variant.env_overrides`).

    Raises:
        MorficError: A key that is not an env config field (a bug in the variant's entry) or a wrong type.
    """
    if not overrides:
        return cfg
    doc = train_cfg_to_dict(cfg)
    for key, value in overrides.items():
        node = doc["env"]
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.get(part) if isinstance(node, dict) else None
            if not isinstance(node, dict):
                raise MorficError(f"variant env override 'env.{key}' names no env config section.")
        if leaf not in node:
            raise MorficError(f"variant env override 'env.{key}' is not an env config key.")
        node[leaf] = value
    return train_cfg_from_dict(doc)


# ---------------------------------------------------------------------------- dict round trip
def train_cfg_to_dict(cfg: TrainCfg) -> dict[str, Any]:
    """The resolved config as a JSON-serialisable dict (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


#: Values of fields a run recorded before the field existed: what that morfic did (fields not listed take their
#: default). A callable gets the recorded config, e.g. to depend on the variant. These are never the defaults of a
#: new run; they keep an old checkpoint evaluating, diagnosing and resuming exactly as it was trained.
LEGACY_VALUES: dict[str, Any] = {
    "model.film_scale": lambda doc: 0.1 if doc.get("variant") == "film-scaled" else 1.0,
    "model.hyper_conditions": "layers",
    "model.shared_morphology_encoder": False,
    "env.obs.history_includes_current": True,
    "env.rand.rerandomize_interval_s": 0.0,
}


def fill_legacy(doc: dict[str, Any]) -> dict[str, Any]:
    """A recorded config with every field it lacks from :data:`LEGACY_VALUES` filled in (a new dict).

    Only sections the record has are filled; a complete record comes back unchanged.
    """
    out = json.loads(json.dumps(doc))
    for key, value in LEGACY_VALUES.items():
        *parents, leaf = key.split(".")
        node = out
        for part in parents:
            node = node.get(part) if isinstance(node, dict) else None
            if node is None:
                break
        if isinstance(node, dict) and leaf not in node:
            node[leaf] = value(doc) if callable(value) else value
    return out


def train_cfg_from_dict(doc: dict[str, Any]) -> TrainCfg:
    """Rebuild a :class:`TrainCfg` from :func:`train_cfg_to_dict`'s output (e.g. a checkpoint manifest).

    Fields the record lacks (it was written by an older morfic) get :data:`LEGACY_VALUES`, not today's defaults.

    Raises:
        MorficError: Unknown keys or values of the wrong type.
    """
    out = _build(TrainCfg, fill_legacy(doc), "")
    if out.model.hyper_conditions not in HYPER_CONDITIONS:
        raise MorficError(
            f"model.hyper_conditions must be one of {', '.join(HYPER_CONDITIONS)}; got '{out.model.hyper_conditions}'."
        )
    return out


def _build(cls: type, doc: dict[str, Any], prefix: str) -> Any:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(doc) - names)
    if unknown:
        raise MorficError(f"unknown config key '{prefix}{unknown[0]}'.")
    kwargs = {}
    for name, value in doc.items():
        kwargs[name] = _coerce(hints[name], value, f"{prefix}{name}")
    return cls(**kwargs)


def _coerce(tp: Any, value: Any, key: str) -> Any:
    """``value`` (parsed JSON) as type ``tp``; raises MorficError naming ``key`` when it does not fit."""
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise MorficError(f"config key '{key}' is a section; set one of its fields, e.g. '{key}.<field>=...'.")
        return _build(tp, value, f"{key}.")
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(arg, value, key)
            except MorficError as exc:
                errors.append(str(exc))
        raise MorficError(errors[0] if errors else f"config key '{key}' cannot be {value!r}.")
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise MorficError(f"config key '{key}' takes a list, e.g. {key}=[1,2]; got {value!r}.")
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v, key) for v in value)
        if len(args) != len(value):
            raise MorficError(f"config key '{key}' takes {len(args)} values; got {len(value)}.")
        return tuple(_coerce(a, v, key) for a, v in zip(args, value, strict=True))
    if tp is bool:
        if not isinstance(value, bool):
            raise MorficError(f"config key '{key}' takes true or false; got {value!r}.")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise MorficError(f"config key '{key}' takes an integer; got {value!r}.")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise MorficError(f"config key '{key}' takes a number; got {value!r}.")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise MorficError(f"config key '{key}' takes a string; got {value!r}.")
        return value
    return value


# ---------------------------------------------------------------------------- --set overrides
def parse_override(item: str) -> tuple[str, Any]:
    """Split ``key=value``; the value is JSON when it parses as JSON, else a plain string.

    Raises:
        MorficError: No ``=``, or an empty key.
    """
    key, sep, raw = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise MorficError(f"--set takes key=value (e.g. --set ppo.learning_rate=3e-4), got '{item}'.")
    raw = raw.strip()
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = {"none": None, "null": None, "true": True, "false": False}.get(raw.lower(), raw)
    return key, value


def valid_keys(cfg: TrainCfg) -> list[str]:
    """Every dotted key ``--set`` accepts."""
    out: list[str] = []

    def walk(obj: Any, prefix: str) -> None:
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if dataclasses.is_dataclass(value):
                walk(value, f"{prefix}{f.name}.")
            else:
                out.append(f"{prefix}{f.name}")

    walk(cfg, "")
    return out


def apply_overrides(cfg: TrainCfg, items: list[str]) -> TrainCfg:
    """Apply ``--set key=value`` items in order.

    Raises:
        MorficError: An unknown key (with the closest valid ones) or a value of the wrong type.
    """
    doc = train_cfg_to_dict(cfg)
    keys = valid_keys(cfg)
    for item in items:
        key, value = parse_override(item)
        if key not in keys:
            close = difflib.get_close_matches(key, keys, n=3, cutoff=0.5)
            hint = f" Did you mean: {', '.join(close)}?" if close else " See docs/training.md for the keys."
            raise MorficError(f"unknown config key '{key}' in --set.{hint}")
        node = doc
        *parents, leaf = key.split(".")
        for part in parents:
            node = node[part]
        node[leaf] = value
    out = train_cfg_from_dict(doc)
    resolve_variant(out.variant)
    validate_train_cfg(out)  # ranges, finiteness, known schedules, env count vs memory (morfic_cli/validation.py)
    return out
