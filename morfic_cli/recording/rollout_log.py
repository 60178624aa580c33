"""MCAP rollout logs: one file per robot and command of ``morfic eval``, with a 3D scene Foxglove draws.

A log holds, in zstd-compressed chunks (see ``docs/mcap.md``):

* ``/rollout/step`` (:data:`ROLLOUT_TOPIC`): one protobuf ``morfic.RolloutStep`` per policy step, env-major, every
  field of :data:`ROLLOUT_FIELDS` for every env (:mod:`morfic_cli.recording.rollout_proto`), so Foxglove plots e.g.
  ``/rollout/step.envs[0].base_pos[2]`` or ``/rollout/step.envs[3].reward_terms.r_lin``;
* with a :class:`~morfic_cli.recording.scene.RolloutScene` (the first few envs by default): ``/scene``, one
  ``foxglove.SceneUpdate`` with every geom of those envs, and ``/tf``, ``foxglove.FrameTransforms``: the fixed frames
  once, the moving bodies per policy step, so Foxglove's 3D panel shows the robots walk;
* one MCAP metadata record named :data:`METADATA_NAME` with the run's metadata.

The log time of a step's messages is the step's time in ns; the scene and the fixed frames are logged at time 0.
Numbers are float32 (protobuf ``float``), bit-exact, NaN and inf included, so :func:`read_rollout` returns exactly
the float32 values written. Shapes use T = steps, N = num_envs, K = number of reward terms, E = scene envs.
"""

from __future__ import annotations

import json
import math
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from morfic_cli.recording.rollout_proto import STEP_MESSAGE, StepCodec

if TYPE_CHECKING:
    from morfic_cli.recording.scene import RolloutScene

ROLLOUT_FORMAT = "morfic.rollout/2"
"""Value of the ``format`` metadata key; bumped when the message layout changes (1: JSON messages, read still)."""

ROLLOUT_TOPIC = "/rollout/step"
"""Topic of the channel carrying one message per policy step."""

ROLLOUT_SCHEMA_NAME = STEP_MESSAGE
"""Name of the protobuf message of the numeric channel (the MCAP schema name, Foxglove's datatype)."""

SCENE_TOPIC = "/scene"
"""Topic of the ``foxglove.SceneUpdate`` with the geoms of the scene envs (one message, log time 0)."""

TF_TOPIC = "/tf"
"""Topic of the ``foxglove.FrameTransforms``: fixed frames at log time 0, moving bodies every step."""

DEFAULT_SCENE_ENVS = 4
"""How many envs (the first ones) carry a 3D scene in a log unless asked otherwise."""

METADATA_NAME = "morfic"
"""Name of the MCAP metadata record holding the log's metadata."""

NUM_TERMS = "K"
"""Placeholder in a field's shape for the number of reward terms."""

RESERVED_KEYS: tuple[str, ...] = ("format", "num_envs", "term_names", "scene_envs", "json_keys")
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
        (NUM_TERMS,),
        "",
        "Per-term reward contributions (sign x weight x term x dt), summing to reward; "
        "keyed by term name in messages, columns in term_names order in arrays",
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


def _json_default(value: Any) -> Any:
    """``json.dumps`` hook for numpy scalars and arrays in metadata."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def encode_metadata(
    metadata: Mapping[str, Any], term_names: Sequence[str], num_envs: int, scene_envs: Sequence[int] = ()
) -> dict[str, str]:
    """The str -> str map of the metadata record.

    Strings are stored as they are; every other value as JSON, its key listed in the JSON list ``json_keys``
    so that :func:`decode_metadata` gives it back typed. Adds ``format``, ``num_envs``, ``term_names`` and
    ``scene_envs`` (the env indices with a 3D scene).

    Raises:
        ValueError: A key is not a string or is reserved, a value is not JSON-serialisable (or is NaN/inf), or
            ``num_envs`` / ``term_names`` in ``metadata`` disagree with the writer's.
    """
    values: dict[str, Any] = {}
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise ValueError(f"rollout metadata: keys must be strings, got {key!r}")
        if key in ("format", "json_keys", "scene_envs"):
            raise ValueError(f"rollout metadata: key {key!r} is reserved")
        values[key] = value
    own = {
        "format": ROLLOUT_FORMAT,
        "num_envs": num_envs,
        "term_names": list(term_names),
        "scene_envs": [int(i) for i in scene_envs],
    }
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


def step_codec(term_names: Sequence[str]) -> StepCodec:
    """The protobuf codec of :data:`ROLLOUT_FIELDS` with these reward terms."""
    k = len(term_names)
    fields = {
        name: (tuple(k if d == NUM_TERMS else int(d) for d in spec.shape), spec.dtype)
        for name, spec in ROLLOUT_FIELDS.items()
    }
    return StepCodec.build(fields, term_names)


class RolloutLogWriter:
    """Writes a rollout log (MCAP) step by step; a context manager that closes the file on exit.

    Example::

        with RolloutLogWriter(path, num_envs=64, term_names=names, metadata={"robot": "go2", "seed": 0},
                              scene=RolloutScene(models[:4], range(4), qpos_adr)) as log:
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
        scene: RolloutScene | None = None,
    ) -> None:
        """Open ``path`` and write the header, schemas, channels, metadata record and (with a scene) the geoms.

        Args:
            path: Output file (conventionally ``*.mcap``); overwritten if it exists.
            num_envs: N, the leading dim of every array of :meth:`write_step`.
            term_names: K distinct reward-term names (identifiers), the columns of ``reward_terms``.
            metadata: Run metadata (see ``docs/mcap.md`` for the keys ``morfic eval`` sets); strings are
                stored as is, other values as JSON and read back typed.
            scene: The 3D scene of some envs (their env ids must be < N); None writes numbers only.

        Raises:
            ValueError: Bad ``num_envs``, ``term_names``, scene env ids or metadata (nothing is written then).
        """
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        names = list(term_names)
        if isinstance(term_names, str) or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"term_names must be a sequence of non-empty strings, got {term_names!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"term_names must be distinct, got {names}")
        if scene is not None and not all(0 <= i < num_envs for i in scene.env_ids):
            raise ValueError(f"scene env ids {scene.env_ids} must lie in 0..{num_envs - 1}")
        self.path = Path(path)
        self.num_envs = int(num_envs)
        self.term_names = names
        self.scene = scene
        self._codec = step_codec(names)
        record = encode_metadata(metadata, names, self.num_envs, scene.env_ids if scene is not None else ())
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start()
        schema_id = self._writer.register_schema(ROLLOUT_SCHEMA_NAME, "protobuf", self._codec.schema_data)
        self._channel = self._writer.register_channel(
            ROLLOUT_TOPIC, "protobuf", schema_id, metadata={"num_envs": str(self.num_envs)}
        )
        self._writer.add_metadata(METADATA_NAME, record)
        self._tf = None
        if scene is not None:
            from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
            from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

            scene_ch = self._register(SCENE_TOPIC, SceneUpdate)
            self._tf = self._register(TF_TOPIC, FrameTransforms)
            self._writer.add_message(scene_ch, 0, scene.scene_update(0).SerializeToString(), 0, sequence=0)
            self._writer.add_message(self._tf, 0, scene.static_transforms(0).SerializeToString(), 0, sequence=0)
        self._count = 0
        self._last: tuple[int, float] | None = None
        self._closed = False

    def _register(self, topic: str, message_class: Any) -> int:
        """A protobuf channel for a foxglove schema (its FileDescriptorSet as the schema data)."""
        from mcap_protobuf.schema import build_file_descriptor_set

        data = build_file_descriptor_set(message_class).SerializeToString()
        schema_id = self._writer.register_schema(message_class.DESCRIPTOR.full_name, "protobuf", data)
        return self._writer.register_channel(topic, "protobuf", schema_id)

    def write_step(self, step: int, time_s: float, data: Mapping[str, np.ndarray]) -> None:
        """Append one policy step (and, with a scene, the scene envs' moving frames at that time).

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
        log_time = round(time_s * 1e9)
        payload = self._codec.encode(step, time_s, arrays)
        self._writer.add_message(self._channel, log_time, payload, log_time, sequence=self._count)
        if self.scene is not None and self._tf is not None:
            qpos = self.scene.qpos(arrays["base_pos"], arrays["base_quat"], arrays["joint_pos"])
            tf = self.scene.step_transforms(qpos, log_time).SerializeToString()
            self._writer.add_message(self._tf, log_time, tf, log_time, sequence=self._count + 1)
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


def _arrays_from_json(messages: Sequence[dict], term_names: Sequence[str], num_envs: int) -> dict[str, np.ndarray]:
    """Format 1 (JSON messages, env-major, null for non-finite): per-field (T, N, *suffix) arrays."""
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
        kind = bool if spec.dtype == "bool" else np.float64  # None (JSON null) -> NaN
        arrays[name] = np.array(rows, dtype=kind).reshape(shape).astype(bool if kind is bool else np.float32)
    return arrays


def read_rollout(path: Path) -> RolloutLog:
    """Read the numbers of a rollout log written by :class:`RolloutLogWriter`, with the ``mcap`` library's reader.

    Reads only the ``/rollout/step`` channel (the scene is for Foxglove). Logs of format 1 (JSON messages) read
    to the same arrays.

    Raises:
        ValueError: The file has no ``morfic`` metadata record or an unknown ``format``.
    """
    with open(path, "rb") as f:
        reader = make_reader(f)
        records = [m for m in reader.iter_metadata() if m.name == METADATA_NAME]
        if not records:
            raise ValueError(f"{path}: no {METADATA_NAME!r} metadata record; not a morfic rollout log")
        metadata = decode_metadata(records[-1].metadata)
        fmt = metadata.get("format")
        if fmt not in (ROLLOUT_FORMAT, "morfic.rollout/1"):
            raise ValueError(f"{path}: rollout format {fmt!r}, expected {ROLLOUT_FORMAT!r}")
        schema, payloads = None, []
        for sch, _, msg in reader.iter_messages(topics=[ROLLOUT_TOPIC], log_time_order=False):
            schema = sch
            payloads.append(msg.data)
    term_names = list(metadata["term_names"])
    num_envs = int(metadata["num_envs"])
    if fmt == "morfic.rollout/1":
        messages = [json.loads(p) for p in payloads]
        return RolloutLog(
            metadata,
            term_names,
            _arrays_from_json(messages, term_names, num_envs),
            np.array([m["step"] for m in messages], dtype=np.int64),
            np.array([m["time_s"] for m in messages], dtype=np.float64),
        )
    codec = (
        step_codec(term_names) if schema is None else StepCodec.from_schema(step_codec(term_names).fields, schema.data)
    )
    steps, times, arrays = codec.decode(payloads, num_envs)
    return RolloutLog(metadata=metadata, term_names=term_names, arrays=arrays, steps=steps, time_s=times)
