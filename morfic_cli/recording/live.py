"""The live view of ``morfic play``: the rollout log's channels served over the Foxglove WebSocket protocol.

:class:`LiveView` publishes, through ``foxglove-sdk``'s WebSocket server (subprotocol ``foxglove.websocket.v1``),
the same three channels a rollout log holds (``docs/mcap.md``), encoded by the same code:
``/rollout/step`` (``morfic.RolloutStep``), ``/scene`` (``foxglove.SceneUpdate``) and ``/tf``
(``foxglove.FrameTransforms``), all protobuf. Message times are wall-clock ns (what Foxglove's live timeline
shows). The scene and the fixed frames are sent again when a client subscribes and every
:data:`SCENE_REPEAT_S` seconds, so a client that connects late sees the robots too.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping, Sequence

import numpy as np
from foxglove.websocket import ServerListener

from morfic_cli.recording.rollout_log import (
    ROLLOUT_SCHEMA_NAME,
    ROLLOUT_TOPIC,
    SCENE_TOPIC,
    TF_TOPIC,
    check_step_data,
    step_codec,
)
from morfic_cli.recording.scene import RolloutScene

SCENE_REPEAT_S = 2.0
"""Seconds between two sends of the scene and the fixed frames."""


class _Resend(ServerListener):
    """Server listener: a new subscription asks for the scene and the fixed frames to be sent again."""

    def __init__(self) -> None:
        self.wanted = threading.Event()

    def on_subscribe(self, client, channel) -> None:
        """A client subscribed to a channel (called on the server's thread)."""
        self.wanted.set()


class LiveView:
    """A Foxglove WebSocket server publishing a running rollout.

    Args:
        num_envs: N, envs in each step's arrays.
        term_names: K reward-term names (the columns of ``reward_terms``).
        scene: The 3D scene of some envs (None: numbers only).
        host: Interface to bind (``127.0.0.1``: this machine only).
        port: TCP port (0: any free one; :attr:`port` says which).
    """

    def __init__(self, *, num_envs: int, term_names: Sequence[str], scene: RolloutScene | None, host: str,
                 port: int) -> None:
        import foxglove
        from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
        from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
        from mcap_protobuf.schema import build_file_descriptor_set

        self.num_envs = int(num_envs)
        self.term_names = list(term_names)
        self.scene = scene
        self._codec = step_codec(self.term_names)
        self._listener = _Resend()
        self.server = foxglove.start_server(name="morfic play", host=host, port=port,
                                            server_listener=self._listener)

        def channel(topic: str, name: str, data: bytes) -> foxglove.Channel:
            return foxglove.Channel(topic, schema=foxglove.Schema(name=name, encoding="protobuf", data=data),
                                    message_encoding="protobuf")

        self._steps = channel(ROLLOUT_TOPIC, ROLLOUT_SCHEMA_NAME, self._codec.schema_data)
        self._scene = self._tf = None
        if scene is not None:
            self._scene = channel(SCENE_TOPIC, "foxglove.SceneUpdate",
                                  build_file_descriptor_set(SceneUpdate).SerializeToString())
            self._tf = channel(TF_TOPIC, "foxglove.FrameTransforms",
                               build_file_descriptor_set(FrameTransforms).SerializeToString())
        self._last_scene = -np.inf

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self.server.port)

    def app_url(self) -> str:
        """The Foxglove app URL that opens this server as a data source."""
        return self.server.app_url() or ""

    def publish(self, step: int, time_s: float, data: Mapping[str, np.ndarray]) -> None:
        """Send one policy step (numbers and, with a scene, the moving frames); the scene again when due.

        Args:
            step: Policy step index.
            time_s: Simulated time (s), in the message.
            data: Every rollout field, (N, ...) arrays (see :func:`~morfic_cli.recording.rollout_log.field_shape`).
        """
        now = time.time_ns()
        arrays = check_step_data(data, self.num_envs, len(self.term_names))
        if self.scene is not None:
            if self._listener.wanted.is_set() or time.monotonic() - self._last_scene >= SCENE_REPEAT_S:
                self._listener.wanted.clear()
                self._last_scene = time.monotonic()
                self._scene.log(self.scene.scene_update(now).SerializeToString(), log_time=now)
                self._tf.log(self.scene.static_transforms(now).SerializeToString(), log_time=now)
            qpos = self.scene.qpos(arrays["base_pos"], arrays["base_quat"], arrays["joint_pos"])
            self._tf.log(self.scene.step_transforms(qpos, now).SerializeToString(), log_time=now)
        self._steps.log(self._codec.encode(step, time_s, arrays), log_time=now)

    def close(self) -> None:
        """Close the channels and stop the server."""
        for ch in (self._steps, self._scene, self._tf):
            if ch is not None:
                ch.close()
        self.server.stop()
