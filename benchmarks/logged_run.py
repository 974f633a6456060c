"""A logged run against the same run unlogged: helix_ctc_analytic on native FMUs, serial (target: logged <= 2x).

Each round runs the scenario twice, in alternating order: with every signal logged to a temporary MCAP file the way
``cosim run`` logs by default (the scenario's ``logging`` section: ``samples`` layout, the 3D scene, a forked writer
process), and with ``--no-log``, both through :func:`cosim.run.run_scenario`. Printed per round: the stepping loop's
wall time of each (``RunResult.wall_time``), their ratio, and the whole call (start-up, FMU loading and the log's
completion); then the ranges, the machine's load (``uptime``), and where a logged step's time goes:

- the master's own logging work per step: the CPU time of the master's thread in the loop (around
  :func:`cosim.engine.cloop.simulate`), logged minus unlogged in the same round: the rows copied, the scene drawn,
  the blocks pickled and written down the pipe; CPU time, so neither its sleeps on a full pipe nor the other
  processes of a busy machine count (the system calls and switches of writing to a writer that lags behind do:
  measured here, a writer that drops all it receives left the master 5-11 us a step of CPU where the real one left
  12-18);
- the master's time blocked writing to the writer's pipe (the writer not keeping up), measured around its writes;
- the writer process's throughput: the calls the master sent in one logged run (captured on the way) replayed
  through the writer's loop (:func:`cosim.observers.log_writer._serve`) in this process, with no master beside it:
  what the writer needs per step on a core of its own (wall time, best of 3, and the CPU time of that run).

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


class LoopCpu:
    """While entered, the CPU seconds of the calling thread inside the loop in C (:func:`cosim.engine.cloop.simulate`,
    which a run of native FMUs takes), summed in :attr:`seconds`."""

    def __enter__(self) -> "LoopCpu":
        from cosim.engine import cloop

        self._module, self._original, self.seconds = cloop, cloop.simulate, 0.0
        watch, original = self, self._original

        def timed(*args) -> None:
            t0 = time.thread_time()
            try:
                original(*args)
            finally:
                watch.seconds += time.thread_time() - t0

        cloop.simulate = timed
        return self

    def __exit__(self, *exc) -> None:
        self._module.simulate = self._original


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


def replay(sent: list[bytes], path: Path, rounds: int) -> tuple[float, float]:
    """Best wall seconds of the writer's loop over the captured calls (the file opened at ``path``), and the CPU
    seconds of that round."""
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
    best = (float("inf"), float("inf"))
    for _ in range(rounds):
        t0, c0 = time.perf_counter(), time.process_time()
        _serve(io.BytesIO(stream), io.BytesIO())
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
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
    logged, unlogged, whole_l, whole_u, ratios, blocked, cpu_l, cpu_u = [], [], [], [], [], [], [], []
    with PipeWatch() as watch:
        for r in range(args.rounds):
            for log in ((True, False) if r % 2 == 0 else (False, True)):
                watch.reset()
                watch.capture = log and r == 0
                with LoopCpu() as cpu:
                    res, whole = run(args.stop_time, log, tmp / f"run_{r}.mcap")
                watch.capture = False
                (logged if log else unlogged).append(res.wall_time)
                (whole_l if log else whole_u).append(whole)
                (cpu_l if log else cpu_u).append(cpu.seconds)
                if log:
                    blocked.append(watch.blocked)
            ratios.append(logged[-1] / unlogged[-1])
            print(f"round {r + 1}: loop logged {logged[-1]:.4f} s, unlogged {unlogged[-1]:.4f} s: {ratios[-1]:.2f}x; "
                  f"whole call {whole_l[-1]:.3f} / {whole_u[-1]:.3f} s; master blocked on the writer's pipe "
                  f"{blocked[-1]:.4f} s; the master's CPU in the loop {cpu_l[-1]:.4f} / {cpu_u[-1]:.4f} s", flush=True)
        sent = list(watch.sent)
    writer_s, writer_cpu = replay(sent, tmp / "replay.mcap", 3)
    load_after = load()
    us = 1e6 / steps
    work = [(lg - ul) * us for lg, ul in zip(cpu_l, cpu_u)]
    print(f"helix_ctc_analytic, native FMUs, serial, {args.stop_time:g} s at 1 ms ({steps} steps), {args.rounds} "
          f"alternated rounds; load before {load_before}, after {load_after}")
    print(f"loop: logged {span(logged, '.4f')} s, unlogged {span(unlogged, '.4f')} s; ratio {span(ratios, '.2f')}x "
          f"(target <= 2x)")
    print(f"whole call: logged {span(whole_l, '.3f')} s, unlogged {span(whole_u, '.3f')} s")
    print(f"per step: unlogged {span([u * us for u in unlogged], '.2f')} us, logged {span([g * us for g in logged], '.2f')}"
          f" us; the master blocked on the writer's pipe {span([b * us for b in blocked], '.2f')} us")
    print(f"the master's CPU in the loop per step: logged {span([c * us for c in cpu_l], '.2f')} us, unlogged "
          f"{span([c * us for c in cpu_u], '.2f')} us; its own logging work (logged minus unlogged, same round) "
          f"{span(work, '.2f')} us")
    print(f"writer process (its loop replayed alone, best of 3): {writer_s * us:.2f} us per step wall, "
          f"{writer_cpu * us:.2f} us CPU; {writer_s:.3f} s for the run")
    if args.json is not None:
        figures = {
            "loop logged s (median)": statistics.median(logged),
            "loop unlogged s (median)": statistics.median(unlogged),
            "ratio min": min(ratios), "ratio max": max(ratios), "ratio median": statistics.median(ratios),
            "whole call logged s (median)": statistics.median(whole_l),
            "whole call unlogged s (median)": statistics.median(whole_u),
            "master logging work us/step (median)": statistics.median(work),
            "master loop cpu logged us/step (median)": statistics.median(cpu_l) * us,
            "master loop cpu unlogged us/step (median)": statistics.median(cpu_u) * us,
            "blocked on writer pipe us/step (median)": statistics.median(blocked) * us,
            "writer process us/step": writer_s * us,
            "writer process cpu us/step": writer_cpu * us,
            "command": "python benchmarks/logged_run.py " + " ".join(sys.argv[1:]),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "load": f"before {load_before}; after {load_after}",
        }
        args.json.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
