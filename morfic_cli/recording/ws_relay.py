"""A WebSocket front for ``foxglove-sdk``'s server that also speaks the subprotocol name ``foxglove.websocket.v1``.

``foxglove-sdk`` (0.2x-0.30) accepts only clients that offer the subprotocol ``foxglove.sdk.v1``: a client that
offers only ``foxglove.websocket.v1`` (the protocol's original name: older Lichtblick and Foxglove Studio
releases, ``@foxglove/ws-protocol`` clients, roslibjs-foxglove) gets HTTP 400 and the server logs only "handshake
failed". The two names are the same protocol on the wire (Foxglove's stance: ``sdk.v1`` is ``websocket.v1``
renamed), so :class:`SubprotocolRelay` listens where the user asked, accepts either name (``foxglove.sdk.v1``
first), and relays every frame unchanged to and from the SDK's server on a private port of 127.0.0.1, connecting
there as ``foxglove.sdk.v1``. A client that offers neither gets HTTP 400 with a body that names both, and the
refusal is reported on morfic's side through ``on_refused`` (stderr by default).
"""

from __future__ import annotations

import asyncio
import sys
import threading
from collections.abc import Callable

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
"""The subprotocol ``foxglove-sdk``'s server accepts."""
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
"""The Foxglove WebSocket protocol's original subprotocol name (same messages)."""
SUBPROTOCOLS = (SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL)
"""What the relay accepts, in order of preference."""


def refusal_message(offered: list[str]) -> str:
    """The text of the HTTP 400 a client gets when it offers no subprotocol the relay speaks.

    Args:
        offered: The subprotocols the client offered (may be empty).

    Returns:
        One line naming what was offered and what is accepted.
    """
    got = ", ".join(offered) if offered else "none"
    return (f"morfic play speaks the Foxglove WebSocket protocol: offer the subprotocol {SDK_SUBPROTOCOL} or "
            f"{LEGACY_SUBPROTOCOL} (this client offered: {got})")


def _offered(request) -> list[str]:
    """The subprotocols of a handshake request's ``Sec-WebSocket-Protocol`` headers, in order."""
    return [p.strip() for value in request.headers.get_all("Sec-WebSocket-Protocol")
            for p in value.split(",") if p.strip()]


class SubprotocolRelay:
    """Listen on ``host:port`` and relay each client to the WebSocket server at ``127.0.0.1:upstream_port``.

    The relay runs its own asyncio loop in a daemon thread; the constructor returns once it listens, and raises
    the ``OSError`` of a port that cannot be bound.

    Args:
        upstream_port: Port of ``foxglove-sdk``'s server on 127.0.0.1.
        host: Interface to bind.
        port: TCP port (0: any free one; :attr:`port` says which).
        on_refused: Called with :func:`refusal_message` when a client offers no accepted subprotocol
            (default: printed on stderr).
    """

    def __init__(self, upstream_port: int, *, host: str, port: int,
                 on_refused: Callable[[str], None] | None = None) -> None:
        self.upstream = f"ws://127.0.0.1:{int(upstream_port)}"
        self.on_refused = on_refused or (lambda msg: print(f"morfic play: refused a client: {msg}",
                                                           file=sys.stderr, flush=True))
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

    async def _serve(self, host: str, port: int):
        from websockets.asyncio.server import serve

        def select(connection, offered: list[str]) -> str | None:
            return next((p for p in SUBPROTOCOLS if p in offered), None)

        def check(connection, request):
            offered = _offered(request)
            if not any(p in offered for p in SUBPROTOCOLS):
                msg = refusal_message(offered)
                self.on_refused(msg)
                return connection.respond(400, msg + "\n")
            return None

        return await serve(self._relay, host, port, subprotocols=list(SUBPROTOCOLS), select_subprotocol=select,
                           process_request=check, compression=None, max_size=None, ping_interval=None)

    async def _relay(self, client) -> None:
        from websockets.asyncio.client import connect
        from websockets.exceptions import ConnectionClosed

        async with connect(self.upstream, subprotocols=[SDK_SUBPROTOCOL], compression=None, max_size=None,
                           ping_interval=None) as upstream:
            async def pump(src, dst) -> None:
                try:
                    async for frame in src:
                        await dst.send(frame)
                except ConnectionClosed:
                    pass

            tasks = [asyncio.ensure_future(pump(client, upstream)), asyncio.ensure_future(pump(upstream, client))]
            _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)

    def close(self) -> None:
        """Stop listening, close the clients' connections and the loop."""
        if self._loop.is_closed():
            return

        async def shutdown() -> None:
            self._server.close()
            await self._server.wait_closed()

        try:
            asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(timeout=10)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=10)
            self._loop.close()
