"""Warm sweep against cold (issue 34): N cases (default 8) over plant.mass.payload started from a checkpoint at T
against the same cases from t = 0.

The scenario is ``scenarios/helix_ctc_analytic.yaml`` (the thesis helix, 10 s, native FMUs). The checkpoint is
written once by a run to T (default 5 s, ``run --checkpoint-at T``, no log; its wall time is printed as the one-time
cost). The cold sweep is :func:`cosim.analysis.sweep.run_sweep` with each case's payload set before t = 0, run to the
stop time; the warm sweep is the same call with ``checkpoint=`` (``sweep --from-checkpoint``): each case restores the
checkpoint's state in its worker, sets its payload at T and runs from T to the stop time. Both on the embedded
pool of the same ``--workers`` worker processes, each timed from the call until
:func:`run_sweep` returns (cluster start-up and shutdown included), alternated ``--repeat`` times in one run (median
reported, the best too), so the machine's load drifts affect both alike. "One case stepping" is the mean of the
cases' own ``wall_time_s`` (the run's stepping loop in its worker); "one case whole" is one case (payload 0.1 kg) run
by :func:`cosim.analysis.sweep.run_loaded_case` in this process between the sweeps, timed from the call to its
return (the supervised child's fork, FMU extraction and instantiation, the checkpoint's read and restore, the run);
the rest of a sweep's wall time is the workers' start, the cases' hand-over and the shutdown.

    python benchmarks/warm_sweep.py [--at 5] [--stop 10] [--cases 8] [--workers 2] [--repeat 1]

Expected: the cases' stepping halves (half the simulated time); the sweep's fixed costs (forking the workers,
each case's FMU instantiation, the checkpoint's restore) do not, so the whole sweep gains a little less.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[2:]))
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"))
    ap.add_argument("--at", type=float, default=5.0, help="the checkpoint's time T, s (default 5)")
    ap.add_argument("--stop", type=float, default=None,
                    help="the cases' end, s (default: the scenario's own, 10 s for the helix)")
    ap.add_argument("--cases", type=int, default=8, help="payloads 0, 0.05, ... kg (default 8 cases)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes of both sweeps (default 2)")
    ap.add_argument("--repeat", type=int, default=1, help="alternate cold and warm N times (median)")
    record.add_options(ap)
    args = ap.parse_args()
    return record.measured(args, "warm_sweep", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    sys.path.insert(0, str(ROOT))
    from cosim.analysis.sweep import Case, WarmStart, prebuild, read_results, run_loaded_case, run_sweep
    from cosim.engine.scenario import load_scenario
    from cosim.io.checkpoint import read_checkpoint
    from cosim.run import RunOptions, resumed_scenario, run_scenario

    scenario = str(Path(args.scenario).resolve())
    stop = args.stop if args.stop is not None else load_scenario(scenario).time.stop
    payloads = [round(0.05 * k, 6) for k in range(args.cases)]
    cold = [Case({"time.stop": stop, "plant.mass.payload": p}) for p in payloads]
    warm = [Case({"plant.mass.payload": p}) for p in payloads]
    print(f"{len(payloads)} cases of {Path(scenario).name}, plant.mass.payload = {payloads[0]:g} ... "
          f"{payloads[-1]:g} kg; cold: 0 -> {stop:g} s, warm: {args.at:g} -> {stop:g} s from a checkpoint at "
          f"{args.at:g} s; {args.workers} worker processes each; {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.2f} before")

    def check(rows, length):  # noqa: ANN001, ANN202 - every case ran its whole length (a payload may miss 1 um)
        for r in rows:
            assert r["status"] == "ok" or r["message"].startswith("acceptance check failed"), (r["case"], r["message"])
            assert abs(float(r["sim_time_s"]) - length) < 1e-9, (r["case"], r["sim_time_s"], length)

    with tempfile.TemporaryDirectory() as tmp:
        ckpt = Path(tmp) / "at.ckpt"
        t0 = time.perf_counter()
        run_scenario(load_scenario(scenario, {("time", "stop"): args.at}),
                     RunOptions(log=False, checkpoint_at=args.at, checkpoint_out=ckpt))
        t_checkpoint = time.perf_counter() - t0
        fmu_files = prebuild([load_scenario(scenario)])
        one_cold = load_scenario(scenario, {("time", "stop"): stop,
                                            ("components", "plant", "parameters", "mass.payload"): 0.1})
        one_warm = resumed_scenario(read_checkpoint(ckpt), stop, load_scenario(scenario))
        start = WarmStart(str(ckpt), args.at, "", stop)  # a checkpoint of a run without a log: read_all False

        def one_case(kind: str) -> float:
            t0 = time.perf_counter()
            row = (run_loaded_case(one_cold, fmu_files) if kind == "cold" else
                   run_loaded_case(one_warm, fmu_files, None, start, {"plant.mass.payload": 0.1}))
            assert row["status"] == "ok" or row["message"].startswith("acceptance check failed"), row["message"]
            return time.perf_counter() - t0

        t_cold, t_warm, case_cold, case_warm, whole_cold, whole_warm = [], [], [], [], [], []
        for i in range(args.repeat):
            for kind in (("cold", "warm") if i % 2 == 0 else ("warm", "cold")):
                with tempfile.TemporaryDirectory() as out:
                    t0 = time.perf_counter()
                    if kind == "cold":
                        run_sweep(scenario, cold, out, workers=args.workers)
                    else:
                        run_sweep(scenario, warm, out, workers=args.workers, checkpoint=ckpt, stop_time=stop)
                    elapsed = time.perf_counter() - t0
                    rows = read_results(out)
                assert len(rows) == len(payloads), (len(rows), len(payloads))
                check(rows, stop if kind == "cold" else stop - args.at)
                loop = sum(float(r["wall_time_s"]) for r in rows) / len(rows)
                (t_cold if kind == "cold" else t_warm).append(elapsed)
                (case_cold if kind == "cold" else case_warm).append(loop)
                (whole_cold if kind == "cold" else whole_warm).append(one_case(kind))
            if args.repeat > 1:
                print(f"  run {i + 1}: cold {t_cold[-1]:.2f} s, warm {t_warm[-1]:.2f} s, "
                      f"{t_cold[-1] / t_warm[-1]:.2f}x (load average {os.getloadavg()[0]:.2f})")
    tc, tw = statistics.median(t_cold), statistics.median(t_warm)
    cc, cw = statistics.median(case_cold), statistics.median(case_warm)
    what = f"median of {args.repeat}" if args.repeat > 1 else "one run each"
    print(f"{'':28}{f'cold (0-{stop:g} s)':>18}{f'warm ({args.at:g}-{stop:g} s)':>18}   ({what})")
    print(f"{'sweep wall time, s':28}{tc:18.2f}{tw:18.2f}")
    print(f"{'one case stepping, s':28}{cc:18.3f}{cw:18.3f}")
    print(f"{'one case whole, s':28}{statistics.median(whole_cold):18.3f}{statistics.median(whole_warm):18.3f}")
    print(f"warm sweep {tc / tw:.2f}x faster than cold (cases' stepping {cc / cw:.2f}x); writing the checkpoint "
          f"(a run to {args.at:g} s, once) took {t_checkpoint:.2f} s; load average {os.getloadavg()[0]:.2f} after")
    rec.put("cold_s", t_cold)
    rec.put("warm_s", t_warm)
    rec.put("cold_median_s", tc)
    rec.put("warm_median_s", tw)
    rec.put("speedup_median", tc / tw)
    rec.put("stepping_speedup_median", cc / cw)
    rec.put("checkpoint_run_s", t_checkpoint)
    if args.repeat > 1:
        print(f"best of {args.repeat}: cold {min(t_cold):.2f} s, warm {min(t_warm):.2f} s, "
              f"{min(t_cold) / min(t_warm):.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
