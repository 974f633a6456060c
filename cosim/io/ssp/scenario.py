"""An SSP archive as a system structure: :func:`open_ssp` unpacks it for a ``with`` block (removed when the block
ends, also on error and Ctrl-C) and gives the :class:`~cosim.engine.structure.SystemStructure` the engine runs,
naming the archive and its SHA-256 (:attr:`~cosim.engine.structure.SystemStructure.ssp`), which a run's log
records, so that ``run --from-log`` unpacks the same archive again (:func:`reopen_ssp`).

Between the archive and the structure, the archive is read into a scenario document (:func:`~cosim.io.ssp.read.
read_ssp`: the components, connections, time grid and algorithm the SSD gives, the sections our annotation
carries) and validated as a YAML scenario's document is, ``--set`` overrides included: one set of checks and one
override mechanism for every format, and the document is what a run's log records to make the system again."""

from __future__ import annotations

import copy
import hashlib
import os
import shutil
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from ...engine.scenario import ScenarioFile, read_scenario, scenario_from_data
from ...errors import file_problem
from ...fmi.extract import SSP_PREFIX, sweep_orphans
from .read import read_ssp
from .spec import SspError, is_ssp

if TYPE_CHECKING:
    from ...engine.schema import Scenario
    from ...engine.structure import SystemStructure

__all__ = ["is_ssp", "open_ssp", "reopen_ssp", "read_archive", "reopen_archive", "read_source", "ArchiveFile"]


MAX_ARCHIVE_BYTES = 16 * 1024 ** 3
"""The largest SSP archive a log may name for ``run --from-log`` (it is hashed whole before it is unpacked): four
FMUs of :data:`cosim.fmi.extract.MAX_FMU_BYTES` each."""


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@contextmanager
def _unpacking(ssp: Path) -> Iterator[Path]:
    """A temporary folder for ``ssp``'s FMUs, removed when the block ends (also on error)."""
    sweep_orphans()  # archives unpacked by runs that were killed (SIGKILL) go now
    tmp = Path(tempfile.mkdtemp(prefix=f"{SSP_PREFIX}{os.getpid()}-{ssp.stem}-"))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _archive(ssp: Path, tmp: Path, sha256: str) -> dict[str, str]:
    """:attr:`~cosim.engine.structure.SystemStructure.ssp` of a system read from ``ssp`` unpacked into ``tmp``."""
    return {"file": os.path.normpath(ssp.absolute()), "sha256": sha256, "unpacked": str(tmp)}


@dataclass
class ArchiveFile:
    """An SSP archive read once and unpacked (inside :func:`read_archive`'s block): ``file`` (its path), ``data``
    (the scenario document read from it), ``archive`` (what a structure names of it: file, SHA-256, unpacked
    folder). :meth:`load` validates the document with overrides, as a YAML file's
    (:class:`cosim.engine.scenario.ScenarioFile`), so the variants of one archive (a sweep's cases) read it once."""

    file: str
    data: dict[str, Any]
    archive: dict[str, str]

    def load(self, overrides: dict[tuple, Any] | None = None) -> Scenario:
        """The archive's scenario with ``overrides`` applied; an :class:`SspError` when neither the archive nor
        ``overrides`` give the base step or the stop time."""
        missing = [(key, flag) for key, flag in (("step", "--step"), ("stop", "--stop-time"))
                   if key not in self.data["time"] and ("time", key) not in (overrides or {})]
        if missing:
            what = " and ".join(f"the {'base step' if k == 'step' else 'stop time'}" for k, _ in missing)
            # Refused (correctness): no time grid: the step or stop would be a guess
            raise SspError(self.file, f"{what}: neither the SSD's default experiment nor the FMUs give it; "
                                      f"pass {' and '.join(f for _, f in missing)}")
        scenario = scenario_from_data(self.data, self.file, overrides)
        scenario.with_archive(self.archive)
        return scenario

    def adopt(self, data: dict[str, Any], unpacked: str) -> dict[str, Any]:
        """``data`` (a scenario document of a run of this archive, unpacked then into ``unpacked``) with its
        components' FMU paths moved into this unpacking (the same archive unpacks its FMUs to the same places
        relative to its folder)."""
        data = copy.deepcopy(data)
        for comp in (data.get("components") or {}).values():
            path = comp.get("path") if isinstance(comp, dict) else None
            if isinstance(path, str) and Path(path).is_relative_to(unpacked):
                comp["path"] = str(Path(self.archive["unpacked"]) / Path(path).relative_to(unpacked))
        return data


@contextmanager
def read_archive(ssp: str | Path) -> Iterator[ArchiveFile]:
    """``ssp`` read and its FMUs unpacked into a temporary directory for the ``with`` block (removed when the block
    ends, also on error and Ctrl-C)."""
    ssp = Path(ssp)
    with _unpacking(ssp) as tmp:
        data = read_ssp(ssp, tmp)  # reads the file (an archive that is not one is named by it) before it is hashed
        yield ArchiveFile(str(ssp), data, _archive(ssp, tmp, _sha256(ssp)))


@contextmanager
def read_source(path: str | Path) -> Iterator[ScenarioFile | ArchiveFile]:
    """A scenario read once for the ``with`` block, to make variants of it (``load(overrides)``): a YAML file's
    (:class:`cosim.engine.scenario.ScenarioFile`), or an SSP archive's (:func:`read_archive`, its FMUs unpacked for
    the block)."""
    if is_ssp(path):
        with read_archive(path) as archive:
            yield archive
    else:
        yield read_scenario(path)


@contextmanager
def open_ssp(ssp: str | Path, overrides: dict[tuple, Any] | None = None) -> Iterator[SystemStructure]:
    """The system structure of an SSP archive, valid inside the ``with`` block (its FMUs are unpacked into a
    temporary directory removed when the block ends, also on error).

    ``overrides`` as for :func:`cosim.engine.scenario.load_scenario` (``--set``, ``--stop-time``, and
    ``("time", "step")`` for ``--step``). The structure's :attr:`~cosim.engine.structure.SystemStructure.ssp` names
    the archive and its SHA-256, which a run's log records for :func:`reopen_ssp`.
    """
    with read_archive(ssp) as archive:
        yield archive.load(overrides).structure()


@contextmanager
def reopen_ssp(archive: dict[str, str], data: dict[str, Any], source: str,
               overrides: dict[tuple, Any] | None = None) -> Iterator[SystemStructure]:
    """The system structure of the scenario document ``data`` of a run made from an SSP archive (as its log records
    it: ``archive`` is the run's :attr:`~cosim.engine.structure.SystemStructure.ssp`), with its FMUs unpacked again
    from that archive for the ``with`` block (:func:`reopen_archive`); ``source`` names the log in messages."""
    with reopen_archive(archive, data, source) as again:
        yield again.load(overrides).structure()


@contextmanager
def reopen_archive(archive: dict[str, str], data: dict[str, Any], source: str) -> Iterator[ArchiveFile]:
    """The scenario document ``data`` of a run made from the SSP archive ``archive`` (what a log or a checkpoint
    records: :attr:`~cosim.engine.structure.SystemStructure.ssp`), the archive unpacked again for the ``with`` block
    and ``data``'s FMU paths moved into it (:meth:`ArchiveFile.adopt`); ``source`` (the log, the checkpoint) names
    it in messages.

    Raises :class:`SspError` naming ``source`` and the archive when the archive is gone, or is not the file the
    run was made from (its SHA-256 differs): the recorded scenario's values would not be the archive's.
    """
    try:
        ssp, sha256, unpacked = Path(archive["file"]), archive["sha256"], archive["unpacked"]
    except (KeyError, TypeError):
        # Refused (correctness): the archive the run was made from cannot be found again
        raise SspError(source, f"the recorded ssp metadata is incomplete ({archive!r}): expected file, sha256 and "
                               "unpacked") from None
    head = f"the run was made from the SSP archive {ssp}, which"
    problem = file_problem(ssp)  # a log or checkpoint names it: a FIFO or a device would be hashed for ever
    if problem not in (None, "no such file"):
        # Refused (security): a FIFO or a device named by a log or checkpoint would be hashed for ever
        raise SspError(source, f"{head} cannot be read: {problem}")
    try:
        size = ssp.stat().st_size
    except OSError:
        size = 0  # gone or unreadable: said below
    if size > MAX_ARCHIVE_BYTES:  # a log names it: a huge (or sparse) file would be hashed for minutes
        # Refused (security): a huge or sparse file named by a log or checkpoint would be hashed for minutes
        raise SspError(source, f"{head} is {size:,} bytes, more than any archive is read "
                               f"(cosim.io.ssp.scenario.MAX_ARCHIVE_BYTES, {MAX_ARCHIVE_BYTES:,}): refused")
    try:
        now = _sha256(ssp)
    except FileNotFoundError:
        # Refused (correctness): the run's FMUs are gone with the archive
        raise SspError(source, f"{head} is gone: its FMUs were unpacked from it for the run only; put the archive "
                               "back to run it again") from None
    except OSError as exc:
        # Refused (correctness): the archive cannot be read: the run's FMUs cannot be unpacked
        raise SspError(source, f"{head} cannot be read: {exc.strerror or exc}") from None
    if now != sha256:
        # Refused (correctness): the recorded values may no longer be the archive's
        raise SspError(source, f"{head} has changed since (SHA-256 {sha256[:16]}... then, {now[:16]}... now): the "
                               f"recorded FMUs and values may no longer be the archive's; run the archive itself "
                               f"(`python -m cosim run {ssp}`)")
    with _unpacking(ssp) as tmp:
        read_ssp(ssp, tmp)  # the FMUs go where they went for the run, relative to the folder (numbered by place)
        again = ArchiveFile(source, {}, _archive(ssp, tmp, sha256))
        yield replace(again, data=again.adopt(data, unpacked))
