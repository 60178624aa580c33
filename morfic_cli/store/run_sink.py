"""The store end of a training's checkpoints: each one written as manifests, then ONE ref update of ``runs/NAME``.

:class:`RunSink` is the store's :class:`~morfic_cli.rl.checkpoint.CheckpointSink`, wired by the training entry
points (:func:`morfic_cli.rl.runner.new_run`, :func:`~morfic_cli.rl.runner.resume_run`). Whatever instant a kill
hits, ``runs/NAME`` names a checkpoint whose inputs (the trainer state) are there. The update is a compare-and-set on
the version this process last wrote (or resumed from; none for a new run), so two trainings that write one run at
once cannot interleave their checkpoints: the second to checkpoint stops with an error.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from morfic_cli.errors import MorficError
from morfic_cli.runs import RUNS_PREFIX
from morfic_cli.store.lock import LockTimeoutError
from morfic_cli.store.refs import RefMovedError

if TYPE_CHECKING:
    from morfic_cli.store import Store


class RunSink:
    """Writes a run's checkpoints into ``store`` under ref ``runs/NAME``.

    Attributes:
        head: The id ``runs/NAME`` must point at when the next checkpoint is written (None: no ref yet).
    """

    def __init__(self, store: Store, name: str, head: str | None = None) -> None:
        self.store, self.name, self.head = store, name, head

    @property
    def ref(self) -> str:
        """``runs/NAME``."""
        return RUNS_PREFIX + self.name

    def write(
        self,
        files: dict[str, bytes],
        config: dict[str, Any],
        meta: dict[str, Any],
        inputs: dict[str, tuple[dict[str, bytes], dict[str, Any], dict[str, Any]]],
    ) -> tuple[str, int]:
        """Write each input as a ``checkpoint`` manifest, the checkpoint naming them, then advance the ref.

        Returns:
            (checkpoint id, the ref's new version).

        Raises:
            MorficError: Another process moved ``runs/NAME`` meanwhile, or the store lock stayed busy.
        """
        iteration = meta.get("iteration")
        with self._stopped_on_lock_timeout(iteration), self.store.writing():
            ids = {
                role: self.store.put_manifest("checkpoint", config=c, files=f, meta=m)
                for role, (f, c, m) in inputs.items()
            }
            ckpt = self.store.put_manifest("checkpoint", config=config, meta=meta, inputs=ids, files=files)
            try:  # the one visible step, unless another process wrote this run meanwhile
                version = self.store.set_ref(self.ref, ckpt, expect=self.head)
            except RefMovedError as exc:
                raise MorficError(self._moved_message(exc, iteration)) from exc
        self.head = ckpt
        return ckpt, version

    def _moved_message(self, exc: RefMovedError, iteration: Any) -> str:
        """What a training whose run another process wrote meanwhile says as it stops (it lost the race)."""
        ref = self.ref
        if exc.current is None:
            now = "was removed"
        else:
            try:
                other = self.store.read_manifest(exc.current.id).meta.get("iteration")
            except MorficError:
                other = None
            at = f" at iteration {other}" if other is not None else ""
            now = (
                f"was created by another process ({exc.current.id[:12]}{at})"
                if self.head is None
                else f"was advanced by another process (version {exc.current.version} is {exc.current.id[:12]}{at}, "
                f"not this training's last checkpoint {self.head[:12]})"
            )
        return (
            f"run '{ref}' {now} while this training ran: two trainings cannot write one run, so this one "
            f"stops without recording its checkpoint at iteration {iteration} (gc removes it); the ref keeps "
            f"the other training's checkpoints (`morfic store show {ref} --history`). Give each training its own "
            f"--name; `morfic train --resume {ref}` continues from the ref's current version."
        )

    @contextlib.contextmanager
    def _stopped_on_lock_timeout(self, iteration: Any) -> Iterator[None]:
        """Turn a store lock that stayed busy (a long gc) during a checkpoint into an error that says how to go on."""
        try:
            yield
        except LockTimeoutError as exc:
            ref = self.ref
            last = (
                f"`morfic train --resume {ref}` continues from its last checkpoint"
                if self.head is not None
                else f"it has no checkpoint yet: start it again with `morfic train --name {self.name}` (and its "
                "--variant, --preset, --seed and --set)"
            )
            raise MorficError(
                f"{exc} This training stopped at iteration {iteration} without writing that checkpoint; {last}."
            ) from exc
