"""MCAP rollout logs: a hand-made 3-env x 5-step rollout written, then read back with morfic and without."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from morfic_cli.recording.rollout_log import (
    METADATA_NAME,
    ROLLOUT_FIELDS,
    ROLLOUT_FORMAT,
    ROLLOUT_SCHEMA_NAME,
    ROLLOUT_TOPIC,
    RolloutLogWriter,
    read_rollout,
)

N, T = 3, 5
TERMS = ["r_lin", "p_vz"]
DT = 0.02
META = {
    "run": "run-1a2b",
    "checkpoint": "ckpt-3c4d",
    "robot": "go2",
    "descriptor": [0.25, 1.5, -3.0],
    "mode": "zero-shot",
    "command": [0.5, 0.0, 0.25],
    "seed": 7,
    "morfic_version": "0.1.0",
    "deterministic": True,
    "push_scale": 0.1,
    "numeric_string": "42",
}


def make_step(t: int) -> dict[str, np.ndarray]:
    """Step t of the hand-made rollout: every value encodes (t, env i, component j), e.g. 1.01 = t 1, i 0, j 1.

    Values like 0.1 are not exact in binary, so they test the float32 round trip.
    """
    i = np.arange(N, dtype=np.float64)[:, None]

    def vec(n: int, offset: float = 0.0) -> np.ndarray:
        return offset + t + 0.1 * i + 0.01 * np.arange(n)

    return {
        "base_pos": vec(3),
        "base_quat": np.tile([1.0, 0.0, 0.0, 0.0], (N, 1)),
        "base_lin_vel": vec(3, 10.0),
        "base_ang_vel": vec(3, -10.0),
        "command": np.tile([0.5, 0.0, 0.25], (N, 1)),
        "joint_pos": vec(12, 100.0),
        "joint_vel": vec(12, -100.0),
        "action": vec(12, 0.5),
        "reward": 0.001 * t + i[:, 0],
        "reward_terms": np.stack([0.001 * t + i[:, 0], -0.003 * np.ones(N)], axis=1),
        "value": 1e-7 * (t + 1) + i[:, 0],
        "done": np.array([t == 4, False, t == 2]),
        "time_out": np.array([t == 4, False, False]),
    }


@pytest.fixture
def log_path(tmp_path: Path) -> Path:
    path = tmp_path / "logs" / "go2" / "cmd0.mcap"  # parents created by the writer
    with RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata=META) as log:
        for t in range(T):
            log.write_step(10 + t, 0.2 + t * DT, make_step(t))
    return path


def test_read_rollout_gives_back_the_written_values(log_path):
    log = read_rollout(log_path)
    assert log.term_names == TERMS
    assert log.num_steps == T and log.num_envs == N
    assert log.steps.dtype == np.int64 and log.steps.tolist() == [10, 11, 12, 13, 14]
    assert log.time_s.dtype == np.float64 and log.time_s.tolist() == [0.2 + t * DT for t in range(T)]
    assert list(log.arrays) == list(ROLLOUT_FIELDS)
    for name, spec in ROLLOUT_FIELDS.items():
        want = np.stack([make_step(t)[name] for t in range(T)]).astype(np.float32 if spec.dtype == "float32" else bool)
        got = log.arrays[name]
        assert got.dtype == want.dtype, name
        assert got.shape == want.shape, name
        np.testing.assert_array_equal(got, want, err_msg=name)  # exact float32
    assert log.arrays["reward_terms"].shape == (T, N, 2)
    assert log.arrays["joint_pos"][3, 2, 11] == np.float32(100 + 3 + 0.2 + 0.11)
    assert log.arrays["done"][:, 0].tolist() == [False, False, False, False, True]
    assert log.arrays["reward_terms"][:, 1, 1].tolist() == [np.float32(-0.003)] * T


def test_metadata_round_trips_typed(log_path):
    meta = read_rollout(log_path).metadata
    assert meta == {**META, "format": ROLLOUT_FORMAT, "num_envs": N, "term_names": TERMS, "scene_envs": []}
    assert isinstance(meta["seed"], int) and meta["deterministic"] is True
    assert meta["numeric_string"] == "42"  # strings stay strings even when they look like JSON

    with open(log_path, "rb") as f:
        records = list(make_reader(f).iter_metadata())
    assert [r.name for r in records] == [METADATA_NAME]
    raw = records[0].metadata
    assert raw["robot"] == "go2" and raw["numeric_string"] == "42"  # str values stored as is
    assert raw["seed"] == "7" and raw["command"] == "[0.5, 0.0, 0.25]" and raw["term_names"] == '["r_lin", "p_vz"]'
    assert set(json.loads(raw["json_keys"])) == {
        "descriptor",
        "command",
        "seed",
        "deterministic",
        "push_scale",
        "num_envs",
        "term_names",
        "scene_envs",
    }


def test_raw_mcap_schema_channel_chunks_and_messages(log_path):
    """The numeric channel is protobuf with its FileDescriptorSet; mcap-protobuf-support decodes it (no morfic)."""
    from mcap_protobuf.decoder import DecoderFactory

    with open(log_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        messages = list(reader.iter_decoded_messages(topics=[ROLLOUT_TOPIC]))

    (schema,) = summary.schemas.values()  # no scene: one schema, one channel
    assert schema.encoding == "protobuf" and schema.name == ROLLOUT_SCHEMA_NAME == "morfic.RolloutStep"
    (channel,) = summary.channels.values()
    assert channel.topic == ROLLOUT_TOPIC and channel.message_encoding == "protobuf" and channel.schema_id == schema.id
    assert channel.metadata == {"num_envs": str(N)}
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert summary.statistics.message_count == T

    assert len(messages) == T
    for t, (sch, ch, msg, body) in enumerate(messages):
        assert sch.id == schema.id and ch.id == channel.id
        assert msg.log_time == msg.publish_time == round((0.2 + t * DT) * 1e9)
        assert body.step == 10 + t and body.time_s == 0.2 + t * DT
        assert len(body.envs) == N
        env1 = body.envs[1]
        assert [f.name for f in env1.DESCRIPTOR.fields] == list(ROLLOUT_FIELDS)
        assert list(env1.base_pos) == [np.float32(t + 0.1 + 0.01 * j) for j in range(3)]
        assert len(env1.joint_pos) == 12
        # reward terms by name, as Foxglove plots /rollout/step.envs[1].reward_terms.r_lin
        assert env1.reward_terms.r_lin == np.float32(0.001 * t + 1) and env1.reward_terms.p_vz == np.float32(-0.003)
        assert env1.done is False and body.envs[2].done is (t == 2)


def test_non_finite_values_read_back_as_written(tmp_path):
    path = tmp_path / "nan.mcap"
    data = make_step(0)
    data["value"] = np.array([np.nan, np.inf, 1.0])
    with RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={}) as log:
        log.write_step(0, 0.0, data)
    value = read_rollout(path).arrays["value"][0]
    assert np.isnan(value[0]) and value[1] == np.inf and value[2] == 1.0


def test_term_names_must_be_identifiers(tmp_path):
    with pytest.raises(ValueError, match="identifiers"):
        RolloutLogWriter(tmp_path / "x.mcap", num_envs=N, term_names=["r lin"], metadata={})


def test_format_1_json_logs_still_read(tmp_path):
    """A log of the previous layout (JSON messages, null for NaN) reads to the same arrays."""
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "v1.mcap"
    env = {
        "base_pos": [0.1, 0.2, 0.3],
        "base_quat": [1.0, 0.0, 0.0, 0.0],
        "base_lin_vel": [1.5, 0.0, 0.0],
        "base_ang_vel": [0.0, 0.0, 0.0],
        "command": [2.0, 0.0, 0.0],
        "joint_pos": [0.5] * 12,
        "joint_vel": [0.0] * 12,
        "action": [0.25] * 12,
        "reward": 0.07,
        "reward_terms": {"r_lin": 0.08, "p_vz": None},
        "value": 1.9,
        "done": True,
        "time_out": False,
    }
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start()
        sid = w.register_schema("morfic.RolloutStep", "jsonschema", b"{}")
        cid = w.register_channel(ROLLOUT_TOPIC, "json", sid)
        w.add_metadata(
            METADATA_NAME,
            {
                "format": "morfic.rollout/1",
                "num_envs": "1",
                "term_names": '["r_lin", "p_vz"]',
                "json_keys": '["num_envs", "term_names"]',
            },
        )
        w.add_message(cid, 20_000_000, json.dumps({"step": 0, "time_s": 0.02, "envs": [env]}).encode(), 20_000_000)
        w.finish()
    log = read_rollout(path)
    assert log.steps.tolist() == [0] and log.time_s.tolist() == [0.02]
    assert log.arrays["base_pos"].tolist() == [[[np.float32(0.1), np.float32(0.2), np.float32(0.3)]]]
    assert log.arrays["reward_terms"][0, 0, 0] == np.float32(0.08) and np.isnan(log.arrays["reward_terms"][0, 0, 1])
    assert log.arrays["done"].tolist() == [[True]] and log.arrays["joint_pos"].shape == (1, 1, 12)


@pytest.mark.parametrize(
    ("name", "value", "match"),
    [
        ("base_pos", np.zeros((N, 4)), r"'base_pos': expected shape \(num_envs, 3\) = \(3, 3\), got \(3, 4\)"),
        ("base_pos", np.zeros((2, 3)), r"'base_pos': expected shape \(num_envs, 3\) = \(3, 3\), got \(2, 3\)"),
        ("reward_terms", np.zeros((N, 3)), r"'reward_terms': expected shape \(num_envs, K\) = \(3, 2\), got \(3, 3\)"),
        ("reward", np.zeros((N, 1)), r"'reward': expected shape \(num_envs\) = \(3,\), got \(3, 1\)"),
        ("done", np.array([0.0, 1.0, 0.5]), r"'done': expected bool"),
        ("action", np.array([["a"] * 12] * N), r"'action': expected numbers"),
    ],
)
def test_bad_step_data_raises_and_writes_nothing(tmp_path, name, value, match):
    path = tmp_path / "bad.mcap"
    with RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={}) as log:
        log.write_step(0, 0.0, make_step(0))
        with pytest.raises(ValueError, match=match):
            log.write_step(1, DT, {**make_step(1), name: value})
    assert read_rollout(path).num_steps == 1


def test_field_set_step_order_and_closed_writer(tmp_path):
    path = tmp_path / "x.mcap"
    log = RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={})
    data = make_step(0)
    with pytest.raises(ValueError, match=r"missing fields \['value'\], unknown fields \['valeu'\]"):
        log.write_step(0, 0.0, {**{k: v for k, v in data.items() if k != "value"}, "valeu": data["value"]})
    log.write_step(0, 1.0, {**data, "done": np.array([1, 0, 1])})  # 0/1 integers are accepted as bools
    with pytest.raises(ValueError, match="step must increase"):
        log.write_step(0, 2.0, data)
    with pytest.raises(ValueError, match="time_s not decrease"):
        log.write_step(1, 0.5, data)
    with pytest.raises(ValueError, match="finite time_s >= 0"):
        log.write_step(1, float("nan"), data)
    log.close()
    log.close()  # idempotent
    with pytest.raises(ValueError, match="closed"):
        log.write_step(5, 3.0, data)
    assert read_rollout(path).arrays["done"][0].tolist() == [True, False, True]


def test_bad_constructor_arguments(tmp_path):
    path = tmp_path / "x.mcap"
    with pytest.raises(ValueError, match="reserved"):
        RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={"format": "mine"})
    with pytest.raises(ValueError, match="term_names"):
        RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={"term_names": ["a", "b"]})
    with pytest.raises(ValueError, match="'bad'"):
        RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={"bad": object()})
    with pytest.raises(ValueError, match="distinct"):
        RolloutLogWriter(path, num_envs=N, term_names=["a", "a"], metadata={})
    with pytest.raises(ValueError, match="num_envs"):
        RolloutLogWriter(path, num_envs=0, term_names=TERMS, metadata={})
    assert not path.exists()  # nothing written before the arguments are checked
    # agreeing num_envs / term_names, numpy values and tuples are fine
    with RolloutLogWriter(
        path,
        num_envs=N,
        term_names=TERMS,
        metadata={"num_envs": N, "term_names": TERMS, "seed": np.int64(3), "cmd": (1.0, 0.0)},
    ):
        pass
    log = read_rollout(path)
    assert log.metadata["seed"] == 3 and log.metadata["cmd"] == [1.0, 0.0]
    assert log.num_steps == 0 and log.arrays["reward_terms"].shape == (0, N, 2)


def test_float32_round_trip_is_exact_for_random_values(tmp_path):
    rng = np.random.default_rng(0)
    bits = rng.integers(0, 2**32, size=(T, N, 12), dtype=np.uint32).view(np.float32)
    bits[~np.isfinite(bits)] = 1.5  # every finite float32, from subnormals to 3e38
    path = tmp_path / "r.mcap"
    with RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={}) as log:
        for t in range(T):
            log.write_step(t, t * DT, {**make_step(t), "joint_vel": bits[t]})
    np.testing.assert_array_equal(read_rollout(path).arrays["joint_vel"], bits)


def test_exception_inside_with_still_leaves_a_readable_log(tmp_path):
    path = tmp_path / "crash.mcap"
    with pytest.raises(RuntimeError), RolloutLogWriter(path, num_envs=N, term_names=TERMS, metadata={}) as log:
        log.write_step(0, 0.0, make_step(0))
        log.write_step(1, DT, make_step(1))
        raise RuntimeError("policy crashed")
    log = read_rollout(path)
    assert log.steps.tolist() == [0, 1]
    np.testing.assert_array_equal(log.arrays["base_pos"][1], make_step(1)["base_pos"].astype(np.float32))


def test_read_rollout_rejects_a_foreign_mcap(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    with pytest.raises(ValueError, match="not a morfic rollout log"):
        read_rollout(path)
