"""Every place morfic reaches into rsl-rl beyond its public API, in one module.

Written against **rsl-rl-lib 5.5.1** (``pyproject.toml`` requires ``>=5.5,<6``). Where rsl-rl offers a public
hook, morfic uses it instead: models and the algorithm are plugged in by ``class_name`` (``resolve_class``), the
runner's file checkpoints are switched off by overriding ``OnPolicyRunner.save`` in a subclass, the training
curve is a subclass of rsl-rl's ``Logger``. What has no public hook is here, each with what it relies on, so an
rsl-rl upgrade is checked against this file alone (``tests/rl/test_ppo.py`` and ``tests/rl/test_train.py``
exercise every function).
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel


def raw_models(alg: Any) -> tuple[MLPModel, MLPModel]:
    """The unwrapped (actor, critic) of an rsl-rl ``PPO``.

    Relies on: ``PPO._raw_actor`` / ``PPO._raw_critic`` (the models before ``torch.compile`` / DDP wrapping); the
    public ``actor`` / ``critic`` may be wrappers without the morfic methods (``estimate_privileged``, ...).
    """
    return alg._raw_actor, alg._raw_critic


@contextlib.contextmanager
def tapped_mini_batches(storage: Any, tap: Callable[[Callable[..., Iterator[Any]], int, int], Iterator[Any]]):
    """While the context is open, ``storage.mini_batch_generator(m, e)`` yields from ``tap(original, m, e)``.

    Relies on: ``PPO.update`` drawing its mini-batches from ``self.storage.mini_batch_generator(num_mini_batches,
    num_learning_epochs)`` and running loss, backward and optimiser step on each batch before asking for the
    next, so code after a ``yield`` in ``tap`` runs right after PPO's step on that batch. rsl-rl has no per-batch
    callback. The instance attribute shadows the class method and is deleted on exit.
    """
    storage.mini_batch_generator = functools.partial(tap, storage.mini_batch_generator)
    try:
        yield
    finally:
        del storage.mini_batch_generator  # back to the class method


def replace_logger(runner: Any, make: Callable[[Any], Any]) -> None:
    """Swap the logger an ``OnPolicyRunner`` built for ``make(old_logger)``.

    Relies on: ``OnPolicyRunner.__init__`` building ``self.logger`` itself (no logger argument) and ``learn``
    calling ``self.logger.log(...)`` / ``process_env_step`` on whatever ``self.logger`` is.
    """
    runner.logger = make(runner.logger)
