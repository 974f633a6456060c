"""Sweep speed-up (issues 17 and 36): N cases (default 8) on 2 worker processes against the same cases serially.

The cases are a CTC gain grid on ``scenarios/helix_ctc_analytic.yaml``, each the scenario's
whole run (the thesis helix, 10 s simulated; ``--stop`` for another length), no logs. Three ways, each timed
from its start to its last result, alternated ``--repeat N`` times (median; the machine's other load moves single
figures by 10-50 %), all giving the same metrics (checked here, digit for digit):

- the serial loop: :func:`cosim.analysis.sweep.run_loaded_case` runs the cases one after another in this process
  (the file read once and the FMUs built beforehand, as the sweep does; each case extracts its FMUs, as every run);
- the serial loop prepared as the sweep prepares the process its workers fork from (the FMUs also extracted
  and our native FMUs' libraries loaded once beforehand, :func:`cosim.analysis.sweep.extract_for_cases`):
  against it, the sweep's ratio is what the second worker alone gives;
- the sweep: :func:`cosim.analysis.sweep.run_sweep` on its embedded cluster of 2 worker processes (its
  preparation, the workers' fork and shutdown included).

``--warm`` also times the same sweep on a Dask cluster that is already running (a ``LocalCluster`` of worker
processes preloading :mod:`cosim.analysis.sweep`, warmed by one untimed sweep, reached with ``scheduler=``): what
``cosim sweep --scheduler`` costs.

    python benchmarks/sweep.py [--stop S] [--repeat N] [--warm] [--cases N] [--set fmus=native]
                               [--scenario scenarios/helix_ctc_analytic.yaml]

Over the prepared loop the speed-up is bounded by 2 on 2 cores, and by less: the sweep pays once per sweep what
serial runs do not (forking its 2 workers, handing each case over and its row back), and the sweep's process,
which validates the cases and writes the table, shares the cores with the workers. Other processes on the machine
take cores from the sweep (which needs both) rather than from the serial loop (one).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

import record

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
    record.add_options(ap)
    args = ap.parse_args()
    return record.measured(args, "sweep", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    sys.path.insert(0, str(ROOT))
    from cosim.engine.overrides import dotted_overrides
    from cosim.engine.scenario import load_scenario, read_scenario
    from cosim.analysis.sweep import (Case, drop_preloaded, extract_for_cases, prebuild, read_results, run_loaded_case,
                                      run_sweep)
    from cosim.fmi import Extractions

    import statistics

    scenario = str(Path(args.scenario).resolve())
    stop = args.stop if args.stop is not None else load_scenario(scenario).time.stop
    common = dict(item.split("=", 1) for item in args.set)
    cases = [Case({**common, "time.stop": stop, "ctl.gain.kp[1]": 1.0e4 + 2.5e3 * k}) for k in range(args.cases)]
    fmu_files = prebuild([load_scenario(scenario, dotted_overrides(cases[0].values))])
    print(f"{len(cases)} cases of {Path(scenario).name}{' with ' + str(common) if common else ''}, {stop:g} s "
          f"simulated each (the case length); "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} before")
    t_serial, t_prepared, t_sweep, t_warm, loops_serial, loops_worker = [], [], [], [], [], []
    warm = None
    if args.warm:  # a Dask cluster as `dask scheduler` / `dask worker --preload cosim.analysis.sweep` make one
        import dask
        from distributed import LocalCluster

        from cosim.analysis.cluster import PRELOAD, WORKER_CONFIG

        with dask.config.set(WORKER_CONFIG):
            warm = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                silence_logs=logging.ERROR, preload=[PRELOAD])
        address = warm.scheduler_address
        with tempfile.TemporaryDirectory() as tmp:  # warm-up: each worker imports and runs a case once
            run_sweep(scenario, [Case({**c.values, "time.stop": 0.01}) for c in cases], tmp, scheduler=address)

    def check(rows, serial):  # noqa: ANN001, ANN202
        for c, r in zip(cases, serial):
            for k in ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "max_error_y", "max_error_z", "peak_effort"):
                assert float(rows[c.id][k]) == r[k], (c.values, k, rows[c.id][k], r[k])

    def serial_loop(prepared: bool) -> tuple[float, list[dict]]:
        t0 = time.perf_counter()
        source = read_scenario(scenario)  # as run_sweep: the file read once, each case validated from it
        loaded = [source.load(dotted_overrides(c.values, "sweep case")) for c in cases]
        held = Extractions()
        if prepared:
            extract_for_cases(held, loaded[0], fmu_files)  # as run_sweep before its workers fork
        rows = [run_loaded_case(sc, fmu_files) for sc in loaded]
        held.release()
        drop_preloaded()
        assert all(r["status"] == "ok" for r in rows), [r["message"] for r in rows]
        return time.perf_counter() - t0, rows

    for i in range(args.repeat):
        elapsed, serial = serial_loop(False)
        t_serial.append(elapsed)
        elapsed, prepared = serial_loop(True)
        t_prepared.append(elapsed)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            summary = run_sweep(scenario, cases, tmp, workers=args.workers)
            t_sweep.append(time.perf_counter() - t0)
            rows = {r["case"]: r for r in read_results(tmp)}
        assert summary.ok, summary.text()
        check(rows, serial)
        check(rows, prepared)
        if warm is not None:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                done = run_sweep(scenario, cases, tmp, scheduler=address)
                assert done.ok, done.text()
                t_warm.append(time.perf_counter() - t0)
                check({r["case"]: r for r in read_results(tmp)}, serial)
        loops_serial.append(sum(r["wall_time_s"] for r in serial) / len(serial))
        loops_worker.append(sum(float(r["wall_time_s"]) for r in rows.values()) / len(rows))
        if args.repeat > 1:
            warm_text = f", Dask cluster {t_warm[-1]:.2f} s ({t_serial[-1] / t_warm[-1]:.2f}x)" if t_warm else ""
            print(f"  run {i + 1}: serial {t_serial[-1]:.2f} s, serial prepared {t_prepared[-1]:.2f} s, sweep "
                  f"{t_sweep[-1]:.2f} s, {t_serial[-1] / t_sweep[-1]:.2f}x / {t_prepared[-1] / t_sweep[-1]:.2f}x"
                  f"{warm_text} (load average {os.getloadavg()[0]:.2f})")
    if warm is not None:
        warm.close()
    ts, tq, tp = statistics.median(t_serial), statistics.median(t_prepared), statistics.median(t_sweep)
    what = "median of " + str(args.repeat) if args.repeat > 1 else "one run each"
    print(f"{'':24}{'serial loop':>16}{'serial, prepared':>18}{f'sweep ({args.workers} workers)':>18}   ({what}, "
          f"{stop:g} s cases)")
    print(f"{'wall time, s':24}{ts:16.2f}{tq:18.2f}{tp:18.2f}")
    print(f"{'per case, s':24}{ts / len(cases):16.3f}{tq / len(cases):18.3f}{tp / len(cases):18.3f}")
    print(f"{'one case stepping, s':24}{statistics.median(loops_serial):16.3f}{'':18}"
          f"{statistics.median(loops_worker):18.3f}")
    print(f"speed-up {ts / tp:.2f}x over the serial loop (targets on 2 cores: 32 cases of 0.1 s 1.5x, 100 cases 1.7x); "
          f"{tq / tp:.2f}x over the serial loop prepared as the workers are (the second worker's gain); {stop:g} s "
          f"simulated per case; metrics identical; load average {os.getloadavg()[0]:.2f} after")
    rec.put("cases", len(cases))
    rec.put("case_stop_s", stop)
    rec.put("serial_s", t_serial)  # every run, in order (the first extracts the FMUs: the slowest)
    rec.put("prepared_s", t_prepared)
    rec.put("sweep_s", t_sweep)
    rec.put("serial_median_s", ts)
    rec.put("prepared_median_s", tq)
    rec.put("sweep_median_s", tp)
    rec.put("speedup_median", ts / tp)
    rec.put("speedup_prepared_median", tq / tp)
    rec.put("speedup_runs", [a / b for a, b in zip(t_serial, t_sweep)])
    rec.put("speedup_prepared_runs", [a / b for a, b in zip(t_prepared, t_sweep)])
    rec.put("stepping_serial_s", statistics.median(loops_serial))
    rec.put("stepping_worker_s", statistics.median(loops_worker))
    if t_warm:
        rec.put("dask_warm_s", t_warm)
        tw = statistics.median(t_warm)
        print(f"on a running, warmed-up Dask cluster of {args.workers} workers (scheduler=, no start-up): "
              f"{tw:.2f} s, speed-up {ts / tw:.2f}x; metrics identical")
    if args.repeat > 1:  # the least disturbed run of each side (other processes only ever slow a run down)
        warm_text = f", Dask cluster {min(t_warm):.2f} s, {min(t_serial) / min(t_warm):.2f}x" if t_warm else ""
        print(f"best of {args.repeat}: serial {min(t_serial):.2f} s, prepared {min(t_prepared):.2f} s, sweep "
              f"{min(t_sweep):.2f} s, {min(t_serial) / min(t_sweep):.2f}x / {min(t_prepared) / min(t_sweep):.2f}x"
              f"{warm_text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
