"""Checkpointing: what a training checkpoint holds, handed to a :class:`CheckpointSink` (rl/ never writes the store).

A checkpoint is the weights (``model.pt``: ``{"actor": state dict, "critic": state dict}``), the curve so far
(``curve.csv``, and ``curve.png`` in a training's last checkpoint), the resolved config, the meta, and one input:
the trainer state (:mod:`morfic_cli.rl.trainer_state`), which the sink writes first so that the checkpoint can name
it. The CLI and the pipeline wire the sink to the store (:class:`morfic_cli.store.run_sink.RunSink`: one
compare-and-set ref update per checkpoint).
"""

from __future__ import annotations

import dataclasses
import io
from typing import Any, Protocol

import torch

#: One artifact a checkpoint names as an input: (files, config, meta).
Part = tuple[dict[str, bytes], dict[str, Any], dict[str, Any]]


class CheckpointSink(Protocol):
    """Where a training's checkpoints go.

    Attributes:
        head: The checkpoint the run's name must still name when the next one is written (None: no checkpoint yet);
            :meth:`write` advances it, a resume sets it.
    """

    head: str | None

    def write(
        self, files: dict[str, bytes], config: dict[str, Any], meta: dict[str, Any], inputs: dict[str, Part]
    ) -> tuple[str, int]:
        """Write ``inputs`` (role -> part), then the checkpoint naming them; return (checkpoint id, run version).

        Raises:
            MorficError: The checkpoint could not be recorded (another process wrote the run, a lock stayed busy).
        """
        ...

    @property
    def ref(self) -> str:
        """The run's name in the sink (``runs/NAME``)."""
        ...


@dataclasses.dataclass
class Checkpoint:
    """A checkpoint written to the sink."""

    id: str
    ref: str
    version: int
    iteration: int


def to_bytes(obj: Any) -> bytes:
    """``torch.save`` of ``obj`` into bytes."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()
