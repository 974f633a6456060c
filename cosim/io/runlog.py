"""Read a run's MCAP log back into arrays, and write decimated baselines of it.

A run log (see :mod:`cosim.observers.mcap_log`) holds one JSON channel ``/<component>`` per
component. Its messages are one sample each, ``{"t": ..., "<variable>": value, ...}`` (the
channel's metadata says ``layout: samples``, the default; logs written before layouts have no
``layout``), or blocks of samples, ``{"t": [...], "<variable>": [...], ...}`` (one array
element per sample; ``layout: blocks``); both read alike. Here every logged variable becomes a
:class:`Signal` named ``component.variable`` (``plant.p.x``, ``ctl.u[1]``) with its time
stamps, values, unit and causality. The ``/scene`` channels (Foxglove drawing) and ``/tf`` are
skipped.

Time stamps are simulation time: a log whose ``time`` metadata gives an offset (log times
from the run's wall-clock start, see :mod:`cosim.observers.publish`) has it subtracted here, so old
logs (pure simulation time) and new ones read alike.

A *baseline* is the same format decimated in time (``write_baseline``): small enough
to keep in a repository, read by the same code, so comparing a run against its
baseline is comparing two logs.
"""

from __future__ import annotations

import difflib
import json
import os
import struct
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import lz4.frame
import numpy as np
import orjson
import zstandard
from mcap.exceptions import McapError, RecordLengthLimitExceeded, UnsupportedCompressionError
from mcap.records import Attachment, Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from ..engine.grid import MAX_TIME_S
from ..engine.bounded_yaml import MAX_YAML_NODES
from ..engine.scenario import MAX_SCENARIO_BYTES, scenario_from_data
from ..engine.structure import DOCUMENT_ATTACHMENT, SystemStructure
from ..errors import CosimError, Issue, ScenarioError, file_problem, written_by_rename
from ..fmi.extract import SSP_PREFIX
from .output import check_output
from .ssp import reopen_ssp

__all__ = ["Signal", "RunLog", "read_run", "write_baseline", "log_records", "open_from_log", "time_offset_ns", "samples", "AXES",
           "MAX_CHUNK_BYTES"]

AXES = ("x", "y", "z")
_SKIP_TOPICS = {"/scene", "/scene/reference", "/tf", "/events"}


def time_offset_ns(metadata: dict[str, dict[str, str]]) -> int:
    """Log time minus simulation time, ns, from a log's metadata records (see
    :func:`cosim.observers.publish.time_metadata`); 0 for logs without a ``time`` record (pure simulation time)."""
    try:
        return int(metadata.get("time", {}).get("offset_ns", 0))
    except ValueError:
        return 0


def samples(message: dict) -> list[dict]:
    """The samples of a component channel's decoded message, one ``{"t": s, "<variable>": value, ...}``
    each: those of a block (``"t"`` a list), or the message itself (a log written before blocks)."""
    if not isinstance(message.get("t"), list):
        return [message]
    keys = list(message)
    return [dict(zip(keys, values)) for values in zip(*message.values())]


@dataclass(frozen=True)
class Signal:
    """One logged variable: ``t`` (n,) s, ``y`` (n,) in ``unit``; ``t_ns`` are the exact stamps."""

    name: str
    t_ns: np.ndarray
    y: np.ndarray
    unit: str = ""
    description: str = ""
    causality: str = ""

    @property
    def t(self) -> np.ndarray:
        return self.t_ns * 1e-9


@dataclass
class RunLog:
    """Every signal of one run, by ``component.variable``, plus the log's metadata."""

    path: Path
    signals: dict[str, Signal]
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    channel_metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    events: list[dict] = field(default_factory=list)  # the /events channel in time order: {"t", "event", "set"} (a
    # scenario event) or {"t", "component", "kind"} (a model-exchange component's own)

    @property
    def name(self) -> str:
        """The scenario name (metadata), else the file stem."""
        return self.metadata.get("scenario", {}).get("name") or self.path.stem

    @property
    def robot(self) -> str | None:
        r = self.metadata.get("scenario", {}).get("robot")
        return r if r and r != "None" else None

    @property
    def status(self) -> str:
        return self.metadata.get("outcome", {}).get("status", "unknown")

    @property
    def components(self) -> list[str]:
        return list(dict.fromkeys(n.split(".", 1)[0] for n in self.signals))

    def __contains__(self, name: str) -> bool:
        return name in self.signals

    def signal(self, name: str) -> Signal:
        """The signal ``name``; an unknown name raises CosimError with the closest names."""
        try:
            return self.signals[name]
        except KeyError:
            close = difflib.get_close_matches(name, list(self.signals), n=4)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; it has {len(self.signals)} signals"
            # Refused (correctness): a name the log does not hold: which signal is meant is a guess
            raise CosimError(f"{self.path}: no signal {name!r}{hint}") from None

    def vector(self, prefix: str) -> tuple[np.ndarray, np.ndarray]:
        """``"plant.p"`` -> (t (n,) s, values (n, 3)) from ``plant.p.x/.y/.z``."""
        parts = [self.signal(f"{prefix}.{a}") for a in AXES]
        return parts[0].t, np.column_stack([s.y for s in parts])

    def joints(self, prefix: str, n: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """``"ctl.u"`` -> (t (n,) s, values (n, 3)) from ``ctl.u[1]..[3]``."""
        parts = [self.signal(f"{prefix}[{i}]") for i in range(1, n + 1)]
        return parts[0].t, np.column_stack([s.y for s in parts])

    def find(self, variable: str) -> list[str]:
        """Names of every signal whose variable part is ``variable`` (``"p.x"`` -> ``["plant.p.x", ...]``)."""
        return [n for n in self.signals if n.split(".", 1)[1] == variable]


MAX_CHUNK_BYTES = 256 * 1024 ** 2
"""Largest MCAP chunk read, uncompressed: a chunk that declares more is refused before it is inflated, one that
inflates past what it declares is refused at that point. The logs written here have chunks of 1 MiB
(:attr:`cosim.observers.mcap_log.McapRecorder.CHUNK_SIZE`); an 82 KB file whose one zstd chunk inflated to 2.5 GiB exhausted
the memory of ``recover`` (issue 25)."""


class _Clamped:
    """A binary file as the mcap package reads it, no read longer than what is left of the file: a damaged length
    field (up to 2**64) reads what there is, instead of allocating what it says first."""

    def __init__(self, f) -> None:
        self._f = f
        self.size = os.fstat(f.fileno()).st_size

    def read(self, n: int = -1) -> bytes:
        left = max(0, self.size - self._f.tell())
        return self._f.read(left if n is None or n < 0 else min(n, left))


def _inflate(chunk, path: Path, offset: int) -> bytes:
    """The uncompressed records of an MCAP ``chunk`` (at byte ``offset`` of ``path``), never more than it declares
    nor than :data:`MAX_CHUNK_BYTES`: CosimError otherwise, naming the file, the offset and the limit."""
    declared = chunk.uncompressed_size
    where = f"{path}: the MCAP chunk at byte {offset}"
    if declared > MAX_CHUNK_BYTES:
        # Refused (security): a forged chunk: an 82 KB log inflated to 2.5 GiB
        raise CosimError(f"{where} declares {declared:,} bytes uncompressed, more than the {MAX_CHUNK_BYTES:,} read "
                         f"(cosim.io.runlog.MAX_CHUNK_BYTES; the logs written here have chunks of 1 MiB): refused")
    try:
        if chunk.compression == "zstd":
            data = zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True).read(declared + 1)
        elif chunk.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=declared + 1)
        elif chunk.compression == "":
            data = chunk.data
        else:
            # Refused (correctness): a chunk we cannot inflate: its records would be missing
            raise UnsupportedCompressionError(chunk.compression)
    except (zstandard.ZstdError, RuntimeError, ValueError, EOFError) as exc:  # RuntimeError: lz4's
        # Refused (correctness): a damaged chunk: its records would be missing
        raise McapError(f"chunk at byte {offset}: {exc}") from None
    if len(data) > declared:
        # Refused (security): read no further than declared: a forged chunk is bounded
        raise CosimError(f"{where} inflates past the {declared:,} bytes it declares: refused (a damaged or forged "
                         f"log)")
    if len(data) < declared:  # cut short (a killed writer) or damaged: no partial record is parsed
        # Refused (correctness): cut short: a partial record would be parsed as a whole one
        raise McapError(f"chunk at byte {offset} inflates to {len(data):,} of the {declared:,} bytes it declares")
    return data


def log_records(f, path: str | Path, chunks: bool = True, limit: int | None = None) -> Iterator:
    """Every record of the MCAP file ``f`` (binary, at its start) in file order, the records of a chunk in its place
    (``chunks=False``: chunks skipped, not inflated; the records outside them only: attachments, metadata, summary).
    ``limit``: no record longer (the mcap reader's ``RecordLengthLimitExceeded`` before it is read).

    Bounded whatever the file says: a chunk is inflated to no more than it declares and :data:`MAX_CHUNK_BYTES`
    (CosimError naming ``path``, the chunk's byte offset and the limit), no record is longer than the file and no
    read goes past its end. A damaged or cut file raises the mcap package's errors (``McapError``).
    """

    src = _Clamped(f)
    start = 8  # the first record follows the magic
    try:
        size = src.size if limit is None else min(src.size, limit)
        for rec in StreamReader(src, emit_chunks=True, record_size_limit=size).records:
            if isinstance(rec, Chunk):
                if chunks:
                    yield from breakup_chunk(replace(rec, compression="", data=_inflate(rec, Path(path), start)))
            else:
                yield rec
            start = f.tell()
    except (struct.error, EOFError) as exc:  # the mcap reader's own errors for a record cut short: as its others
        # Refused (correctness): cut short: a partial record would be parsed as a whole one
        raise McapError(f"the file ends inside a record ({exc})") from None


def _open_error(path: Path, exc: Exception) -> CosimError:
    return CosimError(f"{path}: cannot read the MCAP log ({type(exc).__name__}: {exc}); if the run was killed, "
                      f"rewrite it first with `python -m cosim recover {path}`")


def read_run(path: str | Path, components: Iterable[str] | None = None) -> RunLog:
    """Read a run log. ``components`` limits the channels read (default: all but ``/scene``).

    Raises CosimError naming the file when it is missing, not an MCAP file, unfinished, or holds a chunk past
    :data:`MAX_CHUNK_BYTES`.
    """
    path = Path(path)
    problem = file_problem(path)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a log would be read for ever
        raise CosimError(f"{path}: {problem}")
    wanted = None if components is None else {f"/{c}" for c in components}
    columns: dict[str, dict[str, list]] = {}  # per component, per key (t included): the values in file order
    stamps: dict[str, list[int]] = {}  # simulation time (blocks) or log time (one sample a message), ns
    logged: dict[str, list[bool]] = {}  # per stamp: a log time (the time offset is subtracted once it is known)
    props: dict[str, dict] = {}
    metadata: dict[str, dict[str, str]] = {}
    attachments: dict[str, bytes] = {}
    channel_md: dict[str, dict[str, str]] = {}
    events: list[tuple[int, dict]] = []
    schemas: dict[int, Schema] = {}
    read: dict[int, str] = {}  # channel id -> component, for the channels read
    seen: set[int] = set()
    footer = False
    try:
        with open(path, "rb") as f:
            for rec in log_records(f, path):
                if isinstance(rec, Message):
                    comp = read.get(rec.channel_id)
                    if comp is None:
                        continue
                    d = orjson.loads(rec.data)
                    if comp == "/events":
                        events.append((rec.log_time, d))
                        continue
                    cols = columns[comp]
                    if isinstance(d.get("t"), list):  # a block of samples: the stamps from its times
                        stamps[comp] += [round(t * 1e9) for t in d["t"]]
                        logged[comp] += [False] * len(d["t"])
                        for key, values in d.items():
                            cols.setdefault(key, []).extend(values)
                    else:  # one sample
                        stamps[comp].append(rec.log_time)
                        logged[comp].append(True)
                        for key, value in d.items():
                            cols.setdefault(key, []).append(value)
                elif isinstance(rec, Schema):
                    schemas.setdefault(rec.id, rec)
                elif isinstance(rec, Channel) and rec.id not in seen:  # the summary repeats them
                    seen.add(rec.id)
                    if rec.topic == "/events":
                        read[rec.id] = "/events"
                    if rec.topic in _SKIP_TOPICS or (wanted is not None and rec.topic not in wanted):
                        continue
                    comp = rec.topic.lstrip("/")
                    read[rec.id] = comp
                    channel_md[comp] = dict(rec.metadata)
                    schema = schemas.get(rec.schema_id)
                    props[comp] = orjson.loads(schema.data).get("properties", {}) if schema is not None else {}
                    columns[comp], stamps[comp], logged[comp] = {}, [], []
                elif isinstance(rec, Metadata):
                    metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Attachment):
                    attachments[rec.name] = bytes(rec.data)
                elif isinstance(rec, Footer):
                    footer = True
        if not footer:
            # Refused (correctness): an unfinished log: recover says what was kept, this would not
            raise McapError("no footer (unfinished log)")
    except (McapError, OSError, ValueError, orjson.JSONDecodeError) as exc:
        # Refused (correctness): a damaged log: its values would be partial
        raise _open_error(path, exc) from None
    if wanted is not None:
        missing = sorted(w[1:] for w in wanted if w[1:] not in columns)
        if missing:
            # Refused (correctness): a component the log does not hold was asked for
            raise CosimError(f"{path}: no channel for component(s) {', '.join(missing)}; "
                             f"it has {', '.join(sorted(channel_md)) or 'none'}")
    offset = time_offset_ns(metadata)
    signals: dict[str, Signal] = {}
    for comp, cols in columns.items():
        if not stamps[comp]:
            continue
        t_ns = np.asarray(stamps[comp], dtype=np.int64) - offset * np.asarray(logged[comp], dtype=np.int64)
        order = np.argsort(t_ns, kind="stable")
        t_ns = t_ns[order]
        for key, values in cols.items():
            if key == "t":
                continue
            if len(values) != len(order):
                # Refused (correctness): values and time stamps do not pair: each value's time would be a guess
                raise CosimError(f"{path}: channel /{comp} has {len(values)} values of {key!r} for "
                                 f"{len(order)} time stamps")
            meta = props[comp].get(key, {})
            item = meta.get("items", {}) if channel_md[comp].get("layout") == "blocks" else meta
            signals[f"{comp}.{key}"] = Signal(f"{comp}.{key}", t_ns, _column(values, item)[order],
                                              meta.get("unit", ""), meta.get("description", ""),
                                              meta.get("causality", ""))
    ordered = sorted(range(len(events)), key=lambda i: events[i][0])  # log time order, file order among equals
    return RunLog(path, signals, metadata, attachments, channel_md, [events[i][1] for i in ordered])


def _column(values: list, meta: dict) -> np.ndarray:
    """Values of one variable over time: floats (n,), (n, count) for arrays of numbers; else objects.

    JSON null (a NaN written by orjson) becomes nan; strings and base64 binaries stay as they are.
    """
    item = meta.get("items", meta)
    if item.get("type") in ("number", "integer", "boolean"):
        try:
            return np.array(values, dtype=float)
        except (TypeError, ValueError):  # ragged or mixed: keep the objects
            pass
    column = np.empty(len(values), dtype=object)
    column[:] = values
    return column


def write_baseline(source: str | Path, out: str | Path, period: float = 0.01,
                   components: Sequence[str] | None = None) -> tuple[Path, int]:
    """Decimate a run log to one sample per component every ``period`` s into ``out``.

    The baseline keeps the source's schemas, channels (minus ``/scene``), layout, metadata and
    attachments, and adds a ``baseline`` metadata record (source, period). Samples are kept
    where the simulation time is a multiple of ``period`` (the run's stamps are integer ns, so
    the pick is exact): whole messages of a log with one sample a message, the samples on the
    period of each block otherwise. Returns (path, samples kept).
    """
    source, out = Path(source), Path(out)
    problem = file_problem(source)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a log would be read for ever
        raise CosimError(f"{source}: {problem}")
    if not 1e-9 <= period <= MAX_TIME_S:  # nan and infinities too: stamps are whole nanoseconds of a grid
        # Refused (correctness): no grid of whole nanoseconds has that period
        raise CosimError(f"baseline period must be from 1 ns to {MAX_TIME_S:g} s, got {period:g} s")
    # as every output: a regular file or nothing (a device or a FIFO was replaced by a regular file: as root,
    # --out /dev/null destroyed /dev/null), never the source, its folder made
    check_output(out, (source,))
    period_ns = int(round(period * 1e9))
    wanted = None if components is None else {f"/{c}" for c in components}
    written = 0
    try:
        with written_by_rename(out) as tmp, open(source, "rb") as f, open(tmp, "wb") as dst:
            schemas: dict[int, Schema] = {}  # first pass: what comes before or after the messages
            channels: dict[int, Channel] = {}
            metadata: list[Metadata] = []
            attachments: list[Attachment] = []
            footer = False
            for rec in log_records(f, source):
                if isinstance(rec, Schema):
                    schemas.setdefault(rec.id, rec)
                elif isinstance(rec, Channel):
                    channels.setdefault(rec.id, rec)
                elif isinstance(rec, Metadata):
                    metadata.append(rec)
                elif isinstance(rec, Attachment):
                    attachments.append(rec)
                elif isinstance(rec, Footer):
                    footer = True
            if not footer:
                # Refused (correctness): an unfinished log: recover says what was kept, this would not
                raise McapError("no footer (unfinished log)")
            w = Writer(dst, compression=CompressionType.ZSTD)
            w.start(profile="", library="cosim-baseline")
            schema_ids, channel_ids = {}, {}
            for ch in channels.values():
                if ch.topic in _SKIP_TOPICS or (wanted is not None and ch.topic not in wanted):
                    continue
                sch = schemas[ch.schema_id]
                if sch.id not in schema_ids:
                    schema_ids[sch.id] = w.register_schema(sch.name, sch.encoding, sch.data)
                channel_ids[ch.id] = w.register_channel(ch.topic, ch.message_encoding, schema_ids[sch.id],
                                                        dict(ch.metadata))
            if wanted is not None:
                found = {ch.topic for ch in channels.values()}
                missing = sorted(c[1:] for c in wanted - found)
                if missing:
                    # Refused (correctness): a component the log does not hold was asked for
                    raise CosimError(f"{source}: no channel for component(s) {', '.join(missing)}")
            offset = time_offset_ns({rec.name: dict(rec.metadata) for rec in metadata})
            f.seek(0)
            for msg in log_records(f, source):  # second pass: the messages kept
                if not isinstance(msg, Message) or msg.channel_id not in channel_ids:
                    continue
                ch = channels[msg.channel_id]
                if ch.metadata.get("layout") != "blocks":  # one sample a message
                    if (msg.log_time - offset) % period_ns == 0:
                        w.add_message(channel_ids[ch.id], msg.log_time, msg.data, msg.publish_time)
                        written += 1
                    continue
                block = orjson.loads(msg.data)  # the block's samples on the period, as a block
                keep = [i for i, t in enumerate(block["t"]) if round(t * 1e9) % period_ns == 0]
                if keep:
                    stamp = round(block["t"][keep[-1]] * 1e9) + offset
                    w.add_message(channel_ids[ch.id], stamp,
                                  orjson.dumps({k: [v[i] for i in keep] for k, v in block.items()}), stamp)
                    written += len(keep)
            for rec in metadata:
                w.add_metadata(rec.name, dict(rec.metadata))
            w.add_metadata("baseline", {"source": str(source), "period_s": repr(period)})
            for att in attachments:
                w.add_attachment(att.create_time, att.log_time, att.name, att.media_type, att.data)
            w.finish()
    except CosimError:
        raise
    except Exception as exc:  # the source is unreadable: no half-written baseline is left behind
        # Refused (correctness): a damaged log: its baseline would be partial
        raise _open_error(source, exc) from None
    return out, written


_BEFORE_SCENARIO_BYTES = MAX_SCENARIO_BYTES + 2 ** 20
"""The longest record :func:`open_from_log` reads before the scenario as run: a run writes only its header, metadata
and that attachment (a scenario's bytes at most) first; a forged attachment of gigabytes there was read whole."""


@contextmanager
def open_from_log(path: str | Path, overrides: dict[tuple, Any] | None = None) -> Iterator[SystemStructure]:
    """The system structure of the scenario a run log records (:data:`DOCUMENT_ATTACHMENT`), with ``overrides`` on
    top, to run it again inside the ``with`` block.

    Its log goes where ``--out`` says (the CLI's default: beside the first, ``<name>.rerun.mcap``), never to the
    recorded ``logging.out`` (the first
    run's log). A run made from an SSP archive recorded the archive (metadata ``ssp``): its FMUs, unpacked for that
    run only, are unpacked again from it for the block (:func:`cosim.io.ssp.reopen_ssp`). Raises
    :class:`ScenarioError` naming ``path`` when it is missing, not an MCAP log or records no scenario, or when the
    archive is gone or has changed since; a recorded FMU file that is gone is reported when the FMUs are located, as
    for a scenario file.
    """
    path = Path(path)
    problem = file_problem(path)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a log would be read for ever
        raise ScenarioError(Issue("", problem.replace("no such file", "no such log file"), str(path)))
    found = archive = None
    try:
        with open(path, "rb") as f:
            for rec in log_records(f, path, chunks=False, limit=_BEFORE_SCENARIO_BYTES):
                if isinstance(rec, Metadata) and rec.name == "ssp":  # written before the scenario as run
                    archive = dict(rec.metadata)
                if isinstance(rec, Attachment) and rec.name == DOCUMENT_ATTACHMENT:
                    found = bytes(rec.data)
                    break
    except RecordLengthLimitExceeded as exc:  # what a run writes before it is small: a forged or foreign log
        # Refused (security): a forged attachment of gigabytes was read whole
        raise ScenarioError(Issue("", f"a record before the scenario as run is larger than "
                                      f"{_BEFORE_SCENARIO_BYTES:,} bytes ({exc}): not a run's log as written here, "
                                      "refused", str(path))) from None
    except (McapError, OSError, ValueError) as exc:  # before the attachment: read up to it otherwise
        # Refused (correctness): a damaged log: the scenario as run cannot be read
        raise ScenarioError(Issue("", f"not a readable MCAP log ({type(exc).__name__}: {exc}); give a run's log",
                                  str(path))) from None
    if found is None:
        # Refused (correctness): nothing records what was run: running it again would be a guess
        raise ScenarioError(Issue("", f"the log records no scenario as run ({DOCUMENT_ATTACHMENT}): written by an "
                                      "older version or not by `python -m cosim run`; run its scenario file instead",
                                  str(path)))
    values = found.count(b",") + found.count(b"[") + found.count(b"{")
    if len(found) > MAX_SCENARIO_BYTES or values > MAX_YAML_NODES:  # as a scenario file is bounded
        # Refused (security): bounded as a scenario file is (memory, an alias-bomb's size)
        raise ScenarioError(Issue("", f"{DOCUMENT_ATTACHMENT} holds {len(found):,} bytes, about {values:,} values: "
                                      f"more than a scenario may ({MAX_SCENARIO_BYTES:,} bytes, {MAX_YAML_NODES:,} "
                                      "values, as for a scenario file): refused", str(path)))
    try:
        data = json.loads(found)
    except (ValueError, RecursionError) as exc:  # RecursionError: nested past the parser's depth
        # Refused (correctness): the scenario as run cannot be read
        raise ScenarioError(Issue("", f"{DOCUMENT_ATTACHMENT} is not JSON ({exc})", str(path))) from None
    if not isinstance(data, dict):
        # Refused (correctness): the scenario as run cannot be read
        raise ScenarioError(Issue("", f"{DOCUMENT_ATTACHMENT} is not a scenario mapping", str(path)))
    if isinstance(data.get("logging"), dict):
        data["logging"]["out"] = None
    if archive is not None:
        with reopen_ssp(archive, data, str(path), overrides) as scenario:
            yield scenario
        return
    _unpacked_archive_gone(data, path)
    yield scenario_from_data(data, str(path), overrides).structure()


def _unpacked_archive_gone(data: dict[str, Any], path: Path) -> None:
    """A log of an SSP archive's run written before logs recorded the archive: its FMU paths point into the archive's
    temporary folder, removed after that run. One line saying so, rather than one "not found" per FMU."""
    for name, comp in (data.get("components") or {}).items():
        fmu = Path(comp["path"]) if isinstance(comp, dict) and isinstance(comp.get("path"), str) else None
        if fmu is not None and len(fmu.parents) > 2 and fmu.parents[2].name.startswith(SSP_PREFIX) \
                and not fmu.exists():  # <archive folder>/fmus/<place>/<name>.fmu (cosim.io.ssp.read_ssp)
            # Refused (correctness): its FMUs are gone with the archive's folder
            raise ScenarioError(Issue(f"components.{name}.path", f"the run was made from an SSP archive, unpacked "
                                      f"for that run only into {fmu.parents[2]} (gone), and the log (written by an "
                                      "older version) does not name the archive: run the archive again", str(path)))
