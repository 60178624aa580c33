"""The live view of ``morfic play``: the rollout log's channels served over the Foxglove WebSocket protocol.

:class:`LiveView` publishes, through ``foxglove-sdk``'s WebSocket server, the same channels a rollout log holds
(``docs/mcap.md``), encoded by the same code: ``/rollout/step`` (``morfic.RolloutStep``), ``/scene``
(``foxglove.SceneUpdate``) and ``/tf`` (``foxglove.FrameTransforms``, the moving bodies), all protobuf, plus
``/tf_static``: the fixed frames (each env's offset, feet, rotors) on their own channel, so the moving ``/tf``
stream never has to carry them. Message times are wall-clock ns (what Foxglove's live timeline shows). The scene
and the fixed frames are sent again when a client subscribes and every :data:`SCENE_REPEAT_S` seconds, so a client
that connects late, or seeks back in its buffer, has them again within that time.

The SDK's server accepts only the subprotocol ``foxglove.sdk.v1``; it listens on a private port of 127.0.0.1 and
a :class:`~morfic_cli.recording.ws_relay.SubprotocolRelay` listens where the user asked, accepting
``foxglove.sdk.v1`` and ``foxglove.websocket.v1`` (the protocol's original name, the same messages). The relay is
also what faces bad clients: it refuses what is not the protocol, bounds each client's queue, and reports each bad
client in one warning line (``docs/mcap.md``, "Bad clients").
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
TF_STATIC_TOPIC = "/tf_static"
"""The live view's channel of the fixed frames (``foxglove.FrameTransforms``)."""


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
        host: Interface to bind, explicitly (``127.0.0.1``: this machine only; ``0.0.0.0``: every interface; empty
            is refused). The SDK's own server always binds 127.0.0.1.
        port: TCP port (0: any free one; :attr:`port` says which).

    Raises:
        ValueError: ``host`` is empty.
        OSError: ``host:port`` cannot be bound (e.g. the port is taken).
    """

    def __init__(
        self, *, num_envs: int, term_names: Sequence[str], scene: RolloutScene | None, host: str, port: int
    ) -> None:
        import foxglove
        from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
        from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
        from mcap_protobuf.schema import build_file_descriptor_set

        self.num_envs = int(num_envs)
        self.term_names = list(term_names)
        self.scene = scene
        self._codec = step_codec(self.term_names)
        self._listener = _Resend()
        from morfic_cli.recording.ws_relay import SubprotocolRelay

        self.server = foxglove.start_server(
            name="morfic play", host="127.0.0.1", port=0, server_listener=self._listener
        )
        try:
            self.relay = SubprotocolRelay(self.server.port, host=host, port=port)
        except BaseException:
            self.server.stop()
            raise
        self.host = host

        def channel(topic: str, name: str, data: bytes) -> foxglove.Channel:
            return foxglove.Channel(
                topic, schema=foxglove.Schema(name=name, encoding="protobuf", data=data), message_encoding="protobuf"
            )

        self._steps = channel(ROLLOUT_TOPIC, ROLLOUT_SCHEMA_NAME, self._codec.schema_data)
        # the scene's channels (scene, moving frames, static frames), with a scene only
        self._scene_channels: tuple[foxglove.Channel, foxglove.Channel, foxglove.Channel] | None = None
        if scene is not None:
            tf_schema = build_file_descriptor_set(FrameTransforms).SerializeToString()
            self._scene_channels = (
                channel(
                    SCENE_TOPIC, "foxglove.SceneUpdate", build_file_descriptor_set(SceneUpdate).SerializeToString()
                ),
                channel(TF_TOPIC, "foxglove.FrameTransforms", tf_schema),
                channel(TF_STATIC_TOPIC, "foxglove.FrameTransforms", tf_schema),
            )
        self._last_scene = -np.inf

    @property
    def port(self) -> int:
        """The port clients connect to (the relay's)."""
        return int(self.relay.port)

    def app_url(self) -> str:
        """The Foxglove app URL that opens this server as a data source."""
        from urllib.parse import quote

        host = "127.0.0.1" if self.host in ("", "0.0.0.0", "::") else self.host
        return f"https://app.foxglove.dev?ds=foxglove-websocket&ds.url={quote(f'ws://{host}:{self.port}', safe='')}"

    def publish(self, step: int, time_s: float, data: Mapping[str, np.ndarray]) -> None:
        """Send one policy step (numbers and, with a scene, the moving frames); the scene again when due.

        Args:
            step: Policy step index.
            time_s: Simulated time (s), in the message.
            data: Every rollout field, (N, ...) arrays (see :func:`~morfic_cli.recording.rollout_log.field_shape`).
        """
        now = time.time_ns()
        arrays = check_step_data(data, self.num_envs, len(self.term_names))
        if self.scene is not None and self._scene_channels is not None:
            scene_ch, tf_ch, tf_static_ch = self._scene_channels
            if self._listener.wanted.is_set() or time.monotonic() - self._last_scene >= SCENE_REPEAT_S:
                self._listener.wanted.clear()
                self._last_scene = time.monotonic()
                scene_ch.log(self.scene.scene_update(now).SerializeToString(), log_time=now)
                tf_static_ch.log(self.scene.static_transforms(now).SerializeToString(), log_time=now)
            qpos = self.scene.qpos(arrays["base_pos"], arrays["base_quat"], arrays["joint_pos"])
            tf_ch.log(self.scene.step_transforms(qpos, now).SerializeToString(), log_time=now)
        self._steps.log(self._codec.encode(step, time_s, arrays), log_time=now)

    def close(self) -> None:
        """Close the channels, the relay and the server."""
        for ch in (self._steps, *(self._scene_channels or ())):
            ch.close()
        try:
            self.relay.close()
        finally:
            self.server.stop()
