"""Model exchange against co-simulation: helix_ctc_me vs helix_ctc_analytic, side by side.

Both scenarios run the same helix, IK and CTC FMUs against the same analytic plant: in
``helix_ctc_analytic`` the plant is an FMI 2.0 co-simulation FMU that integrates itself with
fixed-step RK4 (``delta.dynamics.integrate``, 1 ms); in ``helix_ctc_me`` it is the FMI 3.0 model-exchange FMU of the
same dynamics, integrated by the master (``cosim/fmi/model_exchange.py``, ``cosim/fmi/integrators.py``)
with the solver named in the scenario. Each run is timed on its stepping loop (``RunResult.wall_time``;
no FMU build, instantiation or worker start) with logging off; the scenarios run alternately
``--rounds`` times so drifts in machine load affect both alike, and the best of each is kept.
The platform RMSE of each run is printed as a check that they compute the same thing.

``--solvers`` runs the model-exchange scenario once per listed solver (default: the scenario's
own, then the other), so the choice written in the scenario is measured, not assumed.

    python benchmarks/model_exchange.py [--stop-time 10] [--rounds 3] [--solvers dop853,cvode]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CS = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
ME = ROOT / "scenarios" / "helix_ctc_me.yaml"
TARGET_RATIO = 1.5  # issue 13: model exchange at most 1.5x the co-simulation run's wall time


def run(path: Path, stop: float, solver: str | None, parallel: str) -> tuple[float, float]:
    """(loop wall seconds, worst per-axis RMSE) of one run."""
    from cosim.run import run_scenario
    from cosim.engine.scenario import load_scenario

    overrides = {("time", "stop"): stop, ("parallel",): parallel}
    if solver is not None:
        overrides[("components", "plant", "solver")] = solver
    res = run_scenario(load_scenario(path, overrides), log=False)
    return res.wall_time, max(e.rmse for e in res.errors)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds per run (default 10)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations; the best of each is kept (default 3)")
    ap.add_argument("--solvers", default=None,
                    help="comma-separated ME solvers to time (default: the scenario's, then the other)")
    ap.add_argument("--parallel", default="off", choices=["off", "on", "auto"],
                    help="the scenarios' parallel key for every run (default off: one process, like for like)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from cosim.fmi.integrators import SOLVERS
    from cosim.engine.scenario import load_scenario

    own = load_scenario(ME).components["plant"].solver
    solvers = args.solvers.split(",") if args.solvers else [own] + [s for s in SOLVERS if s != own]
    best: dict[str, float] = {}
    rmse: dict[str, float] = {}
    labels = ["co-simulation (helix_ctc_analytic)"] + [f"model exchange, {s} (helix_ctc_me)" for s in solvers]
    for r in range(args.rounds):
        for label, solver in zip(labels, [None] + solvers):
            path = CS if solver is None else ME
            wall, err = run(path, args.stop_time, solver, args.parallel)
            best[label] = min(best.get(label, float("inf")), wall)
            rmse[label] = err
            print(f"round {r + 1}: {label}: {wall:.3f} s", flush=True)
    base = best[labels[0]]
    print(f"\n{args.stop_time:g} s simulated, best of {args.rounds}, parallel: {args.parallel}")
    for label in labels:
        ratio = best[label] / base
        verdict = "" if label == labels[0] else (
            f"  ratio {ratio:.2f} ({'meets' if ratio <= TARGET_RATIO else 'misses'} the {TARGET_RATIO} target)")
        print(f"  {label:<44} {best[label]:7.3f} s  RMSE {rmse[label]:.4g} m{verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
