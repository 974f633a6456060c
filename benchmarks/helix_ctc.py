"""helix_ctc: wall time per simulated second, co-simulation vs a monolithic in-process loop.

The co-simulation is ``scenarios/helix_ctc.yaml`` run by the master (helix FMU -> IK FMU ->
CTC FMU -> Exudyn plant FMU, Gauss-Seidel, 1 ms). The monolithic loop does the same
computation without FMI: the same Exudyn plant (``multibody.make_plant``), the same
helix (``delta.trajectories.Helix``), the same kinematics as the IK FMU
(``delta.kinematics.inverse_kinematics``) and the same CTC law (``delta.control.CTC`` on
``delta.dynamics``), called directly in a Python loop with the master's data flow
(reference at t + h, effort computed from the state at t and held over the step).
The co-simulation runs twice: serial (``parallel: off``) and parallel (``parallel: on``: the
helix and IK FMUs, which depend on time alone, run ahead in a worker process on the second
core; same values, see cosim/engine/offload.py). All are timed on their stepping loop only (no FMU
build, instantiation, worker start or plant assembly; the time of the whole call, start-up
included, is printed too), alternated ``--rounds`` times so machine load drifts affect them
alike; the best of each is kept. The platform RMSE of each is printed as a check that they
compute the same thing.

``--fmus`` picks the build of our FMUs (default: the scenario's, ``auto``: native where a C compiler is found);
docs/figures.md's rows are ``--fmus python``.

    python benchmarks/helix_ctc.py [--stop-time 10] [--rounds 3] [--log] [--fmus auto|python|native]
                                   [--json FILE | --record]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "helix_ctc.yaml"
STEP_NS = 1_000_000  # the scenario's 1 ms step


def monolithic(stop_time: float) -> tuple[float, list[float], dict[str, float]]:
    """Wall seconds of the loop, RMSE per axis and time per part, for ``stop_time`` s."""
    from delta.control import DEFAULT_GAINS, CTC
    from delta.dynamics import LinearDeltaMasses
    from delta.kinematics import inverse_kinematics
    from delta.model import build_model
    from delta.robots import get_preset
    from delta.trajectories import Helix
    from multibody import make_plant

    robot = get_preset("linear_delta_thesis")
    masses = LinearDeltaMasses()
    helix = Helix()
    gains = DEFAULT_GAINS["linear"]
    h = STEP_NS * 1e-9
    model = build_model(robot, masses)
    law = CTC(model, gains["ctc"]["kp"], gains["ctc"]["kd"], h, u_max=gains["u_max"]["u_max"])

    def reference(t: float):
        p, v, a = helix.evaluate_scalar(t)  # the trajectory FMU's per-step path
        q, qd, qdd, fault = inverse_kinematics(model, p, v, a)
        if fault:
            raise SystemExit(f"helix leaves the workspace at t = {t} s (leg {abs(fault)})")
        return p, q, qd, qdd

    p0, v0, _ = helix.evaluate(0.0)
    plant = make_plant(robot, masses, fidelity="full", p0=p0, v0=v0)
    out = plant.reset(p0, v0)
    _, q_ref, qd_ref, qdd_ref = reference(0.0)
    u = law.output_scalar(out.q, out.qd, q_ref, qd_ref, qdd_ref)  # the controller FMU's path
    n = int(round(stop_time * 1e9)) // STEP_NS
    sq = [0.0, 0.0, 0.0]
    parts = {"plant": 0.0, "trajectory + IK": 0.0, "control": 0.0}
    clock = time.perf_counter
    t_start = clock()
    for k in range(n):
        t = (k * STEP_NS) * 1e-9
        c0 = clock()
        out = plant.step(t, h, u)
        c1 = clock()
        p_ref, q_ref, qd_ref, qdd_ref = reference(t + h)
        c2 = clock()
        u = law.output_scalar(out.q, out.qd, q_ref, qd_ref, qdd_ref)  # the controller FMU's path
        c3 = clock()
        parts["plant"] += c1 - c0
        parts["trajectory + IK"] += c2 - c1
        parts["control"] += c3 - c2
        for i in range(3):
            sq[i] += (float(out.p[i]) - p_ref[i]) ** 2
    wall = clock() - t_start
    return wall, [math.sqrt(s / n) for s in sq], parts


def cosim(stop_time: float, log: bool, out: Path, parallel: str = "off", fmus: str = "auto"):
    """The master's RunResult for helix_ctc over ``stop_time`` s, and the whole call's wall time."""
    from cosim.run import run_scenario
    from cosim.engine.scenario import load_scenario

    scenario = load_scenario(SCENARIO, {("time", "stop"): stop_time, ("parallel",): parallel, ("fmus",): fmus})
    t0 = time.perf_counter()
    res = run_scenario(scenario, out=out, log=log)
    return res, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds (default 10)")
    ap.add_argument("--rounds", type=int, default=3, help="alternated rounds, best kept (default 3)")
    ap.add_argument("--log", action="store_true", help="also time the co-simulation with every signal logged")
    ap.add_argument("--fmus", choices=("auto", "python", "native"), default="auto",
                    help="the build of our FMUs (default auto, the scenario's)")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "helix_ctc") as rec:
        _measure(args, rec)


def _measure(args, rec: record.Recording) -> None:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    tmp = Path(tempfile.mkdtemp(prefix="helix_ctc_bench_"))
    cosim(0.01, False, tmp / "warm.mcap", fmus=args.fmus)  # build/cache the FMUs outside the measurement
    runs = [("serial", "off", False, "co-simulation, serial"), ("parallel", "on", False, "co-simulation, parallel")]
    if args.log:
        runs += [("serial_log", "off", True, "serial, all logged"), ("parallel_log", "on", True, "parallel, all logged")]
    best = {key: math.inf for key in ["mono"] + [r[0] for r in runs]}
    whole = dict.fromkeys(best, math.inf)
    rmse: dict[str, list[float]] = {}
    shares: dict[str, dict[str, float]] = {}
    worker: dict[str, dict[str, float]] = {}
    parts: dict[str, float] = {}
    for _ in range(args.rounds):
        wall, rmse["mono"], mono_parts = monolithic(args.stop_time)
        if wall < best["mono"]:
            best["mono"], parts = wall, mono_parts
        for key, parallel, log, _label in runs:
            res, call = cosim(args.stop_time, log, tmp / "bench.mcap", parallel, args.fmus)
            if res.status != "completed":
                sys.exit(f"co-simulation did not complete: {res.status} {res.message}")
            if parallel == "on" and not res.worker_time:
                sys.exit(f"the parallel run did not run in parallel: {res.notes}")
            rmse[key] = [e.rmse for e in res.errors]
            whole[key] = min(whole[key], call)
            if res.wall_time < best[key]:
                best[key], shares[key], worker[key] = res.wall_time, dict(res.component_time), res.worker_time
    per_s = {k: v / args.stop_time for k, v in best.items()}
    rec.put("loop_s", best)  # best of the rounds: "mono" the monolithic loop, the others the co-simulations
    rec.put("whole_call_s", {k: v for k, v in whole.items() if k != "mono"})
    rec.put("ratio_to_monolithic", {k: v / best["mono"] for k, v in best.items() if k != "mono"})
    rec.put("rmse_m", rmse)
    rec.put("monolithic_split", {k: v / best["mono"] for k, v in parts.items()})
    rec.put("worker_s", worker)
    print(f"helix_ctc, {args.stop_time:g} s simulated at 1 ms, best of {args.rounds} alternated rounds")
    print(f"  monolithic loop (no FMI)      : {per_s['mono']:7.3f} s wall per simulated s "
          f"({best['mono']:.3f} s)  RMSE x/y/z {' / '.join(f'{e:.3e}' for e in rmse['mono'])} m")
    print("      " + ", ".join(f"{k} {v / best['mono'] * 100:.0f}%" for k, v in parts.items()))
    for key, _parallel, _log, label in runs:
        print(f"  {label:<30}: {per_s[key]:7.3f} s wall per simulated s ({best[key]:.3f} s)  "
              f"ratio to monolithic {best[key] / best['mono']:.2f}  RMSE x/y/z "
              f"{' / '.join(f'{e:.3e}' for e in rmse[key])} m")
        total = sum(shares[key].values())
        print("      " + ", ".join(f"{k} {v / best[key] * 100:.0f}%" for k, v in shares[key].items())
              + f", master {(best[key] - total) / best[key] * 100:.0f}%; whole call incl. start-up {whole[key]:.2f} s"
              + ("; in the worker: " + ", ".join(f"{k} {v:.2f} s" for k, v in worker[key].items())
                 if worker[key] else ""))
    same = all(rmse[key] == rmse["serial"] for key, *_ in runs)
    print(f"  serial and parallel RMSE identical to the last digit: {same}")
    for key, label in (("serial", "serial"), ("parallel", "parallel")):
        print(f"  10 s of helix_ctc ({label}, no logging): {per_s[key] * 10:.2f} s wall (target <= 5 s); "
              f"ratio {best[key] / best['mono']:.2f} (target <= 1.3)")


if __name__ == "__main__":
    main()
