"""docs/mcap.md's step semantics by a round trip: a `morfic eval` MCAP log -> the exported ONNX policy's input.

Step t of a log holds the action a_t and V(s_t) of the state it was taken in, but the state *after* a_t. So the
policy input of a_t is rebuilt from steps t-16..t-1 (docs/deploy.md's layout, 16 frames, o_t last, each frame from
one logged step, with that step's clipped action as ``last_action``) and reproduces the logged a_t to float32
precision; the same input built one step later (from step t's state, the obvious reading) does not.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")

BUNDLE = Path(__file__).resolve().parents[2] / "artifacts" / "bundles" / "film-cpu-s0.tar"
STEPS = 60


def _rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v for quaternions q = (w, x, y, z). Shapes: (T, 4), (3,) -> (T, 3), float32."""
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return (v - w * t + np.cross(u, t)).astype(np.float32)


def frames(log: dict[str, np.ndarray], meta: dict, robot: str) -> np.ndarray:
    """o built from each logged step's state and action, by policy.json's layout. Shape: (T, 48), float32."""
    obs, control = meta["observation"], meta["control"]
    q0 = np.asarray(meta["robots"][robot]["default_joint_pos"], dtype=np.float32)
    raw = {
        "base_lin_vel": log["base_lin_vel"],
        "base_ang_vel": log["base_ang_vel"],
        "projected_gravity": _rotate_inverse(log["base_quat"], np.array([0.0, 0.0, -1.0], np.float32)),
        "command": log["command"],
        "joint_pos": log["joint_pos"] - q0,
        "joint_vel": log["joint_vel"],
        "last_action": np.clip(log["action"], -control["action_clip"], control["action_clip"]),
    }
    o = np.concatenate([raw[term["name"]] for term in obs["terms"]], axis=1)
    scale = np.concatenate([np.asarray(term["scale"], dtype=np.float32) for term in obs["terms"]])
    return np.clip(o * scale, -obs["clip"], obs["clip"]).astype(np.float32)


def test_the_policy_input_of_step_t_comes_from_the_state_logged_at_step_t_minus_1(run_cli, tmp_path):
    import onnxruntime as ort

    from morfic_cli.recording.rollout_log import read_rollout

    store = str(tmp_path / "store")
    assert run_cli("store", "import", str(BUNDLE), "--store", store)[0] == 0
    code, _, err = run_cli(
        "eval",
        "runs/film-cpu-s0",
        "--robots",
        "go1",
        "--envs",
        "1",
        "--steps",
        str(STEPS),
        "--command-vx",
        "1.0",
        "--scene-envs",
        "0",
        "--out",
        str(tmp_path / "eval"),
        "-q",
        "--store",
        store,
    )
    assert code == 0, err
    code, _, err = run_cli("export", "runs/film-cpu-s0", "--out", str(tmp_path / "policy"), "-q", "--store", store)
    assert code == 0, err
    meta = json.loads((tmp_path / "policy" / "policy.json").read_text())
    log = read_rollout(tmp_path / "eval" / "go1-descriptor-vx1.mcap").arrays
    env0 = {k: v[:, 0] for k, v in log.items()}
    assert not env0["done"].any()  # one episode: no reset inside the window
    session = ort.InferenceSession(str(tmp_path / "policy" / meta["model_file"]), providers=["CPUExecutionProvider"])
    morphology = np.asarray(meta["robots"]["go1"]["morphology"], dtype=np.float32)[None]
    h = meta["observation"]["history_len"]
    assert h == 16

    def actions(o: np.ndarray, last: int) -> np.ndarray:
        """The policy's a_t for t = h..T-1 from the frames of steps t-h+1+last-1 .. t+last-1, oldest first."""
        history = np.stack([o[t + last - h : t + last] for t in range(h, STEPS)])  # (T-h, h, 48)
        return session.run(["actions"], {"history": history, "morphology": np.repeat(morphology, len(history), 0)})[0]

    o = frames(env0, meta, "go1")
    logged = env0["action"][h:]
    right = np.abs(actions(o, last=0) - logged).max()  # o_t from step t-1: the history ends at step t-1
    wrong = np.abs(actions(o, last=1) - logged).max()  # o_t from step t: the history ends at step t
    assert right < 1e-5, right  # float32 and onnxruntime vs torch: 1.4e-6 measured
    assert wrong > 0.1, wrong  # from step t's state: off by up to 4.7 (measured)
