"""Live view: serve a running co-simulation over the Foxglove WebSocket protocol (``foxglove-sdk``).

``python -m cosim run SCENARIO --live [PORT]`` adds a :class:`LiveView` to the run. It starts a
Foxglove WebSocket server (subprotocol ``foxglove.sdk.v1``) and attaches a sink to the run's
:class:`cosim.observers.publish.Publisher` that logs every channel into the server's ``foxglove.Context``
(component samples encoded by :func:`cosim.observers.log_writer.encode_messages` in the scenario's
``logging.layout``, one message per sample by default, as for the log), so a viewer connected to
``ws://localhost:PORT`` (the Foxglove app: *Open connection*, *Foxglove WebSocket*) sees exactly
the channels, schemas and 3D scene of the MCAP log, message for message, while the log is still
written. The server also broadcasts the run's current log time (the *Time* capability), so the
viewer's clock follows the simulation. The viewers reach the server through a relay
(:mod:`cosim.observers.relay`) that passes every byte unchanged and answers a viewer's close, which the server
does not. Combine it with ``--realtime`` to watch at wall-clock pace;
without it the run goes as fast as it can and the viewer sees it fast-forwarded.

``--live-wait [SECONDS]`` holds the run before it sends anything (every channel advertised, nothing logged yet) until
a viewer subscribes to a channel, at most SECONDS (:data:`cosim.cli.run.LIVE_WAIT_S` by default), so a viewer started
after the run misses nothing: the first message it gets is the first of the log. Meanwhile the run's phase is ``waiting``
(:data:`cosim.engine.supervision.WAITING`), which the watchdog and the supervisor take for progress; a stop signal ends
the wait as it ends a step.
"""

from __future__ import annotations

import logging
import socket
import sys
import threading
import time
from collections.abc import Sequence

from ..engine.cloop import Blocks, steps_to
from ..engine.execution import Execution, StopRequest
from ..engine.supervision import WAITING
from ..errors import CosimError, printable, shown
from .log_writer import FoxgloveChannels, encode_messages, live_view_serving
from .publish import Publisher
from .relay import Relay

__all__ = ["DEFAULT_PORT", "LiveView", "ViewerMessages", "parse_address"]

DEFAULT_PORT = 8765
_TIME_PERIOD_NS = 33_000_000  # viewer clock updates per simulated second: about 30
BACKLOG_MESSAGES = 1024
"""Messages queued per viewer (foxglove-sdk's ``message_backlog_size``): a viewer that reads slower than the run
loses its oldest messages, one that stops reading costs the run nothing."""
STOP_TIMEOUT = 2.0
"""s the server may take to close its connections at the end of the run; a viewer that does not take its close by
then (it stopped reading) is dropped with one warning line, and the run ends (issue 25: a stalled viewer held a
10 s run 51 s, through SIGINT, and SIGTERM then lost the finished log)."""
SETTLE_S = 0.2
"""s the wait goes on after a viewer's last subscription: the server announces the channels of one subscribe request
one by one, so the first announced is not yet all of them (a measured 1 in 3 got the first sample on one channel of
five without this)."""
DRAIN_QUIET_S = 0.5
"""s without a message passed to a viewer after which the run's end stops waiting for the rest of what is due to the
viewers (see :meth:`LiveView._drain`)."""
_POLL_S = 0.02  # s between two looks at the stop request while waiting


def parse_address(text: str | int | None) -> tuple[str, int]:
    """``"8765"``, ``"0.0.0.0:8765"`` or None (the default port) -> (host, port); CosimError when invalid."""
    if text is None:
        return "127.0.0.1", DEFAULT_PORT
    host, _, port = str(text).rpartition(":")
    try:
        value = int(port)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:
        raise CosimError(f"--live: expected a port number 0..65535 (or HOST:PORT), got {shown(repr(text))}")
    return host or "127.0.0.1", value


def _check_free(host: str, port: int) -> None:
    """Raise CosimError now (before any FMU is loaded) when ``host:port`` cannot be bound."""
    if port == 0:
        return
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            raise CosimError(f"--live: cannot serve on {host}:{port}: {exc.strerror or exc} "
                             f"(choose another port: --live PORT)") from None


class _ContextSink(FoxgloveChannels):
    """A publisher's sink logging into a ``foxglove.Context`` (see :class:`cosim.observers.publish.Publisher`)."""

    def __init__(self, context, viewers: dict[int, int], first=None) -> None:
        self._context = context
        self._channels: list = []
        self._log: dict[int, object] = {}
        self._layouts: dict = {}
        self._first = first  # called once before the first message is sent: every channel is declared by then
        self._ids: dict[int, int] = {}  # the publisher's channel id -> the server's
        self._viewers = viewers  # the server's channel id -> viewers subscribed to it (the live view's listener)
        self.due = 0  # messages handed to the server for its viewers: one per message and subscribed viewer

    def channel(self, cid: int, *args, **kwargs) -> None:
        super().channel(cid, *args, **kwargs)
        self._ids[cid] = self._channels[-1].id()

    def _sending(self) -> None:
        first, self._first = self._first, None
        first()

    def blocks(self, offset_ns: int, blocks) -> None:
        if self._first is not None:
            self._sending()
        for cid, stamps, data, skip in blocks:
            log = self._log[cid]
            sent = 0
            for t, message in zip(*encode_messages(self._layouts[cid], stamps, data, skip, offset_ns)):
                log(message, t)
                sent += 1
            self.due += sent * self._viewers.get(self._ids[cid], 0)

    def message(self, cid: int, log_time: int, data: bytes) -> None:
        if self._first is not None:
            self._sending()
        self._log[cid](data, log_time)
        self.due += self._viewers.get(self._ids[cid], 0)

    def close(self) -> None:
        for ch in self._channels:
            ch.close()
        self._channels.clear()


class ViewerMessages(logging.Handler):
    """What the Foxglove server logs about its viewers while the live view serves (a viewer's bad request, a
    dropped connection), shown on stderr as the platform shows outside text: each line escaped
    (:func:`cosim.errors.printable`: a viewer's op string may hold terminal escapes) and cut to
    :data:`SHOWN_CHARS`, the first :data:`SHOWN_LINES` of them, then one line counting the rest when serving
    ends (200 vanishing viewers printed 4 697 lines)."""

    LOGGERS = ("foxglove", "foxglove_py")  # the SDK's Rust side logs under both
    SHOWN_LINES = 5
    SHOWN_CHARS = 200

    def __init__(self, stream=None) -> None:
        super().__init__(logging.WARNING)
        self.stream = stream
        self.shown = 0
        self.more = 0
        self._saved: list[tuple[logging.Logger, bool]] = []

    @classmethod
    def attach(cls, stream=None) -> "ViewerMessages":
        handler = cls(stream)
        for name in cls.LOGGERS:
            lg = logging.getLogger(name)
            handler._saved.append((lg, lg.propagate))
            lg.addHandler(handler)
            lg.propagate = False
        return handler

    def detach(self) -> None:
        for lg, propagate in self._saved:
            lg.removeHandler(self)
            lg.propagate = propagate
        self._saved = []
        if self.more:
            self._write(f"warning: live view: {self.more} more message(s) of its server not shown")
            self.more = 0

    def emit(self, record: logging.LogRecord) -> None:
        if record.name.startswith("foxglove") and "McapError" in record.getMessage():
            return  # the log file's own: its sink reports those (cosim.observers.log_writer.sink)
        if self.shown >= self.SHOWN_LINES:
            self.more += 1
            return
        self.shown += 1
        text = printable(record.getMessage())
        if len(text) > self.SHOWN_CHARS:
            text = text[:self.SHOWN_CHARS] + f"... ({len(text)} characters)"
        self._write(f"warning: live view: {text}")

    def _write(self, line: str) -> None:
        stream = self.stream if self.stream is not None else sys.stderr
        print(line, file=stream, flush=True)


class LiveView:
    """Observer serving ``publisher``'s channels on a Foxglove WebSocket server during the run.

    Place it before the publisher among the run's observers (its sink is then attached before the
    publisher declares the channels, and the server advertises each as it is declared). ``port=0`` picks a free
    port (:attr:`port` after :meth:`start`).
    """

    def __init__(self, publisher: Publisher, port: int = DEFAULT_PORT, host: str = "127.0.0.1",
                 name: str = "delta-cosim", wait: float | None = None):
        _check_free(host, port)
        if wait is not None and not wait > 0:
            raise CosimError(f"--live-wait: expected a number of seconds > 0, got {wait!r}")
        self.publisher = publisher
        self.host = host
        self.port = port
        self.name = name
        self.wait = wait
        self.stop_request: StopRequest | None = None  # the run's: a stop signal ends the wait for a viewer
        self.waited: float | None = None  # s waited for a viewer (None: no wait); ``viewed``: whether one came
        self.viewed = False
        self.server = None
        self._relay: Relay | None = None
        self._sink: _ContextSink | None = None
        self._subscribed: float | None = None  # monotonic time of the last subscription seen while waiting
        self._viewers: dict[int, int] = {}  # the server's channel id -> viewers subscribed (its listener's count)

    @property
    def url(self) -> str:
        return f"ws://{'localhost' if self.host in ('127.0.0.1', '0.0.0.0') else self.host}:{self.port}"

    def start(self, rt: Execution) -> None:
        import foxglove  # lazy: --help loads this module without it
        from foxglove.websocket import Capability  # lazy: --help loads this module without it

        context = foxglove.Context()
        self._messages = ViewerMessages.attach()  # what the server logs of its viewers: escaped, a few lines
        live_view_serving(True)  # no log writer is forked from this process while its threads run
        try:  # the viewers' address is the relay's (it answers their close); the server listens on loopback behind it
            self._relay = Relay(self.host, self.port)
            self.server = foxglove.start_server(name=self.name, host="127.0.0.1", port=0,
                                                capabilities=[Capability.Time], context=context,
                                                message_backlog_size=BACKLOG_MESSAGES,
                                                server_listener=self._listener())
        except (OSError, RuntimeError) as exc:
            if self._relay is not None:
                self._relay.stop()
                self._relay = None
            live_view_serving(False)
            self._messages.detach()
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise CosimError(f"--live: cannot serve on {self.host}:{self.port}: {reason}") from None
        self._relay.start(("127.0.0.1", self.server.port))
        self.port = self._relay.port
        self._sink = _ContextSink(context, self._viewers,
                                  None if self.wait is None else lambda: self._wait_for_viewer(rt))
        self.publisher.attach(self._sink)
        self._offset = self.publisher.origin(rt)
        self._next_time = rt.now_ns
        self._grid = rt.grid
        self.server.broadcast_time(rt.now_ns + self._offset)

    def _listener(self):
        """The server's listener: counts the viewers of each channel (what the run's end waits to see delivered),
        notes the time of each subscription (what ``--live-wait`` waits for)."""
        from foxglove.websocket import ServerListener  # lazy: --help loads this module without it

        view, viewers = self, self._viewers

        class Subscriptions(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                viewers[channel.id] = viewers.get(channel.id, 0) + 1
                view._subscribed = time.monotonic()

            def on_unsubscribe(self, client, channel) -> None:
                viewers[channel.id] = max(0, viewers.get(channel.id, 0) - 1)

        return Subscriptions()

    def _wait_for_viewer(self, rt: Execution) -> None:
        """Hold the run until a viewer has subscribed (and :data:`SETTLE_S` passed since its last subscription), at
        most :attr:`wait` s; the run's phase meanwhile ``waiting``. Called by the sink before the first message."""
        phase = rt.current[2]
        rt.current[2] = WAITING
        start = time.monotonic()
        try:
            while True:
                now = time.monotonic()
                seen = self._subscribed
                if seen is not None and now - seen >= SETTLE_S:
                    self.viewed = True
                    break
                if now - start >= self.wait:  # the bound holds whatever viewers do (one subscribing again and
                    self.viewed = seen is not None  # again every 0.1 s held the run past it)
                    break
                if self.stop_request is not None and self.stop_request.requested:
                    raise self.stop_request.interrupted()
                time.sleep(_POLL_S)
        finally:
            rt.current[2] = phase
            self.waited = time.monotonic() - start
        self.server.broadcast_time(rt.now_ns + self._offset)  # the viewer's clock from the start

    def loop_blocks(self) -> Blocks:
        """The master's loop in C may run blocks of macro steps with this view (:class:`cosim.engine.cloop.Blocks`):
        each ends at the step where the viewers' clock is due."""
        return Blocks(lambda k: steps_to(self._grid, k, self._next_time), self._block_stepped)

    def _block_stepped(self, k: int, n: int) -> None:
        if n:
            self.stepped(k + n - 1, self._grid.t_ns(k + n), ())

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        if t_ns >= self._next_time:
            self._next_time = t_ns + _TIME_PERIOD_NS
            self.server.broadcast_time(t_ns + self._offset)

    def finish(self, rt: Execution | None, error: BaseException | None) -> None:
        due = 0
        if self._sink is not None:
            try:
                self.publisher.flush()  # the last samples
            except CosimError:  # the log's write failed: the recorder reports it when it finishes
                pass
            due = self._sink.due
            self._sink.close()
            self._sink = None
        if self.server is not None:
            server, self.server = self.server, None
            self._stop(server, due)

    def _drain(self, due: int, end: float) -> None:
        """Wait until the server has passed its viewers the ``due`` messages it was given for them (the relay counts
        them), until no viewer is connected any more, until :data:`DRAIN_QUIET_S` pass with none passed (what is
        left was dropped by a viewer's lossy backlog, or the viewer stopped reading), or until ``end`` (a viewer that
        reads, but slowly): the server's stop sends its Close ahead of what its queues still hold, so a viewer would
        lose the end of the run (the last 20 of 501 samples, seen on a loaded machine)."""
        relay = self._relay
        if relay is None:
            return
        last, since = relay.delivered, time.monotonic()
        while relay.delivered < due and relay.connected():
            now = time.monotonic()
            if now >= end:
                return
            if relay.delivered != last:
                last, since = relay.delivered, now
            elif now - since >= DRAIN_QUIET_S:
                return
            time.sleep(_POLL_S / 2)

    def _stop(self, server, due: int = 0) -> None:
        """What is due to the viewers passed on (:meth:`_drain`), then ``server.stop()``, which waits for every
        viewer to take its close, then the relay's end, which waits for each viewer to take what it was given:
        :data:`STOP_TIMEOUT` at most in all (the server's stop in a thread of its own, left behind when a viewer
        never reads again: the process still ends)."""

        start = time.monotonic()
        end = start + STOP_TIMEOUT
        self._drain(due, start + STOP_TIMEOUT / 2)  # half of the end's time at most: the stop keeps the other half
        stopper = threading.Thread(target=server.stop, name="live-view-stop", daemon=True)
        stopper.start()
        stopper.join(max(0.0, end - time.monotonic()))
        dropped = stopper.is_alive()
        if self._relay is not None:  # the viewers' connections: what they were given written, then closed
            relay, self._relay = self._relay, None
            dropped = relay.stop(max(0.0, end - time.monotonic())) > 0 or dropped
        live_view_serving(False)  # its threads idle from now on (a stopper left behind is a thread: no fork either)
        self._messages.detach()
        if dropped:
            print(f"warning: live view on {self.url}: a viewer did not take the end of the run within "
                  f"{STOP_TIMEOUT:g} s (it stopped reading): dropped", file=sys.stderr, flush=True)

    def summary(self) -> str:
        text = f"live view served on {self.url} (Foxglove WebSocket, subprotocol foxglove.sdk.v1)"
        if self.waited is not None:
            text += (f"; the run waited {self.waited:.3g} s for its first viewer" if self.viewed else
                     f"; no viewer subscribed within {self.wait:g} s (--live-wait): the run went on without one")
        return text
