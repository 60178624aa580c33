"""`morfic eval` on a smoke checkpoint: every robot in both modes, stored MCAP logs, table, bad input."""

from __future__ import annotations

import csv
import io
import json
import os

import numpy as np
import pytest
from smoke_runs import copy_store

from morfic_cli.evaluation.protocol import EvalCfg, eval_columns, evaluate, rollout_role
from morfic_cli.evaluation.terminations import read_terminations, termination_counts, termination_names
from morfic_cli.morphology.robots import list_robots

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def smoke_store(smoke_runs):
    """One smoke-trained film checkpoint (the session's template), shared by the tests of this module (copied per
    test)."""
    return smoke_runs.template()


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    return copy_store(smoke_store, tmp_path, monkeypatch)


def test_every_robot_in_both_modes_through_the_cli(run_cli, store):
    code, out, err = run_cli(
        "eval",
        "runs/film-s0",
        "--robots",
        "all",
        "--mode",
        "both",
        "--envs",
        "2",
        "--steps",
        "6",
        "--command-vx",
        "1.0",
        "--format",
        "json",
        "--quiet",
    )
    assert code == 0, err
    rows = json.loads(out)
    robots = list_robots()
    assert [(r["robot"], r["mode"]) for r in rows] == [(n, m) for n in robots for m in ("descriptor", "full")]
    for row in rows:
        assert {
            "robot",
            "mode",
            "command_vx",
            "vx_mean",
            "vx_std",
            "vx_env_std",
            "vx_peak_1s_mean",
            "survival",
            "valid",
        } <= set(row)
        assert row["command_vx"] == 1.0 and 0.0 <= row["survival"] <= 1.0 and isinstance(row["valid"], bool)
        assert row["num_envs"] == 2 and row["steps"] == 6
        assert " / " in row["cell"]
        assert list(row["terminations"]) == list(termination_names())  # envs per term, zeros included
    assert next(r for r in rows if r["robot"] == "go2")["d"] == 0.0
    manifest = store.read_manifest("evals/film-s0")
    assert manifest.kind == "eval"
    assert manifest.inputs["checkpoint"] == store.resolve("runs/film-s0")
    assert len([k for k in manifest.inputs if k.startswith("rollout/")]) == 2 * len(robots)
    table = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "eval.csv").decode())))
    assert [r["robot"] for r in table] == [r["robot"] for r in rows]


def test_stored_mcap_logs_read_back_to_the_rollout_arrays(store, tmp_path):
    from mcap.reader import make_reader

    from morfic_cli.recording.rollout_log import read_rollout

    cfg = EvalCfg(robots=("a1",), modes=("descriptor",), command_vx=(1.5,), num_envs=3, steps=7, seed=2)
    result = evaluate(store, "runs/film-s0", cfg)
    role = rollout_role("a1", "descriptor", 1.5)
    rollout = result.rollouts[role]
    rid = store.read_manifest(result.id).inputs[role]
    path = tmp_path / "a1.mcap"
    path.write_bytes(store.read_file(rid, "rollout.mcap"))
    log = read_rollout(path)
    for key in ("base_pos", "base_quat", "joint_pos", "action", "reward", "value", "reward_terms"):
        np.testing.assert_array_equal(log.arrays[key], rollout.arrays[key].astype(log.arrays[key].dtype), key)
    np.testing.assert_array_equal(log.arrays["done"], rollout.arrays["done"])
    assert log.term_names == rollout.term_names
    assert log.metadata["robot"] == "a1" and log.metadata["mode"] == "descriptor"
    assert log.metadata["checkpoint"] == store.resolve("runs/film-s0")
    assert log.metadata["command"] == [1.5, 0.0, 0.0] and log.metadata["seed"] == 2
    with open(path, "rb") as fh:  # the mcap library's own reader sees 7 step messages (and 7 + 1 /tf, 1 /scene)
        assert sum(1 for _ in make_reader(fh).iter_messages(topics=["/rollout/step"])) == 7
    # per-step rewards are the sum of the logged term contributions
    np.testing.assert_allclose(rollout.arrays["reward_terms"].sum(-1), rollout.arrays["reward"], atol=1e-5)


def test_rollout_metrics_follow_the_recorded_arrays(store):
    """The table row is the metrics function applied to the recorded arrays (no second code path)."""
    from morfic_cli.evaluation.metrics import transfer_metrics

    cfg = EvalCfg(robots=("go2",), command_vx=(1.0,), num_envs=4, steps=30, seed=1)
    result = evaluate(store, "runs/film-s0", cfg)
    rollout = result.rollouts[rollout_role("go2", "descriptor", 1.0)]
    a = rollout.arrays
    m = transfer_metrics(
        a["base_lin_vel"][..., 0],
        a["done"] & ~a["time_out"],
        1.0,
        0.02,
        tilt=a["tilt"],
        height_ratio=a["height_ratio"],
        foot_slip=a["foot_slip"],
    )
    row = result.rows[0]
    assert row["vx_mean"] == pytest.approx(m.vx_mean) and row["survival"] == m.survival
    assert not a["time_out"].any()  # the eval episode is longer than the rollout
    np.testing.assert_allclose(a["command"][..., 0], 1.0)
    assert a["base_pos"].shape == (30, 4, 3) and a["value"].shape == (30, 4)
    # the termination counts are those of the recorded masks, stored beside eval.csv (whose columns stay the table's)
    names = list(termination_names())
    assert rollout.termination_names == names and a["terminations"].shape == (30, 4, len(names))
    assert row["terminations"] == termination_counts(a["done"], a["time_out"], a["terminations"], names)
    assert [(r["robot"], r["term"], r["envs"]) for r in read_terminations(store, result.id)] == [
        ("go2", k, n) for k, n in row["terminations"].items()
    ]
    header = store.read_file(result.id, "eval.csv").decode().splitlines()[0]
    assert header.split(",") == list(eval_columns())


def test_every_fall_of_a_real_eval_is_counted_under_the_terms_that_ended_it(store):
    """B1 on the Go2 template at 2 m/s: the smoke policy falls within 30 steps (4 envs), so there is something to
    count; each fallen env tripped at least one term on its fatal step, and no surviving env is counted."""
    cfg = EvalCfg(robots=("b1",), command_vx=(2.0,), num_envs=4, steps=30, seed=0, scene_envs=0)
    result = evaluate(store, "runs/film-s0", cfg)
    a = result.rollouts[rollout_role("b1", "descriptor", 2.0)].arrays
    row = result.rows[0]
    fell = a["done"].any(0)
    assert fell.any() and row["survival"] == pytest.approx(1.0 - fell.mean())
    assert sum(row["terminations"].values()) >= int(fell.sum())
    fatal = a["terminations"][a["done"].argmax(0), np.arange(4)]  # (N, K): the terms on each env's first end
    assert (fatal.any(-1) == fell).all()  # an end has a term, and a term ended the episode
    assert list(fatal.sum(0)) == list(row["terminations"].values())


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["runs/nothing"], "no artifact 'runs/nothing'"),
        (["runs/film-s0", "--robots", "go3"], "unknown robot 'go3'"),
        (["runs/film-s0", "--command-vx", "fast"], "--command-vx takes"),
        (
            ["runs/film-s0", "--mode", "sideways"],
            "'sideways' is not one of 'descriptor', 'full', 'actuation-matched', 'both'",
        ),
        (["runs/film-s0", "--envs", "0"], "Invalid value for '--envs'"),
    ],
)
def test_bad_input_is_an_error_and_writes_nothing(run_cli, store, argv, needle):
    refs = store.list_refs()
    code, out, err = run_cli("eval", argv[0], "--steps", "2", "--envs", "2", *argv[1:])  # later flags win
    assert code == 1 and err.startswith("Error: ") and needle in err, err
    assert out == "" and store.list_refs() == refs


def test_eval_of_a_trainer_state_is_refused(run_cli, store):
    state = store.read_manifest("runs/film-s0").inputs["trainer_state"]
    code, _, err = run_cli("eval", state, "--robots", "go2", "--steps", "2", "--envs", "1")
    assert code == 1 and "not a training checkpoint" in err
    assert os.environ["MORFIC_STORE"] == str(store.root)


def test_video_is_stored_and_written_into_out(run_cli, store, tmp_path, gl_backend):
    out = tmp_path / "results"
    code, _, err = run_cli(
        "eval",
        "runs/film-s0",
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "4",
        "--command-vx",
        "1.0",
        "--video",
        "--out",
        str(out),
        "--format",
        "json",
        "--quiet",
    )
    assert code == 0, err
    videos = sorted(p.name for p in out.iterdir())
    ext = "mp4" if any(n.endswith(".mp4") for n in videos) else "gif"
    assert videos == sorted(
        [
            "eval.csv",
            "terminations.csv",
            "go2-descriptor-vx1-frames.png",
            f"go2-descriptor-vx1.{ext}",
            "go2-descriptor-vx1-speed.png",
            "go2-descriptor-vx1-speed.pdf",
            "go2-descriptor-vx1.mcap",
        ]
    )
    media = store.ls("media")
    assert len(media) == 1
    manifest = store.read_manifest(media[0]["id"])
    assert manifest.inputs["eval"] == store.resolve("evals/film-s0")
    assert store.read_manifest(manifest.inputs["rollout"]).kind == "rollout"
    assert store.read_file(manifest.id, f"video.{ext}") == (out / f"go2-descriptor-vx1.{ext}").read_bytes()
    # the eval figure in --out is the one stored with the rollout
    speed = (out / "go2-descriptor-vx1-speed.png").read_bytes()
    assert speed.startswith(b"\x89PNG") and store.read_file(manifest.inputs["rollout"], "speed.png") == speed


def test_out_holds_the_mcap_log_of_every_rollout(run_cli, store, tmp_path):
    from morfic_cli.recording.rollout_log import read_rollout

    out = tmp_path / "results"
    code, _, err = run_cli(
        "eval",
        "runs/film-s0",
        "--robots",
        "go2,a1",
        "--envs",
        "2",
        "--steps",
        "3",
        "--command-vx",
        "1.0,1.5",
        "--out",
        str(out),
        "--format",
        "json",
    )
    assert code == 0, err
    logs = sorted(p.name for p in out.glob("*.mcap"))
    assert logs == sorted(f"{r}-descriptor-vx{vx}.mcap" for r in ("a1", "go2") for vx in ("1", "1.5"))
    manifest = store.read_manifest("evals/film-s0")
    for role, rid in manifest.inputs.items():
        if role.startswith("rollout/"):
            name = role.removeprefix("rollout/").replace("/", "-") + ".mcap"
            assert (out / name).read_bytes() == store.read_file(rid, "rollout.mcap")
            assert f"rollout log (MCAP, open in Foxglove): {out / name}" in err
    log = read_rollout(out / "a1-descriptor-vx1.5.mcap")
    assert log.num_envs == 2 and log.num_steps == 3
    assert log.metadata["robot"] == "a1" and log.metadata["command"] == [1.5, 0.0, 0.0]


def _compose(transforms: dict, frame: str, stop: str) -> tuple[np.ndarray, np.ndarray]:
    """World pose of ``frame`` relative to ``stop`` from parent-relative foxglove transforms (w, x, y, z)."""
    import mujoco

    pos, quat = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    while frame != stop:
        parent, t, q = transforms[frame]
        # pose_in_parent o pose: p' = t + R(q) p, q' = q * quat
        rotated = np.zeros(3)
        mujoco.mju_rotVecQuat(rotated, pos, q)
        new_q = np.zeros(4)
        mujoco.mju_mulQuat(new_q, q, quat)
        pos, quat, frame = t + rotated, new_q, parent
    return pos, quat


def test_eval_log_has_a_3d_scene_foxglove_reads(store, tmp_path):
    """Read with the mcap library and the protobuf schemas in the file only: numbers, body frames and geoms."""
    from collections import defaultdict

    import mujoco
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    cfg = EvalCfg(robots=("a1",), modes=("full",), command_vx=(1.0,), num_envs=3, steps=6, seed=1, scene_envs=2)
    result = evaluate(store, "runs/film-s0", cfg)
    role = rollout_role("a1", "full", 1.0)
    rollout = result.rollouts[role]
    path = tmp_path / "a1.mcap"
    path.write_bytes(store.read_file(store.read_manifest(result.id).inputs[role], "rollout.mcap"))

    by_topic, schemas = defaultdict(list), {}
    with open(path, "rb") as fh:
        for schema, channel, message, decoded in make_reader(
            fh, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            by_topic[channel.topic].append((message.log_time, decoded))
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
    assert schemas == {
        "/rollout/step": ("morfic.RolloutStep", "protobuf", "protobuf"),
        "/scene": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
        "/tf": ("foxglove.FrameTransforms", "protobuf", "protobuf"),
    }
    steps = by_topic["/rollout/step"]
    assert len(steps) == 6 and len(by_topic["/scene"]) == 1 and len(by_topic["/tf"]) == 1 + 6

    # the numbers are those the rollout produced
    a = rollout.arrays
    for k, (_, msg) in enumerate(steps):
        assert msg.step == k and len(msg.envs) == 3
        for i, env in enumerate(msg.envs):
            for key in ("base_pos", "base_quat", "joint_pos", "joint_vel", "action", "command"):
                np.testing.assert_array_equal(np.array(getattr(env, key), np.float32), a[key][k, i], key)
            assert env.value == a["value"][k, i] and env.reward == a["reward"][k, i] and env.done == a["done"][k, i]
            assert [getattr(env.reward_terms, n) for n in rollout.term_names] == a["reward_terms"][k, i].tolist()

    # every body's frame at step k is MuJoCo's xpos / xquat at the logged qpos of that env and step
    (t0, static), tf_steps = by_topic["/tf"][0], by_topic["/tf"][1:]
    assert t0 == 0
    fixed = {t.child_frame_id: t for t in static.transforms}
    offsets = [fixed[f"env{i}/world"].translation for i in range(2)]
    assert fixed["env0/world"].parent_frame_id == "world" and abs(offsets[1].y - offsets[0].y) >= 1.0
    for k, ((t_step, msg), (t_tf, moving)) in enumerate(zip(steps, tf_steps, strict=True)):
        assert t_tf == t_step
        transforms = {}
        for t in [*static.transforms, *moving.transforms]:
            transforms[t.child_frame_id] = (
                t.parent_frame_id,
                np.array([t.translation.x, t.translation.y, t.translation.z]),
                np.array([t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z]),
            )
        for i in range(2):
            model = rollout.models[i]
            data = mujoco.MjData(model)
            env = msg.envs[i]
            data.qpos[0:3], data.qpos[3:7] = env.base_pos, env.base_quat
            joints = [f"{leg}_{j}_joint" for leg in ("FL", "FR", "RL", "RR") for j in ("hip", "thigh", "calf")]
            data.qpos[[model.joint(n).qposadr[0] for n in joints]] = env.joint_pos
            mujoco.mj_kinematics(model, data)
            for b in range(1, model.nbody):
                pos, quat = _compose(transforms, f"env{i}/{model.body(b).name}", f"env{i}/world")
                np.testing.assert_allclose(pos, data.xpos[b], atol=1e-9, err_msg=f"step {k} env {i} body {b}")
                sign = 1.0 if np.dot(quat, data.xquat[b]) >= 0 else -1.0
                np.testing.assert_allclose(sign * quat, data.xquat[b], atol=1e-9)
        assert not any(f.startswith("env2/") for f in transforms)  # env 2 carries no frames

    # the scene: one entity per geom of each scene env, in its body's frame, with the geom's type and size
    ((_, scene),) = by_topic["/scene"]
    entities = {e.id: e for e in scene.entities}
    model = rollout.models[0]
    assert "floor" in entities and entities["floor"].cubes[0].size.x >= 100
    drawn = [g for g in range(model.ngeom) if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_PLANE]
    assert len(entities) == 1 + 2 * len(drawn)
    for i in range(2):
        for g in drawn:
            e = entities[f"env{i}/{model.geom(g).name}"]
            size = model.geom_size[g]
            assert e.frame_id == f"env{i}/{model.body(model.geom_bodyid[g]).name}" and e.frame_locked
            kind = mujoco.mjtGeom(model.geom_type[g])
            meta = {kv.key: kv.value for kv in e.metadata}
            if kind == mujoco.mjtGeom.mjGEOM_BOX:
                (cube,) = e.cubes
                assert meta["type"] == "box"
                np.testing.assert_allclose([cube.size.x, cube.size.y, cube.size.z], 2 * size)
                prim = cube
            elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
                (prim,) = e.spheres
                assert meta["type"] == "sphere" and prim.size.x == pytest.approx(2 * size[0])
            else:
                assert kind == mujoco.mjtGeom.mjGEOM_CAPSULE and meta["type"] == "capsule"
                (prim,) = e.cylinders
                assert len(e.spheres) == 2  # the end caps
                assert prim.size.x == pytest.approx(2 * size[0]) and prim.size.z == pytest.approx(2 * size[1])
            p = prim.pose.position
            np.testing.assert_allclose([p.x, p.y, p.z], model.geom_pos[g], atol=1e-12)
            c = prim.color
            np.testing.assert_allclose([c.r, c.g, c.b, c.a], model.geom_rgba[g], rtol=1e-6)
