"""Hostile inputs, round 2 (issue 25): forged logs, a scheduler that is not Dask, results that must mean what they say.

In the style of ``test_faults.py``: every case runs ``python -m cosim`` in a subprocess and asserts its exit code,
one message line naming the cause, no traceback; each runs with its own temporary folder (``TMPDIR``), which must be
empty afterwards, and writes nowhere but ``tmp_path``.
"""

from __future__ import annotations

import os
import resource
from pathlib import Path

import pytest
from cli_helpers import cosim
from test_faults import fails

from cosim.runlog import MAX_CHUNK_BYTES

pytestmark = pytest.mark.integration

MEMORY_LIMIT = 1024 ** 3
"""Address space of a command reading a forged log, bytes: well above what reading a small log takes, well under the
2.5 GiB a bomb inflates to, so a regression fails on the spot instead of exhausting the machine."""


@pytest.fixture
def run(tmp_path):
    """``cosim`` with a temporary folder of its own, which must be left empty."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()

    def call(*args, limit_memory: bool = False, **kw):
        def limit() -> None:
            resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))

        env = {**os.environ, "TMPDIR": str(tmp), **kw.pop("env", {})}
        return cosim(*args, env=env, preexec_fn=limit if limit_memory else None, **kw)

    yield call
    assert not any(tmp.iterdir()), f"left in the temporary folder: {sorted(p.name for p in tmp.iterdir())}"


# --------------------------------------------------------------------------- MCAP decompression bombs

BOMB_BYTES = 5 * 2 ** 29  # 2.5 GiB of zeros: about 80 kB of zstd


def _zeros(compression: str, n: int) -> bytes:
    """``n`` zero bytes compressed as an MCAP chunk is (one zstd or lz4 frame), never held uncompressed."""
    block = bytes(2 ** 22)
    if compression == "zstd":
        import zstandard

        c = zstandard.ZstdCompressor(level=1).compressobj(size=n)
    else:
        import lz4.frame

        c = lz4.frame.LZ4FrameCompressor()
        head = c.begin(source_size=n)
    parts = [] if compression == "zstd" else [head]
    for start in range(0, n, len(block)):
        parts.append(c.compress(block[:n - start]))
    parts.append(c.flush())
    return b"".join(parts)


def forged_log(path: Path, declared: int, inflated: int, compression: str = "zstd") -> int:
    """Write a finished, indexed MCAP log (header, a channel, one chunk, summary with its chunk index, footer)
    whose chunk declares ``declared`` uncompressed bytes and inflates to ``inflated``: a lie when they differ, an
    honest bomb when both are huge. Returns the chunk's byte offset."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema
    from mcap.writer import MCAP0_MAGIC

    schema = Schema(id=1, name="s", encoding="jsonschema", data=b"{}")
    channel = Channel(id=1, topic="/plant", message_encoding="json", schema_id=1, metadata={})
    data = _zeros(compression, inflated)
    b = RecordBuilder()
    Header(profile="", library="forged").write(b)
    schema.write(b)
    channel.write(b)
    offset = len(MCAP0_MAGIC) + b.count
    Chunk(compression=compression, data=data, message_start_time=0, message_end_time=0, uncompressed_crc=0,
          uncompressed_size=declared).write(b)
    length = len(MCAP0_MAGIC) + b.count - offset
    DataEnd(data_section_crc=0).write(b)
    summary = len(MCAP0_MAGIC) + b.count
    schema.write(b)
    channel.write(b)
    ChunkIndex(message_start_time=0, message_end_time=0, chunk_start_offset=offset, chunk_length=length,
               message_index_offsets={1: offset + length}, message_index_length=0, compression=compression,
               compressed_size=len(data), uncompressed_size=declared).write(b)
    Footer(summary_start=summary, summary_offset_start=0, summary_crc=0).write(b)
    path.write_bytes(MCAP0_MAGIC + b.end() + MCAP0_MAGIC)
    return offset


def _commands(log: Path, tmp_path: Path) -> list[tuple]:
    """Every command that reads a log."""
    return [("recover", log, "--out", tmp_path / "r.mcap"), ("compare", log, log),
            ("report", log, "--out", tmp_path / "report"), ("table", log),
            ("baseline", log, "--out", tmp_path / "b.mcap")]


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_lying_about_its_size_is_refused_by_every_reader(tmp_path, run, compression):
    log = tmp_path / "lie.mcap"
    at = forged_log(log, 4096, BOMB_BYTES, compression)
    assert log.stat().st_size < 12 * 2 ** 20, log.stat().st_size  # a small file (lz4 compresses zeros less)
    for args in _commands(log, tmp_path):
        fails(run(*args, limit_memory=True), 2, f"lie.mcap: the MCAP chunk at byte {at} ",
              "inflates past the 4,096 bytes it declares")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lie.mcap", "tmp"], "an output was written"


def test_an_honest_chunk_over_the_limit_is_refused_before_it_is_inflated(tmp_path, run):
    log = tmp_path / "bomb.mcap"
    at = forged_log(log, BOMB_BYTES, BOMB_BYTES)
    assert log.stat().st_size < 200_000, log.stat().st_size  # the 82 KB of issue 25
    for args in _commands(log, tmp_path):
        message = fails(run(*args, limit_memory=True), 2, f"bomb.mcap: the MCAP chunk at byte {at} ",
                        f"declares {BOMB_BYTES:,} bytes", f"{MAX_CHUNK_BYTES:,}", "cosim.runlog.MAX_CHUNK_BYTES")
        assert "refused" in message, message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bomb.mcap", "tmp"], "an output was written"


def test_a_chunk_cut_short_is_damage_not_a_record(tmp_path, run):
    """A chunk that inflates to fewer bytes than it declares (a cut frame) is a damaged log, never parsed in part."""
    log = tmp_path / "short.mcap"
    forged_log(log, 8192, 4096)
    fails(run("compare", log, log), 2, "short.mcap: cannot read the MCAP log", "4,096 of the 8,192 bytes")
