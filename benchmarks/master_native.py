"""The master's per-step cost on C FMUs, side by side in one run, against issue 23's targets.

1. helix_ctc_analytic on the native C FMUs (``fmus: native``), serial, no log, ``--stop-time`` s at
   1 ms: each component's ``component_time_s`` / steps (target <= 2 us per FMU per step). A
   component's time is what the master spends on it in a step: its links copied in, its inputs set,
   its doStep, its outputs read and checked for NaN; the master reads its clock once before a step's
   first component and once after each component (cosim.engine.algorithm: each algorithm's macro step). The master's own share
   of that run (loop wall time minus the components: step loop, observers) is printed too.
2. The master's own cost on two C FMUs (``tests/cfmus``: FMI 2 VanDerPol, its ``x0`` wired to
   Feedthrough's ``Real_input``; serial, no log, ``--steps`` steps of 1 ms; target <= 2 us per step):
   the master's loop wall time per step minus a bare loop making the same FMI calls on the same two
   FMUs (GetReal of x0, SetReal of Real_input, both doSteps) in the cheapest way ctypes offers from
   Python: prototypes without argument types, every argument converted to C beforehand, only the
   time updated in place. What is left is what the master adds: its loop, the link copy, status and
   NaN checks, component timing, method dispatch.

3. The two algorithms on the run of part 1 (issue 36 item 2): Gauss-Seidel and Jacobi, each
   component's turn one C call in both (Jacobi copies every link first, then the turns), as the master
   runs them (its loop in C) and with its loop in Python (``cosim.engine.cloop.make`` replaced here),
   run after one another in each round; the loop's wall time per step of each (best of the rounds) and their
   ratio (target: Jacobi <= 1.15 x Gauss-Seidel).

Parts 1 and 2 run twice: as the master runs (each co-simulation component's turn in one C call,
cosim.fmi.turn, and where every component has one, blocks of macro steps in one call, cosim.engine.cloop:
then a component's time is read by the C loop's clock) and with that helper made unavailable (``cosim.fmi.turn.helper`` replaced here), so the
same FMI calls are made from Python one by one, as on a machine without a C compiler. Each figure is
the best of ``--rounds`` rounds; the runs alternate so machine load drifts affect all alike.

    python benchmarks/master_native.py [--stop-time 10] [--steps 20000] [--rounds 5]
"""

from __future__ import annotations

import argparse
import ctypes
import math
import os
import sys
import time
from ctypes import c_double, c_int, c_size_t, c_uint32, c_void_p
from functools import partial
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # cfmus, the C test FMUs

TARGET_FMU_US = 2.0  # issue 23: each native FMU at most 2 us per 1 ms step in our master
TARGET_MASTER_US = 2.0  # issue 23: the master's own cost at most 2 us per step on two C FMUs
TARGET_JACOBI = 1.15  # issue 36 item 2: the Jacobi loop at most 1.15 x the Gauss-Seidel loop
STEP = 1e-3

TWO_C = """
name: two_c_fmus
components:
  osc: {{path: "{osc}"}}
  thru: {{path: "{thru}"}}
connections:
  - {{from: osc.x0, to: thru.Real_input}}
time: {{stop: {stop}, step: 0.001}}
parallel: "off"
"""


def helix_native(stop: float, algorithm: str = "gauss_seidel"):
    from cosim.run import run_scenario
    from cosim.engine.scenario import load_scenario

    overrides = {("time", "stop"): stop, ("fmus",): "native", ("parallel",): "off", ("algorithm",): algorithm}
    res = run_scenario(load_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml", overrides), log=False)
    if res.status != "completed":
        sys.exit(f"helix_ctc_analytic (native) did not complete: {res.status} {res.message}")
    return res


def bare_calls(osc_path: Path, thru_path: Path, steps: int) -> float:
    """Seconds per step of the two FMUs' per-step FMI calls in a bare Python loop."""
    from cosim.fmi import load_fmu, make_slave

    osc, thru = make_slave("osc", load_fmu(osc_path)), make_slave("thru", load_fmu(thru_path))
    for s in (osc, thru):
        s.bind([], [])
        s.instantiate()
        s.enter_initialization(0.0, steps * STEP)
        s.exit_initialization()

    def fn(s, name):  # the C function without argument types: ctypes converts nothing per call
        return ctypes.CFUNCTYPE(c_int)(ctypes.cast(getattr(s.fmu.dll, name), c_void_p).value)

    value = (c_double * 1)()
    vr_x0 = (c_uint32 * 1)(osc.info.variables["x0"].vr)
    vr_in = (c_uint32 * 1)(thru.info.variables["Real_input"].vr)
    t_arg, h_arg, one = c_double(), c_double(STEP), c_int(1)
    get_x0 = partial(fn(osc, "fmi2GetReal"), c_void_p(osc._c), vr_x0, c_size_t(1), value)
    set_in = partial(fn(thru, "fmi2SetReal"), c_void_p(thru._c), vr_in, c_size_t(1), value)
    step_osc = partial(fn(osc, "fmi2DoStep"), c_void_p(osc._c), t_arg, h_arg, one)
    step_thru = partial(fn(thru, "fmi2DoStep"), c_void_p(thru._c), t_arg, h_arg, one)
    t0 = time.perf_counter()
    for k in range(steps):
        t_arg.value = k * STEP
        step_osc()
        get_x0()
        set_in()
        step_thru()
    per_step = (time.perf_counter() - t0) / steps
    for s in (osc, thru):
        s.terminate()
        s.free()
    return per_step


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated s of helix_ctc_analytic (default 10)")
    ap.add_argument("--steps", type=int, default=20000, help="steps of the two-FMU runs (default 20000)")
    ap.add_argument("--rounds", type=int, default=5, help="rounds, the best of each figure kept (default 5)")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "master_native") as rec:
        _measure(args, rec)


def _measure(args, rec: record.Recording) -> None:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    from cfmus import build

    from cosim.engine import cloop
    from cosim.fmi import turn
    from cosim.run import run_scenario
    from cosim.engine.scenario import parse_scenario

    helix_native(0.01)  # build and cache the native FMUs (and the C turn) outside the measurement
    if turn.helper() is None:
        print(f"the C turn is unavailable here ({turn.unavailable()}): both modes make the calls from Python")
    osc, thru = build("VanDerPol", 2), build("Feedthrough", 2)
    two = parse_scenario(TWO_C.format(osc=osc, thru=thru, stop=args.steps * STEP), str(ROOT / "two_c_fmus.yaml"))
    modes = {"C turns": turn.helper, "Python calls": lambda: None}
    inf = math.inf
    per_comp: dict[str, dict[str, float]] = {m: {} for m in modes}
    best = {m: {"helix_master": inf, "helix_wall": inf, "master": inf, "outside": inf} for m in modes}
    bare = inf
    loops = {(a, where): inf for where in ("C", "Python") for a in ("gauss_seidel", "jacobi")}
    make = cloop.make
    for r in range(args.rounds):
        bare = min(bare, bare_calls(osc, thru, args.steps))
        turn.helper = modes["C turns"]
        for algorithm, where in list(loops)[:: 1 if r % 2 == 0 else -1]:  # each first in every other round
            cloop.make = make if where == "C" else (lambda ex: None)
            try:
                res = helix_native(args.stop_time, algorithm)
            finally:
                cloop.make = make
            loops[algorithm, where] = min(loops[algorithm, where], res.wall_time / res.steps)
        for mode, helper in modes.items():
            turn.helper = helper  # what cosim.fmi's co-simulation wrappers get when they bind their turn
            b = best[mode]
            res = helix_native(args.stop_time)
            for name, sec in res.component_time.items():
                per_comp[mode][name] = min(per_comp[mode].get(name, inf), sec / res.steps)
            b["helix_master"] = min(b["helix_master"], (res.wall_time - sum(res.component_time.values())) / res.steps)
            b["helix_wall"] = min(b["helix_wall"], res.wall_time / res.steps)
            res = run_scenario(two, log=False)
            b["master"] = min(b["master"], res.wall_time / res.steps)
            b["outside"] = min(b["outside"], (res.wall_time - sum(res.component_time.values())) / res.steps)
    turn.helper = modes["C turns"]
    us = 1e6
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; best of {args.rounds} rounds; "
          f"us per 1 ms step")
    print(f"1. helix_ctc_analytic, native FMUs, serial, no log, {args.stop_time:g} s: component_time_s / steps "
          f"(target <= {TARGET_FMU_US:g} each)")
    print(f"   {'':<6} " + "".join(f"{m:>14}" for m in modes))
    rec.put("component_c_us", {name: t * us for name, t in per_comp["C turns"].items()})
    rec.put("component_python_us", {name: t * us for name, t in per_comp["Python calls"].items()})
    rec.put("helix_step_c_us", best["C turns"]["helix_wall"] * us)
    rec.put("helix_master_c_us", best["C turns"]["helix_master"] * us)
    for name in per_comp["C turns"]:
        row = [per_comp[m][name] * us for m in modes]
        verdict = "met" if row[0] <= TARGET_FMU_US else "NOT met"
        print(f"   {name:<6} " + "".join(f"{x:14.2f}" for x in row) + f"   target {verdict}")
    print(f"   {'step':<6} " + "".join(f"{best[m]['helix_wall'] * us:14.2f}" for m in modes) + "   whole step")
    print(f"   {'master':<6} " + "".join(f"{best[m]['helix_master'] * us:14.2f}" for m in modes)
          + "   outside the components (step loop, observers)")
    print(f"2. two C FMUs (VanDerPol.x0 -> Feedthrough.Real_input, FMI 2 CS), serial, no log, {args.steps} steps "
          f"(target <= {TARGET_MASTER_US:g} for the master's own)")
    print(f"   bare FMI calls from a Python loop: {bare * us:.2f}")
    rec.put("two_bare_us", bare * us)
    for mode in modes:
        b = best[mode]
        own = b["master"] - bare
        verdict = "met" if own * us <= TARGET_MASTER_US else "NOT met"
        if own < 0:
            verdict += " (the master's loop in C is faster than a Python loop making the same calls)"
        key = "c" if mode == "C turns" else "python"
        rec.put(f"two_master_{key}_us", b["master"] * us)
        rec.put(f"two_own_{key}_us", own * us)
        print(f"   {mode:<13}: master {b['master'] * us:5.2f} - bare {bare * us:5.2f} = master's own {own * us:5.2f}"
              f"   target {verdict}; outside the component timings {b['outside'] * us:.2f}")
    print(f"3. helix_ctc_analytic, native FMUs, serial, no log, {args.stop_time:g} s, C turns: the loop per step "
          f"(target Jacobi <= {TARGET_JACOBI:g} x Gauss-Seidel)")
    for where in ("C", "Python"):
        gs, jac = loops["gauss_seidel", where], loops["jacobi", where]
        key = where.lower()
        rec.put(f"gauss_seidel_{key}_us", gs * us)
        rec.put(f"jacobi_{key}_us", jac * us)
        rec.put(f"jacobi_ratio_{key}", jac / gs)
        print(f"   loop in {where:<6}: Gauss-Seidel {gs * us:6.2f}   Jacobi {jac * us:6.2f}   ratio {jac / gs:.3f}   "
              f"target {'met' if jac / gs <= TARGET_JACOBI else 'NOT met'}")


if __name__ == "__main__":
    main()
