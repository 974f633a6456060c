"""Native C FMUs against the python build and the monolithic loop, side by side in one run (issue 23).

Printed, each with its target:

1. helix_ctc_analytic on native FMUs against helix_ctc (python FMUs, full Exudyn plant): 10 s of helix,
   no log, the scenarios' own ``parallel`` setting; ratio of the stepping loops' wall times (target >= 10x).
2. Each native FMU's time per 1 ms step in our master (``component_time_s`` / steps, serial run of
   helix_ctc_analytic; target <= 2 us) and the master's own time per step (the loop minus the components).
3. Model exchange: one derivative evaluation of the native ME plant through our master's ME wrapper
   (set time, set states, get derivatives: ``rhs``, what the integrator calls per right-hand side, one C
   call where ``cosim.fmi.turn``'s helper is built; target <= 2 us), beside the same three calls made from
   Python one by one (``set_time``, ``set_x``, ``get_dx``: what a machine without a C compiler gets), and
   helix_ctc_me on native FMUs against the native co-simulation run, with the split of its time (the
   plant component holds the integrator and the FMU calls it makes).
4. helix_ctc with native trajectory, IK and CTC and the Exudyn plant, serial, against the monolithic
   loop of ``benchmarks/helix_ctc.py`` (the same computation in one Python loop; target <= 1.10x).
5. helix_ctc_analytic on native FMUs with every signal logged to MCAP against the same run unlogged
   (target <= 2x), in both log layouts (``logging.layout``: ``samples``, one message per sample, the
   default; ``blocks``, one per block of samples); and the whole runs (start-up, FMU loading and the
   completion of the log included), as the log's writer process finishes the file after the loop.

Each measurement is the stepping loop's wall time (``RunResult.wall_time``: no build, instantiation or
worker start), the best of ``--rounds`` alternated rounds so drifts of the machine's load affect all alike.

    python benchmarks/native.py [--stop-time 10] [--rounds 3]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def run(name: str, stop: float, *, fmus: str, parallel: str | None = None, log: bool = False,
        out: Path | None = None, layout: str | None = None):
    from cosim.run import run_scenario
    from cosim.engine.scenario import load_scenario

    overrides = {("time", "stop"): stop, ("fmus",): fmus}
    if parallel is not None:
        overrides[("parallel",)] = parallel
    if layout is not None:
        overrides[("logging", "layout")] = layout
    res = run_scenario(load_scenario(ROOT / "scenarios" / f"{name}.yaml", overrides), out=out, log=log)
    if res.status != "completed":
        sys.exit(f"{name} ({fmus}) did not complete: {res.status} {res.message}")
    return res


def derivative_call_us(n: int = 20000) -> tuple[float, float]:
    """Microseconds of one derivative evaluation of the native ME plant through cosim.fmi's ME wrapper: its
    ``rhs`` (what the integrators call), and set_time + set_x + get_dx."""
    import ctypes

    from cosim.fmi import load_fmu, make_slave
    from fmus import registry

    slave = make_slave("plant", load_fmu(registry.build("linear_analytic_plant_me", native=True, fmi=2)), "me")
    slave.instantiate()
    slave.enter_initialization(0.0, 1.0)
    slave.exit_initialization()
    nx = slave.nx
    x, dx = (ctypes.c_double * nx)(), (ctypes.c_double * nx)()
    slave.get_x(x)
    best_rhs = best_three = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(n):
            slave.rhs(k * 1e-6, x, dx)
        best_rhs = min(best_rhs, (time.perf_counter() - t0) / n)
        t0 = time.perf_counter()
        for k in range(n):
            slave.set_time(k * 1e-6)
            slave.set_x(x)
            slave.get_dx(dx)
        best_three = min(best_three, (time.perf_counter() - t0) / n)
    slave.terminate()
    slave.free()
    return best_rhs * 1e6, best_three * 1e6


def count_derivative_calls(stop: float) -> int:
    """Derivative evaluations of helix_ctc_me on native FMUs (a separate, untimed run with a counter)."""
    from cosim.fmi import model_exchange as fmu

    calls = 0
    original = fmu.ModelExchange.rhs

    def counted(self, t, x, dx):  # noqa: ANN001, ANN202
        nonlocal calls
        calls += 1
        return original(self, t, x, dx)

    fmu.ModelExchange.rhs = counted
    try:
        run("helix_ctc_me", stop, fmus="native", parallel="off")
    finally:
        fmu.ModelExchange.rhs = original
    return calls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds of each run (default 10)")
    ap.add_argument("--rounds", type=int, default=3, help="alternated rounds, best kept (default 3)")
    args = ap.parse_args()
    from benchmarks.helix_ctc import monolithic

    stop = args.stop_time
    tmp = Path(tempfile.mkdtemp(prefix="native_bench_"))
    for fmus in ("python", "native"):  # build and cache every FMU outside the measurement
        for name in ("helix_ctc_analytic", "helix_ctc", "helix_ctc_me"):
            run(name, 0.01, fmus=fmus)
    keys = {
        "full_python": ("helix_ctc", "python", None, None),
        "analytic_native": ("helix_ctc_analytic", "native", None, None),
        "analytic_native_serial": ("helix_ctc_analytic", "native", "off", None),
        "analytic_native_samples": ("helix_ctc_analytic", "native", None, "samples"),
        "analytic_native_blocks": ("helix_ctc_analytic", "native", None, "blocks"),
        "me_native": ("helix_ctc_me", "native", "off", None),
        "full_native_serial": ("helix_ctc", "native", "off", None),
    }
    best = {k: math.inf for k in (*keys, "mono")}
    whole = {k: math.inf for k in keys}  # the whole run_scenario call: start-up and the log's completion too
    result = {}
    for _ in range(args.rounds):
        for key, (name, fmus, parallel, layout) in keys.items():  # layout None: no log
            t0 = time.perf_counter()
            res = run(name, stop, fmus=fmus, parallel=parallel, log=layout is not None, out=tmp / f"{key}.mcap",
                      layout=layout)
            whole[key] = min(whole[key], time.perf_counter() - t0)
            if res.wall_time < best[key]:
                best[key], result[key] = res.wall_time, res
        wall, _, _ = monolithic(stop)
        best["mono"] = min(best["mono"], wall)
    steps = round(stop / 1e-3)
    print(f"native FMUs (issue 23), {stop:g} s simulated at 1 ms, best of {args.rounds} alternated rounds; "
          f"stepping-loop wall times")
    ratio = best["full_python"] / best["analytic_native"]
    print(f"1. helix_ctc (python FMUs, Exudyn plant) {best['full_python']:.3f} s; helix_ctc_analytic native "
          f"{best['analytic_native']:.3f} s: {ratio:.1f}x faster (target >= 10x)")
    serial = result["analytic_native_serial"]
    per = {k: v / steps * 1e6 for k, v in serial.component_time.items()}
    master = (serial.wall_time - sum(serial.component_time.values())) / steps * 1e6
    print("2. helix_ctc_analytic native, serial, us per step: "
          + ", ".join(f"{k} {v:.2f}" for k, v in per.items())
          + f" (target <= 2 each); master's own {master:.2f}; whole step {serial.wall_time / steps * 1e6:.2f}")
    d_us, three_us = derivative_call_us()
    me = result["me_native"]
    me_plant = me.component_time.get("plant", 0.0)
    n_rhs = count_derivative_calls(stop)
    fmu_calls = n_rhs * d_us * 1e-6
    print(f"3. one derivative evaluation of the native ME plant through the master (set time, states, get "
          f"derivatives): {d_us:.2f} us (target <= 2); the three calls from Python {three_us:.2f} us")
    print(f"   helix_ctc_me native {best['me_native']:.3f} s vs helix_ctc_analytic native serial "
          f"{best['analytic_native_serial']:.3f} s: {best['me_native'] / best['analytic_native_serial']:.2f}x; "
          f"its plant component {me_plant:.3f} s: {n_rhs} derivative evaluations x {d_us:.2f} us = "
          f"{fmu_calls:.3f} s in FMU calls, the other {me_plant - fmu_calls:.3f} s in the integrator")
    ratio_mono = best["full_native_serial"] / best["mono"]
    print(f"4. helix_ctc, native traj/IK/CTC + Exudyn plant, serial {best['full_native_serial']:.3f} s vs the "
          f"monolithic loop {best['mono']:.3f} s: {ratio_mono:.3f}x (target <= 1.10)")
    print(f"5. helix_ctc_analytic native, every signal logged vs unlogged (target <= 2x): loop "
          f"{best['analytic_native']:.3f} s, whole run {whole['analytic_native']:.3f} s unlogged")
    for layout in ("samples", "blocks"):
        key = f"analytic_native_{layout}"
        print(f"   {layout:<8} loop {best[key]:.3f} s: {best[key] / best['analytic_native']:.2f}x; whole run "
              f"(start-up, FMU loading, the log's completion) {whole[key]:.3f} s: "
              f"{whole[key] / whole['analytic_native']:.2f}x, +{whole[key] - whole['analytic_native']:.3f} s")


if __name__ == "__main__":
    main()
