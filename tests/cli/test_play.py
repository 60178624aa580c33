"""`morfic play`: a Foxglove WebSocket client (as the Foxglove app connects) sees the channels and their messages."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import re
import signal
import struct
import subprocess
import sys
import threading
import time

import pytest

pytestmark = pytest.mark.usefixtures("one_torch_thread")

# The Foxglove app offers both names; older clients (Lichtblick < 1.22, @foxglove/ws-protocol) only the first, which
# foxglove-sdk's own server refuses: morfic play accepts it (tests/recording/test_live.py checks each name alone).
SUBPROTOCOLS = ["foxglove.websocket.v1"]


@pytest.fixture(scope="module")
def smoke_store(smoke_runs, tmp_path_factory):
    root = tmp_path_factory.mktemp("play") / "store"
    smoke_runs.store(root)
    return root


def _served_port(lines: list[str], proc: subprocess.Popen, timeout_s: float) -> int:
    """The port `morfic play --port 0` listens on, from the ``ws://127.0.0.1:PORT`` it prints (a thread appends
    its stderr to ``lines``); no port picked beforehand, which another test or worker could take in between."""
    deadline = time.monotonic() + timeout_s  # the server starts after the policy's first step
    while time.monotonic() < deadline and proc.poll() is None:
        found = next((m for line in list(lines) if (m := re.search(r"ws://127\.0\.0\.1:(\d+)", line))), None)
        if found:
            return int(found.group(1))
        time.sleep(0.1)
    raise AssertionError(f"morfic play never listened: {''.join(lines)[-2000:]}")


def _decoder(channel: dict):
    """A protobuf decoder for an advertised channel (its schema is a base64 FileDescriptorSet)."""
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    schema = Schema(
        id=channel["id"],
        name=channel["schemaName"],
        encoding=channel["schemaEncoding"],
        data=base64.b64decode(channel["schema"]),
    )
    return DecoderFactory().decoder_for(channel["encoding"], schema)


async def _watch(port: int, want: dict[str, int], timeout_s: float) -> tuple[str, list[dict], dict[str, list]]:
    """Connect, read the advertised channels, subscribe to all, collect messages until ``want`` counts."""
    import websockets

    async def run():
        for _ in range(600):  # the server starts after the policy's first step
            try:
                ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None)
                break
            except OSError:
                await asyncio.sleep(0.1)
        else:
            raise AssertionError("morfic play never listened")
        channels, subs, got = [], {}, {}
        async with ws:
            while not all(len(got.get(topic, [])) >= n for topic, n in want.items()):
                frame = await ws.recv()
                if isinstance(frame, str):
                    op = json.loads(frame)
                    if op["op"] == "advertise":
                        channels += op["channels"]
                        subs = {c["id"]: c for c in channels}
                        await ws.send(
                            json.dumps(
                                {
                                    "op": "subscribe",
                                    "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in op["channels"]],
                                }
                            )
                        )
                    continue
                opcode, sub_id, _log_time = struct.unpack_from("<BIQ", frame)
                assert opcode == 1  # message data
                channel = subs[sub_id]
                got.setdefault(channel["topic"], []).append(_decoder(channel)(frame[13:]))
            return ws.subprotocol, channels, got

    return await asyncio.wait_for(run(), timeout_s)


def test_play_serves_the_scene_and_numbers_over_foxglove_websocket(smoke_store, tmp_path):
    from morfic_cli.recording.rollout_log import read_rollout

    record = tmp_path / "session.mcap"
    env = {**os.environ, "MORFIC_STORE": str(smoke_store), "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "morfic_cli",
            "play",
            "runs/film-s0",
            "--robot",
            "go1",
            "--envs",
            "2",
            "--port",
            "0",
            "--record",
            str(record),
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    try:
        port = _served_port(lines, proc, 240)
        subprotocol, channels, got = asyncio.run(
            _watch(port, {"/rollout/step": 3, "/tf": 3, "/tf_static": 1, "/scene": 1}, 240)
        )
    finally:
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
        reader.join(timeout=60)
    err = "".join(lines)
    assert proc.returncode == 0, err
    assert subprotocol in SUBPROTOCOLS
    assert {(c["topic"], c["schemaName"], c["encoding"], c["schemaEncoding"]) for c in channels} == {
        ("/rollout/step", "morfic.RolloutStep", "protobuf", "protobuf"),
        ("/scene", "foxglove.SceneUpdate", "protobuf", "protobuf"),
        ("/tf", "foxglove.FrameTransforms", "protobuf", "protobuf"),
        ("/tf_static", "foxglove.FrameTransforms", "protobuf", "protobuf"),
    }
    step = got["/rollout/step"][0]
    assert len(step.envs) == 2 and len(step.envs[0].joint_pos) == 12 and step.envs[0].command[0] == 1.0
    moving = {t.child_frame_id for t in got["/tf"][-1].transforms}
    assert {"env0/base", "env1/base", "env1/RR_calf"} <= moving
    assert {"env0/world", "env1/FL_foot"} <= {t.child_frame_id for t in got["/tf_static"][0].transforms}
    assert {e.frame_id for e in got["/scene"][0].entities} >= {"world", "env0/base", "env1/FL_foot"}
    assert f"ws://127.0.0.1:{port}" in err and "stopped after" in err
    log = read_rollout(record)  # --record wrote the session
    assert log.num_envs == 2 and log.num_steps >= 3 and log.metadata["robot"] == "go1"


def test_play_bad_input(run_cli, smoke_store, monkeypatch):
    monkeypatch.setenv("MORFIC_STORE", str(smoke_store))
    code, _, err = run_cli("play", "runs/film-s0", "--robot", "go3")
    assert code == 1 and "unknown robot 'go3'" in err
    assert run_cli("eval", "runs/film-s0", "--robots", "go3")[2] == err  # one message, one order of the robots
    code, _, err = run_cli("play", "runs/nothing")
    assert code == 1 and "Error:" in err
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform.startswith("linux"):
        code, _, err = run_cli("play", "runs/film-s0", "--viewer", "--steps", "1")
        assert code == 1 and "needs a display" in err


def test_pace_check_says_once_when_the_loop_falls_behind_real_time():
    """50 steps/s wanted (dt 0.02 s); windows of 2 s: at 32 steps/s the first full window reports it, once."""
    from morfic_cli.evaluation.play import PaceCheck

    slow = PaceCheck(0.02)
    reports = [slow.update(n, 1.0 + n / 32.0) for n in range(1, 400)]  # 32 steps/s from the first step on
    hits = [(n, r) for n, r in enumerate(reports, start=1) if r is not None]
    assert hits == [(1 + 64, 32.0)]  # the window from step 1 to step 65: 64 steps in 2.0 s
    on_time = PaceCheck(0.02)
    assert all(on_time.update(n, 1.0 + n * 0.02) is None for n in range(1, 400))
    just_above = PaceCheck(0.02)  # 46 steps/s: within 90 % of real time, not worth a line
    assert all(just_above.update(n, n / 46.0) is None for n in range(1, 400))
