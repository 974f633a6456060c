"""MCAP writer choice (issue 18; issue 23's log writer): replay helix_ctc's logged message stream through each writer.

The messages (their bytes, channels and stamps, in the order the recorder wrote them) are read
from a helix_ctc run log, then written again, side by side, by

- ``mcap-sink``: the ``mcap`` 1.x ``Writer`` fed by the hand-packed ``MessageSink`` that the
  recorder used until issue 18 (one ``struct.pack`` per message into the writer's private open
  chunk; kept below, verbatim in substance, only to measure against);
- ``mcap-public``: the same ``Writer`` through its public ``add_message``;
- ``foxglove-sdk``: ``foxglove.open_mcap`` on a ``foxglove.Context`` whose channels the recorder
  logs into (the channels the live view serves too), given a path, or an open Python file;
  and with zstd level 1, which only this writer lets one choose; and as ``cosim.observers.log_writer.LogSink``
  writes the log (path, level 1, compression in the calling thread: the writer process has one core).

The log's layout is the run's (``logging.layout``; default ``samples``, one message per sample).

Every writer gets the same chunk size (256 KiB) and zstd at its default level (3) unless said.
The time counted is the writing loop plus closing the file (the summary and index), divided by
the run's macro steps (the overhead per simulated step) and by the messages. The message serialisation (orjson) is not counted: it
is the same for every writer. Each writer runs ``--repeat`` times, interleaved; the median is
reported.

    python benchmarks/mcap_writer.py [RUN.mcap] [--repeat N] [--json FILE | --record]

Without RUN.mcap, helix_ctc is run first into a temporary directory (about 5 s).
"""

from __future__ import annotations

import argparse
import statistics
import struct
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
CHUNK = 256 * 1024


# --------------------------------------------------------------------------- the previous writer

_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time


class HandPackedSink:
    """The recorder's ``MessageSink`` before issue 18: ``add_message`` packed by hand into mcap 1.x's open chunk."""

    def __init__(self, writer) -> None:
        from mcap.opcode import Opcode
        from mcap.records import MessageIndex

        class PackedMessageIndex(MessageIndex):
            def write(self, stream) -> None:
                n = len(self.records)
                stream.start_record(Opcode.MESSAGE_INDEX)
                stream.write2(self.channel_id)
                stream.write4(n * 16)
                stream.write(struct.pack(f"<{2 * n}Q", *[x for record in self.records for x in record]))
                stream.finish_record()

        self._chunk_size = writer._Writer__chunk_size
        self._stats = writer._Writer__statistics
        self._chunk = writer._Writer__chunk_builder
        self._finalize = writer._Writer__maybe_finalize_chunk
        self._index_type = PackedMessageIndex

    def add(self, channel_id: int, t_ns: int, data: bytes) -> None:
        st = self._stats
        if st.message_count == 0 or t_ns < st.message_start_time:
            st.message_start_time = t_ns
        st.message_end_time = max(st.message_end_time, t_ns)
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        ch = self._chunk
        if ch.num_messages == 0 or t_ns < ch.message_start_time:
            ch.message_start_time = t_ns
        ch.message_end_time = max(ch.message_end_time, t_ns)
        index = ch.message_indices.get(channel_id)
        if index is None:
            index = ch.message_indices[channel_id] = self._index_type(channel_id=channel_id, records=[])
        buf = ch.record_writer._buffer
        index.records.append((t_ns, buf.tell()))
        ch.num_messages += 1
        buf.write(_HEAD.pack(0x05, 22 + len(data), channel_id, 0, t_ns, t_ns))
        buf.write(data)
        if buf.tell() > self._chunk_size:
            self._finalize()


# --------------------------------------------------------------------------- writers


def _mcap_writer(path: Path, channels: dict, messages: list, sink: bool) -> float:
    from mcap.writer import CompressionType, Writer

    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD, chunk_size=CHUNK)
        w.start(profile="", library="bench")
        ids = {}
        for cid, (topic, schema, metadata) in channels.items():
            sid = w.register_schema(schema.name, schema.encoding, schema.data)
            ids[cid] = w.register_channel(topic, "json", sid, metadata)
        if sink:
            add = HandPackedSink(w).add
        else:
            def add(c, t, d, _add=w.add_message):
                _add(c, t, d, t)
        stream = [(ids[c], t, d) for c, t, d in messages]
        t0 = time.perf_counter()
        for c, t, d in stream:
            add(c, t, d)
        w.finish()
        return time.perf_counter() - t0


def _foxglove(path: Path, channels: dict, messages: list, file_object: bool, level: int = 0,
              threads: int | None = None) -> float:
    import foxglove
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions

    ctx = foxglove.Context()
    options = MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=CHUNK, compression_level=level,
                               compression_threads=threads)
    f = open(path, "wb") if file_object else None
    w = foxglove.open_mcap(f if file_object else path, allow_overwrite=True, context=ctx, writer_options=options)
    logs = {}
    for cid, (topic, schema, metadata) in channels.items():
        s = foxglove.Schema(name=schema.name, encoding=schema.encoding, data=schema.data)
        logs[cid] = foxglove.Channel(topic, schema=s, message_encoding="json", context=ctx, metadata=metadata).base.log
    stream = [(logs[c], t, d) for c, t, d in messages]
    t0 = time.perf_counter()
    for log, t, d in stream:
        log(d, t)
    w.close()
    elapsed = time.perf_counter() - t0
    if f is not None:
        f.close()
    return elapsed


WRITERS = {
    "mcap-sink (before)": lambda p, c, m: _mcap_writer(p, c, m, sink=True),
    "mcap-public": lambda p, c, m: _mcap_writer(p, c, m, sink=False),
    "foxglove-sdk (path)": lambda p, c, m: _foxglove(p, c, m, file_object=False),
    "foxglove-sdk (file)": lambda p, c, m: _foxglove(p, c, m, file_object=True),
    "foxglove-sdk (zstd 1)": lambda p, c, m: _foxglove(p, c, m, file_object=True, level=1),
    "foxglove-sdk (as log)": lambda p, c, m: _foxglove(p, c, m, file_object=False, level=1, threads=0),
}
# each writer's figures' name in the recorded JSON
FIGURE_KEYS = {"mcap-sink (before)": "sink", "mcap-public": "public", "foxglove-sdk (path)": "sdk_path",
               "foxglove-sdk (file)": "sdk_file", "foxglove-sdk (zstd 1)": "sdk_zstd1",
               "foxglove-sdk (as log)": "sdk_as_log"}


def _stream(path: Path) -> tuple[dict, list, int]:
    """Channels (id -> topic, schema, metadata), messages (channel id, log time, bytes) in file order, steps."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.id: (c.topic, summary.schemas[c.schema_id], dict(c.metadata)) for c in summary.channels.values()}
        messages = [(ch.id, m.log_time, bytes(m.data)) for _, ch, m in reader.iter_messages(log_time_order=False)]
        steps = max(summary.statistics.channel_message_counts.values()) - 1  # the start sample and every step
    return channels, messages, steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", nargs="?", help="a helix_ctc run log (default: run helix_ctc now)")
    ap.add_argument("--repeat", type=int, default=7)
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "mcap_writer") as rec:
        _measure(args, rec)


def _measure(args, rec: record.Recording) -> None:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    tmp = Path(tempfile.mkdtemp(prefix="mcap_writer_"))
    run = Path(args.run) if args.run else None
    if run is None:
        sys.path.insert(0, str(ROOT))
        from cosim.run import run_scenario

        run = tmp / "helix_ctc.mcap"
        run_scenario(ROOT / "scenarios" / "helix_ctc.yaml", out=run, log=True)
    channels, messages, steps = _stream(run)
    size = sum(len(d) for _, _, d in messages)
    print(f"{run}: {len(messages)} messages ({size / 1e6:.1f} MB of JSON) on {len(channels)} channels, {steps} steps")
    times: dict[str, list[float]] = {name: [] for name in WRITERS}
    sizes: dict[str, int] = {}
    for _ in range(args.repeat):
        for name, write in WRITERS.items():
            out = tmp / f"{name.split()[0]}.mcap"
            times[name].append(write(out, channels, messages))
            sizes[name] = out.stat().st_size
    base = statistics.median(times["mcap-sink (before)"])
    print(f"{'writer':<22}{'us/step':>9}{'us/message':>12}{'vs before':>11}{'file MB':>9}")
    for name, ts in times.items():
        t = statistics.median(ts)
        print(f"{name:<22}{t / steps * 1e6:>9.2f}{t / len(messages) * 1e6:>12.2f}{base / t:>10.2f}x"
              f"{sizes[name] / 1e6:>9.2f}")
    print("(median of", args.repeat, "interleaved runs; 'vs before' > 1 means faster than the hand-packed sink)")
    rec.put("messages", len(messages))
    rec.put("steps", steps)
    for name, ts in times.items():
        t = statistics.median(ts)
        rec.put(FIGURE_KEYS[name], {"us_per_step": t / steps * 1e6, "vs_before": base / t,
                                    "file_mb": sizes[name] / 1e6})


if __name__ == "__main__":
    main()
