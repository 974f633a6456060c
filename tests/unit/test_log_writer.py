"""The run log's writer (cosim.log_writer): block messages from raw rows, the MCAP file it writes
(read back by the ``mcap`` reader, indexes and statistics included), an unfinished file, and the
writer process with its failure report."""

from __future__ import annotations

import ctypes
import struct

import orjson
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from cosim.fmu import BOOLEAN, REAL
from cosim.log_writer import BlockLayout, LogSink, McapFile, WriterFailed, WriterProcess, encode_block, row_format
from cosim.publish import block_layout

# a row: 2 doubles (p), an FMI 2 Boolean (C int), an FMI 3 Boolean (C bool), an Int64 array of 2
FMT = row_format(ctypes.c_double, 2) + row_format(ctypes.c_int32, 1) + row_format(ctypes.c_bool, 1) \
    + row_format(ctypes.c_int64, 2)
LAYOUT = BlockLayout(("p.x", "p.y", "ok", "b", "n"), FMT, ((0, 0, False), (1, 0, False), (2, 0, True),
                                                            (3, 0, False), (4, 2, False)))
SAMPLES = [(0.1, -0.0, 1, True, 7, -8), (1e300, 5e-324, 0, False, 2 ** 62, 0), (float("nan"), 2.5, 3, True, -1, 1)]


def _rows(samples) -> bytes:
    return b"".join(struct.pack("=" + FMT, *s) for s in samples)


def test_row_formats_follow_the_ctypes_sizes():
    assert [row_format(t, 3) for t in (ctypes.c_double, ctypes.c_float, ctypes.c_int8, ctypes.c_uint16,
                                       ctypes.c_int32, ctypes.c_uint64, ctypes.c_bool)] == \
        ["3d", "3f", "3b", "3H", "3i", "3Q", "3?"]


def test_block_message_holds_every_sample_exactly():
    stamps = [0, 1_000_000, 2_000_000]
    msg = orjson.loads(encode_block(LAYOUT, stamps, _rows(SAMPLES)))
    assert msg["t"] == [0.0, 0.001, 0.002], msg["t"]
    assert msg["p.x"][:2] == [0.1, 1e300] and msg["p.x"][2] is None, msg["p.x"]  # NaN is JSON null, as orjson
    assert msg["p.y"] == [-0.0, 5e-324, 2.5] and str(msg["p.y"][0]) == "-0.0", msg["p.y"]
    assert msg["ok"] == [True, False, True], f"FMI 2 Booleans as JSON booleans: {msg['ok']}"
    assert msg["b"] == [True, False, True], msg["b"]
    assert msg["n"] == [[7, -8], [2 ** 62, 0], [-1, 1]], msg["n"]
    one = orjson.loads(encode_block(LAYOUT, [5], _rows(SAMPLES[:1])))
    assert one["n"] == [[7, -8]] and one["t"] == [5e-9], one
    # the same rows between other channels' bytes (3 before, 5 after each): the same message
    joint = b"".join(b"abc" + _rows([s]) + b"defgh" for s in SAMPLES)
    assert encode_block(LAYOUT, stamps, joint, (3, 5)) == encode_block(LAYOUT, stamps, _rows(SAMPLES))


def test_values_read_one_by_one_make_the_same_block():
    layout = BlockLayout(("s", "x"))  # no row format: one list of values a sample (strings, binaries)
    msg = orjson.loads(encode_block(layout, [0, 10], [["a", 1.5], ["b\n", 2.5]]))
    assert msg == {"t": [0.0, 1e-8], "s": ["a", "b\n"], "x": [1.5, 2.5]}, msg


def test_layout_of_consecutive_buffer_elements_is_one_run():
    reals, ints = (ctypes.c_double * 4)(), (ctypes.c_int32 * 2)()
    readers = [(reals, 0, None, None), (reals, 1, 2, None), (ints, 1, None, bool), (reals, 3, None, None)]
    layout, runs = block_layout(("a", "b", "c", "d"), readers, [REAL, REAL, BOOLEAN, REAL])
    assert [(arr is reals, i, n) for arr, i, n in runs] == [(True, 0, 3), (False, 1, 1), (True, 3, 1)], runs
    assert layout.fmt == "1d2d1i1d" and layout.columns == ((0, 0, False), (1, 2, False), (3, 0, True),
                                                           (4, 0, False)), layout


def _write(path, finish: bool = True) -> None:
    sink = LogSink(path, chunk_size=300)  # small chunks: several of them
    sink.channel(0, "/a", "cosim.a", b'{"title": "cosim.a"}', {"layout": "blocks"}, LAYOUT)
    sink.channel(1, "/b", "cosim.a", b'{"title": "cosim.a"}', {}, None)  # the same schema: one record
    sink.metadata("time", {"offset_ns": "100"})
    for k in range(10):
        sink.blocks(100, [(0, [3 * k, 3 * k + 1, 3 * k + 2], _rows(SAMPLES), None)])
        sink.message(1, 100 + 3 * k + 2, orjson.dumps({"k": k}))
    sink.attachment("scenario/x.yaml", "application/yaml", b"name: x\n", 5, 6)
    if finish:
        sink.finish()
    else:
        sink.abandon()


def test_file_reads_back_with_its_summary_indexes_and_statistics(tmp_path):
    path = tmp_path / "x.mcap"
    _write(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        st = summary.statistics
        assert (st.message_count, st.schema_count, st.channel_count, st.attachment_count, st.metadata_count) == \
            (20, 1, 2, 1, 1), st
        assert st.channel_message_counts == {1: 10, 2: 10} and st.chunk_count == len(summary.chunk_indexes) > 1, st
        assert (st.message_start_time, st.message_end_time) == (102, 129), st
        assert {c.topic: c.metadata for c in summary.channels.values()} == {"/a": {"layout": "blocks"}, "/b": {}}
        got = [(ch.topic, m.log_time, orjson.loads(m.data)) for _, ch, m in reader.iter_messages()]
        assert [t for _, t, _ in got] == sorted(t for _, t, _ in got), "not in log-time order"
        assert [d["k"] for topic, _, d in got if topic == "/b"] == list(range(10))
        assert all(d["n"] == [[7, -8], [2 ** 62, 0], [-1, 1]] for topic, _, d in got if topic == "/a")
        assert [m.name for m in reader.iter_metadata()] == ["time"]
        assert [(a.name, a.data) for a in reader.iter_attachments()] == [("scenario/x.yaml", b"name: x\n")]
        late = list(reader.iter_messages(starting_at=120))  # through the chunk and message indexes
        assert [m.log_time for _, _, m in late] == [120, 120, 123, 123, 126, 126, 129, 129], late


def test_unfinished_file_has_its_chunks_and_no_summary(tmp_path):
    from mcap.exceptions import EndOfFile, McapError
    from mcap.records import Message

    path = tmp_path / "x.mcap"
    _write(path, finish=False)
    with open(path, "rb") as f, pytest.raises(McapError):  # no footer: the indexed reader fails
        make_reader(f).get_summary()
    messages = []
    with open(path, "rb") as f, pytest.raises(EndOfFile):  # the stream reader reads up to the end
        for record in StreamReader(f).records:
            messages += [record] if isinstance(record, Message) else []
    assert len(messages) == 20, f"{len(messages)} messages in the unfinished file vs 20 written"


def test_writer_process_writes_the_file_and_reports_a_failure(tmp_path):
    path = tmp_path / "p.mcap"
    w = WriterProcess()
    w.open(path, 1024, 1)
    w.channel(0, "/a", "cosim.a", b'{"title": "cosim.a"}', {"layout": "blocks"}, LAYOUT)
    w.blocks(0, [(0, [0, 1, 2], _rows(SAMPLES), None)])
    w.metadata("outcome", {"status": "completed"})
    w.finish()
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == 1
        assert [orjson.loads(m.data)["ok"] for _, _, m in reader.iter_messages()] == [[True, False, True]]
    bad = WriterProcess()
    bad.open(tmp_path / "missing" / "x.mcap", 1024, 1)  # the child cannot create it
    with pytest.raises(WriterFailed, match="No such file or directory"):
        bad.channel(0, "/a", "cosim.a", b"{}", {}, None)
        bad.finish()
