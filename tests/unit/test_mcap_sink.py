"""cosim.mcap_log.MessageSink writes exactly what mcap's Writer.add_message writes."""

import io

import orjson
import pytest

from cosim.mcap_log import MessageSink


def _write(use_sink: bool, chunk_size: int) -> bytes:
    from mcap.writer import CompressionType, Writer

    buf = io.BytesIO()
    w = Writer(buf, compression=CompressionType.ZSTD, chunk_size=chunk_size)
    w.start(profile="", library="cosim")
    sid = w.register_schema(name="s", encoding="jsonschema", data=b'{"title": "s", "type": "object"}')
    cids = [w.register_channel(topic=f"/c{i}", message_encoding="json", schema_id=sid) for i in range(3)]
    sink = MessageSink(w)
    assert use_sink is False or sink.add != sink._add_public, "the fast path must be active with this mcap"
    for k in range(3000):
        for j, cid in enumerate(cids):
            # multi-rate stamps are not monotonic across channels: exercise the min/max bookkeeping
            t = 1_000_000 * (k + (2 if j == 2 else 1))
            data = orjson.dumps({"t": t * 1e-9, "x": k * 0.1 + j, "ok": k % 2})
            if use_sink:
                sink.add(cid, t, data)
            else:
                w.add_message(cid, t, data, t)
        if k == 1500:
            w.flush()  # a periodic flush in the middle ends a chunk early
    w.finish()
    return buf.getvalue()


@pytest.mark.parametrize("chunk_size", [4096, 256 * 1024])
def test_sink_output_is_byte_identical_to_add_message(chunk_size):
    fast, public = _write(True, chunk_size), _write(False, chunk_size)
    assert fast == public, f"files differ: {len(fast)} vs {len(public)} bytes"


def test_sink_falls_back_to_the_public_path_without_writer_internals():
    class Plain:
        def __init__(self):
            self.got = []

        def add_message(self, channel_id, log_time, data, publish_time):
            self.got.append((channel_id, log_time, data, publish_time))

    w = Plain()
    MessageSink(w).add(1, 5, b"{}")
    assert w.got == [(1, 5, b"{}", 5)], f"fallback wrote {w.got}"
