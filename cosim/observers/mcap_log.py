"""MCAP recorder: an observer that writes the run's channels (:mod:`cosim.observers.publish`) to an MCAP file.

- the channels, schemas and messages are those of :class:`cosim.observers.publish.Publisher` (one
  ``/<component>`` JSON channel per component, the ``/scene``, ``/scene/reference`` and
  ``/tf`` Foxglove channels, ``/events``), the same channels the live view (:mod:`cosim.observers.live`)
  serves, written by :mod:`cosim.observers.log_writer` (foxglove-sdk's MCAP writer); component channels in
  the scenario's ``logging.layout``: one message per sample (``samples``, the default) or per
  block of samples (``blocks``);
- a run writes through a writer process (:class:`cosim.observers.log_writer.WriterProcess`, started when the
  recorder is made, so it is ready when the loop starts) where the writer is a fork of the master (it starts at
  once), else from :attr:`McapRecorder.PROCESS_MIN_STEPS` steps on (a new interpreter costs about 0.1 s of a
  core): the master only copies each step's values into blocks, and the child encodes the JSON messages (one
  per sample in the ``samples`` layout), compresses and writes on the other core, and keeps what it was sent
  when the master crashes (a forked child also the rows of each step completed since, which the master mirrors
  into memory they share: :class:`cosim.observers.log_writer.RowMirror`). Other runs write in this process
  (:meth:`McapRecorder.writes_in_a_process`);
- metadata (scenario, versions, platform, the command line and its folder, time stamps: see
  :func:`cosim.observers.publish.time_metadata`) and attachments (the scenario file, the scenario as run with every
  override applied, :attr:`cosim.engine.structure.SystemStructure.document`, and each FMU's modelDescription.xml);
- zstd chunks flushed every ``flush_interval`` wall seconds, so a killed run
  leaves every complete chunk readable (see :mod:`cosim.io.recover`);
- ``finish`` always writes the summary and index, on success, error or Ctrl-C, and the
  ``outcome`` metadata (completed, error, interrupted, stalled; the message);
- a write that fails (disk full) stops the run at the next block of samples handed to the
  writer with one error naming the file and the OS's reason.

Measured (``benchmarks/native.py``, line 5): foxglove-sdk's MCAP writer fed one message per sample
built from a dict in the master's loop cost helix_ctc_analytic about 50 us per 1 ms step (4.6
times the unlogged run). Now the loop only copies each step's rows and hands blocks of them over,
in either layout: the layouts differ in the writer process alone (one message per sample costs
it more, see :class:`cosim.observers.log_writer.LogSink`).
"""

from __future__ import annotations

import os
import platform
import sys
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Sequence

import orjson

from ..engine.cloop import BLOCK, Blocks
from ..engine.execution import Execution
from ..engine.grid import Grid
from ..engine.structure import DOCUMENT_ATTACHMENT, SystemStructure
from ..errors import CosimError, utf8
from .log_writer import LogSink, WriterFailed, WriterProcess, os_reason, writer_forks
from .publish import Publisher, time_metadata

__all__ = ["McapRecorder"]


class _Checked:
    """The sink as the publisher calls it: a failed write becomes the recorder's CosimError."""

    def __init__(self, recorder: "McapRecorder", sink) -> None:
        self._recorder = recorder
        self._sink = sink

    def channel(self, *args) -> None:
        self._call(self._sink.channel, args)

    def blocks(self, *args) -> None:
        self._call(self._sink.blocks, args)

    def message(self, *args) -> None:
        self._call(self._sink.message, args)

    def mirror(self, *args):
        """The writer's :class:`cosim.observers.log_writer.RowMirror` of the publisher's batches of rows, or None (a
        log in this process, a writer that shares no memory with it, or rows that do not fit)."""
        make = getattr(self._sink, "mirror", None)
        if make is None:
            return None
        try:
            return make(*args)
        except (OSError, WriterFailed) as exc:
            raise self._recorder._failure(exc) from None

    def _call(self, f, args) -> None:
        try:
            f(*args)
        except (OSError, WriterFailed) as exc:
            raise self._recorder._failure(exc) from None


class McapRecorder:
    """Observer writing the channels of ``publisher`` to an MCAP file (see the module docstring).

    Place it before the publisher among the run's observers: it attaches its sink to the
    publisher in :meth:`start`, before the publisher declares the channels. ``process``: write
    through a writer process (True), in this process (False), or by the run's length (None; needs
    ``scenario``).
    """

    CHUNK_SIZE = 1024 * 1024
    """Uncompressed bytes per zstd chunk (a periodic flush ends a chunk earlier). 1 MiB rather than 256 KiB:
    foxglove-sdk's writer 8.1 -> 7.5 us per step of helix_ctc_analytic in the samples layout, 4.4 -> 3.9 in
    blocks, and a file 4 % (samples) to 6 % (blocks) smaller (``benchmarks/log_writer_process.py``)."""
    ZSTD_LEVEL = 1
    """zstd level 1: on helix_ctc's messages faster than the default 3 and a smaller file (benchmarks/mcap_writer.py)."""
    PROCESS_MIN_STEPS = 2000
    """Where the writer cannot be forked, runs this long or longer write through a new interpreter (its start
    costs about 0.1 s of a core)."""

    @classmethod
    def writes_in_a_process(cls, n_steps: int) -> bool:
        """Whether a logged run of ``n_steps`` writes through a writer process: always where the writer is a fork
        (it starts at once; a crash of the master then loses only the rows not sent yet, where a log written in
        the master keeps only what it flushed), else from :attr:`PROCESS_MIN_STEPS` steps on."""
        return n_steps >= cls.PROCESS_MIN_STEPS or writer_forks()

    def __init__(self, path: str | Path, publisher: Publisher, system: SystemStructure | None = None,
                 scenario_file: str | Path | None = None, flush_interval: float = 1.0, process: bool | None = None):
        self.path = Path(path)
        self.publisher = publisher
        self.system = system
        self.scenario_file = Path(scenario_file) if scenario_file else None
        self.flush_interval = flush_interval
        if process is None:
            process = system is not None and self.writes_in_a_process(
                Grid(system.start_ns, system.stop_ns, system.step_ns).n_steps)
        self._process = WriterProcess() if process else None  # now: it starts while the FMUs load
        self._sink = None

    @property
    def writer_pid(self) -> int | None:
        """The writer process's pid (None when the log is written in this process)."""
        return self._process.pid if self._process is not None else None

    # -- observer protocol
    def start(self, rt: Execution) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            if self._process is not None:
                self._process.open(self.path, self.CHUNK_SIZE, self.ZSTD_LEVEL)
                self._sink = self._process
            else:
                self._sink = LogSink(self.path, self.CHUNK_SIZE, self.ZSTD_LEVEL)
        except (OSError, WriterFailed) as exc:
            raise self._failure(exc) from None
        self.publisher.attach(_Checked(self, self._sink))
        try:
            self._metadata(rt)
        except (OSError, WriterFailed) as exc:
            raise self._failure(exc) from None
        self._last_flush = time.monotonic()

    def _metadata(self, rt: Execution) -> None:

        import fmpy  # lazy: --help loads this module without it

        w = self._sink
        versions = {"python": sys.version.split()[0], "fmpy": fmpy.__version__, "orjson": orjson.__version__}
        for dist in ("foxglove-sdk", "delta-cosim"):
            try:
                versions[dist] = version(dist)
            except PackageNotFoundError:  # not installed as a distribution: leave it out
                pass
        w.metadata("versions", versions)
        w.metadata("platform", {"system": platform.system(), "machine": platform.machine(), "node": platform.node(),
                                "python_implementation": platform.python_implementation()})
        if self.system is not None:
            s = self.system
            start, stop, step = s.seconds()
            w.metadata("scenario", {
                "name": s.name, "algorithm": s.algorithm, "step_s": repr(step), "stop_s": repr(stop),
                "start_s": repr(start), "robot": str(s.domain.get("robot")), "components": ",".join(s.components),
                "file": utf8(str(self.scenario_file or s.source or ""))})
            if s.ssp is not None:  # before the scenario as run: `run --from-log` unpacks the archive again
                w.metadata("ssp", utf8(dict(s.ssp)))
        w.metadata("command", {"argv": orjson.dumps(utf8(getattr(sys, "orig_argv", sys.argv))).decode(),
                               "cwd": utf8(os.getcwd())})
        pub = self.publisher
        w.metadata("time", time_metadata(pub.stamps, pub.origin(rt), rt.start_ns))
        now = time.time_ns()
        document = None
        if self.system is not None:  # the scenario as run, every override applied: `run --from-log` runs it again
            document = self.system.recorded(self.path.with_name(self.path.name.removesuffix(".partial")))
        if document is not None:  # (the log's own path as it is named once finished)
            w.attachment(DOCUMENT_ATTACHMENT, "application/json",
                         orjson.dumps(utf8(document), option=orjson.OPT_INDENT_2), now, now)
        if self.scenario_file is not None and self.scenario_file.exists() and not _is_log(self.scenario_file):
            ssp = self.scenario_file.suffix.lower() == ".ssp"  # an SSP archive (SSP 1.0 names its MIME type)
            w.attachment(f"scenario/{self.scenario_file.name}", "application/x-ssp-package" if ssp else "application/yaml",
                         self.scenario_file.read_bytes(), now, now)
        for name, info in zip(rt.plan.names, rt.plan.infos):
            w.attachment(f"fmu/{name}/modelDescription.xml", "application/xml", info.model_description_xml(), now, now)

    def loop_blocks(self) -> Blocks:
        """The master's loop in C may run blocks of macro steps with this recorder (:class:`cosim.engine.cloop.Blocks`):
        it needs nothing of a step but a look at the clock, taken after each block (a block lasts at most
        :data:`cosim.engine.cloop.BUDGET_S`)."""
        return Blocks(lambda k: BLOCK, lambda k, n: self.stepped(k + n - 1, 0, ()))

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        if time.monotonic() - self._last_flush > self.flush_interval:  # the blocks so far: the publisher's own
            try:
                self._sink.flush()
            except (OSError, WriterFailed) as exc:
                raise self._failure(exc) from None
            self._last_flush = time.monotonic()

    def _failure(self, exc: BaseException) -> CosimError:
        """A failed write as one line: the file and the OS's reason (e.g. no space left on device)."""

        reason = os_reason(exc) if isinstance(exc, OSError) else str(exc)
        if "space" not in reason:
            try:  # a failed write may not say why: look at the disk
                fs = os.statvfs(self.path.parent)
                if fs.f_bavail * fs.f_frsize < 2 * self.CHUNK_SIZE:
                    reason = f"no space left on device ({fs.f_bavail * fs.f_frsize} bytes free in {self.path.parent})"
            except OSError:
                pass
        return CosimError(f"{self.path}: cannot write the MCAP log: {reason}")

    def finish(self, rt: Execution | None, error: BaseException | None) -> None:
        """Mark the outcome and close the file; raises CosimError when the file cannot be completed."""
        sink, self._sink = self._sink, None
        if sink is None:
            if self._process is not None:  # never started: the child ends without a file
                self._process.abandon()
            return
        try:
            self.publisher.flush()  # the rows not handed over yet
            if error is not None:
                status = "interrupted" if isinstance(error, KeyboardInterrupt) else getattr(error, "outcome", "error")
                text = str(error) or type(error).__name__
                sink.metadata("outcome", {"status": status, "message": text,
                                          "completed_steps": str(rt.k_done if rt else 0)})
            else:
                outcome = {"status": "completed", "completed_steps": str(rt.k_done if rt else 0)}
                if rt is not None and rt.terminated is not None:
                    outcome.update(terminated_by=rt.terminated.component, end_time_s=repr(rt.terminated.time),
                                   message=str(rt.terminated))
                sink.metadata("outcome", outcome)
            sink.finish()
        except (OSError, WriterFailed, CosimError) as exc:  # the file cannot be completed (disk full)
            if isinstance(sink, LogSink):
                try:
                    sink.abandon()
                except OSError:
                    pass
            raise exc if isinstance(exc, CosimError) else self._failure(exc) from None


def _is_log(path: Path) -> bool:
    """Whether ``path`` is an MCAP file: the log a ``run --from-log`` read its scenario from, not attached again."""
    with open(path, "rb") as f:
        return f.read(5) == b"\x89MCAP"
