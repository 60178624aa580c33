"""`morfic export`: ONNX and TorchScript exports of a smoke run, verification, metadata, --check, bad input."""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from morfic_cli.export.artifact import ExportCfg, check_export, export_policy, plan_export, serialise
from morfic_cli.export.verify import model_mismatches
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.robots import list_robots, load_robot
from morfic_cli.rl.load import load_trained
from morfic_cli.store import Store

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def smoke_store(smoke_runs, tmp_path_factory):
    """A smoke-trained film run and its go1 ONNX export (with joint targets, also written to out/)."""
    base = tmp_path_factory.mktemp("export")
    store = smoke_runs.store(base / "store")
    export_policy(store, "runs/film-s0", ExportCfg(robot="go1", targets=True), out=base / "out")
    return base


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    root = tmp_path / "store"
    shutil.copytree(smoke_store / "store", root)
    shutil.copytree(smoke_store / "out", tmp_path / "out")
    monkeypatch.setenv("MORFIC_STORE", str(root))
    return Store(root)


def _actor_outputs(actor, history, morphology):
    n = history.shape[0]
    with torch.no_grad():
        return actor(
            TensorDict({"history": torch.as_tensor(history), "morphology": torch.as_tensor(morphology)}, batch_size=[n])
        ).numpy()


def test_onnx_export_through_the_cli_is_stored_verified_and_written(run_cli, store, tmp_path):
    out = tmp_path / "deploy"
    code, stdout, err = run_cli("export", "runs/film-s0", "--robot", "go2", "--out", str(out), "-f", "json")
    assert code == 0, err
    result = json.loads(stdout)
    assert result["ref"] == "exports/film-s0/go2-onnx@1"
    assert result["inputs"] == ["history"] and result["outputs"] == ["actions"]
    v = result["verification"]
    assert v["ok"] and v["max_abs_diff"] < 1e-5 and v["batch_sizes"] == [256, 1]
    assert v["runtime"].startswith("onnxruntime")
    assert "verified: onnxruntime" in err and "OK" in err  # the verification is printed
    manifest = store.read_manifest("exports/film-s0/go2-onnx")
    assert manifest.kind == "export"
    assert manifest.inputs == {"checkpoint": store.resolve("runs/film-s0")}
    assert set(manifest.files) == {"policy.onnx", "policy.json"}
    assert (out / "policy.onnx").read_bytes() == store.read_file(manifest.id, "policy.onnx")
    meta = json.loads((out / "policy.json").read_text())
    assert meta["baked_robot"] == "go2" and list(meta["robots"]) == ["go2"]
    assert meta["checkpoint"] == manifest.inputs["checkpoint"] and meta["run"] == "film-s0"


def test_onnx_model_has_opset_17_plus_a_dynamic_batch_and_equals_the_torch_actor(store, tmp_path):
    import onnx
    import onnxruntime as ort

    data = (tmp_path / "out" / "policy.onnx").read_bytes()
    meta = json.loads((tmp_path / "out" / "policy.json").read_text())
    proto = onnx.load_from_string(data)
    assert max(o.version for o in proto.opset_import if o.domain in ("", "ai.onnx")) >= 17
    for value in [*proto.graph.input, *proto.graph.output]:
        assert value.type.tensor_type.shape.dim[0].dim_param, value.name  # symbolic batch axis
    assert [i.name for i in proto.graph.input] == ["history"]
    assert [o.name for o in proto.graph.output] == ["actions", "joint_targets"]

    trained = load_trained(store, "runs/film-s0")
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    gen = np.random.default_rng(3)
    m = np.asarray(meta["robots"]["go1"]["morphology"], dtype=np.float32)
    q0 = np.asarray(meta["robots"]["go1"]["default_joint_pos"])
    for batch in (1, 5, 33):
        history = gen.standard_normal((batch, 16, 48)).astype(np.float32)  # [h_t (15), o_t]
        actions, targets = session.run(None, {"history": history})
        expected = _actor_outputs(trained.actor, history, np.repeat(m[None], batch, 0))
        assert actions.shape == (batch, 12)
        assert np.abs(actions - expected).max() < 1e-5
        assert (
            np.abs(targets - np.clip(q0 + 0.25 * expected, *np.asarray(meta["robots"]["go1"]["joint_limits"]).T)).max()
            < 1e-5
        )


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_torchscript_export_with_the_descriptor_as_input(store, tmp_path):
    import io

    result = export_policy(store, "runs/film-s0", ExportCfg(fmt="torchscript"), out=tmp_path / "ts")
    assert result.ref == "exports/film-s0/torchscript@1" and result.verification.ok
    meta = result.metadata
    assert [s["name"] for s in meta["inputs"]] == ["history", "morphology"]
    assert meta["baked_robot"] is None and list(meta["robots"]) == list_robots()
    assert meta["format"] == "torchscript" and meta["onnx_opset"] is None
    scripted = torch.jit.load(io.BytesIO((tmp_path / "ts" / "policy.pt").read_bytes()))
    trained = load_trained(store, "runs/film-s0")
    gen = torch.Generator().manual_seed(1)
    history, morphology = torch.randn(9, 16, 48, generator=gen), torch.rand(9, 11, generator=gen) * 2 - 1
    with torch.no_grad():
        got = scripted(history, morphology).numpy()
    assert np.abs(got - _actor_outputs(trained.actor, history.numpy(), morphology.numpy())).max() < 1e-5


def test_ppo_actor_without_morphology_exports_history_only(tmp_path):
    from morfic_cli.rl.config import smoke_preset
    from morfic_cli.rl.runner import new_run

    store = Store(tmp_path / "ppo")
    run = new_run(store, smoke_preset("ppo", seed=0), "ppo-s0")
    run.train()
    run.env.close()
    result = export_policy(store, "runs/ppo-s0", ExportCfg(fmt="torchscript"))
    assert [s["name"] for s in result.metadata["inputs"]] == ["history"]
    assert result.verification.ok and result.verification.max_abs_diff < 1e-5


def test_metadata_joint_order_gains_and_limits_match_every_robot_model(store):
    trained = load_trained(store, "runs/film-s0")
    _, meta = plan_export(trained, None, False)
    for name in list_robots():
        spec = load_robot(name)
        model = build_model(spec, floor=False)
        assert [model.actuator(i).name for i in range(model.nu)] == meta["joint_names"]
        assert model_mismatches(meta, name, model) == []
        section = meta["robots"][name]
        assert section["kp"] == [spec.kp] * 12 and section["descriptor"] == spec.descriptor.tolist()
    broken = json.loads(json.dumps(meta))
    broken["robots"]["go1"]["kd"][4] = 0.7
    broken["joint_names"] = broken["joint_names"][3:] + broken["joint_names"][:3]
    assert model_mismatches(broken, "go1", build_model(load_robot("go1"), floor=False))  # order is checked
    broken["joint_names"] = meta["joint_names"]
    assert "kd" in " ".join(model_mismatches(broken, "go1", build_model(load_robot("go1"), floor=False)))


def test_metadata_observation_layout_and_control_are_the_envs(store):
    from morfic_cli.envs import observations as O

    trained = load_trained(store, "runs/film-s0")
    _, meta = plan_export(trained, "go1", True)
    obs = meta["observation"]
    assert [(t["name"], t["start"], t["stop"]) for t in obs["terms"]] == list(O.POLICY_LAYOUT)
    scales = np.concatenate([np.asarray(t["scale"], dtype=np.float32) for t in obs["terms"]])
    assert np.array_equal(scales, O.obs_scales(trained.cfg.env.obs).numpy())
    assert obs["size"] == 48 and obs["history_len"] == 16 and obs["clip"] == 100.0  # 15 previous + o_t
    assert "h_t = o_{t-15..t-1}" in obs["history_order"]
    assert meta["control"] == {
        **meta["control"],
        "dt": 0.02,
        "physics_dt": 0.005,
        "decimation": 4,
        "action_scale": 0.25,
    }
    assert meta["descriptor"]["names"][0] == "thigh_mass" and len(meta["descriptor"]["train_min"]) == 11


def test_check_reverifies_a_stored_export_and_an_out_directory(run_cli, store, tmp_path):
    code, out, err = run_cli("export", "exports/film-s0/go1-onnx", "--check", "-f", "json")
    assert code == 0, err
    assert json.loads(out)["ok"] is True and "check: onnxruntime" in err
    code, out, err = run_cli("export", str(tmp_path / "out"), "--check", "--samples", "16", "-f", "json")
    assert code == 0, err
    assert json.loads(out)["verification"]["samples"] == 16


def test_check_catches_edited_metadata_and_a_swapped_model(run_cli, store, tmp_path):
    out = tmp_path / "out"
    meta = json.loads((out / "policy.json").read_text())
    meta["observation"]["terms"][5]["scale"] = [0.1] * 12
    (out / "policy.json").write_text(json.dumps(meta))
    code, stdout, err = run_cli("export", str(out), "--check", "-f", "json")
    assert code == 1 and "Error: " in err and "observation" in err
    assert json.loads(stdout)["ok"] is False

    meta["observation"]["terms"][5]["scale"] = [0.05] * 12
    (out / "policy.json").write_text(json.dumps(meta))
    assert run_cli("export", str(out), "--check")[0] == 0
    trained = load_trained(store, "runs/film-s0")
    module, plan = plan_export(trained, "go1", True)
    with torch.no_grad():
        module.policy.core.mlp[0].bias.add_(0.1)  # another policy behind the same metadata
    (out / "policy.onnx").write_bytes(serialise(module, plan, "onnx"))
    code, _, err = run_cli("export", str(out), "--check")
    assert code == 1 and "model_sha256" in err


def test_failed_verification_stores_nothing(store):
    from morfic_cli.errors import MorficError

    with pytest.raises(MorficError, match="verification failed"):
        export_policy(store, "runs/film-s0", ExportCfg(fmt="torchscript", tolerance=1e-12))
    assert not store.has_ref("exports/film-s0/torchscript")


def test_missing_onnx_packages_name_the_extra(run_cli, store, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # import onnxruntime -> ImportError
    code, out, err = run_cli("export", "runs/film-s0", "--robot", "go1")
    assert code == 1 and out == ""
    assert err.startswith("Error: ") and "pip install 'morfic[export]'" in err and "onnxruntime" in err
    assert len(store.ref_history("exports/film-s0/go1-onnx")) == 1  # the fixture's export only


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["runs/film-s0", "--targets"], "--targets needs --robot"),
        (["runs/film-s0", "--robot", "spot"], "unknown robot 'spot'"),
        (["runs/film-s0", "--to", "tflite"], "'tflite' is not one of"),
        (["runs/nope"], "runs/nope"),
        (["exports/film-s0/go1-onnx"], "not a training checkpoint"),
        (["runs/film-s0", "--check"], "--check takes an export"),
    ],
)
def test_bad_input_is_an_error_line(run_cli, store, argv, needle):
    code, out, err = run_cli("export", *argv)
    assert code == 1, out
    assert err.startswith("Error: ") and needle in err and "Traceback" not in err


def test_check_needs_the_checkpoint_in_the_store(run_cli, smoke_store, tmp_path):
    code, _, err = run_cli("export", str(smoke_store / "out"), "--check", "--store", str(tmp_path / "empty"))
    assert code == 1 and "not in" in err and "morfic store import" in err


def test_check_result_object(store):
    result = check_export(store, "exports/film-s0/go1-onnx", samples=8)
    assert result.ok and result.problems == [] and result.verification.samples == 8


MJLAB_KEYS = (
    "joint_names",
    "joint_stiffness",
    "joint_damping",
    "default_joint_pos",
    "action_scale",
    "observation_names",
    "command_names",
)
MORFIC_KEYS = ("history_length", "history_order", "observation_scales", "dt", "morfic_version", "run", "checkpoint")


def _floats(text):
    return [float(x) for x in text.split(",")]


@pytest.mark.parametrize("robot", ["go1", None])
def test_onnx_metadata_props_agree_with_policy_json(store, tmp_path, robot):
    import onnx
    import onnxruntime as ort

    out = tmp_path / "onnx"
    result = export_policy(store, "runs/film-s0", ExportCfg(robot=robot), out=out)
    meta = json.loads((out / "policy.json").read_text())
    props = {p.key: p.value for p in onnx.load(str(out / "policy.onnx")).metadata_props}
    assert set(MJLAB_KEYS + MORFIC_KEYS) <= set(props)
    who = robot or "go2"  # descriptor as input: the flat keys describe the training template
    section = meta["robots"][who]
    assert props["robot"] == who and props["joint_names"].split(",") == meta["joint_names"]
    assert _floats(props["joint_stiffness"]) == section["kp"] and _floats(props["joint_damping"]) == section["kd"]
    assert _floats(props["default_joint_pos"]) == section["default_joint_pos"]
    assert _floats(props["action_scale"]) == [0.25] * 12 == [meta["control"]["action_scale"]] * 12
    assert props["observation_names"].split(",") == [t["name"] for t in meta["observation"]["terms"]]
    assert props["observation_names"].split(",")[:3] == ["base_lin_vel", "base_ang_vel", "projected_gravity"]
    assert props["command_names"] == "vx,vy,yaw_rate"
    assert int(props["history_length"]) == meta["observation"]["history_len"] == 16  # h_t (15 frames) + o_t
    assert props["history_order"] == meta["observation"]["history_order"]
    scales = _floats(props["observation_scales"])
    assert len(scales) == 48 and scales == [v for t in meta["observation"]["terms"] for v in t["scale"]]
    assert float(props["dt"]) == meta["control"]["dt"] == pytest.approx(0.02)
    assert props["run"] == "film-s0" and props["checkpoint"] == meta["checkpoint"]
    assert props["morfic_version"] == meta["morfic_version"]
    assert set(props["robots"].split(",")) == set(meta["robots"])
    for name, sec in meta["robots"].items():
        assert _floats(props[f"robot.{name}.joint_stiffness"]) == sec["kp"]
    # the sha256 in policy.json is the file's, props included; --check also compares the props
    assert meta["model_sha256"] == result.metadata["model_sha256"]
    assert check_export(store, str(out), samples=8).ok
    # onnxruntime's actions equal torch's on the deployed path
    session = ort.InferenceSession(str(out / "policy.onnx"), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    history = rng.standard_normal((5, meta["observation"]["history_len"], 48)).astype(np.float32)
    morphology = np.repeat(np.asarray([meta["robots"][who]["morphology"]], np.float32), 5, axis=0)
    feeds = {"history": history} if robot else {"history": history, "morphology": morphology}
    (actions,) = session.run(["actions"], feeds)
    expected = _actor_outputs(load_trained(store, "runs/film-s0").actor, history, morphology)
    np.testing.assert_allclose(actions, expected, atol=1e-5, rtol=0)


def test_check_catches_edited_onnx_props(store, tmp_path):
    import onnx

    out = tmp_path / "onnx"
    export_policy(store, "runs/film-s0", ExportCfg(robot="go1"), out=out)
    model = onnx.load(str(out / "policy.onnx"))
    next(p for p in model.metadata_props if p.key == "joint_stiffness").value = "1.0," * 11 + "1.0"
    onnx.save(model, str(out / "policy.onnx"))
    problems = check_export(store, str(out), samples=4).problems
    assert any("metadata_props" in p for p in problems)


@pytest.mark.parametrize("extra", [[], ["--to", "rsl-rl"], ["--check"]])
def test_an_unknown_ref_fails_before_torch_is_imported(tmp_path, extra):
    """The ref is resolved first: the error comes without importing torch and the exporters (11 s on 2 busy cores)."""
    import subprocess

    code = (
        "import sys\nfrom morfic_cli.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit as exc:\n"
        "    print('exit', exc.code)\nprint(sorted(m for m in ('torch', 'morfic_cli.export.artifact') "
        "if m in sys.modules))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, "export", "runs/nothing", *extra, "--store", str(tmp_path / "store")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.stdout.split("\n")[:2] == ["exit 1", "[]"], proc.stdout + proc.stderr
    assert proc.stderr.startswith("Error: no artifact 'runs/nothing'"), proc.stderr
