"""The live view's WebSocket handshake: clients offering only `foxglove.websocket.v1` (or only `foxglove.sdk.v1`)
connect and get the channels; a client offering neither gets HTTP 400 naming both, and morfic says so too."""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import threading
import time

import numpy as np
import pytest

from morfic_cli.recording.live import LiveView
from morfic_cli.recording.ws_relay import LEGACY_SUBPROTOCOL, SDK_SUBPROTOCOL, SubprotocolRelay

TERMS = ["r_lin", "r_yaw"]
N = 2


def _step(t: int) -> dict[str, np.ndarray]:
    z3 = np.zeros((N, 3))
    return {
        "base_pos": z3 + [0.1 * t, 0.0, 0.3],
        "base_quat": np.tile([1.0, 0.0, 0.0, 0.0], (N, 1)),
        "base_lin_vel": z3 + [1.0, 0.0, 0.0],
        "base_ang_vel": z3,
        "command": z3 + [1.0, 0.0, 0.0],
        "joint_pos": np.zeros((N, 12)),
        "joint_vel": np.zeros((N, 12)),
        "action": np.zeros((N, 12)),
        "reward": np.full(N, 0.01 * t),
        "reward_terms": np.zeros((N, 2)),
        "value": np.zeros(N),
        "done": np.zeros(N, bool),
        "time_out": np.zeros(N, bool),
    }


def _scene():
    from morfic_cli.morphology.builder import build_model
    from morfic_cli.morphology.robots import load_robot
    from morfic_cli.recording.scene import RolloutScene

    model = build_model(load_robot("go1"))
    return RolloutScene([model, model], [0, 1], np.asarray(model.jnt_qposadr[1:]))


@pytest.fixture
def live():
    view = LiveView(num_envs=N, term_names=TERMS, scene=_scene(), host="127.0.0.1", port=0)
    stop = threading.Event()

    def publish() -> None:  # a running rollout: one step every 20 ms
        t = 0
        while not stop.is_set():
            view.publish(t, 0.02 * (t + 1), _step(t))
            t += 1
            stop.wait(0.02)

    pump = threading.Thread(target=publish, daemon=True)
    pump.start()
    yield view
    stop.set()
    pump.join()
    view.close()


async def _session(port: int, subprotocols: list[str], want: dict[str, int]):
    """Connect offering ``subprotocols``, subscribe to every advertised channel, decode until ``want`` counts."""
    import websockets
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=subprotocols, max_size=None) as ws:
        ops, channels, got = [], {}, {}
        while not all(len(got.get(topic, [])) >= n for topic, n in want.items()):
            frame = await ws.recv()
            if isinstance(frame, str):
                op = json.loads(frame)
                ops.append(op["op"])
                if op["op"] == "advertise":
                    for c in op["channels"]:
                        schema = Schema(
                            id=c["id"],
                            name=c["schemaName"],
                            encoding=c["schemaEncoding"],
                            data=base64.b64decode(c["schema"]),
                        )
                        channels[c["id"]] = (c, DecoderFactory().decoder_for(c["encoding"], schema))
                    await ws.send(
                        json.dumps(
                            {
                                "op": "subscribe",
                                "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in op["channels"]],
                            }
                        )
                    )
                continue
            opcode, sub_id, _ = struct.unpack_from("<BIQ", frame)
            assert opcode == 1
            channel, decode = channels[sub_id]
            got.setdefault(channel["topic"], []).append(decode(frame[13:]))
        return ws.subprotocol, ops, {c["topic"]: c["schemaName"] for c, _ in channels.values()}, got


@pytest.mark.parametrize("offered", [[LEGACY_SUBPROTOCOL], [SDK_SUBPROTOCOL], [LEGACY_SUBPROTOCOL, SDK_SUBPROTOCOL]])
def test_a_client_offering_either_subprotocol_gets_the_channels(live, offered):
    want = {"/rollout/step": 2, "/tf": 2, "/tf_static": 1, "/scene": 1}
    subprotocol, ops, topics, got = asyncio.run(asyncio.wait_for(_session(live.port, offered, want), 60))
    assert subprotocol == (SDK_SUBPROTOCOL if SDK_SUBPROTOCOL in offered else LEGACY_SUBPROTOCOL)
    assert ops[0] == "serverInfo" and "advertise" in ops
    assert topics == {
        "/rollout/step": "morfic.RolloutStep",
        "/scene": "foxglove.SceneUpdate",
        "/tf": "foxglove.FrameTransforms",
        "/tf_static": "foxglove.FrameTransforms",
    }
    step = got["/rollout/step"][-1]
    assert len(step.envs) == N and step.envs[1].command[0] == 1.0
    # the fixed frames on /tf_static (env offsets, feet), the moving bodies on /tf
    fixed = {t.child_frame_id: t for t in got["/tf_static"][0].transforms}
    assert {"env0/world", "env1/world", "env1/FL_foot"} <= set(fixed)
    assert fixed["env1/world"].translation.y == pytest.approx(1.5)
    moving = {t.child_frame_id for t in got["/tf"][-1].transforms}
    assert {"env0/base", "env1/RR_calf"} <= moving and not moving & set(fixed)
    assert live.app_url().endswith(f"ws%3A%2F%2F127.0.0.1%3A{live.port}")


def test_a_client_offering_neither_gets_a_400_naming_both_and_morfic_says_so(live, caplog):
    import logging

    import websockets

    caplog.set_level(logging.WARNING)
    relay = SubprotocolRelay(live.relay.upstream.rsplit(":", 1)[1], host="127.0.0.1", port=0)
    try:

        async def connect(subprotocols):
            async with websockets.connect(f"ws://127.0.0.1:{relay.port}", subprotocols=subprotocols):
                pass

        for offered in (["foxglove.websocket.v2"], None):
            with pytest.raises(websockets.InvalidStatus) as exc:
                asyncio.run(connect(offered))
            body = exc.value.response.body.decode()
            assert exc.value.response.status_code == 400
            assert SDK_SUBPROTOCOL in body and LEGACY_SUBPROTOCOL in body
        for _ in range(2000):  # until the relay is done with both (20 s at most: a failure guard)
            if relay.busy == 0:
                break
            time.sleep(0.01)
    finally:
        relay.close()
    refused = [r.getMessage() for r in caplog.records if r.name == "morfic_cli.recording.ws_relay"]
    assert len(refused) == 2 and all(m.startswith("live view: refused client 127.0.0.1:") for m in refused)
    assert "offered: foxglove.websocket.v2" in refused[0] and "offered: none" in refused[1]


def test_a_taken_port_is_an_oserror(live):
    with pytest.raises(OSError):
        SubprotocolRelay(1, host="127.0.0.1", port=live.port)
