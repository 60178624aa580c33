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
"""

from __future__ import annotations

import copy
import importlib
import importlib.metadata
from dataclasses import dataclass, field
from typing import Any

from morfic_cli.errors import MorficError, UnknownNameError

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
        tables: The paper's transfer tables it is a column of: ``main`` (zero-shot transfer), ``ablation``.
        actor_class: rsl-rl ``class_name`` of the actor.
        critic_class: rsl-rl ``class_name`` of the critic.
        actor_morphology: Whether the actor sees z_m (False only for ``ppo``).
        critic_morphology: Whether the critic sees z_m.
        critic_defaults: Critic config entries of this variant (conditioning, conditioning_scale, hidden_dims).
        stock: One of the paper's variants (False: a user's class).
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

    @property
    def multiplicative(self) -> bool:
        """Whether the critic is conditioned multiplicatively on z_m (FiLM, AdaLN, hypernetwork: the MorFiC family).

        False for the additive baselines (concat, or no critic conditioning).
        """
        return self.critic_defaults.get("conditioning") in MULTIPLICATIVE_CONDITIONING

    def model_cfgs(self) -> tuple[dict, dict, dict[str, list[str]]]:
        """The rsl-rl ``actor``, ``critic`` and ``obs_groups`` config entries (paper sizes); fresh dicts per call."""
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
        critic_cfg.update(copy.deepcopy(self.critic_defaults))
        obs_groups = {
            "actor": ["history", "morphology"] if self.actor_morphology else ["history"],
            "critic": ["critic", "privileged", "morphology"] if self.critic_morphology else ["critic", "privileged"],
        }
        return actor_cfg, critic_cfg, obs_groups


def _stock(name: str, label: str, tables: tuple[str, ...], conditioning: str, scale: float = 1.0,
           trunk: tuple[int, ...] = PAPER_TRUNK, actor_morphology: bool = True) -> Variant:
    return Variant(name, label, tables, actor_morphology=actor_morphology, critic_morphology=conditioning != "none",
                   critic_defaults={"conditioning": conditioning, "conditioning_scale": scale,
                                    "hidden_dims": list(trunk)})


STOCK: dict[str, Variant] = {v.name: v for v in (
    _stock("ppo", "PPO", ("main",), "none", actor_morphology=False),
    _stock("actor-only", "Actor-only", ("main",), "none"),
    _stock("concat", "Actor+Critic", ("main",), "concat"),
    _stock("film", "MorFiC-F", ("main", "ablation"), "film", 0.1),
    _stock("film-scaled", "MorFiC-F(Scaled)", ("ablation",), "film", 0.1, (1024, 512, 256)),
    _stock("hyper", "MorFiC-H", ("ablation",), "hyper", 0.1),
    _stock("adaln", "MorFiC-A", ("ablation",), "adaln"),
)}
"""The paper's variants, in the order of its tables (sizes: paper Tables "architecture", "conditioning variants")."""

VARIANTS: tuple[str, ...] = tuple(STOCK)
"""The stock ``--variant`` names, in the paper's order."""


def table_variants(table: str) -> tuple[str, ...]:
    """The stock variants that are columns of the paper's transfer table ``table`` (``main``, ``ablation``)."""
    return tuple(v.name for v in STOCK.values() if table in v.tables)


def variant_order(name: str) -> int:
    """Sort key: the paper's order, then every other (user) variant."""
    return VARIANTS.index(name) if name in STOCK else len(VARIANTS)


def variant_label(name: str) -> str:
    """The table label of a variant: the paper's for stock ones, else the name as recorded."""
    return STOCK[name].label if name in STOCK else name


def help_text() -> str:
    """The ``--variant`` choices for the CLI help."""
    return f"{', '.join(VARIANTS)}, or your own critic class by import path (module:Class; docs/extending.md)"


def is_import_path(name: str) -> bool:
    """Whether ``name`` names a user class (``module:Class``) rather than a stock or entry-point variant."""
    return ":" in name


def resolve_variant(name: str) -> Variant:
    """The :class:`Variant` of a ``--variant`` value: a stock name, an entry point, or ``module:Class``.

    Raises:
        UnknownNameError: Neither a stock name, an entry point nor an import path.
        MorficError: The import path's module cannot be imported, has no such class, or it is not a class.
    """
    if name in STOCK:
        return STOCK[name]
    if not is_import_path(name):
        points = {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}
        if name in points:
            return user_variant(name, points[name].load(), f"{points[name].value}")
        exc = UnknownNameError("variant", name, [*VARIANTS, *points])
        exc.args = (f"{exc.args[0].rstrip('.')}; or your own critic class by import path, module:Class "
                    "(docs/extending.md).",)
        raise exc
    module_name, _, attr = name.partition(":")
    if not module_name or not attr:
        raise MorficError(f"variant '{name}' is not an import path; write it as module:Class "
                          "(e.g. my_lab.critics:GatedCritic).")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MorficError(f"variant '{name}': cannot import module '{module_name}' ({exc}). Install the package "
                          "that provides it, or put the folder holding it on PYTHONPATH (docs/extending.md).") from exc
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise MorficError(f"variant '{name}': module '{module_name}' has no '{attr}'; check the class name, "
                              "or install the version of the package that defines it.")
        obj = getattr(obj, part)
    return user_variant(name, obj, name)


def user_variant(name: str, cls: Any, path: str) -> Variant:
    """A user's critic class as a :class:`Variant` (the stock actor with z_m, the class as critic).

    Raises:
        MorficError: ``cls`` is not a class.
    """
    if not isinstance(cls, type):
        raise MorficError(f"variant '{name}' names {type(cls).__name__} '{path}', not a class; a variant is a "
                          "critic class (docs/extending.md).")
    defaults = getattr(cls, "critic_defaults", {}) or {}
    if not isinstance(defaults, dict):
        raise MorficError(f"variant '{name}': {cls.__name__}.critic_defaults must be a dict of critic config "
                          f"entries, got {type(defaults).__name__}.")
    return Variant(name=name, label=str(getattr(cls, "label", cls.__name__)), tables=(),
                   critic_class=f"{cls.__module__}:{cls.__qualname__}", critic_defaults=dict(defaults), stock=False)


def model_cfgs(variant: str) -> tuple[dict, dict, dict[str, list[str]]]:
    """``resolve_variant(variant).model_cfgs()``: the rsl-rl ``actor``, ``critic`` and ``obs_groups`` entries.

    Raises:
        UnknownNameError: An unknown stock name.
        MorficError: A user variant that cannot be imported.
    """
    return resolve_variant(variant).model_cfgs()
