"""Sweep speed-up (issue 17): N cases (default 8) on 2 Dask worker processes against the same cases serially.

The cases are a CTC gain grid on ``scenarios/helix_ctc_analytic.yaml``, each the scenario's
whole run (the thesis helix, 10 s simulated; ``--stop`` for another length), no logs. Serially,
:func:`cosim.analysis.sweep.run_loaded_case` runs them one after another in this process (the file read once
and the FMUs built beforehand, as the sweep does); the sweep is :func:`cosim.analysis.sweep.run_sweep` on an
embedded ``LocalCluster`` of 2 single-threaded worker processes, timed from the call until
:func:`cosim.analysis.sweep.run_sweep` returns (cluster start-up and shutdown included). Both produce the
same metrics (checked here, digit for digit). ``--repeat N`` alternates the two N times and
reports the median (the machine's other load moves single figures by 10-50 %).

``--warm`` also times the same sweep on a cluster that is already running (started as the sweep starts
its own, warmed by one untimed sweep, reached with ``scheduler=``): what each sweep costs once a
persistent cluster serves many (``cosim sweep --scheduler``), without the start-up a cold sweep pays.

    python benchmarks/sweep.py [--stop S] [--repeat N] [--warm] [--cases N] [--set fmus=native]
                               [--scenario scenarios/helix_ctc_analytic.yaml]

The speed-up is bounded by 2 on 2 cores, and by less: the sweep pays once per sweep what serial
runs do not (starting 2 worker processes that each import Dask, about 0.7 s of CPU each, and
each worker's first case importing the FMUs' code, once per worker instead of once), so it
weighs less as the cases grow longer. Other processes on the machine take cores from both sides.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"))
    ap.add_argument("--stop", type=float, default=None,
                    help="simulated time per case, s (default: the scenario's own, 10 s for the helix)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cases", type=int, default=8, help="number of cases of the gain grid (default 8)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a dotted override for every case, e.g. fmus=native (repeatable)")
    ap.add_argument("--repeat", type=int, default=1, help="alternate serial and sweep N times (median)")
    ap.add_argument("--warm", action="store_true",
                    help="also time the sweep on an already running, warmed-up cluster of the same workers")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from cosim.engine.overrides import dotted_overrides
    from cosim.engine.scenario import load_scenario, read_scenario
    from cosim.analysis.sweep import Case, SweepCluster, prebuild, read_results, run_loaded_case, run_sweep

    import statistics

    scenario = str(Path(args.scenario).resolve())
    stop = args.stop if args.stop is not None else load_scenario(scenario).time.stop
    common = dict(item.split("=", 1) for item in args.set)
    cases = [Case({**common, "time.stop": stop, "ctl.gain.kp[1]": 1.0e4 + 2.5e3 * k}) for k in range(args.cases)]
    fmu_files = prebuild([load_scenario(scenario, dotted_overrides(cases[0].values))])
    print(f"{len(cases)} cases of {Path(scenario).name}{' with ' + str(common) if common else ''}, {stop:g} s "
          f"simulated each (the case length); "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} before")
    t_serial, t_sweep, t_warm, loops_serial, loops_worker = [], [], [], [], []
    warm = None
    if args.warm:
        warm = SweepCluster(args.workers, None).start()
        warm.__enter__()
        address = warm.cluster.scheduler_address
        with tempfile.TemporaryDirectory() as tmp:  # warm-up: each worker imports and runs a case once
            run_sweep(scenario, [Case({**c.values, "time.stop": 0.01}) for c in cases], tmp, scheduler=address)

    def check(rows, serial):  # noqa: ANN001, ANN202
        for c, r in zip(cases, serial):
            for k in ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "max_error_y", "max_error_z", "peak_effort"):
                assert float(rows[c.id][k]) == r[k], (c.values, k, rows[c.id][k], r[k])

    for i in range(args.repeat):
        t0 = time.perf_counter()
        source = read_scenario(scenario)  # as run_sweep: the file read once, each case validated from it
        serial = [run_loaded_case(source.load(dotted_overrides(c.values, "sweep case")), fmu_files) for c in cases]
        t_serial.append(time.perf_counter() - t0)
        assert all(r["status"] == "ok" for r in serial), [r["message"] for r in serial]
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            summary = run_sweep(scenario, cases, tmp, workers=args.workers)
            t_sweep.append(time.perf_counter() - t0)
            rows = {r["case"]: r for r in read_results(tmp)}
        assert summary.ok, summary.text()
        check(rows, serial)
        if warm is not None:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                assert run_sweep(scenario, cases, tmp, scheduler=address).ok
                t_warm.append(time.perf_counter() - t0)
                check({r["case"]: r for r in read_results(tmp)}, serial)
        loops_serial.append(sum(r["wall_time_s"] for r in serial) / len(serial))
        loops_worker.append(sum(float(r["wall_time_s"]) for r in rows.values()) / len(rows))
        if args.repeat > 1:
            warm_text = f", warm cluster {t_warm[-1]:.2f} s ({t_serial[-1] / t_warm[-1]:.2f}x)" if t_warm else ""
            print(f"  run {i + 1}: serial {t_serial[-1]:.2f} s, sweep {t_sweep[-1]:.2f} s, "
                  f"{t_serial[-1] / t_sweep[-1]:.2f}x{warm_text} (load average {os.getloadavg()[0]:.2f})")
    if warm is not None:
        warm.close()
    ts, tp = statistics.median(t_serial), statistics.median(t_sweep)
    what = "median of " + str(args.repeat) if args.repeat > 1 else "one run each"
    print(f"{'':24}{'serial (1 process)':>20}{f'Dask ({args.workers} workers)':>20}   ({what}, {stop:g} s cases)")
    print(f"{'wall time, s':24}{ts:20.2f}{tp:20.2f}")
    print(f"{'per case, s':24}{ts / len(cases):20.3f}{tp / len(cases):20.3f}")
    print(f"{'one case, s':24}{statistics.median(loops_serial):20.3f}{statistics.median(loops_worker):20.3f}")
    print(f"speed-up {ts / tp:.2f}x (target >= 1.7x on 2 cores) with {stop:g} s simulated per case; metrics "
          f"identical; load average {os.getloadavg()[0]:.2f} after")
    if t_warm:
        tw = statistics.median(t_warm)
        print(f"on a running, warmed-up cluster of the same {args.workers} workers (scheduler=, no start-up): "
              f"{tw:.2f} s, speed-up {ts / tw:.2f}x (target >= 1.7x); metrics identical")
    if args.repeat > 1:  # the least disturbed run of each side (other processes only ever slow a run down)
        warm_text = f", warm cluster {min(t_warm):.2f} s, {min(t_serial) / min(t_warm):.2f}x" if t_warm else ""
        print(f"best of {args.repeat}: serial {min(t_serial):.2f} s, sweep {min(t_sweep):.2f} s, "
              f"{min(t_serial) / min(t_sweep):.2f}x{warm_text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
