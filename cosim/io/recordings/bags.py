"""ROS bags read through ``rosbags``: ROS 2 bags (a folder with ``metadata.yaml``, or one ``.mcap`` or ``.db3``
file) and ROS 1 bags (``.bag``). Only the connections of the topics asked for are read (the messages of the other
topics are never deserialised, nor kept), so memory holds the selected samples and nothing of the bag's size.

A ROS 2 MCAP file cut short (a recorder killed: no summary, no footer) cannot be opened by ``rosbags``; it is then
streamed record by record through the reader of our own logs (:func:`cosim.io.runlog.log_records`, bounded against
damaged lengths) up to where it ends, its messages deserialised with the types its schemas define; the recording
says where it ended (``end_note``)."""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Mapping

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from ...errors import CosimError
from ..runlog import log_records
from .errors import RecordingError
from .spec import BagSpec, Resolver

__all__ = ["BagSamples", "read_bag", "bag_kind"]


@dataclass
class BagSamples:
    """Per name: stamps (ns, header or log time as asked) and values in message order."""

    t_ns: dict[str, list[int]] = field(default_factory=dict)
    values: dict[str, list[float]] = field(default_factory=dict)
    end_note: str = ""


def bag_kind(path: Path) -> str | None:
    """'ros2' (a bag folder, a ``.db3`` or an MCAP file of profile ros2), 'ros1' (``.bag``), or None."""
    if path.is_dir():  # a bag folder; one without metadata.yaml (its recorder killed before writing it) too
        found = (path / "metadata.yaml").is_file() or any(path.glob("*.mcap")) or any(path.glob("*.db3"))
        return "ros2" if found else None
    if path.suffix == ".bag":
        return "ros1"
    if path.suffix == ".db3":
        return "ros2"
    if path.suffix == ".mcap":
        return "ros2" if _mcap_profile(path) == "ros2" else None
    return None


def _mcap_profile(path: Path) -> str:
    """The profile of an MCAP file's header record ('' for our run logs, 'ros2' for a ROS 2 bag); '' for what is not
    a regular file (a FIFO would block the open: its readers name it)."""
    if not path.is_file():
        return ""
    try:
        with open(path, "rb") as f:
            head = f.read(8 + 1 + 8 + 4 + 64)
    except OSError:
        return ""
    if len(head) < 21 or head[8] != 0x01:
        return ""
    n = int.from_bytes(head[17:21], "little")
    return head[21:21 + n].decode("utf-8", "replace")


def _typestore(kind: str):
    return get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.LATEST)


def read_bag(path: Path, specs: Mapping[str, BagSpec], time: str) -> BagSamples:
    """The samples ``specs`` select in the bag at ``path`` (see the module docstring); ``time``: 'header' (the
    message's ``header.stamp``, or that of the innermost element on the spec's path that has one) or 'log'
    (the time the recorder received it)."""
    kind = bag_kind(path) or "ros2"
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        db3 = sorted(path.glob("*.db3"))
        if len(db3) == 1 and not any(path.glob("*.mcap")):  # rosbags reads a SQLite file by itself
            return read_bag(db3[0], specs, time)
        return _read_cut(path, _cut_mcap(path) or [], specs, time, "no metadata.yaml: its recorder stopped before "
                                                                     "writing it")
    try:
        with AnyReader([path], default_typestore=_typestore(kind)) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            _check_topics(path, specs, topics)
            conns = [c for c in reader.connections if c.topic in {s.topic for s in specs.values()}]
            stream = ((c.topic, c.msgtype, t, lambda raw=raw, c=c: reader.deserialize(raw, c.msgtype))
                      for c, t, raw in reader.messages(connections=conns))
            return _collect(path, specs, stream, time)
    except (AnyReaderError, FileNotFoundError, OSError, KeyError, ValueError) as exc:
        if isinstance(exc, CosimError):
            raise
        cut = _cut_mcap(path)
        if cut is None:
            hint = _HINTS.get("ros1" if kind == "ros1" else path.suffix, "")
            # Refused (correctness): nothing of the bag can be read (a cut ROS 2 .mcap is read up to its cut)
            raise RecordingError(f"{path}: cannot read the {kind.upper()} bag: {_said(exc)}{hint}") from None
        return _read_cut(path, cut, specs, time, _said(exc))


# what to do with a cut bag the reader cannot stream: a ROS 1 bag's index is at its end, SQLite's pages are whole
_HINTS = {"ros1": " (a ROS 1 bag cut short has lost its index: `rosbag reindex` rebuilds it)",
          ".db3": " (a SQLite bag cut short: `sqlite3 FILE .recover` saves what is readable into a new database)"}


def _said(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _check_topics(path: Path, specs: Mapping[str, BagSpec], topics: Mapping[str, str]) -> None:
    for name, spec in specs.items():
        if spec.topic not in topics:
            close = difflib.get_close_matches(spec.topic, list(topics), n=2)
            hint = f"; did you mean {' or '.join(close)}?" if close else ""
            listed = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
            # Refused (correctness): a signal asked for is not in the bag: what would drive it is a guess
            raise RecordingError(f"{path}: {spec.text}: no topic {spec.topic!r}{hint} (topics: {listed})")


def _collect(path: Path, specs: Mapping[str, BagSpec], stream: Iterator, time: str) -> BagSamples:
    """Walk ``stream`` of (topic, msgtype, log time ns, deserialise()) and pick each spec's value and stamp."""
    by_topic: dict[str, list[tuple[str, BagSpec]]] = {}
    for name, spec in specs.items():
        by_topic.setdefault(spec.topic, []).append((name, spec))
    resolvers: dict[str, list[tuple[str, Resolver]]] = {}
    out = BagSamples({n: [] for n in specs}, {n: [] for n in specs})
    counts = dict.fromkeys(by_topic, 0)
    for topic, msgtype, log_ns, load in stream:
        if topic not in by_topic:
            continue
        wanted = resolvers.get(topic)
        if wanted is None:
            wanted = resolvers[topic] = [(n, Resolver(s, msgtype, str(path))) for n, s in by_topic[topic]]
        i = counts[topic]
        try:
            msg = load()
        except CosimError:
            raise
        except Exception as exc:  # noqa: BLE001 - rosbags' deserialisers raise their own and struct's errors
            # Refused (correctness): a message that does not decode: its values would be a guess
            raise RecordingError(f"{path}: {topic}: message {i} (log time {log_ns * 1e-9:.6f} s) is no "
                                 f"{msgtype}: {_said(exc)}") from None
        counts[topic] = i + 1
        for name, res in wanted:
            value, stamped = res.value(msg, i, log_ns * 1e-9)
            if time == "header":
                if stamped is None:
                    # Refused (correctness): no header stamp to time it by: the remedy (time: log) is named
                    raise RecordingError(f"{path}: {res.spec.text}: {res.msgtype} has no header to take a stamp "
                                         "from; read it with time: log (the recorder's receive times)")
                st = stamped.header.stamp
                t = int(st.sec) * 1_000_000_000 + int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
            else:
                t = log_ns
            out.t_ns[name].append(t)
            out.values[name].append(value)
    return out


def _cut_mcap(path: Path) -> list[Path] | None:
    """The MCAP file(s) of a ROS 2 bag that may be cut (an .mcap file, or those of a bag folder); None otherwise."""
    if path.is_file() and path.suffix == ".mcap":
        return [path]
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        return files or None
    return None


def _read_cut(path: Path, files: list[Path], specs: Mapping[str, BagSpec], time: str, why: str) -> BagSamples:
    """Stream the MCAP files of a bag ``rosbags`` refused (``why``) up to where they end."""
    store = get_typestore(Stores.EMPTY)
    schemas: dict[int, Schema] = {}
    channels: dict[int, tuple[str, str]] = {}
    ended: list[str] = []

    def stream() -> Iterator:
        for file in files:
            try:
                with open(file, "rb") as f:
                    for rec in log_records(f, file):
                        if isinstance(rec, Schema):
                            schemas[rec.id] = rec
                            text = rec.data.decode("utf-8", "replace")
                            try:
                                types = (get_types_from_idl(text) if rec.encoding == "ros2idl"
                                         else get_types_from_msg(text, rec.name))
                                store.register({k: v for k, v in types.items() if k not in store.fielddefs})
                            except Exception as exc:  # noqa: BLE001 - rosbags' parser errors vary by version
                                # Refused (correctness): a schema that does not parse: its messages cannot be decoded
                                raise RecordingError(f"{file}: schema {rec.name!r}: {_said(exc)}") from None
                        elif isinstance(rec, Channel):
                            schema = schemas.get(rec.schema_id)
                            channels[rec.id] = (rec.topic, schema.name if schema else "")
                        elif isinstance(rec, Message) and rec.channel_id in channels:
                            topic, msgtype = channels[rec.channel_id]
                            yield topic, msgtype, rec.log_time, (lambda d=rec.data, m=msgtype:
                                                                 store.deserialize_cdr(d, m))
            except (McapError, OSError) as exc:
                ended.append(f"{file.name} ends early at byte {file.stat().st_size:,} ({_said(exc)})")
                return

    out = _collect(path, specs, stream(), time)
    if not channels:
        where = "; ".join(ended) or "no channel in it"
        # Refused (correctness): nothing of the bag can be read
        raise RecordingError(f"{path}: cannot read the ROS 2 bag ({why}), and nothing of it is readable: {where}")
    _check_topics(path, specs, {t: m for t, m in channels.values()})
    out.end_note = f"{path}: cut bag ({why}): " + ("; ".join(ended) or "read to its last record")
    return out
