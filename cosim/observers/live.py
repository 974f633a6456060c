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

import socket
import sys
import threading
from collections.abc import Sequence

from ..engine.execution import Execution
from ..errors import CosimError
from .log_writer import FoxgloveChannels, encode_messages, live_view_serving
from .publish import Publisher

__all__ = ["DEFAULT_PORT", "LiveView", "parse_address"]

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
        live_view_serving(True)  # no log writer is forked from this process while its threads run
        try:
            self.server = foxglove.start_server(name=self.name, host=self.host, port=self.port,
                                                capabilities=[Capability.Time], context=context,
                                                message_backlog_size=BACKLOG_MESSAGES)
        except RuntimeError as exc:
            live_view_serving(False)
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
        if stopper.is_alive():
            print(f"warning: live view on {self.url}: a viewer did not take the end of the run within "
                  f"{STOP_TIMEOUT:g} s (it stopped reading): dropped", file=sys.stderr, flush=True)

    def summary(self) -> str:
        return f"live view served on {self.url} (Foxglove WebSocket, subprotocol foxglove.sdk.v1)"
