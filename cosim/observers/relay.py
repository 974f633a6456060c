"""The live view's front door: a byte relay between its viewers and the Foxglove server that answers a viewer's close.

foxglove-sdk's WebSocket server (0.30, and its source to date) ends a connection whose client sent a Close frame
without a Close frame in answer (its poller leaves its receive loop on the client's Close and drops the socket), so
the client sees code 1006 (abnormal closure) where RFC 6455 section 5.5.1 asks the server to answer a Close with a
Close. :class:`Relay` listens on the live view's public address and passes every byte both ways, unchanged, to the
SDK's server on a loopback port: the HTTP upgrade, the server's frames, its own Close when the run ends, its answer
to a bad request. It follows the frame boundaries of both directions (headers only: payloads are not touched, but
for a client's Close), and when a viewer's Close has arrived whole it sends, at the next boundary of the server's
frames, a Close echoing the viewer's status code (none when it gave none), forwards the viewer's Close to the server
(which then forgets the viewer, as before) and ends both connections.

Back-pressure is passed on: a viewer that reads slower than the server writes pauses the relay's reading from the
server, so the server's own per-viewer backlog (its lossy queue) still decides what such a viewer loses, and the run
never waits for it. The relay runs an asyncio loop in a thread of its own; what it costs the run is measured in
``docs/live-view.md``.
"""

from __future__ import annotations

import socket
import struct
import sys
import threading

from ..errors import printable

__all__ = ["Relay"]

_CLOSE = 0x8
_BINARY = 0x2
_MESSAGE_DATA = 0x01  # the Foxglove WebSocket protocol's binary op of a message on a subscribed channel
_CONTROL_MAX = 125  # bytes of a control frame's payload (RFC 6455 5.5); a Close claiming more is kept to that
_HEADER_END = b"\r\n\r\n"
_HANDSHAKE_LIMIT = 64 * 1024  # bytes of HTTP header before the relay stops looking for its end (a plain pipe then)


class _Frames:
    """Follows the frame boundaries of one direction of a WebSocket connection, after its HTTP header: ``feed(data)``
    returns the offsets in ``data`` where frames end, with each Close frame's payload (unmasked)."""

    def __init__(self, masked: bool) -> None:
        self.masked = masked
        self.header = b""  # a header not yet whole
        self.left = 0  # payload bytes of the current frame still to come
        self.close: bytearray | None = None  # the payload of a Close frame being read
        self.mask = b""
        self.messages = 0  # Foxglove message-data frames seen (binary, first payload byte 0x01)
        self._peek = False  # the current frame is binary and its first payload byte not yet seen

    @property
    def at_boundary(self) -> bool:
        return self.left == 0 and not self.header and self.close is None

    def feed(self, data: bytes) -> list[tuple[int, bytes | None]]:
        ends: list[tuple[int, bytes | None]] = []
        pos, n = 0, len(data)
        while pos < n:
            if self.left:
                take = min(self.left, n - pos)
                if self._peek:
                    self._peek = False
                    self.messages += data[pos] == _MESSAGE_DATA
                if self.close is not None and len(self.close) < _CONTROL_MAX:  # kept bounded: a header may claim 2^63
                    self.close += data[pos:pos + min(take, _CONTROL_MAX - len(self.close))]
                self.left -= take
                pos += take
                if not self.left:
                    ends.append((pos, self._closed()))
                continue
            need = self._header_size()
            got = min(need - len(self.header), n - pos)
            self.header += data[pos:pos + got]
            pos += got
            if len(self.header) < need or need != self._header_size():  # more header, or its length field grew it
                continue
            opcode, length = self.header[0] & 0x0F, self.header[1] & 0x7F
            if length == 126:
                length = struct.unpack_from("!H", self.header, 2)[0]
            elif length == 127:
                length = struct.unpack_from("!Q", self.header, 2)[0]
            self.mask = self.header[-4:] if self.masked else b""
            self.header = b""
            self.close = bytearray() if opcode == _CLOSE else None
            self._peek = opcode == _BINARY and length > 0
            self.left = length
            if not length:
                ends.append((pos, self._closed()))
        return ends

    def _header_size(self) -> int:
        if len(self.header) < 2:
            return 2
        length = self.header[1] & 0x7F
        return 2 + (2 if length == 126 else 8 if length == 127 else 0) + (4 if self.masked else 0)

    def _closed(self) -> bytes | None:
        """The payload of the Close frame that just ended (unmasked), or None when it was another frame."""
        if self.close is None:
            return None
        payload, self.close = bytes(self.close), None
        if self.mask:
            payload = bytes(b ^ self.mask[i % 4] for i, b in enumerate(payload))
        return payload


class _Side:
    """One of the two connections of a relayed viewer (the viewer's, the server's): what it receives goes to the
    other's transport (:meth:`_Pair.received`). An asyncio protocol by its methods, the six a socket transport calls,
    not by deriving from ``asyncio.Protocol``: this module is loaded by every run, which loads asyncio (0.04 s) only
    when a live view starts."""

    def __init__(self, pair: "_Pair", name: str) -> None:
        self.pair, self.name = pair, name
        self.transport: asyncio.Transport | None = None
        self.lost = False  # its connection is gone (closed and flushed, or reset)
        self.head = b""  # the HTTP header so far, until its end
        self.frames: _Frames | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self.pair.received(self, data)

    def eof_received(self):
        self.pair.ended(self)
        return False

    def connection_lost(self, exc) -> None:
        self.lost = True
        self.pair.ended(self)

    # back-pressure: what this side cannot write yet pauses the reading of the other
    def pause_writing(self) -> None:
        other = self.pair.other(self)
        if other.transport is not None:
            other.transport.pause_reading()

    def resume_writing(self) -> None:
        other = self.pair.other(self)
        if other.transport is not None and not other.transport.is_closing():
            other.transport.resume_reading()


class _Pair:
    """A viewer's connection and the relay's connection to the server for it."""

    def __init__(self, relay: "Relay") -> None:
        self.relay = relay
        self.viewer = _Side(self, "viewer")
        self.server = _Side(self, "server")
        self.pending: list[bytes] = []  # what the viewer sent before the server's connection was made
        self.answer: bytes | None = None  # the Close to send the viewer at the server's next frame boundary
        self.server_closed = False  # the server sent its Close: the viewer's Close is its answer, not echoed
        self.done = False

    def other(self, side: _Side) -> _Side:
        return self.server if side is self.viewer else self.viewer

    async def connect(self) -> None:
        import asyncio  # lazy: loaded when a live view starts, not by every run (0.04 s)

        loop = asyncio.get_running_loop()
        try:
            await loop.create_connection(lambda: self.server, self.relay.upstream[0], self.relay.upstream[1])
        except OSError:
            self.finish()
            return
        if self.done:
            self.server.transport.close()
            return
        for data in self.pending:
            self.server.transport.write(data)
        self.pending = []

    def received(self, side: _Side, data: bytes) -> None:
        if self.done:
            return
        from_viewer = side is self.viewer
        if side.frames is None:  # the HTTP upgrade: passed on as it is, its end looked for
            start = len(side.head)
            side.head += data
            end = side.head.find(_HEADER_END, max(0, start - 3))
            if end < 0:
                if len(side.head) > _HANDSHAKE_LIMIT:
                    side.frames = False  # not a WebSocket: a plain pipe from here on
                self._forward(side, data)
                return
            upgraded = from_viewer or side.head.startswith((b"HTTP/1.1 101", b"HTTP/1.0 101"))
            body = end + len(_HEADER_END) - start  # where in ``data`` the frames start
            side.head = b""
            side.frames = _Frames(masked=from_viewer) if upgraded else False
            self._forward(side, data[:body])
            data = data[body:]
            if not data:
                return
        if side.frames is False:
            self._forward(side, data)
        elif from_viewer:
            self._from_viewer(data)
        else:
            self._from_server(data)

    def _forward(self, side: _Side, data: bytes) -> None:
        if not data:
            return
        if side is self.viewer and self.server.transport is None:
            self.pending.append(data)
        else:
            self.other(side).transport.write(data)

    def _from_viewer(self, data: bytes) -> None:
        if not isinstance(self.server.frames, _Frames):  # the server did not upgrade the connection: no frames
            self._forward(self.viewer, data)
            return
        ends = self.viewer.frames.feed(data)
        close = next(((end, payload) for end, payload in ends if payload is not None), None)
        if close is None:
            self._forward(self.viewer, data)
            return
        end, payload = close
        self._forward(self.viewer, data[:end])  # the viewer's Close too: the server forgets the viewer
        if self.server_closed:  # the viewer answers the server's Close: the server's end follows
            return
        self.answer = payload[:2] if len(payload) >= 2 else b""  # its status code echoed (RFC 6455 5.5.1), or none
        self.viewer.transport.pause_reading()  # nothing may follow a Close
        if self.server.frames.at_boundary:
            self._answer()

    def _from_server(self, data: bytes) -> None:
        frames = self.server.frames
        before = frames.messages
        try:
            self._pass_on(frames, data)
        finally:
            self.relay.delivered += frames.messages - before

    def _pass_on(self, frames: _Frames, data: bytes) -> None:
        if self.answer is None:
            for _, payload in frames.feed(data):
                if payload is not None:
                    self.server_closed = True
            self.viewer.transport.write(data)
            return
        if not frames.at_boundary:  # the rest of the frame under way, then the answer
            first = frames.feed(data)
            if first:
                self.viewer.transport.write(data[:first[0][0]])
                self._answer()
            else:
                self.viewer.transport.write(data)

    def _answer(self) -> None:
        """The Close answering the viewer's, then the end of both connections."""
        payload, self.answer = self.answer or b"", None
        self.viewer.transport.write(bytes([0x80 | _CLOSE, len(payload)]) + payload)
        self.finish()

    def ended(self, side: _Side) -> None:
        """One side closed: the other is closed once what it was given is written."""
        if side is self.server and self.answer is not None and not self.done and self.server.frames.at_boundary:
            self._answer()  # the server left first: the viewer still gets its answer (not inside a frame cut short)
        self.finish()
        if all(s.lost or s.transport is None for s in (self.viewer, self.server)):
            self.relay.pairs.discard(self)

    def finish(self) -> None:
        """Close both connections, each once what it was given is written."""
        if self.done:
            return
        self.done = True
        for side in (self.viewer, self.server):
            if side.transport is not None:
                side.transport.close()

    def abort(self) -> None:
        self.done = True
        for side in (self.viewer, self.server):
            if side.transport is not None:
                side.transport.abort()


def _said(loop, context: dict) -> None:
    """An error inside the relay's loop: one line on stderr, as the live view says its server's messages."""
    what = context.get("exception") or context.get("message", "")
    print(f"warning: live view: relay: {printable(str(what))[:200]}", file=sys.stderr, flush=True)


class Relay:
    """Relay ``host:port`` (bound at once: ``port`` 0 picks one, :attr:`port` tells which) to the WebSocket server at
    ``upstream`` (host, port) from :meth:`start` on, in a thread of its own; :meth:`stop` ends it and every relayed
    connection. OSError from the constructor when the address cannot be bound."""

    def __init__(self, host: str, port: int) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._sock.bind((host, port))
            self._sock.listen(128)
        except OSError:
            self._sock.close()
            raise
        self._sock.setblocking(False)
        self.port = self._sock.getsockname()[1]
        self.upstream: tuple[str, int] = ("127.0.0.1", 0)
        self.pairs: set[_Pair] = set()
        self.delivered = 0  # Foxglove messages passed from the server to the viewers (see LiveView._drain)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    def connected(self) -> int:
        """How many viewers' connections are open (from any thread: the set is copied under the GIL)."""
        return sum(1 for pair in list(self.pairs) if not pair.done)

    def start(self, upstream: tuple[str, int]) -> None:
        import asyncio  # lazy: loaded when a live view starts, not by every run (0.04 s)

        self.upstream = upstream
        self._loop = asyncio.new_event_loop()
        ready = threading.Event()
        self._thread = threading.Thread(target=self._serve, args=(ready,), name="live-view-relay", daemon=True)
        self._thread.start()
        ready.wait()

    def _serve(self, ready: threading.Event) -> None:
        import asyncio  # lazy: loaded when a live view starts, not by every run (0.04 s)

        loop = self._loop
        asyncio.set_event_loop(loop)

        def accepted() -> _Side:
            pair = _Pair(self)
            self.pairs.add(pair)
            loop.create_task(pair.connect())
            return pair.viewer

        loop.set_exception_handler(_said)
        self._server = loop.run_until_complete(loop.create_server(accepted, sock=self._sock))
        ready.set()
        loop.run_forever()
        left = [t for t in asyncio.all_tasks(loop) if not t.done()]  # connections to the server under way
        for t in left:
            t.cancel()
        loop.run_until_complete(asyncio.gather(*left, return_exceptions=True))
        loop.close()

    def stop(self, timeout: float = 1.0) -> int:
        """Stop accepting, close every relayed connection (what a viewer was given is written if it reads within
        ``timeout`` s; then its connection is reset), end the thread. Returns how many connections were reset (their
        viewers had stopped reading)."""
        if self._loop is None:
            self._sock.close()
            return 0
        import asyncio  # lazy: loaded when a live view starts, not by every run (0.04 s)

        loop = self._loop
        reset = [0]

        async def ending() -> None:
            self._server.close()
            for pair in list(self.pairs):
                pair.finish()
            end = loop.time() + timeout
            while self.pairs and loop.time() < end:
                await asyncio.sleep(0.02)
            reset[0] = len(self.pairs)
            for pair in list(self.pairs):
                pair.abort()
            await asyncio.sleep(0)  # the resets' callbacks
            loop.stop()

        loop.call_soon_threadsafe(lambda: loop.create_task(ending()))
        self._thread.join(timeout + 2.0)
        return reset[0]
