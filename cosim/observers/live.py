"""Live view: serve a running co-simulation over the Foxglove WebSocket protocol (``foxglove-sdk``).

``python -m cosim run SCENARIO --live [PORT]`` adds a :class:`LiveView` to the run. It starts a
Foxglove WebSocket server (subprotocol ``foxglove.sdk.v1``) and attaches a sink to the run's
:class:`cosim.observers.publish.Publisher` that logs every channel into the server's ``foxglove.Context``
(component samples encoded by :func:`cosim.observers.log_writer.encode_messages` in the scenario's
``logging.layout``, one message per sample by default, as for the log), so a viewer connected to
``ws://localhost:PORT`` (the Foxglove app: *Open connection*, *Foxglove WebSocket*) sees exactly
the channels, schemas and 3D scene of the MCAP log, message for message, while the log is still
written. The server also broadcasts the run's current log time (the *Time* capability), so the
viewer's clock follows the simulation. Combine it with ``--realtime`` to watch at wall-clock pace;
without it the run goes as fast as it can and the viewer sees it fast-forwarded.
"""

from __future__ import annotations

import logging
import socket
import sys
import threading
from collections.abc import Sequence

from ..engine.execution import Execution
from ..errors import CosimError, printable
from .log_writer import FoxgloveChannels, encode_messages, live_view_serving
from .publish import Publisher

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
        raise CosimError(f"--live: expected a port number 0..65535 (or HOST:PORT), got {text!r}")
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

    def __init__(self, context) -> None:
        self._context = context
        self._channels: list = []
        self._log: dict[int, object] = {}
        self._layouts: dict = {}

    def blocks(self, offset_ns: int, blocks) -> None:

        for cid, stamps, data, skip in blocks:
            log = self._log[cid]
            for t, message in zip(*encode_messages(self._layouts[cid], stamps, data, skip, offset_ns)):
                log(message, t)

    def message(self, cid: int, log_time: int, data: bytes) -> None:
        self._log[cid](data, log_time)

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
                 name: str = "delta-cosim"):
        _check_free(host, port)
        self.publisher = publisher
        self.host = host
        self.port = port
        self.name = name
        self.server = None
        self._sink: _ContextSink | None = None

    @property
    def url(self) -> str:
        return f"ws://{'localhost' if self.host in ('127.0.0.1', '0.0.0.0') else self.host}:{self.port}"

    def start(self, rt: Execution) -> None:
        import foxglove  # lazy: --help loads this module without it
        from foxglove.websocket import Capability  # lazy: --help loads this module without it

        context = foxglove.Context()
        self._messages = ViewerMessages.attach()  # what the server logs of its viewers: escaped, a few lines
        live_view_serving(True)  # no log writer is forked from this process while its threads run
        try:
            self.server = foxglove.start_server(name=self.name, host=self.host, port=self.port,
                                                capabilities=[Capability.Time], context=context,
                                                message_backlog_size=BACKLOG_MESSAGES)
        except RuntimeError as exc:
            live_view_serving(False)
            self._messages.detach()
            raise CosimError(f"--live: cannot serve on {self.host}:{self.port}: {exc}") from None
        self.port = self.server.port
        self._sink = _ContextSink(context)
        self.publisher.attach(self._sink)
        self._offset = self.publisher.origin(rt)
        self._next_time = rt.now_ns
        self.server.broadcast_time(rt.now_ns + self._offset)

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        if t_ns >= self._next_time:
            self._next_time = t_ns + _TIME_PERIOD_NS
            self.server.broadcast_time(t_ns + self._offset)

    def finish(self, rt: Execution | None, error: BaseException | None) -> None:
        if self._sink is not None:
            try:
                self.publisher.flush()  # the last samples
            except CosimError:  # the log's write failed: the recorder reports it when it finishes
                pass
            self._sink.close()
            self._sink = None
        if self.server is not None:
            server, self.server = self.server, None
            self._stop(server)

    def _stop(self, server) -> None:
        """``server.stop()``, which waits for every viewer to take its close, waited for :data:`STOP_TIMEOUT` at most
        (in a thread of its own, left behind when a viewer never reads again: the process still ends)."""

        stopper = threading.Thread(target=server.stop, name="live-view-stop", daemon=True)
        stopper.start()
        stopper.join(STOP_TIMEOUT)
        live_view_serving(False)  # its threads idle from now on (a stopper left behind is a thread: no fork either)
        self._messages.detach()
        if stopper.is_alive():
            print(f"warning: live view on {self.url}: a viewer did not take the end of the run within "
                  f"{STOP_TIMEOUT:g} s (it stopped reading): dropped", file=sys.stderr, flush=True)

    def summary(self) -> str:
        return f"live view served on {self.url} (Foxglove WebSocket, subprotocol foxglove.sdk.v1)"
