"""The protobuf message of the numeric channel ``/rollout/step``: its schema, built per log, and the array codec.

One message per policy step, env-major, so Foxglove plots ``/rollout/step.envs[0].base_lin_vel[0]`` or
``/rollout/step.envs[3].reward_terms.r_lin``::

    message RolloutStep { uint32 step = 1; double time_s = 2; repeated EnvStep envs = 3; }
    message EnvStep {                        // one field per entry of ROLLOUT_FIELDS, in that order
      repeated float base_pos = 1; ...; float reward = 9; RewardTerms reward_terms = 10; float value = 11;
      bool done = 12; bool time_out = 13; }
    message RewardTerms { float r_lin = 1; float p_vz = 2; ... }   // one float per reward term, in column order

``RewardTerms`` has one field per term name, so the schema is built for each log from its term names (a
``FileDescriptorSet``, the MCAP ``protobuf`` schema encoding) and the message class is made from it with
``google.protobuf``'s descriptor pool. float32 values travel as protobuf ``float`` (IEEE binary32, bit-exact,
NaN and inf included); ``time_s`` as ``double``. Shapes: N = envs, K = reward terms.

Speed: a packed ``repeated float`` field is, on the wire, a length-delimited field holding the little-endian float32
values, exactly what a ``bytes`` field with those bytes is. So the codec encodes and decodes with a *wire twin* of
the schema in which the vector fields are ``bytes`` (``array.tobytes()`` in, ``np.frombuffer`` out), through the
protobuf library, instead of converting every float to a Python object; the schema written to the log (what
Foxglove and any protobuf reader use) has them as ``repeated float``.
"""

from __future__ import annotations

import itertools
import operator
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

PACKAGE = "morfic"
STEP_MESSAGE = f"{PACKAGE}.RolloutStep"
"""Full name of the step message (the MCAP schema name)."""

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_F = descriptor_pb2.FieldDescriptorProto


def _file_proto(
    fields: Mapping[str, tuple[tuple[int | str, ...], str]], term_names: Sequence[str], wire_twin: bool = False
):
    """The FileDescriptorProto of the three messages for these fields ({name: (shape, dtype)}) and terms.

    ``wire_twin``: vector fields as ``bytes`` (the same wire format as packed ``repeated float``).
    """
    fdp = descriptor_pb2.FileDescriptorProto(name="morfic/rollout_step.proto", package=PACKAGE, syntax="proto3")
    terms = fdp.message_type.add(name="RewardTerms")
    for i, name in enumerate(term_names):
        terms.field.add(name=name, number=i + 1, type=_F.TYPE_FLOAT, label=_F.LABEL_OPTIONAL)
    env = fdp.message_type.add(name="EnvStep")
    for i, (name, (shape, dtype)) in enumerate(fields.items()):
        if name == "reward_terms":
            env.field.add(
                name=name,
                number=i + 1,
                type=_F.TYPE_MESSAGE,
                type_name=f".{PACKAGE}.RewardTerms",
                label=_F.LABEL_OPTIONAL,
            )
        elif dtype == "bool":
            env.field.add(name=name, number=i + 1, type=_F.TYPE_BOOL, label=_F.LABEL_OPTIONAL)
        elif shape == ():
            env.field.add(name=name, number=i + 1, type=_F.TYPE_FLOAT, label=_F.LABEL_OPTIONAL)
        elif wire_twin:
            env.field.add(name=name, number=i + 1, type=_F.TYPE_BYTES, label=_F.LABEL_OPTIONAL)
        else:  # proto3 packs repeated scalars by default
            env.field.add(name=name, number=i + 1, type=_F.TYPE_FLOAT, label=_F.LABEL_REPEATED)
    step = fdp.message_type.add(name="RolloutStep")
    step.field.add(name="step", number=1, type=_F.TYPE_UINT32, label=_F.LABEL_OPTIONAL)
    step.field.add(name="time_s", number=2, type=_F.TYPE_DOUBLE, label=_F.LABEL_OPTIONAL)
    step.field.add(
        name="envs", number=3, type=_F.TYPE_MESSAGE, type_name=f".{PACKAGE}.EnvStep", label=_F.LABEL_REPEATED
    )
    return fdp


@dataclass
class StepCodec:
    """Encodes a step's arrays to ``RolloutStep`` bytes and decodes a log's messages back to arrays.

    Attributes:
        fields: Field name -> (per-env shape suffix with K resolved, dtype "float32" or "bool"), message order.
        term_names: The K reward-term names (protobuf identifiers).
        schema_data: The serialised ``FileDescriptorSet`` (MCAP schema data, encoding ``protobuf``).
    """

    fields: dict[str, tuple[tuple[int, ...], str]]
    term_names: list[str]
    schema_data: bytes
    message_class: Any
    """The wire twin's step message class (vector fields as bytes)."""

    @classmethod
    def build(cls, fields: Mapping[str, tuple[tuple[int, ...], str]], term_names: Sequence[str]) -> StepCodec:
        """The codec for these fields and reward terms.

        Raises:
            ValueError: A term name is not a protobuf identifier (letters, digits, ``_``; not starting with a digit).
        """
        bad = [t for t in term_names if not _IDENT.match(t)]
        if bad:
            raise ValueError(f"term_names must be identifiers ([A-Za-z_][A-Za-z0-9_]*), got {bad}")
        fdp = _file_proto(fields, term_names)
        pool = descriptor_pool.DescriptorPool()
        pool.Add(_file_proto(fields, term_names, wire_twin=True))
        klass = message_factory.GetMessageClass(pool.FindMessageTypeByName(STEP_MESSAGE))
        fds = descriptor_pb2.FileDescriptorSet(file=[fdp])
        return cls(dict(fields), list(term_names), fds.SerializeToString(), klass)

    @classmethod
    def from_schema(cls, fields: Mapping[str, tuple[tuple[int, ...], str]], schema_data: bytes) -> StepCodec:
        """The codec of a written log, from its schema data (the term names are the ``RewardTerms`` fields)."""
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
        (fdp,) = fds.file
        terms = next(m for m in fdp.message_type if m.name == "RewardTerms")
        return cls.build(fields, [f.name for f in terms.field])

    def encode(self, step: int, time_s: float, arrays: Mapping[str, np.ndarray]) -> bytes:
        """One step as ``RolloutStep`` bytes.

        Args:
            step: Policy step index (>= 0).
            time_s: Step time (s).
            arrays: Field -> (N, *suffix) array, float32 or bool (``check_step_data``'s output).
        """
        msg = self.message_class(step=step, time_s=time_s)
        vectors = [n for n, (shape, _) in self.fields.items() if shape != () and n != "reward_terms"]
        scalars = [n for n, (shape, _) in self.fields.items() if shape == ()]
        blobs = {name: [row.tobytes() for row in np.ascontiguousarray(arrays[name], dtype="<f4")] for name in vectors}
        cols = {name: arrays[name].tolist() for name in scalars}
        terms, term_rows = self.term_names, arrays["reward_terms"].tolist()
        for i in range(len(term_rows)):
            env = msg.envs.add()
            for name in vectors:
                setattr(env, name, blobs[name][i])
            for name in scalars:
                setattr(env, name, cols[name][i])
            rt = env.reward_terms
            for name, v in zip(terms, term_rows[i], strict=True):
                setattr(rt, name, v)
        return msg.SerializeToString()

    def decode(self, payloads: Sequence[bytes], num_envs: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Decode T messages back to arrays.

        Returns:
            ``(steps (T,) int64, time_s (T,) float64, {field: (T, N, *suffix)})``, float32 or bool.

        Raises:
            ValueError: A message has other than ``num_envs`` envs.
        """
        vectors = [n for n, (shape, _) in self.fields.items() if shape != () and n != "reward_terms"]
        scalars = [n for n, (shape, _) in self.fields.items() if shape == ()]
        get_vec, get_sc = operator.attrgetter(*vectors), operator.attrgetter(*scalars)
        get_terms = operator.attrgetter(*self.term_names) if self.term_names else (lambda _rt: ())
        rows_v: list[list] = [[] for _ in vectors]
        rows_s, rows_t, steps, times = [], [], [], []
        for data in payloads:
            msg = self.message_class.FromString(data)
            if len(msg.envs) != num_envs:
                raise ValueError(f"rollout step {msg.step}: {len(msg.envs)} envs, metadata says {num_envs}")
            steps.append(msg.step)
            times.append(msg.time_s)
            for env in msg.envs:
                for rows, v in zip(rows_v, get_vec(env), strict=True):
                    rows.append(v)
                rows_s.append(get_sc(env))
                rows_t.append(get_terms(env.reward_terms))
        t = len(steps)
        out: dict[str, np.ndarray] = {}
        for name, rows in zip(vectors, rows_v, strict=True):
            shape = (t, num_envs, *self.fields[name][0])
            out[name] = np.frombuffer(b"".join(rows), dtype="<f4").astype(np.float32).reshape(shape)
        sc = np.array(rows_s, dtype=np.float64).reshape(t, num_envs, len(scalars))
        for k, name in enumerate(scalars):
            out[name] = sc[..., k].astype(bool if self.fields[name][1] == "bool" else np.float32)
        k = len(self.term_names)
        out["reward_terms"] = np.fromiter(
            itertools.chain.from_iterable(rows_t), np.float32, count=t * num_envs * k
        ).reshape(t, num_envs, k)
        return np.array(steps, dtype=np.int64), np.array(times, dtype=np.float64), {n: out[n] for n in self.fields}
