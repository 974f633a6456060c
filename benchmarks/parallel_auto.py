"""``parallel: auto`` against serial (issue 36 item 5): never slower by more than 3 %.

helix_ctc_analytic, no log, with each build of our FMUs (``fmus=native``: 10 s simulated; ``fmus=python``: 3 s,
PythonFMU steps are slower), without and with the other CPU kept busy by a spinning process started here
(``python -c "while True: pass"``). Each case runs ``parallel: auto`` and ``parallel: off`` alternately
``--repeat`` times in this process, after one untimed short run (the FMUs built and cached), each timed from the
call of :func:`cosim.run.run_scenario` to its return (the FMUs' loading, the worker's start when auto takes one,
the run), and prints the medians, their ratio and what auto chose. Without the spinner the machine runs whatever
else it runs at the time (printed: the load average). Where auto chose the serial run, auto and off ran the same
code: their ratio is then the machine's noise.

    python benchmarks/parallel_auto.py [--repeat 5] [--native-stop 10] [--python-stop 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]


def _case(scenario: str, build: str, stop: float, repeat: int) -> tuple[float, float, str]:
    from cosim.engine.scenario import load_scenario
    from cosim.run import run_scenario

    times: dict[str, list[float]] = {"auto": [], "off": []}
    note = ""
    run_scenario(load_scenario(scenario, {("fmus",): build, ("time", "stop"): 0.01}), log=False, progress=False)
    for i in range(repeat):
        for mode in (("auto", "off") if i % 2 == 0 else ("off", "auto")):
            sc = load_scenario(scenario, {("fmus",): build, ("time", "stop"): stop, ("parallel",): mode})
            t0 = time.perf_counter()
            res = run_scenario(sc, log=False, progress=False)
            times[mode].append(time.perf_counter() - t0)
            if mode == "auto":
                note = "; ".join(n for n in res.notes if n.startswith("parallel")) or "parallel: (no note)"
    return statistics.median(times["auto"]), statistics.median(times["off"]), note


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"))
    ap.add_argument("--repeat", type=int, default=5, help="alternations of auto and off per case (median)")
    ap.add_argument("--native-stop", type=float, default=10.0, help="simulated time with native FMUs, s")
    ap.add_argument("--python-stop", type=float, default=3.0, help="simulated time with python FMUs, s")
    record.add_options(ap)
    args = ap.parse_args()
    return record.measured(args, "parallel_auto", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    sys.path.insert(0, str(ROOT))
    print(f"{Path(args.scenario).name}, no log; {os.cpu_count()} CPUs; {args.repeat} alternations each (median)")
    print(f"{'build':8}{'spinner':>9}{'auto, s':>10}{'off, s':>10}{'auto/off':>10}   auto chose")
    worst, worst_worker = 0.0, None
    for load in ("no", "yes"):
        spinner = None
        if load == "yes":
            spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            time.sleep(0.5)
        try:
            for build, stop in (("native", args.native_stop), ("python", args.python_stop)):
                before = os.getloadavg()[0]
                auto, off, note = _case(args.scenario, build, stop, args.repeat)
                worst = max(worst, auto / off)
                if "run ahead" in note:  # auto took a worker: the ratio is auto's own cost or gain
                    worst_worker = max(worst_worker or 0.0, auto / off)
                print(f"{build:8}{load:>9}{auto:10.3f}{off:10.3f}{auto / off:10.3f}   {note} "
                      f"(load average {before:.2f})")
                rec.put(build + ("_spinner" if load == "yes" else ""),
                        {"auto_s": auto, "off_s": off, "ratio": auto / off, "chose": note, "load_before": before})
        finally:
            if spinner is not None:
                spinner.kill()
                spinner.wait()
    took = f"{worst_worker:.3f}" if worst_worker is not None else "none (auto ran every case serially)"
    print(f"largest auto/off {worst:.3f}; where auto took a worker: {took} (target at most 1.03; where auto ran "
          f"serially, auto and off ran the same code and their ratio is the machine's noise)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
