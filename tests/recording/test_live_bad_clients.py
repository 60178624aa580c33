"""The live view under bad clients: garbage, floods, slow readers and abrupt disconnects never stop it.

Real sockets on 127.0.0.1 (ephemeral ports): a raw TCP client for what no WebSocket library would send, a
``websockets`` client for the well-behaved one that must still connect, subscribe and receive afterwards. Each bad
client must cost exactly one warning line (peer address and reason, no traceback); a disconnect costs none. The
timeouts here only guard against hangs: no assertion depends on how long something took.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import socket
import struct
import threading
import time

import numpy as np
import pytest

from morfic_cli.recording.live import LiveView
from morfic_cli.recording.ws_relay import (
    LEGACY_SUBPROTOCOL,
    SDK_SUBPROTOCOL,
    Outbox,
    SubprotocolRelay,
    TooSlow,
    client_frame_error,
    is_loopback,
)

TERMS = ["r_lin", "r_yaw"]
N = 2
GUARD_S = 20.0
"""Failure guard for anything awaited (never reached when things work)."""
RELAY_LOG = "morfic_cli.recording.ws_relay"


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


@pytest.fixture(scope="module")
def live():
    """A running live view (go1 scene, 2 envs, a step every 10 ms) for the whole module."""
    from morfic_cli.morphology.builder import build_model
    from morfic_cli.morphology.robots import load_robot
    from morfic_cli.recording.scene import RolloutScene

    model = build_model(load_robot("go1"))
    scene = RolloutScene([model, model], [0, 1], np.asarray(model.jnt_qposadr[1:]))
    view = LiveView(num_envs=N, term_names=TERMS, scene=scene, host="127.0.0.1", port=0)
    stop = threading.Event()

    def publish() -> None:
        t = 0
        while not stop.is_set():
            view.publish(t, 0.02 * (t + 1), _step(t))
            t += 1
            stop.wait(0.01)

    pump = threading.Thread(target=publish, daemon=True)
    pump.start()
    yield view
    stop.set()
    pump.join()
    view.close()


@pytest.fixture
def relay(live, caplog):
    """A relay of its own in front of the live view's server, with short handshake and close timeouts."""
    caplog.set_level(logging.WARNING)
    r = SubprotocolRelay(
        live.server.port,
        host="127.0.0.1",
        port=0,
        max_frame_bytes=64 << 10,
        handshake_timeout_s=0.5,
        close_timeout_s=2.0,
        ping_interval_s=None,
    )
    yield r
    r.close()


def _wait(cond, what: str) -> None:
    deadline = time.monotonic() + GUARD_S
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(0.01)


def _idle(relay: SubprotocolRelay) -> None:
    """Until the relay is done with every connection (so every line it will write about them is written)."""
    _wait(lambda: relay.busy == 0 and not relay.clients, "the relay to finish with its clients")


def _warnings(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.levelno >= logging.WARNING]


def _one_line_for(caplog, port: int, *fragments: str) -> str:
    """The one warning about the client at local port ``port``; checks it is the only one and is one line."""
    lines = [r for r in _warnings(caplog) if f"127.0.0.1:{port}:" in r.getMessage()]
    assert len(lines) == 1, [r.getMessage() for r in _warnings(caplog)]
    rec = lines[0]
    msg = rec.getMessage()
    assert rec.name == RELAY_LOG and rec.levelno == logging.WARNING and rec.exc_info is None
    assert "\n" not in msg and "Traceback" not in msg and msg.startswith("live view: ")
    assert all(f in msg for f in fragments), msg
    return msg


def _only_relay_lines(caplog) -> None:
    """No other logger (websockets, asyncio, foxglove) said anything at warning level or above."""
    assert all(r.name == RELAY_LOG and r.exc_info is None for r in _warnings(caplog)), [
        (r.name, r.getMessage()) for r in _warnings(caplog)
    ]


async def _good_client(port: int, n: int = 3, subprotocol: str = LEGACY_SUBPROTOCOL) -> int:
    """Connect, subscribe to every advertised channel and receive ``n`` messages; the number received."""
    import websockets

    async with websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=[subprotocol], max_size=None, open_timeout=GUARD_S
    ) as ws:
        got = 0
        while got < n:
            frame = await ws.recv()
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "advertise":
                    await ws.send(
                        json.dumps(
                            {
                                "op": "subscribe",
                                "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in op["channels"]],
                            }
                        )
                    )
            elif frame[0] == 1:
                got += 1
        return got


def _still_serves(port: int) -> None:
    assert asyncio.run(asyncio.wait_for(_good_client(port), GUARD_S)) == 3


class Raw:
    """A TCP client that speaks WebSocket by hand (or not at all)."""

    def __init__(self, port: int, rcvbuf: int | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf is not None:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.settimeout(GUARD_S)
        self.sock.connect(("127.0.0.1", port))
        self.port = self.sock.getsockname()[1]
        self.buf = b""

    def request(self, subprotocol: str | None = LEGACY_SUBPROTOCOL, upgrade: bool = True, key: bool = True) -> bytes:
        lines = ["GET / HTTP/1.1", "Host: 127.0.0.1"]
        if upgrade:
            lines += ["Upgrade: websocket", "Connection: Upgrade", "Sec-WebSocket-Version: 13"]
        if key:
            lines.append("Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==")
        if subprotocol:
            lines.append(f"Sec-WebSocket-Protocol: {subprotocol}")
        return ("\r\n".join(lines) + "\r\n\r\n").encode()

    def handshake(self) -> None:
        self.sock.sendall(self.request())
        while b"\r\n\r\n" not in self.buf:
            self.buf += self._recv()
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        assert head.startswith(b"HTTP/1.1 101"), head

    def _recv(self) -> bytes:
        data = self.sock.recv(65536)
        if not data:
            raise EOFError
        return data

    def _take(self, n: int) -> bytes:
        while len(self.buf) < n:
            self.buf += self._recv()
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def read_frame(self) -> tuple[int, bytes]:
        b0, b1 = self._take(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._take(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._take(8))[0]
        return b0 & 0x0F, self._take(n)

    @staticmethod
    def frame(opcode: int, payload: bytes, *, masked: bool = True, length: int | None = None) -> bytes:
        n = len(payload) if length is None else length
        head = bytes([0x80 | opcode])
        mask_bit = 0x80 if masked else 0
        if n < 126:
            head += bytes([mask_bit | n])
        elif n < 1 << 16:
            head += bytes([mask_bit | 126]) + struct.pack(">H", n)
        else:
            head += bytes([mask_bit | 127]) + struct.pack(">Q", n)
        if not masked:
            return head + payload
        key = os.urandom(4)
        return head + key + bytes(b ^ key[i % 4] for i, b in enumerate(payload))

    def send(self, opcode: int, payload: bytes, **kw) -> None:
        try:
            self.sock.sendall(self.frame(opcode, payload, **kw))
        except (BrokenPipeError, ConnectionResetError):  # the server closed first: what some tests want
            pass

    def subscribe_all(self) -> None:
        """Read up to the advertise and subscribe to every channel."""
        while True:
            opcode, payload = self.read_frame()
            if opcode == 1 and json.loads(payload)["op"] == "advertise":
                subs = [{"id": c["id"], "channelId": c["id"]} for c in json.loads(payload)["channels"]]
                self.send(1, json.dumps({"op": "subscribe", "subscriptions": subs}).encode())
                return

    def finish(self) -> int | None:
        """Read until the server closes; answer its close frame. The close code (None: no close frame)."""
        code = None
        try:
            while True:
                opcode, payload = self.read_frame()
                if opcode == 8 and code is None:
                    code = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 1005
                    self.send(8, payload[:2])
        except (EOFError, ConnectionResetError):
            pass
        self.sock.close()
        return code

    def drain_to_eof(self) -> bytes:
        """Everything the server sends until it closes the connection (an HTTP response, or nothing)."""
        out = self.buf
        try:
            while True:
                out += self._recv()
        except (EOFError, ConnectionResetError):
            pass
        self.sock.close()
        return out

    def reset(self) -> None:
        """Abort with a TCP RST."""
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        self.sock.close()


# --- where it listens ------------------------------------------------------------------------------------------


def _listening(port: int) -> set[str]:
    """Local addresses of the sockets listening on ``port`` (from /proc/net/tcp and tcp6)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for row in f.readlines()[1:]:
                local, state = row.split()[1], row.split()[3]
                addr, p = local.split(":")
                if state == "0A" and int(p, 16) == port:  # LISTEN
                    found.add(
                        socket.inet_ntop(socket.AF_INET, bytes.fromhex(addr)[::-1])
                        if len(addr) == 8
                        else f"{table[-4:]}:{addr}"
                    )
    return found


def test_the_live_view_listens_on_127_0_0_1_only(live):
    assert {a[0] for a in live.relay.addresses} == {"127.0.0.1"}
    if not os.path.exists("/proc/net/tcp"):
        pytest.skip("no /proc/net/tcp to list the listening sockets")
    assert _listening(live.port) == {"127.0.0.1"}  # the relay, where clients connect
    assert _listening(live.server.port) == {"127.0.0.1"}  # foxglove-sdk's server behind it


def test_every_interface_takes_an_explicit_host(run_cli):
    import inspect

    from morfic_cli.cli.play import play
    from morfic_cli.evaluation.play import PlayCfg

    assert PlayCfg().host == "127.0.0.1"
    assert inspect.signature(play).parameters["host"].default == "127.0.0.1"
    for host in ("", "  "):  # asyncio would bind every interface
        with pytest.raises(ValueError, match="not empty"):
            SubprotocolRelay(1, host=host, port=0)
    code, _, err = run_cli("play", "runs/x", "--host", "")
    assert code == 1 and "--host must name an interface" in err
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("::") and not is_loopback("192.168.1.2")


# --- bad handshakes --------------------------------------------------------------------------------------------


def _junk(raw: Raw) -> bytes:
    raw.sock.sendall(b"\x16\x03\x01\x00\xa5\x01junk that is no HTTP\r\n\r\n")
    return raw.drain_to_eof()


def _plain_get(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request(subprotocol=None, upgrade=False))
    return raw.drain_to_eof()


def _wrong_subprotocol(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request(subprotocol="foxglove.websocket.v2"))
    return raw.drain_to_eof()


def _no_subprotocol(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request(subprotocol=None))
    return raw.drain_to_eof()


def _no_key(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request(key=False))
    return raw.drain_to_eof()


def _silent(raw: Raw) -> bytes:
    return raw.drain_to_eof()


def _half_then_stall(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request()[:40])
    return raw.drain_to_eof()


def _half_then_close(raw: Raw) -> bytes:
    raw.sock.sendall(raw.request()[:40])
    raw.sock.shutdown(socket.SHUT_WR)
    return raw.drain_to_eof()


def _connect_and_close(raw: Raw) -> bytes:
    raw.sock.shutdown(socket.SHUT_WR)
    return raw.drain_to_eof()


@pytest.mark.parametrize(
    "bad, answer, reason",
    [
        (_junk, b"", "did not send an HTTP request"),
        (_plain_get, b"HTTP/1.1 426", "without a WebSocket upgrade"),
        (_wrong_subprotocol, b"HTTP/1.1 400", "offered no Foxglove subprotocol (offered: foxglove.websocket.v2)"),
        (_no_subprotocol, b"HTTP/1.1 400", "offered no Foxglove subprotocol (offered: none)"),
        (_no_key, b"HTTP/1.1 400", "Sec-WebSocket-Key"),
        (_silent, b"", "no complete WebSocket handshake within 0.5 s"),
        (_half_then_stall, b"", "no complete WebSocket handshake within 0.5 s"),
        (_half_then_close, b"", "closed the connection before completing a WebSocket handshake"),
        (_connect_and_close, b"", "closed the connection before completing a WebSocket handshake"),
    ],
    ids=lambda v: v.__name__.strip("_") if callable(v) else None,
)
def test_a_bad_handshake_is_refused_in_one_line_and_the_server_keeps_serving(relay, caplog, bad, answer, reason):
    clients = [Raw(relay.port) for _ in range(3)]  # three alike: one line each
    for raw in clients:
        assert bad(raw).startswith(answer)
    _idle(relay)
    for raw in clients:
        _one_line_for(caplog, raw.port, "live view: refused client", reason)
    _only_relay_lines(caplog)
    _still_serves(relay.port)


def test_a_plain_http_request_is_told_what_the_port_is(relay):
    body = _plain_get(Raw(relay.port)).decode()
    assert "426" in body and "Foxglove WebSocket" in body


# --- bad frames ------------------------------------------------------------------------------------------------

BAD_FRAMES = {
    "not json": (1, b"hello", 1008, "not JSON"),
    "json list": (1, b"[1, 2]", 1008, "not an object (list)"),
    "no op": (1, b'{"x": 1}', 1008, "without an op"),
    "unknown op": (1, b'{"op": "frobnicate"}', 1008, "unknown op 'frobnicate'"),
    "subscribe shape": (1, b'{"op": "subscribe", "subscriptions": "all"}', 1008, "subscribe without"),
    "subscribe ids": (
        1,
        b'{"op": "subscribe", "subscriptions": [{"id": "1", "channelId": 1}]}',
        1008,
        "subscribe without",
    ),
    "unsubscribe shape": (1, b'{"op": "unsubscribe", "subscriptionIds": [1.5]}', 1008, "unsubscribe without"),
    "unknown channel": (
        1,
        b'{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 99999}]}',
        1008,
        "subscribed to channel 99999, which the server never advertised",
    ),
    "client message data": (2, b"\x01\x01\x00\x00\x00hi", 1008, "needs the clientPublish capability"),
    "service call": (2, b"\x02" + bytes(16), 1008, "needs the services capability"),
    "binary garbage": (2, b"\xff\x00garbage\x13\x37", 1008, "first byte ff"),
    "empty binary": (2, b"", 1008, "first byte none"),
    "oversized": (1, b"x" * (64 << 10 | 1), 1009, "frame too long"),
    "invalid utf-8": (1, b"\xff\xfe{}", 1007, "invalid frame data"),
    "unmasked": ("unmasked", b'{"op": "unsubscribe", "subscriptionIds": []}', 1002, "broke the WebSocket framing"),
}


@pytest.mark.parametrize("case", list(BAD_FRAMES))
def test_a_bad_frame_closes_that_client_in_one_line_and_the_server_keeps_serving(relay, caplog, case):
    opcode, payload, code, reason = BAD_FRAMES[case]
    raw = Raw(relay.port)
    raw.handshake()
    raw.subscribe_all()
    for _ in range(3):  # several bad frames, one line
        if opcode == "unmasked":
            raw.send(1, payload, masked=False)
        else:
            raw.send(opcode, payload)
    assert raw.finish() == code
    _idle(relay)
    _one_line_for(caplog, raw.port, "live view: closed client", reason, f"close {code}")
    _only_relay_lines(caplog)
    _still_serves(relay.port)


@pytest.mark.parametrize(
    "frame",
    [
        '{"op": "subscribe", "subscriptions": []}',
        '{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 7}]}',
        '{"op": "unsubscribe", "subscriptionIds": [7]}',
        '{"op": "getParameters", "parameterNames": []}',
        '{"op": "advertise", "channels": []}',
        b"\x01\x00\x00\x00\x00payload",
        b"\x02" + bytes(12),
    ],
)
def test_a_well_formed_request_passes_even_one_the_server_declines(frame):
    assert client_frame_error(frame, capabilities={"clientPublish", "services"}, channels={7}) is None


def test_a_declined_request_gets_the_servers_status_and_no_line(relay, caplog):
    async def run() -> dict:
        import websockets

        async with websockets.connect(f"ws://127.0.0.1:{relay.port}", subprotocols=[SDK_SUBPROTOCOL]) as ws:
            await ws.send(json.dumps({"op": "getParameters", "parameterNames": []}))
            while True:
                frame = await ws.recv()
                if isinstance(frame, str) and json.loads(frame)["op"] == "status":
                    return json.loads(frame)

    status = asyncio.run(asyncio.wait_for(run(), GUARD_S))
    assert status["level"] == 2 and "parameters" in status["message"]
    _idle(relay)
    assert not _warnings(caplog)


# --- disconnects -----------------------------------------------------------------------------------------------


def _reset_while_streaming(raw: Raw) -> None:
    raw.handshake()
    raw.subscribe_all()
    while raw.read_frame()[0] != 2:  # a message arrived
        pass
    raw.reset()


def _reset_during_subscribe(raw: Raw) -> None:
    raw.handshake()
    raw.subscribe_all()
    raw.reset()


def _close_mid_frame(raw: Raw) -> None:
    raw.handshake()
    raw.subscribe_all()
    raw.sock.sendall(Raw.frame(1, b'{"op": "unsubscribe", "subscriptionIds": [1]}')[:9])
    raw.sock.shutdown(socket.SHUT_WR)
    raw.drain_to_eof()


def _reset_mid_frame(raw: Raw) -> None:
    raw.handshake()
    raw.subscribe_all()
    raw.sock.sendall(Raw.frame(2, b"\x01" + bytes(500), length=5000)[:300])
    raw.reset()


def _close_cleanly(raw: Raw) -> None:
    raw.handshake()
    raw.subscribe_all()
    raw.send(8, struct.pack(">H", 1000))
    assert raw.finish() == 1000


@pytest.mark.parametrize(
    "drop",
    [_reset_while_streaming, _reset_during_subscribe, _close_mid_frame, _reset_mid_frame, _close_cleanly],
    ids=lambda f: f.__name__.strip("_"),
)
def test_a_disconnect_mid_stream_costs_no_line_and_the_server_keeps_serving(relay, caplog, drop):
    for _ in range(3):
        drop(Raw(relay.port))
    _idle(relay)
    assert not _warnings(caplog), [r.getMessage() for r in _warnings(caplog)]
    _still_serves(relay.port)


# --- many clients, slow clients --------------------------------------------------------------------------------


def test_fifty_clients_at_once_subscribing_and_dropping(live, caplog):
    """On the live view's own relay: 50 concurrent clients, a third leaving cleanly, a third by TCP reset after a
    message, a third by TCP reset right after subscribing; then nothing is left behind and a client is served."""
    import websockets

    caplog.set_level(logging.WARNING)

    async def one(i: int) -> int:
        ws = await websockets.connect(
            f"ws://127.0.0.1:{live.port}",
            max_size=None,
            open_timeout=GUARD_S,
            subprotocols=[(LEGACY_SUBPROTOCOL, SDK_SUBPROTOCOL)[i % 2]],
        )
        got = 0
        while True:
            frame = await ws.recv()
            if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                await ws.send(
                    json.dumps(
                        {
                            "op": "subscribe",
                            "subscriptions": [
                                {"id": c["id"], "channelId": c["id"]} for c in json.loads(frame)["channels"]
                            ],
                        }
                    )
                )
                if i % 3 == 2:
                    break
            elif isinstance(frame, bytes) and frame[0] == 1:
                got += 1
                break
        if i % 3 == 0:
            await ws.close()
        else:
            ws.transport.get_extra_info("socket").setsockopt(
                socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0)
            )
            ws.transport.abort()
        return got

    async def crowd() -> list[int]:
        return await asyncio.gather(*(one(i) for i in range(50)))

    got = asyncio.run(asyncio.wait_for(crowd(), 60))
    assert sum(got) == len([i for i in range(50) if i % 3 != 2])
    _idle(live.relay)
    assert not _warnings(caplog), [r.getMessage() for r in _warnings(caplog)]
    _still_serves(live.port)


@pytest.fixture
def bulk(live):
    """A channel of 32 KiB messages, as fast as they go: backs a slow client up within a second, kernel buffers
    and all, where the live view's own channels would take many."""
    import foxglove

    channel = foxglove.Channel(
        "/test/bulk", schema=foxglove.Schema(name="bulk", encoding="", data=b""), message_encoding="raw"
    )
    stop = threading.Event()

    def flood() -> None:
        payload = bytes(32 << 10)
        while not stop.is_set():
            channel.log(payload)
            stop.wait(0.001)

    pump = threading.Thread(target=flood, daemon=True)
    pump.start()
    yield channel
    stop.set()
    pump.join()
    channel.close()


def test_a_client_that_never_reads_loses_old_messages_not_the_others_service(live, bulk, caplog):
    caplog.set_level(logging.WARNING)
    limit = 64 << 10
    relay = SubprotocolRelay(
        live.server.port, host="127.0.0.1", port=0, backlog_bytes=limit, ping_interval_s=None, close_timeout_s=0.5
    )
    try:
        slow = Raw(relay.port, rcvbuf=4096)
        slow.handshake()
        slow.subscribe_all()  # and never reads again

        def stuck():
            return next((c.outbox for c in list(relay.clients) if c.peer == f"127.0.0.1:{slow.port}"), None)

        _wait(lambda: stuck() is not None and stuck().dropped >= 50, "the slow client's outbox to drop messages")
        for _ in range(2):  # others are served meanwhile, again and again
            _still_serves(relay.port)
        box = stuck()
        assert box.dropped >= 50 and box.peak <= limit + box.largest  # bounded: the limit plus one frame
        assert box.control_bytes < limit
    finally:
        relay.close()  # with the slow client still stuck: its connection is aborted, close() returns
    assert relay.busy == 0 and not relay.clients
    assert slow.drain_to_eof() is not None  # the connection is gone (reset or closed)
    assert not _warnings(caplog), [r.getMessage() for r in _warnings(caplog)]


def test_a_stuck_client_whose_control_messages_pass_the_bound_is_dropped_in_one_line(live, bulk, caplog):
    import foxglove

    caplog.set_level(logging.WARNING)
    limit = 64 << 10
    relay = SubprotocolRelay(
        live.server.port, host="127.0.0.1", port=0, backlog_bytes=limit, ping_interval_s=None, close_timeout_s=0.5
    )
    try:
        slow = Raw(relay.port, rcvbuf=4096)
        slow.handshake()
        slow.subscribe_all()
        _wait(lambda: any(c.outbox.dropped for c in list(relay.clients)), "the slow client to back up")
        schema = foxglove.Schema(name="churn", encoding="", data=bytes(8 << 10))
        for i in range(40):  # each new channel is an advertise of ~11 kB to every client, then an unadvertise
            if not relay.clients:
                break
            foxglove.Channel(f"/test/churn{i}", schema=schema, message_encoding="raw").close()
        _idle(relay)
        _one_line_for(caplog, slow.port, "live view: closed client", "read too slowly", "close 1008")
        _still_serves(relay.port)
    finally:
        relay.close()
    _only_relay_lines(caplog)


def test_a_client_that_stops_answering_pings_is_closed_in_one_line(live, caplog):
    caplog.set_level(logging.WARNING)
    relay = SubprotocolRelay(live.server.port, host="127.0.0.1", port=0, ping_interval_s=0.2, close_timeout_s=0.5)
    try:
        mute = Raw(relay.port)
        mute.handshake()  # then neither reads nor answers
        _idle(relay)
        _one_line_for(caplog, mute.port, "live view: closed client", "did not answer a ping", "close 1011")
        _still_serves(relay.port)
    finally:
        relay.close()
    _only_relay_lines(caplog)


def test_an_unreachable_server_is_one_line_and_a_1011_not_a_traceback(caplog):
    import websockets

    caplog.set_level(logging.WARNING)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        dead = s.getsockname()[1]
    relay = SubprotocolRelay(dead, host="127.0.0.1", port=0, close_timeout_s=0.5)
    try:

        async def run() -> tuple[int, int]:
            async with websockets.connect(f"ws://127.0.0.1:{relay.port}", subprotocols=[SDK_SUBPROTOCOL]) as ws:
                with pytest.raises(websockets.ConnectionClosedError):
                    await ws.recv()
                return ws.local_address[1], ws.close_code

        port, code = asyncio.run(asyncio.wait_for(run(), GUARD_S))
        _idle(relay)
    finally:
        relay.close()
    assert code == 1011
    _one_line_for(caplog, port, "live view: closed client", "relay failed: ConnectionRefusedError")
    _only_relay_lines(caplog)


def test_closing_with_a_handshake_under_way_and_a_stuck_client_returns_and_says_nothing(live, caplog):
    caplog.set_level(logging.WARNING)
    relay = SubprotocolRelay(live.server.port, host="127.0.0.1", port=0, close_timeout_s=0.5)
    silent = Raw(relay.port)  # mid-handshake (10 s allowed)
    half = Raw(relay.port)
    half.sock.sendall(half.request()[:30])
    stuck = Raw(relay.port, rcvbuf=4096)
    stuck.handshake()
    stuck.subscribe_all()
    _wait(lambda: relay.clients, "the stuck client to be relayed")
    relay.close()
    assert relay.busy == 0 and not relay.clients
    for raw in (silent, half, stuck):
        raw.drain_to_eof()
    assert not _warnings(caplog), [r.getMessage() for r in _warnings(caplog)]


# --- the outbox and the frame check on their own ---------------------------------------------------------------


def test_the_outbox_drops_the_oldest_messages_and_keeps_control_messages():
    box = Outbox(100)
    box.put('{"op":"advertise"}')
    data = [bytes([1, i]) + bytes(28) for i in range(10)]  # 30-byte message-data frames
    for frame in data:
        box.put(frame)
    assert box.bytes <= 100 and box.dropped == 8
    assert list(box.frames) == ['{"op":"advertise"}', data[8], data[9]]  # control kept, the newest messages
    big = bytes([1]) + bytes(500)
    box.put(big)  # a frame over the bound alone is still delivered
    assert list(box.frames) == ['{"op":"advertise"}', big] and box.peak == 18 + 501
    box.put(bytes([2]) + bytes(50))  # other binary opcodes (time, ...) are control: kept
    assert box.frames[-1][0] == 2
    box.put('{"op":"advertise","channels":[' + " " * 60 + "]}")  # over the bound with it, but it is the newest
    with pytest.raises(TooSlow, match="read too slowly"):
        box.put('{"op":"status"}')  # the control messages before it pass the bound: too slow

    async def drain() -> list:
        return [await box.get() for _ in range(len(box.frames))]

    assert len(asyncio.run(drain())) == 4 and box.bytes == 0 and box.control_bytes == 0


@pytest.mark.parametrize(
    "frame",
    [
        "",
        "null",
        "3",
        '"op"',
        '{"op": 3}',
        '{"op": "Subscribe"}',
        '{"op": "subscribe"}',
        '{"op": "subscribe", "subscriptions": [{"id": true, "channelId": 1}]}',
        '{"op": "unsubscribe", "subscriptionIds": "1"}',
        b"\x00",
        b"\x04\x00",
        b"\x7fELF",
    ],
)
def test_frames_the_protocol_does_not_define_are_named(frame):
    reason = client_frame_error(frame, capabilities={"clientPublish", "services", "playbackControl"})
    assert reason and reason.startswith("sent ") and "\n" not in reason
