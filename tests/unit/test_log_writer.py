"""The run log's writer (cosim.observers.log_writer): sample and block messages from raw rows, the MCAP file it
writes in both layouts (read back by the ``mcap`` reader, indexes and statistics included), the writer
process with its failure report, and the unfinished file a killed or orphaned writer process leaves
(recovered by ``cosim recover``)."""

from __future__ import annotations

import ctypes
import dataclasses
import os
import struct
import sys
import time

import orjson
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from cosim.fmi import BOOLEAN, REAL
from cosim.observers.log_writer import encode, mirror, process
from cosim.observers.log_writer import (BlockLayout, LogSink, WriterFailed, WriterProcess, encode_block, encode_samples,
                              row_format)
from cosim.observers.publish import block_layout
from cosim.io.runlog import samples

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


def test_sample_messages_are_the_dicts_of_one_sample_each_as_orjson_writes_them():
    """The samples layout writes, byte for byte, ``orjson.dumps({"t": s, "<key>": value, ...})`` (the messages
    of logs written before blocks), from the same rows, alone or between other channels' bytes."""
    stamps = [0, 1_000_000, 2_000_000_123]
    expected = [orjson.dumps(sample) for sample in samples(orjson.loads(encode_block(LAYOUT, stamps, _rows(SAMPLES))))]
    assert expected[0] == b'{"t":0.0,"p.x":0.1,"p.y":-0.0,"ok":true,"b":true,"n":[7,-8]}', expected[0]
    got = encode_samples(LAYOUT, stamps, _rows(SAMPLES))
    assert got == expected, f"{got} vs {expected}"
    joint = b"".join(b"abc" + _rows([s]) + b"defgh" for s in SAMPLES)
    assert encode_samples(LAYOUT, stamps, joint, (3, 5)) == expected
    assert encode_samples(LAYOUT, [5], _rows(SAMPLES[:1])) == [orjson.dumps({"t": 5e-9, **dict(zip(
        LAYOUT.keys, (0.1, -0.0, True, True, [7, -8])))})]


def test_sample_messages_joined_in_c_and_in_python_are_the_same_bytes(monkeypatch):
    """``cosim_samples`` (C, when a compiler is here) and the Python join write the same messages, for numbers
    orjson writes in every form (exponents, -0.0, subnormals, NaN and infinities as null, 64-bit integers,
    Booleans of both FMI versions, arrays), and the C join refuses arrays that do not hold the samples."""
    import random

    from cosim.observers.log_writer import samples_helper

    rnd = random.Random(23)
    specials = [0.0, -0.0, 5e-324, 1e300, -1.5e-7, 1e16, 123456789.0, float("nan"), float("inf"), -float("inf")]
    rows = [(rnd.choice(specials + [rnd.uniform(-1e3, 1e3)]), rnd.choice(specials), rnd.choice([0, 1, -2, 7]),
             rnd.random() < 0.5, rnd.randint(-2 ** 63, 2 ** 63 - 1), rnd.choice([0, -1])) for _ in range(40)]
    stamps = sorted(rnd.randrange(0, 10 ** 12) for _ in rows)
    joint = b"".join(b"abc" + _rows([r]) + b"defgh" for r in rows)
    expected = [orjson.dumps({"t": s * 1e-9, **dict(zip(LAYOUT.keys, (a, b, c != 0, d, [e, f])))})
                for s, (a, b, c, d, e, f) in zip(stamps, rows)]
    got = encode_samples(LAYOUT, stamps, joint, (3, 5))
    assert got == expected, f"first difference: {next((g, x) for g, x in zip(got, expected) if g != x)}"
    monkeypatch.setattr(encode, "_SAMPLES_HELPER", [None])  # no C compiler: the Python join
    assert encode_samples(LAYOUT, stamps, joint, (3, 5)) == expected, "the Python join differs"
    join = samples_helper()
    if join is not None:
        joints, ends, fmi2 = LAYOUT.c_joints()
        out = ctypes.create_string_buffer(4096)
        for times, values in ((b"[1.0,2.0]", b"[1,2,3,4,5,6]"), (b"[1.0]", b"[1,2,3,4,5,6,7]"), (b"[]", b"[]")):
            assert join(times, len(times), values, len(values), 2 if b"2.0" in times else 1, 6, joints, ends, fmi2,
                        out) == -1, f"{times} {values}: arrays not of 1 or 2 samples of 6 values accepted"


def test_values_read_one_by_one_make_the_same_block_and_samples():
    layout = BlockLayout(("s", "x"))  # no row format: one list of values a sample (strings, binaries)
    msg = orjson.loads(encode_block(layout, [0, 10], [["a", 1.5], ["b\n", 2.5]]))
    assert msg == {"t": [0.0, 1e-8], "s": ["a", "b\n"], "x": [1.5, 2.5]}, msg
    got = [orjson.loads(m) for m in encode_samples(layout, [0, 10], [["a", 1.5], ["b\n", 2.5]])]
    assert got == [{"t": 0.0, "s": "a", "x": 1.5}, {"t": 1e-8, "s": "b\n", "x": 2.5}], got


def test_layout_of_consecutive_buffer_elements_is_one_run():
    reals, ints = (ctypes.c_double * 4)(), (ctypes.c_int32 * 2)()
    readers = [(reals, 0, None, None), (reals, 1, 2, None), (ints, 1, None, bool), (reals, 3, None, None)]
    layout, runs = block_layout(("a", "b", "c", "d"), readers, [REAL, REAL, BOOLEAN, REAL])
    assert [(arr is reals, i, n) for arr, i, n in runs] == [(True, 0, 3), (False, 1, 1), (True, 3, 1)], runs
    assert layout.fmt == "1d2d1i1d" and layout.columns == ((0, 0, False), (1, 2, False), (3, 0, True),
                                                           (4, 0, False)), layout


def _write(path, per_sample: bool) -> None:
    """Two channels of the same schema: /a samples (3 a block, 10 blocks), /b one message each time."""
    sink = LogSink(path, chunk_size=300)  # small chunks: several of them
    layout = dataclasses.replace(LAYOUT, per_sample=per_sample)
    sink.channel(0, "/a", "cosim.a", b'{"title": "cosim.a"}', {"layout": "samples" if per_sample else "blocks"},
                 layout)
    sink.channel(1, "/b", "cosim.a", b'{"title": "cosim.a"}', {}, None)  # the same schema: one record
    sink.metadata("time", {"offset_ns": "100"})
    for k in range(10):
        sink.blocks(100, [(0, [3 * k, 3 * k + 1, 3 * k + 2], _rows(SAMPLES), None)])
        sink.message(1, 100 + 3 * k + 2, orjson.dumps({"k": k}))
    sink.attachment("scenario/x.yaml", "application/yaml", b"name: x\n", 5, 6)
    sink.finish()


@pytest.mark.parametrize("per_sample", [True, False], ids=["samples", "blocks"])
def test_file_reads_back_with_its_summary_indexes_and_statistics(tmp_path, per_sample):
    path = tmp_path / "x.mcap"
    _write(path, per_sample)
    n_a = 30 if per_sample else 10
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        st = summary.statistics
        assert (st.message_count, st.schema_count, st.channel_count, st.attachment_count, st.metadata_count) == \
            (n_a + 10, 1, 2, 1, 1), st
        ids = {c.topic: c.id for c in summary.channels.values()}
        assert st.channel_message_counts == {ids["/a"]: n_a, ids["/b"]: 10}, st
        assert st.chunk_count == len(summary.chunk_indexes) > 1, st
        assert (st.message_start_time, st.message_end_time) == (100 if per_sample else 102, 129), st
        assert {c.topic: c.metadata for c in summary.channels.values()} == \
            {"/a": {"layout": "samples" if per_sample else "blocks"}, "/b": {}}
        got = [(ch.topic, m.log_time, orjson.loads(m.data)) for _, ch, m in reader.iter_messages()]
        assert [t for _, t, _ in got] == sorted(t for _, t, _ in got), "not in log-time order"
        assert [d["k"] for topic, _, d in got if topic == "/b"] == list(range(10))
        values = [s["n"] for topic, _, d in got if topic == "/a" for s in samples(d)]
        assert values == [[7, -8], [2 ** 62, 0], [-1, 1]] * 10, values
        if per_sample:  # each sample logged at its own stamp, its t the simulation time
            assert all(t == 100 + round(d["t"] * 1e9) for topic, t, d in got if topic == "/a"), got[:4]
        assert [m.name for m in reader.iter_metadata()] == ["time"]
        assert [(a.name, a.data) for a in reader.iter_attachments()] == [("scenario/x.yaml", b"name: x\n")]
        late = [m.log_time for _, _, m in reader.iter_messages(starting_at=120)]  # through chunk and message indexes
        assert late == [t for _, t, _ in got if t >= 120] and len(late) == (14 if per_sample else 8), late


@pytest.fixture(params=["fork", "exec"])
def start(request, monkeypatch):
    """Both ways the writer process starts: a fork of this process (where possible) and a new interpreter."""
    if request.param == "fork" and not process.writer_forks():
        pytest.skip("a forked writer is not possible here (not POSIX, macOS, or threads running)")
    if request.param == "exec":
        monkeypatch.setattr(process._Fork, "possible", classmethod(lambda cls: False))
    return request.param


def test_writer_process_writes_the_file_and_reports_a_failure(tmp_path, start):
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


def _started_writer(path, per_sample: bool) -> WriterProcess:
    """A writer process that has written and flushed one block of /a (3 samples) and one /b message."""
    w = WriterProcess()
    w.open(path, 1024, 1)
    w.channel(0, "/a", "cosim.a", b'{"title": "cosim.a"}', {"layout": "samples" if per_sample else "blocks"},
              dataclasses.replace(LAYOUT, per_sample=per_sample))
    w.channel(1, "/b", "cosim.b", b'{"title": "cosim.b"}', {}, None)
    w.blocks(0, [(0, [0, 1, 2], _rows(SAMPLES), None)])
    w.message(1, 2, b'{"k":0}')
    w.flush()
    return w


def _messages_on_disk(path) -> int:
    """Messages a stream reader finds in the file so far (its complete chunks)."""
    from mcap.exceptions import McapError
    from mcap.records import Message

    count = 0
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f).records:
                count += isinstance(record, Message)
    except (OSError, McapError):  # not there yet, or ends inside a record
        pass
    return count


def _recovered(path, tmp_path, messages: int, channels: int = 2) -> dict:
    """Recover ``path`` (which the indexed reader refuses: no summary): its ``channels`` and ``messages`` and the
    signals."""
    from mcap.exceptions import McapError

    from cosim.io.recover import recover
    from cosim.io.runlog import read_run

    with open(path, "rb") as f, pytest.raises(McapError):  # unfinished: no footer, no summary
        make_reader(f).get_summary()
    rep = recover(path, tmp_path / "fixed.mcap")
    assert (rep.channels, rep.messages) == (channels, messages), rep
    return read_run(tmp_path / "fixed.mcap").signals


@pytest.mark.parametrize("layout", ["samples", "blocks"])
def test_log_of_a_killed_writer_process_is_recoverable(tmp_path, layout, start):
    """SIGKILL on the child after a flush: every flushed sample comes back, in either layout."""
    path = tmp_path / f"{layout}.mcap"
    w = _started_writer(path, layout == "samples")
    deadline = time.monotonic() + 30  # the child writes in its own time: wait for the flushed chunk
    while _messages_on_disk(path) < (4 if layout == "samples" else 2) and time.monotonic() < deadline:
        time.sleep(0.02)
    w._proc.kill()
    w._proc.wait(10)
    signals = _recovered(path, tmp_path, 4 if layout == "samples" else 2)
    assert list(signals["a.n"].y.tolist()) == [[7, -8], [2 ** 62, 0], [-1, 1]], signals["a.n"].y
    assert signals["a.ok"].y.tolist() == [1.0, 0.0, 1.0] and signals["a.n"].t_ns.tolist() == [0, 1, 2]


@pytest.mark.parametrize("layout", ["samples", "blocks"])
def test_writer_process_left_by_its_master_leaves_an_unfinished_recoverable_log(tmp_path, layout, start):
    """The pipe closes without ``finish`` (the master died): the child writes what it has and exits
    without a summary, as a killed writer would; nothing it was sent is lost."""
    path = tmp_path / f"{layout}.mcap"
    w = _started_writer(path, layout == "samples")
    w.blocks(0, [(0, [3, 4, 5], _rows(SAMPLES), None)])  # after the flush: written when the child abandons
    w.abandon()
    assert w._proc.returncode == 0, w._proc.stderr.read()
    signals = _recovered(path, tmp_path, 7 if layout == "samples" else 3)
    assert signals["a.p.y"].t_ns.tolist() == [0, 1, 2, 3, 4, 5], signals["a.p.y"].t_ns


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_forked_writer_keeps_none_of_the_masters_files(tmp_path):
    """A forked writer closes what it inherited (here a listening socket, as a live view's port, and an open
    file, as the log's claim): only its pipes, its log and what foxglove opens remain, and it is in a session
    of its own (the stop signals and the supervisor's kill of the run's group are the master's)."""
    import socket

    if not process.writer_forks():
        pytest.skip("a forked writer is not possible here")
    held = open(tmp_path / "claim.lock", "w")
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    try:
        w = WriterProcess()
        assert w.forked
        w.open(tmp_path / "f.mcap", 1024, 1)
        w.flush()
        deadline = time.monotonic() + 30
        while not (tmp_path / "f.mcap").exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        fds = os.listdir(f"/proc/{w.pid}/fd")
        targets = {os.readlink(f"/proc/{w.pid}/fd/{fd}") for fd in fds if os.path.exists(f"/proc/{w.pid}/fd/{fd}")}
        inode = os.fstat(server.fileno()).st_ino
        assert str(tmp_path / "claim.lock") not in targets and f"socket:[{inode}]" not in targets, targets
        assert os.getsid(w.pid) == w.pid != os.getsid(0)
        w.finish()
        assert w._proc.returncode == 0
    finally:
        server.close()
        held.close()


ROW_BYTES = struct.calcsize("=" + FMT)


def test_row_mirror_gives_each_sections_rows_after_the_last_stamp_received_of_its_channels():
    """Two batches in one shared memory: a joint one (channels 0 and 1 in each row, 3 and ROW_BYTES bytes) and a
    channel's own rows (channel 2). Each section's rows come back as blocks as the publisher sends them (the joint
    rows with the bytes around each channel, the channel's own with none), minus those whose stamps its channels'
    last block received already has; a batch whose rows were sent (``sent``) gives nothing."""
    import mmap

    shared = mmap.mmap(-1, mirror.RowMirror.BYTES)
    joint_width = 3 + ROW_BYTES
    sections = [([(0, 0, 3), (1, 3, ROW_BYTES)], joint_width, 4), ([(2, 0, ROW_BYTES)], ROW_BYTES, 4)]
    m = mirror.RowMirror(shared, sections)
    joint, own = m.sections
    for t, s in zip([10, 20, 30], SAMPLES):
        joint.put(t, b"abc" + _rows([s]))
    own.put(20, _rows(SAMPLES[:1]))
    own.put(40, _rows(SAMPLES[1:2]))
    got = mirror.RowMirror.unsent(shared, sections, {0: 10, 1: 10, 2: 20})
    assert got == [(0, [20, 30], b"abc" + _rows([SAMPLES[1]]) + b"abc" + _rows([SAMPLES[2]]), (0, ROW_BYTES)),
                   (1, [20, 30], b"abc" + _rows([SAMPLES[1]]) + b"abc" + _rows([SAMPLES[2]]), (3, 0)),
                   (2, [40], _rows(SAMPLES[1:2]), None)], got
    assert encode_block(LAYOUT, got[1][1], got[1][2], got[1][3]) == encode_block(LAYOUT, [20, 30], _rows(SAMPLES[1:]))
    assert [b[1] for b in mirror.RowMirror.unsent(shared, sections, {})] == [[10, 20, 30]] * 2 + [[20, 40]]
    assert mirror.RowMirror.unsent(shared, sections, {0: 30, 1: 30, 2: 40}) == []
    m.sent()
    assert mirror.RowMirror.unsent(shared, sections, {}) == []


def test_row_mirror_keeps_a_channels_rows_of_values_as_a_prefix_of_what_fits():
    """A channel of strings (rows of values, width None): its rows come back as the lists the publisher sends; a row
    that does not fit its section is not kept, nor any after it until the rows are sent (those kept stay every row up
    to a step, never a row with a gap before it)."""
    import mmap

    shared = mmap.mmap(-1, mirror.RowMirror.BYTES)
    sections = [([(0, 0, ROW_BYTES)], ROW_BYTES, 4), ([(5, 0, None)], None, 4)]
    assert mirror.RowMirror.size(None, 4) == 8 + 16 * 4 + mirror.RowMirror.VALUES_BYTES
    m = mirror.RowMirror(shared, sections)
    numbers, values = m.sections
    numbers.put(1, _rows(SAMPLES[:1]))
    rows = [["text", 1.5, [1, 2]], ["", -0.0, [3, 4]]]
    values.put(1, rows[0])
    values.put(2, rows[1])
    got = mirror.RowMirror.unsent(shared, sections, {0: 1})
    assert got == [(5, [1, 2], rows, None)], got
    assert mirror.RowMirror.unsent(shared, sections, {5: 1}) == [(0, [1], _rows(SAMPLES[:1]), None),
                                                                      (5, [2], rows[1:], None)]
    values.put(3, ["x" * mirror.RowMirror.VALUES_BYTES, 0.0, [0, 0]])  # does not fit: nor does any row after it
    values.put(4, rows[0])
    assert mirror.RowMirror.unsent(shared, sections, {0: 1, 5: 0}) == [(5, [1, 2], rows, None)]
    m.sent()
    values.put(5, rows[1])
    assert mirror.RowMirror.unsent(shared, sections, {0: 1, 5: 2}) == [(5, [5], rows[1:], None)]


def test_rows_that_do_not_fit_the_shared_memory_have_no_mirror(tmp_path):
    """The shared memory is made with the writer, before the run's rows are known: when every batch's section does
    not fit, there is no mirror at all (the writer keeps the blocks sent alone, see RowMirror)."""
    if not process.writer_forks():
        pytest.skip("a forked writer is not possible here")
    cap = 256
    size = mirror.RowMirror.size(ROW_BYTES, cap)
    assert size == 8 + cap * 8 + (cap * ROW_BYTES + 7) // 8 * 8 and size % 8 == 0, size
    n = mirror.RowMirror.BYTES // size
    fitting = [([(cid, 0, ROW_BYTES)], ROW_BYTES, cap) for cid in range(n)]
    assert mirror.RowMirror.fits(fitting) and not mirror.RowMirror.fits(fitting + fitting[:1])
    w = WriterProcess()
    w.open(tmp_path / "f.mcap", 1024, 1)
    assert w.mirror(fitting + fitting[:1], 0) is None
    assert w.mirror([], 0) is None
    assert isinstance(w.mirror(fitting, 0), mirror.RowMirror)
    w.finish()


def test_writer_left_by_its_master_writes_each_channels_mirrored_rows_after_its_last_block(tmp_path):
    """A multi-rate run's channels, each batched and mirrored apart (/a every step, /b every other one, /c a channel
    of values read one by one, as strings are, every third): the master dies after sending a block it had not marked
    sent yet (the mirror holds those rows too) and one more step. The writer writes, per channel, the mirrored rows
    later than its last block received: every row once, none lost."""
    if not process.writer_forks():
        pytest.skip("a forked writer is not possible here")
    path = tmp_path / "m.mcap"
    w = WriterProcess()
    w.open(path, 1024, 1)
    for cid, name in enumerate("ab"):
        w.channel(cid, f"/{name}", f"cosim.{name}", b"{}", {"layout": "samples"},
                  dataclasses.replace(LAYOUT, per_sample=True))
    w.channel(2, "/c", "cosim.c", b"{}", {"layout": "samples"}, BlockLayout(("v",), per_sample=True))
    m = w.mirror([([(0, 0, ROW_BYTES)], ROW_BYTES, 4), ([(1, 0, ROW_BYTES)], ROW_BYTES, 4), ([(2, 0, None)], None, 4)],
                 0)
    a, b, c = m.sections
    for t in (0, 1):
        a.put(t, _rows(SAMPLES[t:t + 1]))
    b.put(0, _rows(SAMPLES[:1]))
    c.put(0, [0.5])
    w.blocks(0, [(0, [0, 1], _rows(SAMPLES[:2]), None), (1, [0], _rows(SAMPLES[:1]), None), (2, [0], [[0.5]], None)])
    m.sent()
    a.put(2, _rows(SAMPLES[2:]))
    b.put(2, _rows(SAMPLES[2:]))
    w.blocks(0, [(0, [2], _rows(SAMPLES[2:]), None), (1, [2], _rows(SAMPLES[2:]), None)])  # the master dies here,
    a.put(3, _rows(SAMPLES[:1]))  # before marking them sent; then one more step
    c.put(3, [-1.25])
    w.abandon()
    assert w._proc.returncode == 0, w._proc.stderr.read()
    signals = _recovered(path, tmp_path, 8, channels=3)
    assert signals["c.v"].t_ns.tolist() == [0, 3] and signals["c.v"].y.tolist() == [0.5, -1.25], signals["c.v"]
    assert signals["a.p.x"].t_ns.tolist() == [0, 1, 2, 3], signals["a.p.x"].t_ns
    assert signals["b.p.x"].t_ns.tolist() == [0, 2], signals["b.p.x"].t_ns
    assert signals["a.n"].y.tolist() == [[7, -8], [2 ** 62, 0], [-1, 1], [7, -8]], signals["a.n"].y
