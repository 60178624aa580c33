"""The variant registry: every fact about an actor-critic variant, the paper's seven and a user's own.

A :class:`Variant` holds a variant's ``--variant`` name, its label in the paper's tables, the paper tables it
appears in, the rsl-rl ``class_name`` of its actor and critic, which of them see the morphology latent z_m, and
the critic's defaults (conditioning, scale s, trunk widths). The CLI help, ``train``, ``reproduce``,
``compare-baselines``, the report, its figures and :mod:`morfic_cli.report.paper` read :data:`STOCK` and
:func:`resolve_variant`; nothing else lists the variants.

A user's variant is a critic class in the user's own module, named by import path
(``morfic train --variant my_lab.critics:GatedCritic``) or by an entry point of the group
``morfic.variants``. The protocol (docs/extending.md):

- the class is an rsl-rl model built as ``cls(obs, obs_groups, "critic", 1, **critic_cfg)``; it receives the
  observation groups ``critic`` (N, 16, 48), ``privileged`` (N, 18) and ``morphology`` (N, 11), and its
  ``forward(obs)`` returns the value V, shape (N, 1);
- it provides ``encode_privileged(obs)`` -> z_priv (N, 16), the target of the actor's adaptation module, and
  ``privileged_latent_dim``. Subclassing :class:`~morfic_cli.rl.models.MorficCritic` gives both and z_m =
  ``encode_morphology(obs)`` (N, 64); overriding ``make_modulator`` alone conditions each hidden trunk layer;
- optional class attributes: ``label`` (the name in tables; default the class name) and ``critic_defaults``
  (entries of the critic config, e.g. ``{"conditioning": "gated"}``).

The actor of a user variant is the stock actor with z_m (as ``film``). The run records the import path as its
variant and the resolved model config in the checkpoint manifest; ``eval``, ``diagnose``, ``export``,
``compare-baselines`` and ``report`` reload the class by that path. This module imports neither torch nor the
user's code until a user variant is resolved.

Consent (docs/extending.md, "Which code morfic imports"): a stored run, imported from anyone's bundle, names its
variant, so a user variant is imported only when the user consented to that exact name: named on this command
line (``--variant``, ``--variants``, ``--trust-variant``: :func:`trust_variants`, scoped to one command by
:func:`consent_scope`) or listed in the allow-list in the user's config folder (:func:`allow_list_path`, managed
by ``morfic trust``), which counts only when signed with the user's key (:func:`read_allow_list`), so no file a
bundle brings can act as it. :func:`resolve_variant` is the one place that imports, and it
checks both (:func:`require_trusted`) and the name's form (:func:`check_variant_name`) before it imports
anything; stock names need neither.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import hmac
import importlib
import importlib.metadata
import inspect
import os
import re
import secrets
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from morfic_cli import variant_names
from morfic_cli.errors import MorficError, UnknownNameError, UntrustedVariantError
from morfic_cli.variant_names import is_import_path

ACTOR_CLASS = "morfic_cli.rl.models:MorficActor"
CRITIC_CLASS = "morfic_cli.rl.models:MorficCritic"
ENTRY_POINT_GROUP = "morfic.variants"
"""Entry-point group under which an installed package may name its variants."""

MULTIPLICATIVE_CONDITIONING = ("film", "hyper", "adaln")
"""Critic conditionings that scale the critic's features by z_m (paper Sec. "Method"); concat and none are additive."""

FIXED_ROLLOUT_ACTOR = "film"
"""The variant whose (seed-0) actor the fixed-rollout analysis freezes while every critic is scored on its rollouts
(paper Table "causal advantage": MorFiC-F's actor)."""

PAPER_TRUNK = (512, 256, 128)
"""Hidden widths of the actor and of every critic trunk but film-scaled's (paper Table "architecture")."""


@dataclass(frozen=True)
class Variant:
    """One actor-critic variant.

    Attributes:
        name: The ``--variant`` name (``film``), or the import path of a user variant (``pkg.mod:Class``).
        label: Its name in the paper's tables and our figures (``MorFiC-F``).
        tables: The paper's transfer tables it is a column of: ``main`` (zero-shot transfer), ``ablation``,
            ``external`` (the external baselines, Table "External baselines vs. MorFiC"); ``actuation`` (issue 58's
            variants and film-act's ablations) is none of the paper's; each table's evaluation modes:
            :data:`TABLE_MODES`.
        actor_class: rsl-rl ``class_name`` of the actor.
        critic_class: rsl-rl ``class_name`` of the critic.
        actor_morphology: Whether the actor sees z_m (False only for ``ppo``).
        critic_morphology: Whether the critic sees z_m.
        critic_defaults: Critic config entries of this variant (conditioning, conditioning_scale, hidden_dims).
        stock: One of the paper's variants (False: a user's class).
        actor_defaults: Actor config entries of this variant, over the stock actor's.
        own_models: ``actor_defaults`` / ``critic_defaults`` are the complete model configs, not entries over
            morfic's MLP configs (the external baselines' token models, :mod:`morfic_cli.rl.external`).
        obs_groups: The rsl-rl ``obs_groups`` of this variant; None: the MLP variants' (history, privileged, m).
        env_overrides: Env config entries this variant trains with, by dotted key under ``env`` (``--set env.KEY``
            without the ``env.``), applied to every preset before ``--set`` (:func:`morfic_cli.rl.config.preset_cfg`);
            ``genloco``'s turns procedural geometry on.
    """

    name: str
    label: str
    tables: tuple[str, ...] = ()
    actor_class: str = ACTOR_CLASS
    critic_class: str = CRITIC_CLASS
    actor_morphology: bool = True
    critic_morphology: bool = True
    critic_defaults: dict[str, Any] = field(default_factory=dict)
    stock: bool = True
    actor_defaults: dict[str, Any] = field(default_factory=dict)
    own_models: bool = False
    obs_groups: dict[str, list[str]] | None = None
    env_overrides: dict[str, Any] = field(default_factory=dict)

    @property
    def multiplicative(self) -> bool:
        """Whether the critic is conditioned multiplicatively on z_m (FiLM, AdaLN, hypernetwork: the MorFiC family).

        False for the additive baselines (concat, or no critic conditioning).
        """
        return self.critic_defaults.get("conditioning") in MULTIPLICATIVE_CONDITIONING

    def model_cfgs(self) -> tuple[dict, dict, dict[str, list[str]]]:
        """The rsl-rl ``actor``, ``critic`` and ``obs_groups`` config entries (paper sizes); fresh dicts per call."""
        if self.own_models:
            return (
                copy.deepcopy(self.actor_defaults),
                copy.deepcopy(self.critic_defaults),
                copy.deepcopy(self.obs_groups or {}),
            )
        actor_cfg = {
            "class_name": self.actor_class,
            "hidden_dims": list(PAPER_TRUNK),
            "activation": "elu",
            "obs_normalization": False,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": 1.0, "std_type": "scalar"},
            "morphology_group": "morphology" if self.actor_morphology else None,
            "morphology_hidden_dims": [128],
            "morphology_latent_dim": 64,
            "adaptation_hidden_dims": [256, 128],
            "privileged_latent_dim": 16,
            "latent_dropout": 0.2,
        }
        critic_cfg = {
            "class_name": self.critic_class,
            "hidden_dims": list(PAPER_TRUNK),
            "activation": "elu",
            "obs_normalization": False,
            "privileged_group": "privileged",
            "privileged_hidden_dims": [64],
            "privileged_latent_dim": 16,
            "morphology_group": "morphology" if self.critic_morphology else None,
            "morphology_hidden_dims": [128],
            "morphology_latent_dim": 64,
            "conditioning": "none",
            "conditioning_scale": 1.0,
            "hyper_rank": 16,
            "generator_hidden_dim": 128,
        }
        actor_cfg.update(copy.deepcopy(self.actor_defaults))
        critic_cfg.update(copy.deepcopy(self.critic_defaults))
        obs_groups = (
            copy.deepcopy(self.obs_groups)
            if self.obs_groups is not None
            else {
                "actor": ["history", "morphology"] if self.actor_morphology else ["history"],
                "critic": ["critic", "privileged", "morphology"]
                if self.critic_morphology
                else ["critic", "privileged"],
            }
        )
        return actor_cfg, critic_cfg, obs_groups


def _stock(
    name: str,
    label: str,
    tables: tuple[str, ...],
    conditioning: str,
    scale: float = 1.0,
    trunk: tuple[int, ...] = PAPER_TRUNK,
    actor_morphology: bool = True,
) -> Variant:
    return Variant(
        name,
        label,
        tables,
        actor_morphology=actor_morphology,
        critic_morphology=conditioning != "none",
        critic_defaults={"conditioning": conditioning, "conditioning_scale": scale, "hidden_dims": list(trunk)},
    )


_GAUSSIAN = {"class_name": "GaussianDistribution", "init_std": 1.0, "std_type": "scalar"}
_BOT = {"d_model": 64, "nhead": 2, "num_layers": 8, "dim_feedforward": 128}
"""BodyTransformer's "BoT-Hard" encoder (Sferrazza et al. 2024): 8 layers, d = 64, 2 heads, feed-forward 128."""


def _external(
    name: str,
    label: str,
    actor: dict[str, Any],
    critic: dict[str, Any],
    obs_groups: dict[str, list[str]],
    env_overrides: dict[str, Any] | None = None,
) -> Variant:
    """An external baseline: its own token models and observation groups (docs/training.md, "External baselines")."""
    return Variant(
        name,
        label,
        ("external",),
        actor_class=actor["class_name"],
        critic_class=critic["class_name"],
        actor_morphology=False,
        critic_morphology=False,
        critic_defaults=critic,
        actor_defaults=actor,
        own_models=True,
        obs_groups=obs_groups,
        env_overrides=env_overrides or {},
    )


_URMA_GROUPS = ["joint_description", "foot_description", "foot_state"]


ACTUATION_ENV: dict[str, Any] = {
    "rand.geometry.enabled": True,
    "rand.geometry.limits_from_support": True,
    "rand.actuation.enabled": True,
    "rand.actuation.mass_scale": [0.8, 4.0],
    "rand.actuation.kp_factor": [0.8, 3.2],
    "rand.actuation.kd_factor": [0.6, 5.0],
    "rand.actuation.torque_factor": [0.8, 2.0],
    "rand.actuation.curriculum": True,
    "obs.extended_morphology": True,
}
"""The env of ``film-act`` and ``ppo-act`` (docs/training.md, "Actuation variants"): procedural geometry with the
support's joint limits, total masses x 0.8-4 (log-uniform, under the morphology curriculum) with Kp, Kd and torque
limits following the mass and jittered to cover robots/*.toml's own gains, and z_m of the extended descriptor."""

ACTUATION_ABLATIONS: dict[str, tuple[str, dict[str, Any]]] = {
    "film-act-wide": ("MorFiC-F(act)-wide", {"rand.actuation.curriculum": False}),
    "film-act-11d": ("MorFiC-F(act)-11D", {"obs.extended_morphology": False}),
    "film-act-template": ("MorFiC-F(act)-template", {"rand.geometry.enabled": False}),
    "film-act-light": ("MorFiC-F(act)-light", {"rand.actuation.mass_scale": [0.8, 1.0]}),
}
"""Issue 58's ablations of ``film-act``: name -> (label, the one :data:`ACTUATION_ENV` entry switched off), in the
order of docs/training.md's table: the fixed wide support (no morphology curriculum), the paper's 11-D z_m (no
actuation in it), the Go2 template's geometry (no procedural geometry; ``limits_from_support`` stays on and acts on
nothing: without geometry train mode draws every descriptor entry, the joint limits too, from the paper's support)
and no heavier masses (s_m in [0.8, 1.0]: gains and torque limits still follow the mass and keep their jitter)."""


def _film_act(name: str, label: str, off: Mapping[str, Any]) -> Variant:
    """A variant of film's networks on :data:`ACTUATION_ENV`, ``off``'s entries replaced (film-act, its ablations)."""
    return Variant(
        name,
        label,
        ("actuation",),
        critic_defaults={"conditioning": "film", "conditioning_scale": 0.1, "hidden_dims": list(PAPER_TRUNK)},
        env_overrides=copy.deepcopy({**ACTUATION_ENV, **off}),
    )


STOCK: dict[str, Variant] = {
    v.name: v
    for v in (
        _stock("ppo", "PPO", ("main",), "none", actor_morphology=False),
        _stock("actor-only", "Actor-only", ("main",), "none"),
        _stock("concat", "Actor+Critic", ("main",), "concat"),
        _stock("film", "MorFiC-F", ("main", "ablation"), "film", 0.1),
        _stock("film-scaled", "MorFiC-F(Scaled)", ("ablation",), "film", 0.1, (1024, 512, 256)),
        _stock("hyper", "MorFiC-H", ("ablation",), "hyper", 0.1),
        _stock("adaln", "MorFiC-A", ("ablation",), "adaln"),
        _external(
            "bot",
            "BodyTransformer",
            {"class_name": "morfic_cli.rl.bot:BotActor", **_BOT, "distribution_cfg": dict(_GAUSSIAN)},
            {"class_name": "morfic_cli.rl.bot:BotCritic", **_BOT, "privileged_group": "privileged"},
            {"actor": ["history"], "critic": ["critic", "privileged"]},
        ),
        _external(
            "urma",
            "URMA",
            {
                "class_name": "morfic_cli.rl.urma:UrmaActor",
                "state_group": "history",
                "distribution_cfg": dict(_GAUSSIAN),
            },
            {"class_name": "morfic_cli.rl.urma:UrmaCritic", "state_group": "critic", "privileged_group": "privileged"},
            {"actor": ["history", *_URMA_GROUPS], "critic": ["critic", "privileged", *_URMA_GROUPS]},
            {"obs.body_tokens": True},
        ),
        # GenLoco (Feng et al. 2022): ppo's networks, trained on procedurally generated robots (docs/training.md)
        Variant(
            "genloco",
            "GenLoco",
            ("external",),
            actor_morphology=False,
            critic_morphology=False,
            critic_defaults={"conditioning": "none", "conditioning_scale": 1.0, "hidden_dims": list(PAPER_TRUNK)},
            env_overrides={"rand.geometry.enabled": True},
        ),
        # issue 58: film and ppo on generated, heavier bodies whose gains follow their mass (ACTUATION_ENV)
        _film_act("film-act", "MorFiC-F(act)", {}),
        Variant(
            "ppo-act",
            "PPO(act)",
            ("actuation",),
            actor_morphology=False,
            critic_morphology=False,
            critic_defaults={"conditioning": "none", "conditioning_scale": 1.0, "hidden_dims": list(PAPER_TRUNK)},
            env_overrides=copy.deepcopy(ACTUATION_ENV),
        ),
        *(_film_act(name, label, off) for name, (label, off) in ACTUATION_ABLATIONS.items()),
    )
}
"""The paper's variants, in the order of its tables (sizes: paper Tables "architecture", "conditioning variants"), then
the external baselines re-implemented in morfic's pipeline (table ``external``: paper Table "External baselines vs.
MorFiC"), then the actuation variants of issue 58 and film-act's ablations (table ``actuation``, in none of the
paper's)."""

VARIANTS: tuple[str, ...] = tuple(STOCK)
"""The stock ``--variant`` names, in the paper's order."""

REPRODUCE_VARIANTS: tuple[str, ...] = tuple(v.name for v in STOCK.values() if "actuation" not in v.tables)
"""What ``reproduce --variants all`` trains: every stock variant but issue 58's (trained by name, docs/training.md)."""


def table_variants(table: str) -> tuple[str, ...]:
    """The stock variants that are columns of the paper's transfer table ``table`` (``main``, ``ablation``)."""
    return tuple(v.name for v in STOCK.values() if table in v.tables)


EVAL_MODES: tuple[str, ...] = ("descriptor", "full", "actuation-matched")
"""The evaluation modes (``morfic eval --mode``, docs/eval.md), in the order of the tables."""

TABLE_MODES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "main": (("descriptor", "full"), ("descriptor",)),
    "ablation": (("descriptor", "full"), ("descriptor",)),
    "external": (("descriptor", "full"), ("descriptor", "full")),
    "actuation": (EVAL_MODES, EVAL_MODES),
}
"""The modes each table's runs are evaluated in: (at the paper's commands, 2.0 and 2.5 m/s; at the trained regime's
1.0 m/s). The paper's tables: both modes, and descriptor mode at 1.0 m/s (the configs, and so the content addresses,
of the shipped runs' evals); the external baselines: full mode at 1.0 m/s too (issue 57); issue 58's: all three."""


def eval_modes(variant: str, *, trained_regime: bool = False) -> tuple[str, ...]:
    """The modes a run of ``variant`` is evaluated in, at the paper's commands or (``trained_regime``) at 1.0 m/s.

    The union of its tables' :data:`TABLE_MODES`, in :data:`EVAL_MODES` order; a user variant (in no table) is
    evaluated as the paper's. The one place both ``reproduce`` (:meth:`morfic_cli.pipeline.Pipeline.eval_cfg`) and
    scripts/experiment_tables.py (the 1.0 m/s eval) read. Imports nothing of a user variant.
    """
    tables = STOCK[variant].tables if variant in STOCK else ()
    wanted = {m for t in tables or ("main",) for m in TABLE_MODES[t][trained_regime]}
    return tuple(m for m in EVAL_MODES if m in wanted)


def variant_order(name: str) -> int:
    """Sort key: the paper's order, then every other (user) variant."""
    return VARIANTS.index(name) if name in STOCK else len(VARIANTS)


def variant_label(name: str) -> str:
    """The table label of a variant: the paper's for stock ones, else the name as recorded."""
    return STOCK[name].label if name in STOCK else name


def help_text() -> str:
    """The ``--variant`` choices for the CLI help."""
    return f"{', '.join(VARIANTS)}, or your own critic class by import path (module:Class; docs/extending.md)"


def check_variant_name(name: object) -> str:
    """``name`` when well-formed, else MorficError (:func:`morfic_cli.variant_names.check_variant_name`).

    Raises:
        MorficError: Not a string, too long, or not of either form.
    """
    return variant_names.check_variant_name(name, VARIANTS)


def stored_variants(config: Mapping[str, Any], meta: Mapping[str, Any]) -> list[str]:
    """The variant names a stored manifest records, checked for form (:func:`morfic_cli.variant_names.stored_variants`).

    Raises:
        MorficError: One of them is not a well-formed variant name, or ``variants`` is not a list.
    """
    return variant_names.stored_variants(config, meta, VARIANTS)


# ---------------------------------------------------------------------------- consent
_named: set[str] = set()
"""User variants named on this command line (``--variant``, ``--variants``, ``--trust-variant``)."""


def trust_variants(names: Iterable[str]) -> None:
    """Consent to importing these user variants in this process (until :func:`consent_scope` ends).

    The CLI calls it with the names given on the command line; a Python caller that builds a user variant's models
    itself calls it with the names it means. Stock names need no consent and are ignored.

    Raises:
        MorficError: A name that is not well-formed (:func:`check_variant_name`).
    """
    for name in names:
        if check_variant_name(name) not in STOCK:
            _named.add(name)


@contextlib.contextmanager
def consent_scope(names: Iterable[str] = ()) -> Iterator[None]:
    """While open, this process consents to exactly ``names`` (plus the allow-list); the consent before is restored.

    One CLI command runs in one scope (``morfic_cli.cli.main``), so consent given to one command never carries over
    to the next in the same process; a cluster worker runs its job in a scope of the driver's consent.
    """
    saved = set(_named)
    _named.clear()
    try:
        trust_variants(names)
        yield
    finally:
        _named.clear()
        _named.update(saved)


def allow_list_path() -> Path:
    """The allow-list of trusted user variants: ``$XDG_CONFIG_HOME/morfic/trusted-variants``.

    ``~/.config/morfic/trusted-variants`` when ``XDG_CONFIG_HOME`` is unset or not an absolute path. It lives in
    the user's config folder, never in a store, and morfic reads only the names it signed (:func:`allow_list`).
    """
    base = os.environ.get("XDG_CONFIG_HOME", "")
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".config"
    return root / "morfic" / "trusted-variants"


def trust_key_path() -> Path:
    """The per-user key that signs the allow-list: ``.trust-key`` beside it (64 hex digits, mode 0600).

    Its name starts with ``.``, and no file a bundle carries may have such a part (``plain_name_problem`` in
    :mod:`morfic_cli.store.manifest`), so neither ``store get`` (whatever its ``--out``) nor any other write-out of a
    stored file can create or replace it. ``morfic trust`` creates it once.
    """
    return allow_list_path().with_name(".trust-key")


SIGNATURE = "# signature: hmac-sha256 "
"""The allow-list line that holds the HMAC-SHA256, under :func:`trust_key_path`'s key, of the names below it."""

_KEY = re.compile(r"[0-9a-f]{64}")


def _trust_key(create: bool = False) -> bytes | None:
    """The signing key; None when there is none (or it is not 64 hex digits) and ``create`` is not set."""
    path = trust_key_path()
    try:
        text = path.read_text(encoding="ascii", errors="replace").strip()
    except FileNotFoundError:
        if not create:
            return None
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:  # another `morfic trust` made it meanwhile
            return _trust_key()
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(secrets.token_hex(32) + "\n")
        return _trust_key()
    except OSError as exc:
        raise MorficError(
            f"cannot read the key of the allow-list {path} ({exc.strerror}); fix its permissions, or "
            "pass --trust-variant to this command."
        ) from exc
    if _KEY.fullmatch(text):
        return text.encode()
    if create:
        raise MorficError(
            f"the key of the allow-list {path} is not one `morfic trust` wrote (64 hex digits); remove "
            "it and run `morfic trust` again for each variant you trust."
        )
    return None


def _signature(key: bytes, names: list[str]) -> str:
    return hmac.new(
        key, "".join(f"{n}\n" for n in ["morfic trusted-variants 1", *names]).encode(), hashlib.sha256
    ).hexdigest()


def _allow_list_lines() -> list[str]:
    try:
        return allow_list_path().read_text(encoding="utf-8", errors="replace").splitlines()
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise MorficError(
            f"cannot read the allow-list of trusted variants {allow_list_path()} ({exc.strerror}); "
            "fix its permissions, or pass --trust-variant to this command."
        ) from exc


def read_allow_list() -> tuple[list[str], list[str]]:
    """``(trusted, ignored)``: the allow-list's names its signature vouches for, and those it ignores.

    One name a line; blank lines and other ``#`` lines skipped. The names are ignored, all of them, when the signature
    is missing or does not match.

    Only ``morfic trust`` (and ``train --variant``) write the signature, with the user's key
    (:func:`trust_key_path`), so a file put there by anything else (a bundle's file fetched with ``store get``, an
    edit by hand) trusts nothing.
    """
    lines = [line.strip() for line in _allow_list_lines()]
    names = [n for n in dict.fromkeys(lines) if n and not n.startswith("#")]
    signed = [line[len(SIGNATURE) :] for line in lines if line.startswith(SIGNATURE)]
    key = _trust_key() if names else None
    if key is not None and len(signed) == 1 and hmac.compare_digest(signed[0], _signature(key, names)):
        return names, []
    return [], names


def allow_list() -> list[str]:
    """The user variants on the allow-list that ``morfic trust`` signed (:func:`read_allow_list`)."""
    return read_allow_list()[0]


def _write_allow_list(names: list[str]) -> None:
    path = allow_list_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    key = _trust_key(create=True)
    assert key is not None  # created, or an error
    lines = [
        "# User variants morfic may import when a stored run names them. Written by `morfic trust` "
        "(docs/extending.md): a line added by hand voids the signature, and with it the list.",
        SIGNATURE + _signature(key, names),
        *names,
    ]
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".trusted-variants-")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write("".join(f"{line}\n" for line in lines))
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def add_to_allow_list(names: Iterable[str]) -> list[str]:
    """Put user variants on the allow-list; returns those that were not on it (stock names are never added).

    The list is written again, signed (:func:`read_allow_list`); names it listed without a valid signature are
    dropped.

    Raises:
        MorficError: A name that is not well-formed.
        OSError: The config folder cannot be written.
    """
    new = [n for n in dict.fromkeys(check_variant_name(n) for n in names) if n not in STOCK]
    trusted, ignored = read_allow_list()
    new = [n for n in new if n not in trusted]
    if new or (ignored and trusted):
        _write_allow_list(trusted + new)
    return new


def remove_from_allow_list(names: Iterable[str]) -> list[str]:
    """Take names off the allow-list; returns those that were on it (signed).

    Raises:
        OSError: The config folder cannot be written.
    """
    drop = set(names)
    trusted = allow_list()
    removed = [n for n in trusted if n in drop]
    if removed:
        _write_allow_list([n for n in trusted if n not in drop])
    return removed


def _well_formed(name: str) -> bool:
    try:
        check_variant_name(name)
    except MorficError:
        return False
    return True


def trusted_variants() -> list[str]:
    """Every user variant this process may import now: named on this command line, or on the allow-list.

    A line of the allow-list that is no well-formed name (edited by hand) is left out: it can never match one.
    """
    return sorted(_named | {n for n in allow_list() if _well_formed(n)})


def is_trusted(name: str) -> bool:
    """Whether ``name`` may be imported now: a stock name, named on this command line, or on the allow-list."""
    return name in STOCK or name in _named or name in allow_list()


def require_trusted(name: str, *, source: str | None = None) -> None:
    """Raise :class:`UntrustedVariantError` unless ``name`` may be imported (:func:`is_trusted`); imports nothing.

    ``source`` names the stored run that asks for it (``runs/NAME`` or an id), for the message.
    """
    if is_trusted(name):
        return
    how = (
        f"If you trust that code, pass --trust-variant {name} to this command, or trust it for every command "
        f"with `morfic trust {name}` (the allow-list {allow_list_path()})."
    )
    if name in read_allow_list()[1]:
        how += (
            " The allow-list names it, but morfic ignores that list: `morfic trust` did not sign it (a file from "
            "elsewhere, or edited by hand); `morfic trust --list` says more."
        )
    if source is not None:
        raise UntrustedVariantError(
            f"run {source} needs the user variant {name}; morfic will not import code named "
            f"by a stored run without --trust-variant {name}. {how}"
        )
    raise UntrustedVariantError(
        f"the user variant {name} was neither named on this command line nor trusted; morfic "
        f"imports a user's code only with consent. {how}"
    )


def resolve_variant(name: str, *, source: str | None = None) -> Variant:
    """The :class:`Variant` of a variant name: a stock name, an entry point, or ``module:Class``.

    A user variant (entry point or import path) is imported only when it is well-formed and trusted
    (:func:`require_trusted`): both are checked before anything is imported. ``source``: the stored run that names
    it (for the message), None for a name from the command line.

    Raises:
        UnknownNameError: Neither a stock name, an entry point nor an import path.
        UntrustedVariantError: A user variant without the user's consent (nothing imported).
        MorficError: A name that is not well-formed; the import path's module cannot be imported, has no such
            class, or it is not a class.
    """
    if check_variant_name(name) in STOCK:
        return STOCK[name]
    if not is_import_path(name):
        points = {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}  # metadata only
        if name in points:
            require_trusted(name, source=source)
            return user_variant(name, points[name].load(), f"{points[name].value}")
        exc = UnknownNameError("variant", name, [*VARIANTS, *points])
        exc.args = (
            f"{exc.args[0].rstrip('.')}; or your own critic class by import path, module:Class (docs/extending.md).",
        )
        raise exc
    require_trusted(name, source=source)
    module_name, _, attr = name.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MorficError(
            f"variant '{name}': cannot import module '{module_name}' ({exc}). Install the package "
            "that provides it (a variant's code travels as its own package: docs/extending.md)."
        ) from exc
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise MorficError(
                f"variant '{name}': module '{module_name}' has no '{attr}'; check the class name, "
                "or install the version of the package that defines it."
            )
        obj = getattr(obj, part)
    return user_variant(name, obj, name)


def user_variant(name: str, cls: Any, path: str) -> Variant:
    """A user's critic class as a :class:`Variant` (the stock actor with z_m, the class as critic).

    Raises:
        MorficError: ``cls`` is not a class, not an rsl-rl critic model (a ``torch.nn.Module`` with
            ``encode_privileged``), or cannot be built as ``cls(obs, obs_groups, "critic", 1, **critic_cfg)``.
    """
    if not isinstance(cls, type):
        raise MorficError(
            f"variant '{name}' names {type(cls).__name__} '{path}', not a class; a variant is a "
            "critic class (docs/extending.md)."
        )
    import torch

    protocol = (
        "a critic model: a torch.nn.Module subclass with forward and encode_privileged, built as cls(obs, "
        "obs_groups, 'critic', 1, **critic_cfg); subclass morfic_cli.rl.models.MorficCritic "
        '(docs/extending.md, "The protocol")'
    )
    if not issubclass(cls, torch.nn.Module) or not callable(getattr(cls, "encode_privileged", None)):
        raise MorficError(f"variant '{name}': class {cls.__qualname__} is not {protocol}.")
    defaults = getattr(cls, "critic_defaults", {}) or {}
    if not isinstance(defaults, dict):
        raise MorficError(
            f"variant '{name}': {cls.__name__}.critic_defaults must be a dict of critic config "
            f"entries, got {type(defaults).__name__}."
        )
    variant = Variant(
        name=name,
        label=str(getattr(cls, "label", cls.__name__)),
        tables=(),
        critic_class=f"{cls.__module__}:{cls.__qualname__}",
        critic_defaults=dict(defaults),
        stock=False,
    )
    critic_cfg = {k: v for k, v in variant.model_cfgs()[1].items() if k != "class_name"}
    try:
        inspect.signature(cls).bind(None, None, "critic", 1, **critic_cfg)
    except TypeError as exc:
        raise MorficError(f"variant '{name}': class {cls.__qualname__} is not {protocol} ({exc}).") from None
    except ValueError:  # no signature to inspect (a C type): building it says more
        pass
    return variant


def model_cfgs(variant: str) -> tuple[dict, dict, dict[str, list[str]]]:
    """``resolve_variant(variant).model_cfgs()``: the rsl-rl ``actor``, ``critic`` and ``obs_groups`` entries.

    Raises:
        UnknownNameError: An unknown stock name.
        MorficError: A user variant that cannot be imported.
    """
    return resolve_variant(variant).model_cfgs()
