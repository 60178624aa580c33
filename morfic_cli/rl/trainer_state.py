"""Trainer state (optimiser, env, RNG, logger) as tensors + JSON: loading it can never run code.

A checkpoint's trainer state is a nested structure of dicts, lists, tuples, tensors, numpy arrays and
plain values. :func:`encode` splits it into two files:

- ``trainer.json``: the structure, with every tensor replaced by ``{"__tensor__": "t0"}``. Other
  markers: ``{"__tuple__": [...]}``, ``{"__ndarray__": "t1"}`` (a numpy array kept as a tensor),
  ``{"__float__": "nan"}`` (non-finite floats), ``{"__dict__": [[key, value], ...]}`` (dicts whose keys
  are not all plain strings, e.g. optimiser states keyed by parameter index).
- ``trainer-tensors.pt``: a flat ``{"t0": tensor, ...}`` dict saved with ``torch.save`` and read with
  ``torch.load(weights_only=True)``, which only rebuilds tensors and plain containers.

:func:`decode` inverts it exactly (dtypes, shapes and values), and raises :class:`MorficError` for
anything that is not such a pair, since a bundle may come from anyone.
"""

from __future__ import annotations

import io
import json
import math
from typing import Any

import torch

from morfic_cli.errors import MorficError

#: File names of the two halves in a trainer-state manifest.
JSON_FILE = "trainer.json"
TENSORS_FILE = "trainer-tensors.pt"

#: Version of the trainer.json layout.
FORMAT = 1

_MARKERS = ("__tensor__", "__ndarray__", "__tuple__", "__float__", "__dict__")


def encode(state: Any) -> dict[str, bytes]:
    """``{JSON_FILE: bytes, TENSORS_FILE: bytes}`` of a trainer-state structure.

    Raises:
        TypeError: A value that is none of the supported kinds (a bug in the caller, not user input).
    """
    tensors: dict[str, torch.Tensor] = {}

    def put(tensor: torch.Tensor) -> str:
        key = f"t{len(tensors)}"
        tensors[key] = tensor.detach().to("cpu").clone().contiguous()
        return key

    def enc(value: Any) -> Any:
        if isinstance(value, torch.Tensor):
            return {"__tensor__": put(value)}
        if value is None or isinstance(value, bool | int | str):
            return value
        if isinstance(value, float):
            return value if math.isfinite(value) else {"__float__": repr(value)}
        if isinstance(value, tuple):
            return {"__tuple__": [enc(v) for v in value]}
        if isinstance(value, list):
            return [enc(v) for v in value]
        if isinstance(value, dict):
            if all(isinstance(k, str) and k not in _MARKERS for k in value):
                return {k: enc(v) for k, v in value.items()}
            return {"__dict__": [[enc(k), enc(v)] for k, v in value.items()]}
        if type(value).__module__ == "numpy":
            if hasattr(value, "shape") and value.shape != ():
                return {"__ndarray__": put(torch.from_numpy(value.copy()))}
            return enc(value.item())
        raise TypeError(f"cannot store a {type(value).__name__} in a trainer state")

    doc = {"format": FORMAT, "state": enc(state)}
    buf = io.BytesIO()
    torch.save(tensors, buf)
    return {JSON_FILE: json.dumps(doc, sort_keys=True).encode(), TENSORS_FILE: buf.getvalue()}


def decode(json_bytes: bytes, tensor_bytes: bytes, what: str) -> Any:
    """The structure :func:`encode` was given.

    Args:
        json_bytes: The ``trainer.json`` bytes.
        tensor_bytes: The ``trainer-tensors.pt`` bytes.
        what: Names the checkpoint in error messages.

    Raises:
        MorficError: Either half is damaged or not a trainer state.
    """
    def bad(why: str) -> MorficError:
        return MorficError(f"the trainer state of {what} is damaged ({why}); resume from an earlier checkpoint "
                           "(--resume runs/NAME@-1) or start a new run.")

    try:
        doc = json.loads(json_bytes)
    except (ValueError, RecursionError) as exc:
        raise bad(f"{JSON_FILE} is not JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or "state" not in doc:
        raise bad(f"{JSON_FILE} is not a format-{FORMAT} trainer state")
    tensors = load_tensors(tensor_bytes, f"{TENSORS_FILE} of {what}")
    if not (isinstance(tensors, dict) and all(isinstance(v, torch.Tensor) for v in tensors.values())):
        raise bad(f"{TENSORS_FILE} is not a dict of tensors")

    def tensor(key: Any) -> torch.Tensor:
        if not isinstance(key, str) or key not in tensors:
            raise bad(f"it names a tensor {str(key)[:20]!r} that {TENSORS_FILE} does not hold")
        return tensors[key]

    def dec(value: Any) -> Any:
        if isinstance(value, list):
            return [dec(v) for v in value]
        if not isinstance(value, dict):
            return value
        if len(value) == 1:
            (key, inner), = value.items()
            if key == "__tensor__":
                return tensor(inner)
            if key == "__ndarray__":
                return tensor(inner).numpy()
            if key == "__tuple__" and isinstance(inner, list):
                return tuple(dec(v) for v in inner)
            if key == "__float__" and inner in ("nan", "inf", "-inf"):
                return float(inner)
            if key == "__dict__" and isinstance(inner, list):
                if not all(isinstance(kv, list) and len(kv) == 2 for kv in inner):
                    raise bad("a __dict__ entry is not a [key, value] pair")
                try:
                    return {dec(k): dec(v) for k, v in inner}
                except TypeError:
                    raise bad("a __dict__ key is not hashable") from None
        return {k: dec(v) for k, v in value.items()}

    try:
        return dec(doc["state"])
    except RecursionError:
        raise bad(f"{JSON_FILE} is nested too deeply") from None


def load_tensors(data: bytes, what: str, map_location: str | torch.device = "cpu") -> Any:
    """``torch.load(weights_only=True)`` of ``data`` (tensors and plain containers only, never code).

    Raises:
        MorficError: The bytes are not such a file (a damaged file, or a pickle that would need code).
    """
    try:
        return torch.load(io.BytesIO(data), map_location=map_location, weights_only=True)
    except Exception as exc:  # UnpicklingError, RuntimeError, EOFError, ...: all mean "not a safe tensor file"
        first = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__
        raise MorficError(f"{what} cannot be loaded as tensors ({first}); morfic only loads tensor files, never "
                          "pickled objects, since a bundle may come from anyone. Use a checkpoint written by "
                          "`morfic train`.") from None
