"""A WebSocket front for ``foxglove-sdk``'s server that also speaks the subprotocol name ``foxglove.websocket.v1``.

``foxglove-sdk`` (0.2x-0.30) accepts only clients that offer the subprotocol ``foxglove.sdk.v1``: a client that
offers only ``foxglove.websocket.v1`` (the protocol's original name: older Lichtblick and Foxglove Studio
releases, ``@foxglove/ws-protocol`` clients, roslibjs-foxglove) gets HTTP 400 and the server logs only "handshake
failed". The two names are the same protocol on the wire (Foxglove's stance: ``sdk.v1`` is ``websocket.v1``
renamed), so :class:`SubprotocolRelay` listens where the user asked, accepts either name (``foxglove.sdk.v1``
first), and relays every frame unchanged to and from the SDK's server on a private port of 127.0.0.1, connecting
there as ``foxglove.sdk.v1``.

The relay is also what faces bad clients (``docs/mcap.md``, "Bad clients"):

* a handshake that is not a WebSocket handshake for either subprotocol is refused (HTTP 400; 426 for a plain
  HTTP request), and one that is not complete within ``handshake_timeout_s`` is dropped;
* each client frame must be a message the protocol defines (:func:`client_frame_error`) and at most
  ``max_frame_bytes`` long; the first one that is not closes that client's connection (1008, or 1009 for a
  frame too long) before it reaches the SDK's server;
* each client has its own outgoing queue of at most ``backlog_bytes``: a client that reads slower than the
  stream loses its oldest message-data frames (the messages of the channels), never the control messages
  (``serverInfo``, ``advertise``, ...); one whose control messages alone pass the bound is closed (1008);
* every bad client costs exactly one warning line on the logger ``morfic_cli.recording.ws_relay`` (peer address
  and reason, no traceback); a client that merely disconnects, however abruptly, costs none.
"""

from __future__ import annotations

import asyncio
import collections
import ipaddress
import json
import logging
import threading
from collections.abc import Collection, Sequence

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
"""The subprotocol ``foxglove-sdk``'s server accepts."""
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
"""The Foxglove WebSocket protocol's original subprotocol name (same messages)."""
SUBPROTOCOLS = (SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL)
"""What the relay accepts, in order of preference."""

CLIENT_OPS = frozenset(
    {
        "subscribe",
        "unsubscribe",
        "advertise",
        "unadvertise",
        "getParameters",
        "setParameters",
        "subscribeParameterUpdates",
        "unsubscribeParameterUpdates",
        "subscribeConnectionGraph",
        "unsubscribeConnectionGraph",
        "fetchAsset",
    }
)
"""The JSON operations a client may send (those ``foxglove-sdk``'s server parses)."""
CLIENT_BINARY_OPCODES = {
    1: ("message data", "clientPublish"),
    2: ("service call request", "services"),
    3: ("playback control request", "playbackControl"),
}
"""The first byte of a client's binary frame: the operation, and the server capability it needs."""
MESSAGE_DATA = 1
"""Opcode of the server's binary message-data frames (the only frames a slow client loses)."""

MAX_FRAME_BYTES = 1 << 20
"""Longest client frame (bytes): a client sends small JSON requests; a longer frame closes it (1009)."""
BACKLOG_BYTES = 4 << 20
"""Per-client bound (bytes) on the frames waiting to be sent to it (see :class:`Outbox`)."""
HANDSHAKE_TIMEOUT_S = 10.0
"""Seconds a connection has to complete its WebSocket handshake."""
PING_INTERVAL_S = 20.0
"""Seconds between keepalive pings to each client; a client that does not answer within as long is closed."""

CLOSE_TIMEOUT_S = 2.0
"""Seconds a client has to answer a close frame (ours, or the shutdown's) before its connection is aborted."""

log = logging.getLogger(__name__)
"""Where bad clients are reported, one warning line each."""


def refusal_message(offered: list[str]) -> str:
    """The text of the HTTP 400 a client gets when it offers no subprotocol the relay speaks.

    Args:
        offered: The subprotocols the client offered (may be empty).

    Returns:
        One line naming what was offered and what is accepted.
    """
    got = ", ".join(offered) if offered else "none"
    return (
        f"morfic play speaks the Foxglove WebSocket protocol: offer the subprotocol {SDK_SUBPROTOCOL} or "
        f"{LEGACY_SUBPROTOCOL} (this client offered: {got})"
    )


UPGRADE_MESSAGE = (
    "this is the live view of morfic play, a Foxglove WebSocket server: open ws://<this host:port> "
    "in Foxglove (Open connection -> Foxglove WebSocket)"
)
"""The body of the HTTP 426 a plain HTTP request (no WebSocket upgrade) gets."""


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` keeps a server on this machine (a loopback address, or ``localhost``)."""
    host = host.strip().strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def one_line(text: object, limit: int = 160) -> str:
    """``text`` as one printable line of at most ``limit`` characters (control characters escaped)."""
    s = "".join(c if c.isprintable() else f"\\x{ord(c):02x}" for c in str(text))
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _ids(items: object, keys: tuple[str, ...]) -> bool:
    """Whether ``items`` is a list of objects whose ``keys`` are all integers."""
    return isinstance(items, list) and all(
        isinstance(item, dict) and all(type(item.get(k)) is int for k in keys) for item in items
    )


def client_frame_error(
    frame: str | bytes, *, capabilities: Collection[str] = (), channels: Collection[int] | None = None
) -> str | None:
    """What is wrong with one frame from a client, or None when it is a message the protocol defines.

    A text frame must be a JSON object whose ``op`` is one of :data:`CLIENT_OPS`; ``subscribe`` must carry
    ``subscriptions: [{id, channelId}]`` (integers) on channels the server advertised, ``unsubscribe``
    ``subscriptionIds: [int]``. A binary frame must start with one of :data:`CLIENT_BINARY_OPCODES` whose
    capability the server announced. Whatever else such a message asks for (a parameter, an asset) is the server's
    to answer, with a status message.

    Args:
        frame: The frame's payload (``str`` for a text frame).
        capabilities: What the server's ``serverInfo`` announced.
        channels: The channel ids advertised to this client so far (None: not checked).

    Returns:
        A short reason, or None.
    """
    if isinstance(frame, bytes):
        if not frame or frame[0] not in CLIENT_BINARY_OPCODES:
            return f"sent a binary frame with no client opcode (first byte {frame[:1].hex() or 'none'})"
        name, capability = CLIENT_BINARY_OPCODES[frame[0]]
        if capability not in capabilities:
            return f"sent {name} (binary), which needs the {capability} capability the server does not announce"
        return None
    try:
        msg = json.loads(frame)
    except ValueError:
        return "sent a text frame that is not JSON"
    if not isinstance(msg, dict):
        return f"sent JSON that is not an object ({type(msg).__name__})"
    op = msg.get("op")
    if not isinstance(op, str):
        return "sent a JSON object without an op"
    if op not in CLIENT_OPS:
        return f"sent an unknown op {one_line(repr(op), 40)}"
    if op == "subscribe":
        if not _ids(msg.get("subscriptions"), ("id", "channelId")):
            return "sent a subscribe without subscriptions: [{id, channelId}]"
        unknown = [
            s["channelId"] for s in msg["subscriptions"] if channels is not None and s["channelId"] not in channels
        ]
        if unknown:
            return f"subscribed to channel {unknown[0]}, which the server never advertised"
    if op == "unsubscribe" and not (
        isinstance(msg.get("subscriptionIds"), list) and all(type(i) is int for i in msg["subscriptionIds"])
    ):
        return "sent an unsubscribe without subscriptionIds: [int]"
    return None


class TooSlow(Exception):
    """A client's control messages alone passed its backlog bound."""


class Outbox:
    """The frames waiting to be sent to one client, at most ``limit`` bytes of them (plus the newest frame).

    When a frame brings the total over ``limit``, the oldest message-data frames (server binary opcode 1: the
    channels' messages) are dropped until it fits, never the newest frame; the other frames (JSON control
    messages such as ``advertise``, other binary opcodes) are never dropped, and :exc:`TooSlow` is raised when
    they alone (the newest aside) pass ``limit``. So a client that stops reading holds at most ``limit`` bytes
    plus one frame here.

    Args:
        limit: The bound in bytes.
    """

    def __init__(self, limit: int) -> None:
        self.limit = int(limit)
        self.frames: collections.deque[str | bytes] = collections.deque()
        self.bytes = 0
        """Bytes queued now."""
        self.control_bytes = 0
        """Of which not droppable."""
        self.dropped = 0
        """Message-data frames dropped so far."""
        self.peak = 0
        """Most bytes ever queued (after dropping)."""
        self.largest = 0
        """Longest frame put so far."""
        self._ready = asyncio.Event()

    @staticmethod
    def droppable(frame: str | bytes) -> bool:
        """Whether ``frame`` is a server message-data frame."""
        return isinstance(frame, bytes) and frame[:1] == bytes([MESSAGE_DATA])

    def put(self, frame: str | bytes) -> None:
        """Queue ``frame``, dropping the oldest message-data frames over the bound.

        Raises:
            TooSlow: The frames that cannot be dropped pass the bound.
        """
        n = len(frame)
        self.frames.append(frame)
        self.bytes += n
        self.largest = max(self.largest, n)
        if not self.droppable(frame):
            self.control_bytes += n
        if self.bytes > self.limit:
            held = []
            while self.bytes > self.limit and len(self.frames) > 1:
                old = self.frames.popleft()
                if self.droppable(old):
                    self.bytes -= len(old)
                    self.dropped += 1
                else:
                    held.append(old)
            self.frames.extendleft(reversed(held))
        self.peak = max(self.peak, self.bytes)
        self._ready.set()
        if self.control_bytes - (0 if self.droppable(frame) else n) > self.limit:  # the newest aside, as above
            raise TooSlow(
                f"read too slowly: {self.control_bytes} bytes of control messages waiting, over the "
                f"{self.limit} bytes bound"
            )

    async def get(self) -> str | bytes:
        """The oldest queued frame, once there is one."""
        while not self.frames:
            self._ready.clear()
            await self._ready.wait()
        frame = self.frames.popleft()
        self.bytes -= len(frame)
        if not self.droppable(frame):
            self.control_bytes -= len(frame)
        return frame


class _BadClient(Exception):
    """Close the client with ``code`` and report ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


def _offered(request) -> list[str]:
    """The subprotocols of a handshake request's ``Sec-WebSocket-Protocol`` headers, in order."""
    return [
        p.strip() for value in request.headers.get_all("Sec-WebSocket-Protocol") for p in value.split(",") if p.strip()
    ]


def _peer(connection) -> str:
    """``host:port`` of a connection's client (``[host]:port`` for IPv6)."""
    try:
        addr = connection.remote_address
    except Exception:  # the transport is already gone
        addr = None
    if not isinstance(addr, tuple) or len(addr) < 2:
        return "unknown peer"
    host = str(addr[0])
    return f"[{host}]:{addr[1]}" if ":" in host else f"{host}:{addr[1]}"


def _handshake_failure(exc: BaseException | None) -> str:
    """Why a WebSocket handshake did not complete, from the handshake's exception."""
    from websockets.exceptions import InvalidMessage

    if isinstance(exc, InvalidMessage) and isinstance(exc.__cause__, EOFError):
        return "closed the connection before completing a WebSocket handshake"
    if isinstance(exc, InvalidMessage) and exc.__cause__ is not None:
        return f"did not send an HTTP request ({one_line(exc.__cause__, 80)})"
    if exc is None:
        return "closed the connection before completing a WebSocket handshake"
    return f"sent a bad WebSocket handshake ({one_line(exc, 100)})"


_PROTOCOL_CLOSES = {1002: "broke the WebSocket framing", 1007: "sent invalid frame data", 1009: "sent a frame too long"}
"""Close codes the relay's WebSocket layer sends on a client's fault, and what the client did."""


async def _close_upstream(upstream) -> None:
    """Close the connection to the upstream server, reading (and dropping) what it still sends meanwhile.

    Unread, its frames would stand between us and its close frame, and the close would wait out its timeout.
    """
    from websockets.exceptions import ConnectionClosed

    async def discard() -> None:
        try:
            async for _ in upstream:
                pass
        except ConnectionClosed:
            pass

    reader = asyncio.ensure_future(discard())
    try:
        await upstream.close()
    finally:
        reader.cancel()
        await asyncio.gather(reader, return_exceptions=True)


class SubprotocolRelay:
    """Listen on ``host:port`` and relay each client to the WebSocket server at ``127.0.0.1:upstream_port``.

    The relay runs its own asyncio loop in a daemon thread; the constructor returns once it listens, and raises
    the ``OSError`` of a port that cannot be bound. Each client gets its own connection to the upstream server.

    Args:
        upstream_port: Port of ``foxglove-sdk``'s server on 127.0.0.1.
        host: Interface to bind, an explicit address or name (``127.0.0.1``: this machine only; ``0.0.0.0``:
            every interface). Empty is refused: asyncio would bind every interface.
        port: TCP port (0: any free one; :attr:`port` says which).
        max_frame_bytes: Longest frame a client may send.
        backlog_bytes: Per-client bound on the frames waiting to be sent (:class:`Outbox`).
        handshake_timeout_s: Time a connection has to complete its handshake.
        ping_interval_s: Keepalive ping period (None: no pings); a client that does not answer a ping within as
            long is closed.
        close_timeout_s: Time a closing client has to answer the close frame before its connection is aborted
            (also at :meth:`close`, for every connection left).

    Raises:
        ValueError: ``host`` is empty.
        OSError: ``host:port`` cannot be bound.
    """

    def __init__(
        self,
        upstream_port: int,
        *,
        host: str,
        port: int,
        max_frame_bytes: int = MAX_FRAME_BYTES,
        backlog_bytes: int = BACKLOG_BYTES,
        handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
        ping_interval_s: float | None = PING_INTERVAL_S,
        close_timeout_s: float = CLOSE_TIMEOUT_S,
    ) -> None:
        if not isinstance(host, str) or not host.strip():
            raise ValueError(
                "the live view's host must be an address or a name (127.0.0.1: this machine only; "
                "0.0.0.0: every interface), not empty"
            )
        self.upstream = f"ws://127.0.0.1:{int(upstream_port)}"
        self.max_frame_bytes = int(max_frame_bytes)
        self.backlog_bytes = int(backlog_bytes)
        self.handshake_timeout_s = float(handshake_timeout_s)
        self.ping_interval_s = ping_interval_s
        self.close_timeout_s = float(close_timeout_s)
        self.clients: set[_Client] = set()
        """The clients past the handshake, now (read from any thread)."""
        self._busy = 0
        self._conns: set = set()  # every TCP connection, handshakes included (to abort at close)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="morfic-ws-relay", daemon=True)
        self._thread.start()
        try:
            self._server = asyncio.run_coroutine_threadsafe(self._serve(host, port), self._loop).result()
        except BaseException:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join()
            self._loop.close()
            raise
        self.port = int(self._server.sockets[0].getsockname()[1])

    @property
    def busy(self) -> int:
        """Connections the relay is still handling (handshakes included); 0 once every client is done with."""
        return self._busy

    @property
    def addresses(self) -> list[tuple]:
        """The addresses of the listening sockets (``getsockname()``)."""
        return [s.getsockname() for s in self._server.sockets]

    def report(self, connection, reason: str, *, refused: bool = False) -> None:
        """One warning line for a bad client, the first time only (``connection.reported``).

        None once the relay is closing: a handshake cut short by the shutdown is no client's fault.
        """
        if getattr(connection, "reported", False) or not self._server.is_serving():
            return
        connection.reported = True
        log.warning(
            "live view: %s client %s: %s", "refused" if refused else "closed", _peer(connection), one_line(reason, 240)
        )

    async def _serve(self, host: str, port: int):
        from websockets.asyncio.server import ServerConnection, serve
        from websockets.protocol import State
        from websockets.typing import Subprotocol

        relay = self

        class Connection(ServerConnection):
            """A client connection whose failed handshake is reported once, and counted in :attr:`busy`."""

            reported = False
            refusal: str | None = None

            def connection_made(self, transport) -> None:
                relay._busy += 1
                relay._conns.add(self)
                super().connection_made(transport)

            def connection_lost(self, exc) -> None:
                relay._conns.discard(self)
                super().connection_lost(exc)

            async def handshake(self, *args, **kwargs) -> None:
                try:
                    try:
                        await asyncio.wait_for(super().handshake(*args, **kwargs), relay.handshake_timeout_s)
                    except asyncio.TimeoutError:
                        relay.report(
                            self,
                            f"sent no complete WebSocket handshake within {relay.handshake_timeout_s:g} s",
                            refused=True,
                        )
                        raise
                    except Exception as exc:
                        relay.report(self, _handshake_failure(exc), refused=True)
                        raise
                    if self.protocol.state is not State.OPEN:
                        relay.report(
                            self, self.refusal or _handshake_failure(self.protocol.handshake_exc), refused=True
                        )
                finally:  # reported first: busy reaching 0 means every report is out
                    if self.protocol.state is not State.OPEN:
                        relay._busy -= 1

        def select(connection, offered: Sequence[Subprotocol]) -> Subprotocol | None:
            return next((Subprotocol(p) for p in SUBPROTOCOLS if p in offered), None)

        def check(connection, request):
            if "websocket" not in request.headers.get("Upgrade", "").lower():
                connection.refusal = (
                    f"sent an HTTP request without a WebSocket upgrade ({one_line(request.path, 60)}) -> HTTP 426"
                )
                return connection.respond(426, UPGRADE_MESSAGE + "\n")
            offered = _offered(request)
            if not any(p in offered for p in SUBPROTOCOLS):
                connection.refusal = (
                    f"offered no Foxglove subprotocol (offered: "
                    f"{one_line(', '.join(offered) or 'none', 80)}) -> HTTP 400"
                )
                return connection.respond(400, refusal_message(offered) + "\n")
            return None

        return await serve(
            self._relay,
            host,
            port,
            subprotocols=[Subprotocol(p) for p in SUBPROTOCOLS],
            select_subprotocol=select,
            process_request=check,
            compression=None,
            max_size=self.max_frame_bytes,
            open_timeout=None,
            ping_interval=self.ping_interval_s,
            ping_timeout=self.ping_interval_s,
            close_timeout=self.close_timeout_s,
            create_connection=Connection,
        )

    async def _relay(self, client) -> None:
        try:
            await self._relay_client(client)
        except Exception as exc:  # e.g. the upstream server is gone: one line, not websockets' traceback
            self.report(client, f"relay failed: {type(exc).__name__}: {exc} -> close 1011")
            await self._close_client(client, 1011, "morfic play's relay failed")
        finally:
            self._busy -= 1

    async def _relay_client(self, client) -> None:
        from websockets.asyncio.client import connect
        from websockets.exceptions import ConnectionClosed
        from websockets.protocol import State
        from websockets.typing import Subprotocol

        state = _Client(_peer(client), Outbox(self.backlog_bytes))
        self.clients.add(state)
        try:
            upstream = await connect(
                self.upstream,
                subprotocols=[Subprotocol(SDK_SUBPROTOCOL)],
                compression=None,
                max_size=None,
                ping_interval=None,
                close_timeout=self.close_timeout_s,
            )
            try:

                async def inbound() -> None:  # client -> server, checked
                    async for frame in client:
                        reason = state.check(frame)
                        if reason is not None:
                            raise _BadClient(1008, reason)
                        await upstream.send(frame)

                async def fetch() -> None:  # server -> the client's outbox, never waiting on the client
                    async for frame in upstream:
                        if isinstance(frame, str):
                            state.learn(frame)
                        try:
                            state.outbox.put(frame)
                        except TooSlow as exc:
                            raise _BadClient(1008, str(exc)) from None

                async def deliver() -> None:  # outbox -> client, at the client's pace
                    while True:
                        await client.send(await state.outbox.get())

                tasks = [asyncio.ensure_future(f()) for f in (inbound, fetch, deliver)]
                try:
                    done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for task in tasks:
                        task.cancel()
                    await asyncio.gather(*tasks, return_exceptions=True)
            finally:
                await _close_upstream(upstream)
        finally:
            self.clients.discard(state)
        bad = next((e for e in (t.exception() for t in done) if isinstance(e, _BadClient)), None)
        if bad is not None:
            self.report(client, f"{bad.reason} -> close {bad.code}")
            await self._close_client(client, bad.code, one_line(bad.reason, 120))
            return
        for task in done:  # a relay bug, not the client's doing: raised, reported by _relay
            exc = task.exception()
            if exc is not None and not isinstance(exc, ConnectionClosed):
                raise exc
        if tasks[1] in done and client.protocol.state is State.OPEN:  # the upstream server went away
            self.report(client, "the live view's server closed its side -> close 1011")
            await self._close_client(client, 1011, "the live view's server closed")
            return
        await client.wait_closed()
        proto = client.protocol
        sent = proto.close_sent
        if sent is not None and not proto.close_rcvd_then_sent:
            if sent.code in _PROTOCOL_CLOSES:
                self.report(client, f"{_PROTOCOL_CLOSES[sent.code]} ({sent.reason}) -> close {sent.code}")
            elif sent.code == 1011 and proto.close_rcvd is None and "ping" in sent.reason:
                self.report(client, f"did not answer a ping within {self.ping_interval_s:g} s -> close 1011")

    async def _close_client(self, client, code: int, reason: str) -> None:
        """Close with ``code``; abort the TCP connection if that takes over ``close_timeout_s``.

        ``close()`` alone can wait forever on a client that does not read: it first waits for room in the write
        buffer, which ``close_timeout`` does not cover.
        """
        try:
            await asyncio.wait_for(client.close(code, reason), self.close_timeout_s)
        except asyncio.TimeoutError:
            client.transport.abort()

    def close(self) -> None:
        """Stop listening, close the clients' connections and the loop.

        Clients get a close frame (1001) and ``close_timeout_s`` to answer it; the connections still open then
        (a client that does not read, a handshake under way) are aborted.
        """
        if self._loop.is_closed():
            return

        async def shutdown() -> None:
            self._server.close()
            try:
                await asyncio.wait_for(asyncio.shield(self._server.wait_closed()), self.close_timeout_s)
            except asyncio.TimeoutError:
                for conn in list(self._conns):
                    conn.transport.abort()
                await self._server.wait_closed()

        try:
            asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(timeout=self.close_timeout_s + 10)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=10)
            self._loop.close()


class _Client:
    """One relayed client: its address, its outbox, and what the server told it (for the frame checks)."""

    def __init__(self, peer: str, outbox: Outbox) -> None:
        self.peer = peer
        self.outbox = outbox
        self.capabilities: set[str] = set()
        """The ``serverInfo``'s capabilities."""
        self.channels: set[int] = set()
        """The channel ids ever advertised to the client."""

    def learn(self, frame: str) -> None:
        """Note the capabilities of a ``serverInfo`` and the channels of an ``advertise`` on their way out."""
        try:
            msg = json.loads(frame)
        except ValueError:
            return
        if not isinstance(msg, dict):
            return
        if msg.get("op") == "serverInfo" and isinstance(msg.get("capabilities"), list):
            self.capabilities = {c for c in msg["capabilities"] if isinstance(c, str)}
        elif msg.get("op") == "advertise" and isinstance(msg.get("channels"), list):
            self.channels |= {c["id"] for c in msg["channels"] if isinstance(c, dict) and type(c.get("id")) is int}

    def check(self, frame: str | bytes) -> str | None:
        """:func:`client_frame_error` against what the server told this client."""
        return client_frame_error(frame, capabilities=self.capabilities, channels=self.channels)
