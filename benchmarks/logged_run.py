"""A logged run against the same run unlogged: helix_ctc_analytic on native FMUs, serial (target: logged <= 2x).

Each round runs the scenario twice, in alternating order: with every signal logged to a temporary MCAP file the way
``cosim run`` logs by default (the scenario's ``logging`` section: ``samples`` layout, the 3D scene, a forked writer
process), and with ``--no-log``, both through :func:`cosim.run.run_scenario`. Printed per round: the stepping loop's
wall time of each (``RunResult.wall_time``), their ratio, and the whole call (start-up, FMU loading and the log's
completion); then the ranges, the machine's load (``uptime``), and where a logged step's time goes:

- the master's own logging work per step: a third run in each round, logged with a writer that drops every sample
  and message it receives (a fork of the master with :meth:`LogSink.blocks` and :meth:`LogSink.message` made
  no-ops), less the time its writes to the pipe blocked (that writer off its core on a busy machine), against the
  unlogged run: the rows copied, the scene drawn, the blocks pickled and written down the pipe;
- the master's time blocked writing to the writer's pipe (the writer not keeping up), measured around its writes;
- the writer process's throughput: the calls the master sent in one logged run (captured on the way) replayed
  through the writer's loop (:func:`cosim.observers.log_writer._serve`) in this process, with no master beside it:
  what the writer needs per step on a core of its own.

    python benchmarks/logged_run.py [--rounds 5] [--stop-time 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"


def load() -> str:
    """The machine's load averages (1, 5, 15 min) as uptime prints them."""
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


class PipeWatch:
    """Times and captures the master's writes to its log writer's pipe (:meth:`WriterProcess._write`)."""

    def __init__(self) -> None:
        from cosim.observers.log_writer import process

        self._cls = process.WriterProcess
        self._original = self._cls._write
        self.capture = False
        self.sent: list[bytes] = []
        self.blocked = 0.0
        self.writes = 0

    def __enter__(self) -> "PipeWatch":
        watch, original = self, self._original

        def timed(proc) -> None:  # noqa: ANN001
            if watch.capture:
                watch.sent.append(b"".join(proc._queue))
            t0 = time.perf_counter()
            original(proc)
            watch.blocked += time.perf_counter() - t0
            watch.writes += 1

        self._cls._write = timed
        return self

    def __exit__(self, *exc) -> None:
        self._cls._write = self._original

    def reset(self) -> None:
        self.blocked, self.writes = 0.0, 0


class WriterDrops:
    """While entered, a forked writer drops the samples and messages it receives (the master's work unchanged)."""

    def __enter__(self) -> "WriterDrops":
        from cosim.observers.log_writer import sink

        self._cls = sink.LogSink
        self._saved = self._cls.blocks, self._cls.message
        self._cls.blocks = self._cls.message = lambda *args: None
        return self

    def __exit__(self, *exc) -> None:
        self._cls.blocks, self._cls.message = self._saved


def run(stop: float, log: bool, out: Path):
    from cosim.engine.scenario import load_scenario
    from cosim.run import run_scenario

    scenario = load_scenario(SCENARIO, {("time", "stop"): stop, ("fmus",): "native", ("parallel",): "off"})
    t0 = time.perf_counter()
    res = run_scenario(scenario, out=out, log=log)
    whole = time.perf_counter() - t0
    if res.status != "completed":
        sys.exit(f"helix_ctc_analytic did not complete: {res.status} {res.message}")
    return res, whole


def replay(sent: list[bytes], path: Path, rounds: int) -> float:
    """Best wall seconds of the writer's loop over the captured calls (the file opened at ``path``)."""
    import pickle
    import struct

    from cosim.observers.log_writer import _serve

    data, framed, i = b"".join(sent), [], 0
    while i < len(data):
        n = struct.unpack_from("<I", data, i)[0]
        op, args = pickle.loads(data[i + 4:i + 4 + n])
        if op == "open":
            args = (str(path), *args[1:])
        payload = pickle.dumps((op, args), protocol=pickle.HIGHEST_PROTOCOL)
        framed += (struct.pack("<I", len(payload)), payload)
        i += 4 + n
    stream = b"".join(framed)
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        _serve(io.BytesIO(stream), io.BytesIO())
        best = min(best, time.perf_counter() - t0)
    return best


def span(values: list[float], fmt: str) -> str:
    return f"{format(min(values), fmt)}-{format(max(values), fmt)} (median {format(statistics.median(values), fmt)})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="alternated rounds (default 5)")
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds of each run (default 10)")
    ap.add_argument("--json", type=Path, default=None, metavar="FILE", help="also write the figures to FILE as JSON")
    args = ap.parse_args()
    if args.rounds < 1 or not args.stop_time > 0:
        sys.exit("logged_run.py: --rounds must be >= 1 and --stop-time > 0")
    tmp = Path(tempfile.mkdtemp(prefix="logged_run_"))
    load_before = load()
    steps = round(args.stop_time / 1e-3)
    run(0.01, True, tmp / "warm.mcap")  # build and cache the FMUs outside the measurement
    from cosim.observers.log_writer import writer_forks

    forks = writer_forks()
    logged, unlogged, whole_l, whole_u, ratios, blocked, work = [], [], [], [], [], [], []
    with PipeWatch() as watch:
        for r in range(args.rounds):
            kinds = ("logged", "unlogged", "dropped") if forks else ("logged", "unlogged")
            for kind in (kinds if r % 2 == 0 else kinds[::-1]):
                watch.reset()
                watch.capture = kind == "logged" and r == 0
                if kind == "dropped":
                    with WriterDrops():
                        dropped, _ = run(args.stop_time, True, tmp / f"dropped_{r}.mcap")
                    dropped_blocked = watch.blocked  # a writer that drops all may still be off its core a while
                    continue
                res, whole = run(args.stop_time, kind == "logged", tmp / f"run_{r}.mcap")
                watch.capture = False
                (logged if kind == "logged" else unlogged).append(res.wall_time)
                (whole_l if kind == "logged" else whole_u).append(whole)
                if kind == "logged":
                    blocked.append(watch.blocked)
            ratios.append(logged[-1] / unlogged[-1])
            if forks:
                work.append((dropped.wall_time - dropped_blocked - unlogged[-1]) * 1e6 / steps)
            print(f"round {r + 1}: loop logged {logged[-1]:.4f} s, unlogged {unlogged[-1]:.4f} s: {ratios[-1]:.2f}x; "
                  f"whole call {whole_l[-1]:.3f} / {whole_u[-1]:.3f} s; master blocked on the writer's pipe "
                  f"{blocked[-1]:.4f} s" + (f"; logged with the writer dropping all {dropped.wall_time:.4f} s"
                                            if forks else ""), flush=True)
        sent = list(watch.sent)
    writer_s = replay(sent, tmp / "replay.mcap", 3)
    load_after = load()
    us = 1e6 / steps
    print(f"helix_ctc_analytic, native FMUs, serial, {args.stop_time:g} s at 1 ms ({steps} steps), {args.rounds} "
          f"alternated rounds; load before {load_before}, after {load_after}")
    print(f"loop: logged {span(logged, '.4f')} s, unlogged {span(unlogged, '.4f')} s; ratio {span(ratios, '.2f')}x "
          f"(target <= 2x)")
    print(f"whole call: logged {span(whole_l, '.3f')} s, unlogged {span(whole_u, '.3f')} s")
    print(f"per step: unlogged {span([u * us for u in unlogged], '.2f')} us, logged {span([g * us for g in logged], '.2f')}"
          f" us; the master blocked on the writer's pipe {span([b * us for b in blocked], '.2f')} us")
    print("the master's own logging work (logged with a writer that drops all, less its waits on the pipe, minus "
          "unlogged, same round): "
          + (f"{span(work, '.2f')} us per step" if work else "not measured (the writer is not a fork here)"))
    print(f"writer process (its loop replayed alone, best of 3): {writer_s * us:.2f} us per step, "
          f"{writer_s:.3f} s for the run")
    if args.json is not None:
        figures = {
            "loop logged s (median)": statistics.median(logged),
            "loop unlogged s (median)": statistics.median(unlogged),
            "ratio min": min(ratios), "ratio max": max(ratios), "ratio median": statistics.median(ratios),
            "whole call logged s (median)": statistics.median(whole_l),
            "whole call unlogged s (median)": statistics.median(whole_u),
            "master logging work us/step (median)": statistics.median(work) if work else None,
            "blocked on writer pipe us/step (median)": statistics.median(blocked) * us,
            "writer process us/step": writer_s * us,
            "command": "python benchmarks/logged_run.py " + " ".join(sys.argv[1:]),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "load": f"before {load_before}; after {load_after}",
        }
        args.json.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
