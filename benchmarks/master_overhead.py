"""Master overhead per macro step with trivial FMUs, with and without MCAP logging.

The FMUs' own cost (pythonfmu runs Python in every set, step and get) would drown the
master's, so it is measured separately: the same C functions (SetReal, DoStep, GetReal),
bound the way the master binds them, are called on the same FMUs in a bare loop, and that
time is subtracted from the master's time per step.

    python benchmarks/master_overhead.py [--steps N]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from ctypes import c_double, c_uint32
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

SCENARIO = """
name: overhead
components:
  src: {{path: "{src}"}}
  g1: {{path: "{gain}"}}
  g2: {{path: "{gain}"}}
  plant: {{path: "{integ}"}}
connections:
  - {{from: src.y, to: g1.u}}
  - {{from: g1.y, to: g2.u}}
  - {{from: g2.y, to: plant.u}}
time: {{stop: {stop}, step: 0.001}}
parallel: "off"  # the master's own serial loop (an open chain is never offloaded anyway)
logging: {{signals: all, flush_interval: 1.0}}
"""


def bare_fmi_cost(fmus: dict, steps: int) -> float:
    """Seconds per step for the FMI calls alone (same FMUs, same calls, no master): the connected
    outputs are read, as the master reads them without a log (plant.x only with one)."""
    from cosim.fmi import load_fmu, make_slave

    specs = [("src", fmus["CosimTSource"], [], ["y"]), ("g1", fmus["CosimTGain"], ["u"], ["y"]),
             ("g2", fmus["CosimTGain"], ["u"], ["y"]), ("plant", fmus["CosimTIntegrator"], ["u"], [])]
    calls, slaves = [], []
    for name, path, ins, outs in specs:
        s = make_slave(name, load_fmu(path))
        slaves.append(s)
        s.bind([], [])
        s.instantiate()
        s.enter_initialization(0.0, 1e9)
        s.exit_initialization()
        info = s.info.variables
        vin = (c_uint32 * len(ins))(*[info[n].vr for n in ins])
        vout = (c_uint32 * len(outs))(*[info[n].vr for n in outs])
        bin_, bout = (c_double * max(1, len(ins)))(), (c_double * max(1, len(outs)))()
        dll = s.fmu.dll  # the C functions bound as the master binds them (cosim.fmi.slave.Base)
        setr = s._bound_call(dll, "fmi2SetReal", s._c, vin, len(ins), bin_) if ins else None
        getr = s._bound_call(dll, "fmi2GetReal", s._c, vout, len(outs), bout) if outs else None
        calls.append((s._c, setr, s._hot_function(dll, "fmi2DoStep"), getr))
    h = 0.001
    t0 = time.perf_counter()
    for k in range(steps):
        t = k * h
        for c, setr, dostep, getr in calls:
            if setr is not None:
                setr()
            dostep(c, t, h, 1)
            if getr is not None:
                getr()
    per_step = (time.perf_counter() - t0) / steps
    for s in slaves:
        s.terminate()
        s.free()
    return per_step


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20000, help="macro steps of each run (default 20000)")
    args = ap.parse_args()
    from fmu_helpers import build_test_fmus

    from cosim.run import run_scenario
    from cosim.engine.scenario import parse_scenario

    tmp = Path(tempfile.mkdtemp(prefix="cosim_bench_"))
    fmus = build_test_fmus(tmp / "fmus")
    text = SCENARIO.format(src=fmus["CosimTSource"], gain=fmus["CosimTGain"], integ=fmus["CosimTIntegrator"],
                           stop=args.steps * 0.001)
    scenario = parse_scenario(text, str(tmp / "overhead.yaml"))
    # interleave the bare and master runs so machine load drifts affect both alike; keep the best of 5
    bare = float("inf")
    best = {False: float("inf"), True: float("inf")}
    for _ in range(5):
        bare = min(bare, bare_fmi_cost(fmus, args.steps))
        for log in (False, True):
            res = run_scenario(scenario, out=tmp / "bench.mcap", log=log)
            best[log] = min(best[log], res.wall_time / res.steps)
    rows = [("no logging", best[False]), ("all signals logged", best[True])]
    print(f"4 trivial pythonfmu FMUs (source -> gain -> gain -> integrator), {args.steps} steps, best of 5")
    print(f"  bare FMI calls (bound as the master binds them):{bare * 1e6:8.2f} us/step")
    for label, per_step in rows:
        print(f"  master, {label:<20}: {per_step * 1e6:8.2f} us/step  -> overhead {(per_step - bare) * 1e6:7.2f} us/step")


if __name__ == "__main__":
    main()
