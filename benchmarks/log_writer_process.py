"""The log's writer process, replayed in this process (issue 23): where its time per simulated step goes.

helix_ctc_analytic on native FMUs is run once per layout (``samples``, ``blocks``) with every signal
logged through :class:`cosim.observers.log_writer.WriterProcess`; the bytes the master sends down the pipe (the
pickled calls: channels, blocks of rows, scene messages, metadata, attachments) are captured on the
way. Each stream is then replayed, ``--rounds`` times alternated, best kept, with no master beside it:

- ``whole``: the child's loop itself (:func:`cosim.observers.log_writer._serve`: unpickling, encoding, writing,
  closing the file), what the writer process needs per step on a core of its own;
- ``encode``: :func:`cosim.observers.log_writer.encode_messages` over every block of samples (JSON messages);
- ``write``: foxglove-sdk's MCAP writer given every message already encoded (the channels'
  ``log`` calls in the order :class:`cosim.observers.log_writer.LogSink` makes them, and ``close``), with zstd
  at the recorder's level and chunk size, and at the chunk sizes of ``--chunks``.

    python benchmarks/log_writer_process.py [--rounds 5] [--chunks 262144 1048576]
"""

from __future__ import annotations

import argparse
import io
import math
import pickle
import struct
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def capture(layout: str, out: Path) -> list[tuple[str, tuple]]:
    """The calls the master sends to the writer process in a 10 s run of helix_ctc_analytic (native FMUs)."""
    from benchmarks.native import run
    from cosim.observers import log_writer

    sent: list[bytes] = []
    original = log_writer.WriterProcess._write

    def tee(self):  # noqa: ANN001, ANN202
        sent.append(b"".join(self._queue))
        original(self)

    log_writer.WriterProcess._write = tee
    try:
        run("helix_ctc_analytic", 10.0, fmus="native", log=True, out=out, layout=layout)
    finally:
        log_writer.WriterProcess._write = original
    data, calls, i = b"".join(sent), [], 0
    while i < len(data):
        n = struct.unpack_from("<I", data, i)[0]
        calls.append(pickle.loads(data[i + 4:i + 4 + n]))
        i += 4 + n
    return calls


def stream(calls: list[tuple[str, tuple]], path: Path) -> bytes:
    """The calls framed as the pipe carries them, the file opened at ``path``."""
    framed = []
    for op, args in calls:
        if op == "open":
            args = (str(path), *args[1:])
        payload = pickle.dumps((op, args), protocol=pickle.HIGHEST_PROTOCOL)
        framed += (struct.pack("<I", len(payload)), payload)
    return b"".join(framed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="alternated rounds, best kept (default 5)")
    ap.add_argument("--chunks", type=int, nargs="*", default=[262144, 1048576],
                    help="chunk sizes (uncompressed bytes) of the write-only measurement")
    args = ap.parse_args()

    from benchmarks.native import run
    from cosim.observers import log_writer
    from cosim.observers.mcap_log import McapRecorder

    tmp = Path(tempfile.mkdtemp(prefix="writer_bench_"))
    run("helix_ctc_analytic", 0.01, fmus="native")  # build and cache the FMUs outside the capture
    layouts = ("samples", "blocks")
    calls = {lay: capture(lay, tmp / f"run_{lay}.mcap") for lay in layouts}
    steps = 10000
    best: dict[tuple[str, str], float] = {}

    def keep(key, seconds):  # noqa: ANN001, ANN202
        best[key] = min(best.get(key, math.inf), seconds)

    for _ in range(args.rounds):
        for lay in layouts:
            data = stream(calls[lay], tmp / f"replay_{lay}.mcap")
            t0 = time.perf_counter()
            log_writer._serve(io.BytesIO(data), io.BytesIO())
            keep((lay, "whole"), time.perf_counter() - t0)
            layouts_of = {a[0]: a[5] for op, a in calls[lay] if op == "channel"}
            messages = []
            t0 = time.perf_counter()
            for op, a in calls[lay]:
                if op == "blocks":
                    for cid, stamps, rows, skip in a[1]:
                        times, datas = log_writer.encode_messages(layouts_of[cid], stamps, rows, skip, a[0])
                        messages += zip([cid] * len(times), times, datas)
                elif op == "message":
                    messages.append(a)
            keep((lay, "encode"), time.perf_counter() - t0)
            for chunk in args.chunks:
                sink = log_writer.LogSink(tmp / f"write_{lay}.mcap", chunk, McapRecorder.ZSTD_LEVEL)
                for op, a in calls[lay]:
                    if op == "channel":
                        sink.channel(*a)
                logs = sink._log
                ordered = [(logs[cid], t, d) for cid, t, d in messages]
                t0 = time.perf_counter()
                for log, t, d in ordered:
                    log(d, t)
                sink.finish()
                keep((lay, f"write {chunk // 1024} KiB chunks"), time.perf_counter() - t0)
    n_msgs = {lay: sum(len(a[1]) if op == "blocks" else 0 for op, a in calls[lay]) for lay in layouts}
    print(f"the log's writer process replayed (helix_ctc_analytic native, 10 s at 1 ms), best of {args.rounds}; "
          f"us per simulated step")
    for lay in layouts:
        print(f"{lay}: " + "; ".join(f"{what} {s / steps * 1e6:.2f}" for (la, what), s in best.items() if la == lay)
              + f" ({n_msgs[lay]} blocks of samples)")


if __name__ == "__main__":
    main()
