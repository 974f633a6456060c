"""Sweep speed-up (issue 17): 8 cases on 2 Dask worker processes against the same 8 cases serially.

The 8 cases are a CTC gain grid on ``scenarios/helix_ctc_analytic.yaml`` (``--stop`` s simulated
each, no logs). Serially, :func:`cosim.sweep.run_case` runs them one after another in this process
(the FMUs built beforehand, as the sweep does); the sweep is :func:`cosim.sweep.run_sweep` on an
embedded ``LocalCluster(n_workers=2, threads_per_worker=1, processes=True)``, timed from the call
to the last row written, cluster start-up and shutdown included. Both produce the same metrics
(checked here, digit for digit).

    python benchmarks/sweep.py [--stop 2.0] [--scenario scenarios/helix_ctc_analytic.yaml]

The speed-up is bounded by 2 on 2 cores; the cluster start-up (about 1-2 s) is paid once, so it
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
    ap.add_argument("--stop", type=float, default=2.0, help="simulated time per case, s (default 2)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from cosim.scenario import dotted_overrides, load_scenario
    from cosim.sweep import Case, _prebuild, run_case, run_sweep

    scenario = str(Path(args.scenario).resolve())
    cases = [Case({"time.stop": args.stop, "ctl.gain.kp[1]": 1.0e4 + 2.5e3 * k}) for k in range(8)]
    fmu_files = _prebuild([load_scenario(scenario, dotted_overrides(cases[0].values))])
    print(f"{len(cases)} cases of {Path(scenario).name}, {args.stop:g} s simulated each; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} before")

    t0 = time.perf_counter()
    serial = [run_case(scenario, c.values, fmu_files) for c in cases]
    t_serial = time.perf_counter() - t0
    assert all(r["status"] == "ok" for r in serial), [r["message"] for r in serial]

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        summary = run_sweep(scenario, cases, tmp, workers=args.workers)
        t_sweep = time.perf_counter() - t0
        from cosim.sweep import read_results

        rows = {r["case"]: r for r in read_results(tmp)}
    assert summary.ok, summary.text()
    for c, r in zip(cases, serial):
        for k in ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "max_error_y", "max_error_z", "peak_effort"):
            assert float(rows[c.id][k]) == r[k], (c.values, k, rows[c.id][k], r[k])
    per_case = sum(r["wall_time_s"] for r in serial) / len(serial)
    in_workers = sum(float(r["wall_time_s"]) for r in rows.values()) / len(rows)
    print(f"{'':24}{'serial (1 process)':>20}{f'Dask ({args.workers} workers)':>20}")
    print(f"{'wall time, s':24}{t_serial:20.2f}{t_sweep:20.2f}")
    print(f"{'per case, s':24}{t_serial / len(cases):20.3f}{t_sweep / len(cases):20.3f}")
    print(f"speed-up {t_serial / t_sweep:.2f}x (target >= 1.7x on 2 cores); one case's loop {per_case:.2f} s; "
          f"in a worker {in_workers:.2f} s; metrics identical; load average {os.getloadavg()[0]:.2f} after")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
