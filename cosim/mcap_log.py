"""MCAP recorder: an observer that writes the run's channels (:mod:`cosim.publish`) to an MCAP file.

- the channels, schemas and messages are those of :class:`cosim.publish.Publisher` (one
  ``/<component>`` JSON channel per component, the ``/scene``, ``/scene/reference`` and
  ``/tf`` Foxglove channels, ``/events``), written by ``foxglove-sdk``'s MCAP writer from the
  publisher's ``foxglove.Context``, the same channels the live view (:mod:`cosim.live`) serves;
- metadata (scenario, versions, platform, time stamps: see :func:`cosim.publish.time_metadata`)
  and attachments (the scenario file and each FMU's modelDescription.xml);
- zstd chunks flushed every ``flush_interval`` wall seconds, so a killed run
  leaves every complete chunk readable (see :mod:`cosim.recover`);
- ``finish`` always writes the summary and index, on success, error or Ctrl-C, and the
  ``outcome`` metadata (completed, error, interrupted, stalled; the message);
- a write that fails (disk full) stops the run at the next step with one error naming the
  file and the OS's reason; foxglove-sdk reports such failures through Python logging, so
  they are caught there instead of being printed once per lost message.

The writer was chosen by measurement (``benchmarks/mcap_writer.py``): foxglove-sdk writes
helix_ctc's message stream 1.3 times as fast as the hand-packed mcap 1.x writer used before
(both zstd level 3), 1.55 times at the level 1 used here.
"""

from __future__ import annotations

import logging
import os
import platform
import sys
import time
from pathlib import Path
from typing import Sequence

import orjson

from .algorithm import Runtime
from .errors import CosimError
from .publish import Publisher, time_metadata

__all__ = ["McapRecorder"]


class _WriteFailures(logging.Handler):
    """Catches the MCAP writer's per-message failures, which foxglove-sdk reports through Python
    logging (``foxglove.*`` loggers, one record per lost message) instead of raising: the first
    is kept for the error, none is printed (a full disk would print one line per message)."""

    LOGGERS = ("foxglove", "foxglove_py")  # the SDK's Rust side logs under both

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.first: str | None = None
        self._loggers = [(lg, lg.propagate) for lg in map(logging.getLogger, self.LOGGERS)]
        for lg, _ in self._loggers:
            lg.addHandler(self)
            lg.propagate = False

    def emit(self, record: logging.LogRecord) -> None:
        if self.first is None:
            self.first = record.getMessage()

    def detach(self) -> None:
        for lg, propagate in self._loggers:
            lg.removeHandler(self)
            lg.propagate = propagate


class McapRecorder:
    """Observer writing the channels of ``publisher`` to an MCAP file (see the module docstring).

    Place it before the publisher among the run's observers: it opens the file on the
    publisher's context in :meth:`start`, before the publisher logs the first sample.
    """

    CHUNK_SIZE = 256 * 1024
    """Uncompressed bytes per zstd chunk (a periodic flush ends a chunk earlier)."""
    ZSTD_LEVEL = 1
    """zstd level 1: on helix_ctc's messages faster than the default 3 and a smaller file (benchmarks/mcap_writer.py)."""

    def __init__(self, path: str | Path, publisher: Publisher, scenario=None, scenario_file: str | Path | None = None,
                 flush_interval: float = 1.0):
        self.path = Path(path)
        self.publisher = publisher
        self.scenario = scenario
        self.scenario_file = Path(scenario_file) if scenario_file else None
        self.flush_interval = flush_interval
        self._writer = None

    # -- observer protocol
    def start(self, rt: Runtime) -> None:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.path.parent.mkdir(parents=True, exist_ok=True)
        options = MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=self.CHUNK_SIZE,
                                   compression_level=self.ZSTD_LEVEL)
        self._failures = _WriteFailures()  # before opening: the writer reports failed writes through logging
        try:  # a path, not a Python file: the writer (Rust) then holds no Python object
            self._writer = foxglove.open_mcap(self.path, allow_overwrite=True, context=self.publisher.context,
                                              writer_options=options)
        except Exception as exc:  # foxglove raises a bare error type for I/O failures
            raise CosimError(f"{self.path}: cannot write the MCAP log: {exc}") from None
        self._metadata(rt)
        self._last_flush = time.monotonic()

    def _metadata(self, rt: Runtime) -> None:
        from importlib.metadata import PackageNotFoundError, version

        import fmpy

        w = self._writer
        versions = {"python": sys.version.split()[0], "fmpy": fmpy.__version__, "orjson": orjson.__version__}
        for dist in ("foxglove-sdk", "delta-cosim"):
            try:
                versions[dist] = version(dist)
            except PackageNotFoundError:  # not installed as a distribution: leave it out
                pass
        w.write_metadata("versions", versions)
        w.write_metadata("platform", {"system": platform.system(), "machine": platform.machine(),
                                      "node": platform.node(),
                                      "python_implementation": platform.python_implementation()})
        if self.scenario is not None:
            s = self.scenario
            w.write_metadata("scenario", {
                "name": s.name, "algorithm": s.algorithm, "step_s": repr(s.time.step), "stop_s": repr(s.time.stop),
                "start_s": repr(s.time.start), "robot": str(s.robot), "components": ",".join(s.components),
                "file": str(self.scenario_file or s.source or "")})
        pub = self.publisher
        w.write_metadata("time", time_metadata(pub.stamps, pub.origin(rt), rt.start_ns))
        now = time.time_ns()
        if self.scenario_file is not None and self.scenario_file.exists():
            ssp = self.scenario_file.suffix.lower() == ".ssp"  # an SSP archive (SSP 1.0 names its MIME type)
            w.attach(log_time=now, create_time=now, name=f"scenario/{self.scenario_file.name}",
                     media_type="application/x-ssp-package" if ssp else "application/yaml",
                     data=self.scenario_file.read_bytes())
        for name, info in zip(rt.plan.names, rt.plan.infos):
            w.attach(log_time=now, create_time=now, name=f"fmu/{name}/modelDescription.xml",
                     media_type="application/xml", data=info.model_description_xml())

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        if self._failures.first is not None:  # the writer failed on a message (disk full): stop the run now
            raise self._failure()
        if time.monotonic() - self._last_flush > self.flush_interval:
            try:
                self._writer.flush()
            except Exception as exc:  # noqa: BLE001 - foxglove raises a bare error type for I/O failures
                raise self._failure(exc) from None
            self._last_flush = time.monotonic()

    def _failure(self, exc: BaseException | None = None) -> CosimError:
        """The writer's first I/O failure as one line (the OS's reason, e.g. no space left on device)."""
        import re

        text = self._failures.first or str(exc)
        m = re.search(r'message: "([^"]+)"', text)
        reason = m.group(1) if m else text
        try:  # the writer's error often only says that an earlier write failed: look at the disk
            fs = os.statvfs(self.path.parent)
            if m is None and fs.f_bavail * fs.f_frsize < 2 * self.CHUNK_SIZE:
                reason = f"no space left on device ({fs.f_bavail * fs.f_frsize} bytes free in {self.path.parent})"
        except OSError:
            pass
        return CosimError(f"{self.path}: cannot write the MCAP log: {reason}")

    def finish(self, rt: Runtime | None, error: BaseException | None) -> None:
        """Mark the outcome and close the file; raises CosimError when the file cannot be completed."""
        if self._writer is None:
            return
        try:
            if error is not None:
                status = "interrupted" if isinstance(error, KeyboardInterrupt) else getattr(error, "outcome", "error")
                text = str(error) or type(error).__name__
                self._writer.write_metadata("outcome", {"status": status, "message": text,
                                                        "completed_steps": str(rt.k_done if rt else 0)})
            else:
                outcome = {"status": "completed", "completed_steps": str(rt.k_done if rt else 0)}
                if rt is not None and rt.terminated is not None:
                    outcome.update(terminated_by=rt.terminated.component, end_time_s=repr(rt.terminated.time),
                                   message=str(rt.terminated))
                self._writer.write_metadata("outcome", outcome)
            self._writer.close()
            failed = None
        except Exception as exc:  # noqa: BLE001 - the file cannot be completed (disk full): one clear error
            failed = exc
        finally:
            self._writer = None
            self._failures.detach()
        if failed is not None or self._failures.first is not None:
            raise self._failure(failed)
