"""Master overhead per macro step: with trivial FMUs, with and without MCAP logging; on helix_ctc_analytic's native
FMUs, against issue 36's target.

1. Four trivial pythonfmu FMUs. The FMUs' own cost (pythonfmu runs Python in every set, step and get) would drown
   the master's, so it is measured separately: the same C functions (SetReal, DoStep, GetReal), bound the way the
   master binds them, are called on the same FMUs in a bare loop, and that time is subtracted from the master's
   time per step.
2. helix_ctc_analytic on its four native C FMUs (serial, no log; ``--stop-time`` s at 1 ms): the master's own cost
   per step (issue 36 item 7: at most 1 us), everything outside the four components' FMU calls: the loop, the
   link copies, the status and NaN checks, the component timings, the record the watchdog reads, the tracking
   error observer. It is the run's loop wall time per step minus the same FMI calls (each component's set calls,
   fmi2DoStep, its get calls, in the same order, on the same FMUs as initialized by the same run) made by a bare C
   loop (``benchmarks/bare_turns.c``: nothing else, not even a status check), timed alone. The master runs as it
   runs (its loop in C, :mod:`cosim.engine.cloop`) and with its loop in Python (``cosim.engine.cloop.make``
   replaced here), the runs alternating, the best of ``--rounds`` each.

    python benchmarks/master_overhead.py [--steps N] [--stop-time S] [--rounds R] [--only-helix] [--json FILE | --record]
"""

from __future__ import annotations

import argparse
import ctypes
import sys
import tempfile
import time
from ctypes import c_double, c_size_t, c_uint32, c_void_p
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

TARGET_HELIX_US = 1.0  # issue 36 item 7: the master's own cost on helix_ctc_analytic native at most 1 us a step


class _Call(ctypes.Structure):  # bare_turns.c's Call
    _fields_ = [("function", c_void_p), ("instance", c_void_p), ("vrs", c_void_p), ("n", c_size_t),
                ("values", c_void_p)]


class _Component(ctypes.Structure):  # bare_turns.c's Component
    _fields_ = [("instance", c_void_p), ("do_step", c_void_p), ("n_set", c_size_t), ("n_get", c_size_t),
                ("sets", ctypes.POINTER(_Call)), ("gets", ctypes.POINTER(_Call))]

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


def _bare_simulate(bare: ctypes.CDLL, spent: list[float]):
    """A stand-in for :func:`cosim.engine.cloop.simulate`: the run's steps as bare FMI 2 calls (bare_turns.c) on the
    components of the loop in C the run made; the seconds of that call appended to ``spent``."""

    def simulate(ex, loop, k_end, stop, report, every) -> None:
        comps = []
        for u in (loop.s.turns[i].contents for i in range(loop.s.n)):
            if u.fmi != 2:
                sys.exit("the bare loop makes FMI 2 calls: helix_ctc_analytic's native FMUs are no FMI 2 FMUs here")
            sets = [_Call(e.function, u.instance, e.vrs, e.n, e.values) for e in u.sets[:u.n_set]]
            gets = [_Call(e.function, u.instance, e.vrs, e.n, e.values) for e in u.gets[:u.n_get]]
            comps.append(_Component(u.instance, u.do_step, len(sets), len(gets), (_Call * max(1, len(sets)))(*sets),
                                    (_Call * max(1, len(gets)))(*gets)))
        k = ex.k_done
        times, steps = ex.grid.chunk(k, k_end)
        arrays = (_Component * len(comps))(*comps), (c_double * len(times))(*times), (c_double * len(steps))(*steps)
        t0 = time.perf_counter()
        bare.bare_steps(arrays[0], c_size_t(len(comps)), arrays[1], arrays[2], c_size_t(k_end - k))
        spent.append(time.perf_counter() - t0)
        ex.k_done = k_end

    return simulate


def helix(args, rec: record.Recording) -> None:
    """Part 2 (see the module docstring)."""
    from cosim.cbuild import Library
    from cosim.engine import cloop
    from cosim.engine.scenario import load_scenario
    from cosim.run import RunOptions, run_scenario

    overrides = {("time", "stop"): args.stop_time, ("fmus",): "native", ("parallel",): "off"}
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml", overrides)
    bare_lib = Library(Path(__file__).with_name("bare_turns.c")).get()
    if bare_lib is None:
        sys.exit("no C compiler here: the bare loop cannot be built")
    make, simulate = cloop.make, cloop.simulate
    modes = {"loop in C": make, "loop in Python": lambda ex: None}
    best = {m: float("inf") for m in modes}
    bare = float("inf")
    run_scenario(scenario, RunOptions(log=False))  # the FMUs built and cached, the helpers compiled
    for r in range(args.rounds):
        order = list(modes) + ["bare"]
        for mode in order[:: 1 if r % 2 == 0 else -1]:
            spent: list[float] = []
            cloop.make = make if mode == "bare" else modes[mode]
            cloop.simulate = _bare_simulate(bare_lib, spent) if mode == "bare" else simulate
            try:
                res = run_scenario(scenario, RunOptions(log=False))
            finally:
                cloop.make, cloop.simulate = make, simulate
            if mode == "bare":
                if not spent:
                    sys.exit("the run did not take the loop in C: no bare figure (is the C turn unavailable?)")
                bare = min(bare, spent[0] / res.steps)
            else:
                if res.status != "completed":
                    sys.exit(f"helix_ctc_analytic (native) did not complete: {res.status} {res.message}")
                best[mode] = min(best[mode], res.wall_time / res.steps)
    us = 1e6
    print(f"helix_ctc_analytic, 4 native C FMUs, serial, no log, {args.stop_time:g} s at 1 ms, best of {args.rounds}")
    print(f"  bare FMI calls from a C loop:          {bare * us:8.2f} us/step")
    rec.put("helix_bare_us", bare * us)
    for mode, per_step in best.items():
        key = "c" if mode == "loop in C" else "python"
        rec.put(f"helix_loop_{key}_us", per_step * us)
        rec.put(f"helix_own_{key}_us", (per_step - bare) * us)
        own = (per_step - bare) * us
        verdict = "met" if own <= TARGET_HELIX_US else "NOT met"
        print(f"  master, {mode:<15}: {per_step * us:8.2f} us/step  -> master's own {own:6.2f} us/step"
              f"   target <= {TARGET_HELIX_US:g}: {verdict}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20000, help="macro steps of each run of part 1 (default 20000)")
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated s of helix_ctc_analytic (default 10)")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of part 2, the best of each kept (default 5)")
    ap.add_argument("--only-helix", action="store_true", help="part 2 only")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "master_overhead") as rec:
        if not args.only_helix:
            trivial(args, rec)
        helix(args, rec)


def trivial(args, rec: record.Recording) -> None:
    """Part 1 (see the module docstring)."""
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
    rec.put("trivial_bare_us", bare * 1e6)
    rec.put("trivial_master_us", best[False] * 1e6)
    rec.put("trivial_master_logged_us", best[True] * 1e6)
    rec.put("trivial_overhead_us", (best[False] - bare) * 1e6)
    rec.put("trivial_overhead_logged_us", (best[True] - bare) * 1e6)
    for label, per_step in rows:
        below = "  (below the bare loop: the master's loop in C makes these calls from C)" if per_step < bare else ""
        print(f"  master, {label:<20}: {per_step * 1e6:8.2f} us/step  -> overhead {(per_step - bare) * 1e6:7.2f} us/step"
              + below)


if __name__ == "__main__":
    main()
