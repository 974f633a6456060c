"""Model exchange against co-simulation: helix_ctc_me vs helix_ctc_analytic, side by side.

Both scenarios run the same helix, IK and CTC FMUs against the same analytic plant: in
``helix_ctc_analytic`` the plant is a co-simulation FMU that integrates itself with fixed-step RK4
(``delta.dynamics.integrate``, 1 ms); in ``helix_ctc_me`` it is the FMI 3.0 model-exchange FMU of the
same dynamics, integrated by the master (``cosim/fmi/model_exchange.py``; ``cvode`` and ``dopri5`` in C,
``cosim/fmi/me_loop.c``, where a C compiler is; ``dop853`` in Python, ``cosim/fmi/integrators.py``) with
the solver named in the scenario. Each run is timed on its stepping loop (``RunResult.wall_time``; no FMU
build, instantiation or worker start) with logging off, serial; the scenarios run alternately ``--rounds``
times so drifts in machine load affect both alike; the best of each is kept, and the median of the ratios of each
round's pair (this machine's runs fall in two bands, one about half as long as the other, so a best of rounds may
pair a fast-band run with a slow-band one). ``--fmus`` picks the
build of every FMU (default native: the C FMUs, the master at its limit).

Then, untimed, each model-exchange run is checked against the co-simulation run: the largest distance
between their plants' end-effector positions (``plant.p``) over the run, which must stay within 1e-6 m.

``--solvers`` runs the model-exchange scenario once per listed solver (default: the scenario's own,
then the others), so the choice written in the scenario is measured, not assumed.

    python benchmarks/model_exchange.py [--stop-time 10] [--rounds 3] [--solvers dopri5,cvode,dop853]
                                        [--json FILE | --record]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
CS = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
ME = ROOT / "scenarios" / "helix_ctc_me.yaml"
TARGET_RATIO = 1.5  # issue 36: model exchange at most 1.5x the co-simulation run's wall time
PLANT_ATOL = 1e-6  # m: the ME plant against the CS plant
SIGNALS = ["plant.p.x", "plant.p.y", "plant.p.z"]


def _scenario(path: Path, stop: float, solver: str | None, fmus: str):
    from cosim.engine.scenario import load_scenario

    overrides = {("time", "stop"): stop, ("parallel",): "off", ("fmus",): fmus}
    if solver is not None:
        overrides[("components", "plant", "solver")] = solver
    return load_scenario(path, overrides)


def run(path: Path, stop: float, solver: str | None, fmus: str) -> float:
    """Loop wall seconds of one run, logging off."""
    from cosim.run import run_scenario

    return run_scenario(_scenario(path, stop, solver, fmus), log=False).wall_time


def plant_positions(path: Path, stop: float, solver: str | None, fmus: str) -> list[list[float]]:
    """plant.p's x, y, z at every step of one (untimed) run."""
    from cosim.observers.recorders import Probe
    from cosim.run import run_scenario

    probe = Probe(SIGNALS)
    run_scenario(_scenario(path, stop, solver, fmus), log=False, observers=[probe], read_all=True)
    return [probe.values[s] for s in SIGNALS]


def largest_distance(a: list[list[float]], b: list[list[float]]) -> float:
    return max(math.dist(p, q) for p, q in zip(zip(*a), zip(*b)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds per run (default 10)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations; the best of each is kept (default 3)")
    ap.add_argument("--solvers", default=None,
                    help="comma-separated ME solvers to time (default: the scenario's, then the others)")
    ap.add_argument("--fmus", default="native", choices=["native", "python"],
                    help="the build of every FMU (default native)")
    record.add_options(ap)
    args = ap.parse_args(argv)
    with record.Recording(args, "model_exchange") as rec:
        _measure(args, rec)
    return 0


def _measure(args, rec: record.Recording) -> None:
    sys.path.insert(0, str(ROOT))
    from cosim.engine.scenario import load_scenario
    from cosim.fmi import me_c
    from cosim.fmi.integrators import SOLVERS

    own = load_scenario(ME).components["plant"].solver
    solvers = args.solvers.split(",") if args.solvers else [own] + [s for s in SOLVERS if s != own]
    best: dict[str, float] = {}
    walls: dict[str, list[float]] = {}
    labels = ["co-simulation (helix_ctc_analytic)"] + [f"model exchange, {s} (helix_ctc_me)" for s in solvers]
    for r in range(args.rounds):
        for label, solver in zip(labels, [None] + solvers):
            wall = run(CS if solver is None else ME, args.stop_time, solver, args.fmus)
            best[label] = min(best.get(label, float("inf")), wall)
            walls.setdefault(label, []).append(wall)
            print(f"round {r + 1}: {label}: {wall:.3f} s", flush=True)
    reference = plant_positions(CS, args.stop_time, None, args.fmus)
    base = best[labels[0]]
    why = me_c.unavailable()
    print(f"\n{args.stop_time:g} s simulated, {args.fmus} FMUs, serial, no log, best of {args.rounds}; "
          f"ME integration {'in Python (' + why + ')' if why else 'in C where the solver has it (cvode, dopri5)'}")
    worst_ratio = 0.0
    for label, solver in zip(labels, [None] + solvers):
        if solver is None:
            print(f"  {label:<44} {best[label]:7.3f} s")
            rec.put("cs_s", best[label])
            continue
        ratio = best[label] / base
        paired = statistics.median(me / cs for me, cs in zip(walls[label], walls[labels[0]]))
        dist = largest_distance(plant_positions(ME, args.stop_time, solver, args.fmus), reference)
        rec.put(f"me_{solver}_s", best[label])
        rec.put(f"ratio_{solver}", ratio)
        rec.put(f"paired_ratio_{solver}", paired)
        rec.put(f"distance_{solver}_m", dist)
        speed = "meets" if ratio <= TARGET_RATIO else "misses"
        accuracy = "meets" if dist <= PLANT_ATOL else "misses"
        print(f"  {label:<44} {best[label]:7.3f} s  ratio {ratio:.2f} ({speed} {TARGET_RATIO}x; the median of the rounds' "
              f"ratios {paired:.2f})  plant vs CS plant "
              f"{dist:.3g} m ({accuracy} {PLANT_ATOL:g} m)")
        if solver == own:
            worst_ratio = ratio
    print(f"the scenario's solver ({own}): ratio {worst_ratio:.2f}")


if __name__ == "__main__":
    raise SystemExit(main())
