"""The live view's relay follows WebSocket frame boundaries however the bytes are cut (cosim.observers.relay)."""

from __future__ import annotations

import os
import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.observers.relay import _Frames


def _frame(opcode: int, payload: bytes, mask: bytes | None) -> bytes:
    n = len(payload)
    length = bytes([n]) if n < 126 else bytes([126]) + struct.pack("!H", n) if n < 65536 else \
        bytes([127]) + struct.pack("!Q", n)
    if mask is None:
        return bytes([0x80 | opcode]) + length + payload
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return bytes([0x80 | opcode, length[0] | 0x80]) + length[1:] + mask + masked


SIZES = st.sampled_from([0, 1, 2, 125, 126, 127, 65535, 65536, 70000])


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(st.tuples(st.sampled_from([0x1, 0x2, 0x8, 0x9, 0xA]), SIZES), min_size=1, max_size=6),
       masked=st.booleans(), cuts=st.lists(st.integers(min_value=1, max_value=70), min_size=1, max_size=40))
def test_boundaries_and_close_payloads_whatever_the_chunks(frames, masked, cuts):
    stream, expected, end = b"", [], 0
    for opcode, size in frames:
        size = min(size, 125) if opcode >= 0x8 else size  # control frames carry at most 125 bytes
        payload = struct.pack("!H", 1000 + size) + b"r" * max(0, size - 2) if opcode == 0x8 and size >= 2 else \
            os.urandom(size)
        stream += _frame(opcode, payload, os.urandom(4) if masked else None)
        end = len(stream)
        expected.append((end, payload if opcode == 0x8 else None))
    parser, got, pos, i = _Frames(masked), [], 0, 0
    while pos < len(stream):  # cut in pieces of the sizes drawn, cycled, the last ones large
        size = cuts[i % len(cuts)] * (1 if i < 200 else 1000)
        chunk = stream[pos:pos + size]
        got += [(pos + at, payload) for at, payload in parser.feed(chunk)]
        pos += len(chunk)
        i += 1
    assert got == expected
    assert parser.at_boundary


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(st.tuples(st.sampled_from([0x1, 0x2, 0x9]), st.sampled_from([0, 1, 13, 300, 70000]),
                                 st.sampled_from([0x01, 0x02, 0x03])), min_size=1, max_size=8),
       cuts=st.lists(st.integers(min_value=1, max_value=70), min_size=1, max_size=40))
def test_message_data_frames_are_counted_whatever_the_chunks(frames, cuts):
    """The server's frames (unmasked) as the relay sees them: it counts the binary frames whose first payload byte is
    the Foxglove protocol's message-data op (0x01), not its time (0x02) or other binary ops, not text or ping frames,
    however the bytes are cut (the first payload byte arriving alone in the next chunk included)."""
    stream, expected = b"", 0
    for opcode, size, op in frames:
        size = min(size, 125) if opcode >= 0x8 else size
        payload = (bytes([op]) + os.urandom(size - 1)) if size else b""
        stream += _frame(opcode, payload, None)
        expected += opcode == 0x2 and size > 0 and op == 0x01
    parser, pos, i = _Frames(masked=False), 0, 0
    while pos < len(stream):
        size = cuts[i % len(cuts)] * (1 if i < 200 else 1000)
        parser.feed(stream[pos:pos + size])
        pos += size
        i += 1
    assert parser.messages == expected


def test_a_close_claiming_a_huge_payload_keeps_at_most_125_bytes():
    """A viewer's Close frame whose header claims 2^40 bytes: the relay keeps at most a control frame's 125 bytes of
    it, however much follows, and still finds where it ends."""
    mask = os.urandom(4)
    claimed = 1 << 40
    parser = _Frames(masked=True)
    header = bytes([0x80 | 0x8, 0x80 | 127]) + struct.pack("!Q", claimed) + mask
    assert parser.feed(header) == []
    sent = 0
    for _ in range(64):  # 64 MiB of it
        assert parser.feed(b"\0" * (1 << 20)) == []
        sent += 1 << 20
    assert len(parser.close) == 125 and parser.left == claimed - sent
