"""MCAP rollout logs: one file per robot and command of ``morfic eval``, readable in Foxglove Studio.

A log holds one JSON message per policy step on channel :data:`ROLLOUT_TOPIC`, described by a JSON
Schema (schema encoding ``jsonschema``, message encoding ``json``), in zstd-compressed chunks, plus one
MCAP metadata record named :data:`METADATA_NAME` with the run's metadata. Each message is env-major::

    {"step": 17, "time_s": 0.34, "envs": [{"base_pos": [x, y, z], ..., "reward_terms": {"r_lin": 0.07, ...},
                                           "value": 1.9, "done": false, "time_out": false}, ...]}

so Foxglove plots e.g. ``/rollout/step.envs[0].base_pos[2]`` or ``/rollout/step.envs[3].reward_terms.r_lin``
(its JSON Schema support has arrays of numbers and arrays of objects, but no arrays of arrays). The log time of
a message is the step's time in ns.

Numbers are stored as float32: the writer casts every numeric field to float32 and prints the shortest decimal
that reads back to the same float32, so :func:`read_rollout` returns exactly the float32 values written.
Non-finite values (NaN, +-inf) are written as JSON ``null`` (JSON has no NaN) and read back as NaN.
Shapes use T = steps, N = num_envs, K = number of reward terms. See ``docs/mcap.md``.
"""

from __future__ import annotations

import json
import math
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

ROLLOUT_FORMAT = "morfic.rollout/1"
"""Value of the ``format`` metadata key; bumped when the message layout changes."""

ROLLOUT_TOPIC = "/rollout/step"
"""Topic of the channel carrying one message per policy step."""

ROLLOUT_SCHEMA_NAME = "morfic.RolloutStep"
"""Name of the JSON Schema of the step messages (Foxglove's datatype name)."""

METADATA_NAME = "morfic"
"""Name of the MCAP metadata record holding the log's metadata."""

NUM_TERMS = "K"
"""Placeholder in a field's shape for the number of reward terms."""

RESERVED_KEYS: tuple[str, ...] = ("format", "num_envs", "term_names", "json_keys")
"""Metadata keys the writer sets itself (``num_envs`` and ``term_names`` may be passed if they agree)."""


@dataclass(frozen=True)
class RolloutField:
    """One per-env field of a rollout step.

    Attributes:
        shape: Per-env shape suffix; () for a scalar, (n,) for a vector, (:data:`NUM_TERMS`,) for reward terms.
        unit: Unit of the values ("" when dimensionless or boolean).
        description: Meaning and frame.
        components: Names of the vector components, in order (empty for scalars and joint vectors).
        dtype: "float32" or "bool", the dtype :func:`read_rollout` returns.
    """

    shape: tuple[int | str, ...]
    unit: str
    description: str
    components: tuple[str, ...] = ()
    dtype: str = "float32"


_JOINTS = "legs FL, FR, RL, RR; joints hip, thigh, calf per leg"

ROLLOUT_FIELDS: dict[str, RolloutField] = {
    "base_pos": RolloutField((3,), "m", "Base position, world frame", ("x", "y", "z")),
    "base_quat": RolloutField(
        (4,), "", "Base orientation quaternion (w, x, y, z), base to world", ("w", "x", "y", "z")
    ),
    "base_lin_vel": RolloutField((3,), "m/s", "Base linear velocity, base (body) frame", ("x", "y", "z")),
    "base_ang_vel": RolloutField((3,), "rad/s", "Base angular velocity, base (body) frame", ("x", "y", "z")),
    "command": RolloutField(
        (3,), "m/s, m/s, rad/s", "Velocity command (vx, vy, yaw rate), base yaw frame", ("vx", "vy", "yaw_rate")
    ),
    "joint_pos": RolloutField((12,), "rad", f"Joint positions q ({_JOINTS})"),
    "joint_vel": RolloutField((12,), "rad/s", f"Joint velocities qdot ({_JOINTS})"),
    "action": RolloutField((12,), "", f"Policy action a_t, PD target q0 + action_scale * a ({_JOINTS})"),
    "reward": RolloutField((), "", "Total reward of the step, as the env returns it (dt-scaled)"),
    "reward_terms": RolloutField(
        (NUM_TERMS,), "", "Per-term reward contributions (sign x weight x term x dt), summing to reward; "
        "keyed by term name in messages, columns in term_names order in arrays"
    ),
    "value": RolloutField((), "", "Critic value V(s_t) of the state the action was taken in"),
    "done": RolloutField(
        (), "", "The episode ended at this step (failure or time-out) and the env reset", dtype="bool"
    ),
    "time_out": RolloutField((), "", "The episode ended by the time limit (truncation, not failure)", dtype="bool"),
}
"""The fields of a rollout step, in message order: name -> per-env shape suffix, unit and meaning."""


def field_shape(name: str, num_envs: int, num_terms: int) -> tuple[int, ...]:
    """The shape a step's array of field ``name`` must have: (N, *suffix), with K = ``num_terms``."""
    return (num_envs, *(num_terms if d == NUM_TERMS else int(d) for d in ROLLOUT_FIELDS[name].shape))


def _shape_desc(name: str) -> str:
    """Symbolic shape of a step's array, e.g. "(num_envs, 3)" or "(num_envs, K)"."""
    return "(" + ", ".join(["num_envs", *(str(d) for d in ROLLOUT_FIELDS[name].shape)]) + ")"


def check_step_data(data: Mapping[str, Any], num_envs: int, num_terms: int) -> dict[str, np.ndarray]:
    """Validate one step's arrays and cast them to their stored dtype.

    Args:
        data: Every field of :data:`ROLLOUT_FIELDS` (no others), each array-like of shape
            :func:`field_shape` (leading dim N).
        num_envs: N.
        num_terms: K.

    Returns:
        Field -> array of shape (N, ...), float32, or bool for ``done`` / ``time_out``.

    Raises:
        ValueError: A field is missing or unknown, has the wrong shape, or a non-numeric (non-0/1 for booleans) dtype.
    """
    missing = [f for f in ROLLOUT_FIELDS if f not in data]
    unknown = sorted(str(f) for f in data if f not in ROLLOUT_FIELDS)
    if missing or unknown:
        raise ValueError(f"rollout step: missing fields {missing}, unknown fields {unknown}")
    out: dict[str, np.ndarray] = {}
    for name, spec in ROLLOUT_FIELDS.items():
        a = np.asarray(data[name])
        expected = field_shape(name, num_envs, num_terms)
        if a.shape != expected:
            raise ValueError(
                f"rollout field {name!r}: expected shape {_shape_desc(name)} = {expected}, got {tuple(a.shape)}"
            )
        if spec.dtype == "bool":
            if a.dtype.kind in "iu" and np.isin(a, (0, 1)).all():
                a = a.astype(bool)
            elif a.dtype.kind != "b":
                raise ValueError(f"rollout field {name!r}: expected bool (or 0/1 integers), got dtype {a.dtype}")
            out[name] = a
        else:
            if a.dtype.kind not in "biuf":
                raise ValueError(f"rollout field {name!r}: expected numbers, got dtype {a.dtype}")
            out[name] = a.astype(np.float32)
    return out


def shortest_decimals(a: np.ndarray) -> np.ndarray:
    """For each float32 value, the double nearest to the shortest decimal that reads back to it.

    Vectorised: for k = 1..9 significant digits, round to k digits (m / 10^j, a correctly rounded division, so
    ``repr`` of the double prints those k digits) and keep the first k whose float32 equals the value. 9 digits
    always suffice for float32; anything left (non-finite values, rare rounding corners) keeps the exact double of
    the float32, which also reads back exactly.

    Args:
        a: float32 array, any shape.

    Returns:
        float64 array of the same shape.
    """
    x = a.astype(np.float64)
    out = x.copy()
    todo = np.isfinite(x) & (x != 0.0)
    if not todo.any():
        return out
    with np.errstate(all="ignore"):
        exp10 = np.floor(np.log10(np.abs(np.where(todo, x, 1.0))))
        for k in range(1, 10):
            j = k - 1 - exp10  # decimal places of k significant digits
            scale = 10.0 ** np.abs(j)
            r = np.where(j >= 0, np.round(x * scale) / scale, np.round(x / scale) * scale)
            ok = todo & (r.astype(np.float32) == a)
            out[ok] = r[ok]
            todo &= ~ok
            if not todo.any():
                break
    return out


def json_floats(a: np.ndarray) -> list:
    """A float32 array as nested lists of floats that JSON prints as the shortest decimal reading back to it.

    Each element becomes :func:`shortest_decimals`' double (so ``json.dumps`` writes e.g. ``0.1``, not
    ``0.10000000149011612``); non-finite values become None (JSON ``null``).

    Args:
        a: float32 array, any shape.

    Returns:
        ``a.tolist()``-shaped nested lists.
    """
    d = shortest_decimals(a)
    finite = np.isfinite(a)
    return d.tolist() if finite.all() else np.where(finite, d, None).tolist()


def step_message(step: int, time_s: float, arrays: Mapping[str, np.ndarray], term_names: Sequence[str]) -> dict:
    """The JSON message of one step, env-major (see the module docstring).

    Args:
        step: Policy step index.
        time_s: Step time (s).
        arrays: Output of :func:`check_step_data`.
        term_names: K reward-term names, the columns of ``arrays["reward_terms"]``.

    Returns:
        ``{"step", "time_s", "envs": [N x {field: value}]}`` with ``reward_terms`` a {term name: value} object.
    """
    cols = {name: a.tolist() if a.dtype == bool else json_floats(a) for name, a in arrays.items()}
    envs = []
    for i in range(len(cols["reward"])):
        env = {name: cols[name][i] for name in ROLLOUT_FIELDS}
        env["reward_terms"] = dict(zip(term_names, env["reward_terms"], strict=True))
        envs.append(env)
    return {"step": step, "time_s": time_s, "envs": envs}


def _field_json_schema(name: str, term_names: Sequence[str]) -> dict:
    """JSON Schema of one per-env field (a number, a boolean, an array of numbers or the reward-term object)."""
    spec = ROLLOUT_FIELDS[name]
    desc = spec.description + (f" [{', '.join(spec.components)}]" if spec.components else "")
    desc += f" ({spec.unit})" if spec.unit else ""
    if name == "reward_terms":
        return {
            "type": "object", "description": desc, "properties": {k: {"type": "number"} for k in term_names},
            "required": list(term_names), "additionalProperties": False,
        }
    if spec.dtype == "bool":
        return {"type": "boolean", "description": desc}
    if spec.shape == ():
        return {"type": "number", "description": desc}
    (n,) = spec.shape
    return {"type": "array", "description": desc, "items": {"type": "number"}, "minItems": n, "maxItems": n}


def rollout_json_schema(term_names: Sequence[str], num_envs: int) -> dict:
    """The JSON Schema of a step message, for ``num_envs`` envs and the given reward terms."""
    env = {
        "type": "object", "properties": {name: _field_json_schema(name, term_names) for name in ROLLOUT_FIELDS},
        "required": list(ROLLOUT_FIELDS), "additionalProperties": False,
    }
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": ROLLOUT_SCHEMA_NAME,
        "description": "One policy step of a morfic evaluation rollout; envs[i] is env i.",
        "type": "object",
        "properties": {
            "step": {"type": "integer", "minimum": 0, "description": "Policy step index"},
            "time_s": {"type": "number", "description": "Step time (s); the message log time is this in ns"},
            "envs": {"type": "array", "items": env, "minItems": num_envs, "maxItems": num_envs},
        },
        "required": ["step", "time_s", "envs"],
        "additionalProperties": False,
    }


def _json_default(value: Any) -> Any:
    """``json.dumps`` hook for numpy scalars and arrays in metadata."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def encode_metadata(metadata: Mapping[str, Any], term_names: Sequence[str], num_envs: int) -> dict[str, str]:
    """The str -> str map of the metadata record.

    Strings are stored as they are; every other value as JSON, its key listed in the JSON list ``json_keys``
    so that :func:`decode_metadata` gives it back typed. Adds ``format``, ``num_envs`` and ``term_names``.

    Raises:
        ValueError: A key is not a string or is reserved, a value is not JSON-serialisable (or is NaN/inf), or
            ``num_envs`` / ``term_names`` in ``metadata`` disagree with the writer's.
    """
    values: dict[str, Any] = {}
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise ValueError(f"rollout metadata: keys must be strings, got {key!r}")
        if key in ("format", "json_keys"):
            raise ValueError(f"rollout metadata: key {key!r} is reserved")
        values[key] = value
    own = {"format": ROLLOUT_FORMAT, "num_envs": num_envs, "term_names": list(term_names)}
    for key in ("num_envs", "term_names"):
        if key in values and json.dumps(values[key], default=_json_default) != json.dumps(own[key]):
            raise ValueError(f"rollout metadata: {key}={values[key]!r} disagrees with the writer's {own[key]!r}")
    values.update(own)
    out: dict[str, str] = {}
    json_keys: list[str] = []
    for key, value in values.items():
        if isinstance(value, str):
            out[key] = value
            continue
        try:
            out[key] = json.dumps(value, default=_json_default, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise ValueError(f"rollout metadata: value of {key!r} is not JSON-serialisable ({e})") from e
        json_keys.append(key)
    out["json_keys"] = json.dumps(json_keys)
    return out


def decode_metadata(record: Mapping[str, str]) -> dict[str, Any]:
    """Inverse of :func:`encode_metadata`: the typed metadata (``json_keys`` itself dropped)."""
    json_keys = set(json.loads(record.get("json_keys", "[]")))
    return {k: json.loads(v) if k in json_keys else v for k, v in record.items() if k != "json_keys"}


class RolloutLogWriter:
    """Writes a rollout log (MCAP) step by step; a context manager that closes the file on exit.

    Example::

        with RolloutLogWriter(path, num_envs=64, term_names=names, metadata={"robot": "go2", "seed": 0}) as log:
            for step in range(T):
                log.write_step(step, step * dt, {"base_pos": pos, ..., "time_out": time_out})

    The parent directory is created if needed. Closing (also on an exception inside the ``with``) writes the
    MCAP summary, so a log cut short by an error is still a valid file with the steps written so far.
    """

    def __init__(
        self,
        path: Path,
        *,
        num_envs: int,
        term_names: Sequence[str],
        metadata: Mapping[str, str | int | float | bool | list],
    ) -> None:
        """Open ``path`` and write the header, schema, channel and metadata record.

        Args:
            path: Output file (conventionally ``*.mcap``); overwritten if it exists.
            num_envs: N, the leading dim of every array of :meth:`write_step`.
            term_names: K distinct, non-empty reward-term names, the columns of ``reward_terms``.
            metadata: Run metadata (see ``docs/mcap.md`` for the keys ``morfic eval`` sets); strings are
                stored as is, other values as JSON and read back typed.

        Raises:
            ValueError: Bad ``num_envs``, ``term_names`` or metadata (nothing is written then).
        """
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        names = list(term_names)
        if isinstance(term_names, str) or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"term_names must be a sequence of non-empty strings, got {term_names!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"term_names must be distinct, got {names}")
        self.path = Path(path)
        self.num_envs = int(num_envs)
        self.term_names = names
        record = encode_metadata(metadata, names, self.num_envs)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start()
        schema = json.dumps(rollout_json_schema(names, self.num_envs)).encode()
        schema_id = self._writer.register_schema(ROLLOUT_SCHEMA_NAME, "jsonschema", schema)
        self._channel = self._writer.register_channel(
            ROLLOUT_TOPIC, "json", schema_id, metadata={"num_envs": str(self.num_envs)}
        )
        self._writer.add_metadata(METADATA_NAME, record)
        self._count = 0
        self._last: tuple[int, float] | None = None
        self._closed = False

    def write_step(self, step: int, time_s: float, data: Mapping[str, np.ndarray]) -> None:
        """Append one policy step.

        Args:
            step: Policy step index, >= 0 and increasing from call to call.
            time_s: Step time (s), finite, >= 0 and non-decreasing; the message's log time is
                ``round(time_s * 1e9)`` ns.
            data: Every field of :data:`ROLLOUT_FIELDS`, each of shape (N, *suffix) (see :func:`field_shape`):
                numbers (cast to float32) or, for ``done`` / ``time_out``, bools. numpy arrays or anything
                ``np.asarray`` takes (CPU tensors).

        Raises:
            ValueError: Wrong field set, shape or dtype (the message names the field and the expected shape),
                a step or time going backwards, or a closed writer.
        """
        if self._closed:
            raise ValueError(f"rollout log {self.path} is closed")
        step = operator.index(step)
        time_s = float(time_s)
        if step < 0 or not math.isfinite(time_s) or time_s < 0:
            raise ValueError(f"rollout step: need step >= 0 and finite time_s >= 0, got step={step}, time_s={time_s}")
        if self._last is not None and (step <= self._last[0] or time_s < self._last[1]):
            raise ValueError(
                f"rollout step: step must increase and time_s not decrease; got ({step}, {time_s}) after {self._last}"
            )
        arrays = check_step_data(data, self.num_envs, len(self.term_names))
        payload = json.dumps(step_message(step, time_s, arrays, self.term_names), separators=(",", ":"))
        log_time = round(time_s * 1e9)
        self._writer.add_message(self._channel, log_time, payload.encode(), log_time, sequence=self._count)
        self._count += 1
        self._last = (step, time_s)

    def close(self) -> None:
        """Write the MCAP summary and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> RolloutLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class RolloutLog:
    """A rollout log read back by :func:`read_rollout`.

    Attributes:
        metadata: The metadata record, typed (strings as written, other values from JSON), including
            ``format``, ``num_envs`` and ``term_names``.
        term_names: The K reward-term names, the columns of ``arrays["reward_terms"]``.
        arrays: Field -> array of shape (T, N, *suffix): float32, bool for ``done`` and ``time_out``;
            ``reward_terms`` is (T, N, K). Non-finite values written come back as NaN.
        steps: Policy step indices, int64. Shape: (T,).
        time_s: Step times (s), float64 as written. Shape: (T,).
    """

    metadata: dict[str, Any]
    term_names: list[str]
    arrays: dict[str, np.ndarray]
    steps: np.ndarray
    time_s: np.ndarray

    @property
    def num_steps(self) -> int:
        """T."""
        return int(self.steps.shape[0])

    @property
    def num_envs(self) -> int:
        """N."""
        return int(self.metadata["num_envs"])


def arrays_from_messages(messages: Sequence[dict], term_names: Sequence[str], num_envs: int) -> dict[str, np.ndarray]:
    """Stack decoded step messages into per-field arrays of shape (T, N, *suffix) (see :class:`RolloutLog`).

    Raises:
        ValueError: A message has other than ``num_envs`` envs.
    """
    for m in messages:
        if len(m["envs"]) != num_envs:
            raise ValueError(f"rollout step {m['step']}: {len(m['envs'])} envs, metadata says {num_envs}")
    arrays: dict[str, np.ndarray] = {}
    for name, spec in ROLLOUT_FIELDS.items():
        if name == "reward_terms":
            rows = [[[env[name][k] for k in term_names] for env in m["envs"]] for m in messages]
        else:
            rows = [[env[name] for env in m["envs"]] for m in messages]
        shape = (len(messages), *field_shape(name, num_envs, len(term_names)))
        if spec.dtype == "bool":
            arrays[name] = np.array(rows, dtype=bool).reshape(shape)
        else:  # None (JSON null) -> NaN
            arrays[name] = np.array(rows, dtype=np.float64).reshape(shape).astype(np.float32)
    return arrays


def read_rollout(path: Path) -> RolloutLog:
    """Read a rollout log written by :class:`RolloutLogWriter`, with the ``mcap`` library's reader.

    Raises:
        ValueError: The file has no ``morfic`` metadata record or an unknown ``format``.
    """
    with open(path, "rb") as f:
        reader = make_reader(f)
        records = [m for m in reader.iter_metadata() if m.name == METADATA_NAME]
        if not records:
            raise ValueError(f"{path}: no {METADATA_NAME!r} metadata record; not a morfic rollout log")
        metadata = decode_metadata(records[-1].metadata)
        if metadata.get("format") != ROLLOUT_FORMAT:
            raise ValueError(f"{path}: rollout format {metadata.get('format')!r}, expected {ROLLOUT_FORMAT!r}")
        messages = [
            json.loads(msg.data) for _, _, msg in reader.iter_messages(topics=[ROLLOUT_TOPIC], log_time_order=False)
        ]
    term_names = list(metadata["term_names"])
    num_envs = int(metadata["num_envs"])
    return RolloutLog(
        metadata=metadata,
        term_names=term_names,
        arrays=arrays_from_messages(messages, term_names, num_envs),
        steps=np.array([m["step"] for m in messages], dtype=np.int64),
        time_s=np.array([m["time_s"] for m in messages], dtype=np.float64),
    )
