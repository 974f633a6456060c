"""The kinematics and dynamics core per call, side by side with an earlier commit, and the analytic plant's run.

Part 1, per call, both trees in one run: each tree (this checkout and ``--baseline``, by default the
parent of the commit that replaced ``delta/scalar_kinematics.py`` by the model / data core) runs the
same probe in its own Python process, alternately ``--rounds`` times, and the best of each is kept:

* ``IK step``: what the IK FMU computes per step: inverse kinematics, the joint-limit check, joint
  velocity and acceleration of 2000 poses of the default helix;
* ``CTC law``: ``CTC.output_scalar`` on 2000 measured states near the helix (fresh ``q`` every call,
  so the forward kinematics is never cached);
* ``forward dynamics``: ``qdd = M^-1 (u - C qd - G)`` at the same states (joint coordinates: the
  model-exchange plant's derivative);
* ``plant step``: what the co-simulation analytic plant does per 1 ms step under a held effort: before,
  SciPy's DOP853 at rtol 1e-10 / atol 1e-12 over ``forward_dynamics`` (as its adapter called it); now
  ``delta.dynamics.integrate`` (one RK4 step in platform coordinates), 500 steps along the helix.

Part 2, this checkout: ``helix_ctc_analytic`` (analytic plant) against ``helix_ctc`` (full Exudyn plant),
``--stop`` s simulated, no log, each timed on its stepping loop (``RunResult.wall_time``), alternately,
best of ``--rounds``, with the CTC tracking RMSE per axis. ``--plant-baseline`` also runs
``helix_ctc_analytic`` in the baseline tree.

Part 3, the ceiling: what 4x leaves the plant's computation. ``helix_ctc_analytic`` runs once more with
the analytic plant FMU computing nothing (its ``advance`` and ``refresh`` replaced by no-ops in the probe
process): its component time is then its FMI exchange alone. Everything but the plant is taken from the
normal run (``wall - component_time["plant"]``), not from the idle one, where the frozen plant would let
the CTC FMU's forward kinematics hit its cache. The ceiling is the run with a plant of exchange only,
``others + exchange``; 4x leaves the plant's computation ``(helix_ctc / 4 - others - exchange) / steps``
per step, against ``(plant - exchange) / steps`` it takes.

    python benchmarks/core.py [--rounds 5] [--stop 10] [--baseline REV] [--plant-baseline]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
SPEEDUP_TARGET = 4.0  # issue 16: helix_ctc_analytic at least 4x faster than helix_ctc
RMSE_TARGET = 1e-7  # m per axis, CTC on the analytic plant
STEP = 1e-3  # s, the communication step of both scenarios

# Runs inside either tree (PYTHONPATH = that tree): the new core if delta.model exists, else the
# plain-float module it replaced. Prints {"ik": us, "ctc": us, "fwd": us} per robot.
ISOLATE = r'''
import sys
# the project's editable install maps its packages to the main checkout: use the tree on PYTHONPATH only
sys.meta_path[:] = [f for f in sys.meta_path if "__editable__" not in getattr(f, "__module__", "")]
'''

PROBE = ISOLATE + r'''
import importlib.util, json, sys, timeit
import numpy as np
from delta.control import default_controller
from delta.dynamics import joint_references, analytic_model
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.trajectories import Helix

NEW = importlib.util.find_spec("delta.model") is not None
N = 2000

def per_call(fn, n):
    return min(timeit.repeat(fn, number=1, repeat=7)) / n * 1e6

out = {}
for robot in (linear_delta_thesis, rotary_delta_prototype):
    t = np.linspace(0.0, 10.0, N)
    p, v, a = Helix().sample(t) if robot.kind == "linear" else Helix(z0=-0.45, rx=0.05, ry=0.05).sample(t)
    model = analytic_model(robot)
    q_ref, qd_ref, qdd_ref = joint_references(model, p, v, a)
    rng = np.random.default_rng(1)
    q = (q_ref + rng.normal(0.0, 1e-4, q_ref.shape)).tolist()
    qd = (qd_ref + rng.normal(0.0, 1e-3, qd_ref.shape)).tolist()
    refs = list(zip(q_ref.tolist(), qd_ref.tolist(), qdd_ref.tolist()))
    poses = list(zip(map(tuple, p.tolist()), map(tuple, v.tolist()), map(tuple, a.tolist())))
    u = [tuple(x) for x in np.tile(model.gravity_term(q_ref[0]), (N, 1)).tolist()]
    ctc = default_controller("ctc", robot, model)
    steps = list(zip(poses[::4][:500], q[::4][:500], qd[::4][:500], u[::4][:500]))
    if NEW:
        from delta.dynamics import forward_dynamics, integrate
        from delta.kinematics import inverse_kinematics
        from delta.model import Data
        m = model.model
        fd = Data(m) if "model" in Data.__slots__ else Data()  # a tree from before Data(model): Data()
        def ik_step():
            for pp, vv, aa in poses:
                inverse_kinematics(m, pp, vv, aa)
        def fwd():
            for x, xd, f in zip(q, qd, u):
                forward_dynamics(m, fd, x, xd, f)
        def plant():
            for (pp, vv, _), x, xd, f in steps:
                integrate(m, pp, vv, f, 1e-3, 1e-3)
    else:
        from delta.scalar_kinematics import ScalarKinematics
        kin = ScalarKinematics(robot)
        def ik_step():
            for pp, vv, aa in poses:
                qq, leg = kin.ik(pp)
                kin.limit_violation(qq)
                kin.joint_rates(qq, pp, vv, aa)
        def fwd():
            for x, xd, f in zip(q, qd, u):
                model.accel(x, xd, f)
        from scipy.integrate import solve_ivp
        def rhs(t, x, f):
            return np.concatenate([x[3:], model.forward_dynamics(x[:3], x[3:], f)])
        def plant():
            for _, x, xd, f in steps:
                solve_ivp(rhs, (0.0, 1e-3), np.array(x + xd), method="DOP853", args=(np.array(f),), rtol=1e-10, atol=1e-12)
    def law():
        for x, xd, (qr, qdr, qddr) in zip(q, qd, refs):
            ctc.output_scalar(x, xd, qr, qdr, qddr)
    out[robot.kind] = {"ik": per_call(ik_step, N), "ctc": per_call(law, N), "fwd": per_call(fwd, N),
                       "plant": per_call(plant, len(steps))}
print(json.dumps(out))
'''

PLANT = ISOLATE + r'''
import json, sys
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario
name, stop, idle = sys.argv[1], float(sys.argv[2]), sys.argv[3:] == ["idle"]
# the python build of our FMUs (what this benchmark measures; a tree from before the native build has no key)
from cosim.engine.scenario import Scenario
BUILD = {("fmus",): "python"} if "fmus" in Scenario.model_fields else {}
if idle:  # the plant FMU's code, loaded by a one-step run, then kept by the process: make it compute nothing
    run_scenario(load_scenario(f"scenarios/{name}.yaml", {("time", "stop"): 1e-3, **BUILD}), log=False)
    # the FMU's own copy (bundled as _dcosim_<hash>.fmus...); a tree whose registry imports the adapters also
    # holds the project's module, which the FMU does not run
    found = {n: m for n, m in sys.modules.items()  # the module that declares it: analytic_plant, once plants
             if n.endswith(("fmus.adapters.analytic_plant", "fmus.adapters.plants")) and hasattr(m, "AnalyticPlant")}
    plants = [m.AnalyticPlant for n, m in found.items() if n.startswith("_dcosim_") or len(found) == 1]
    assert len(plants) == 1, found
    plants[0].advance = lambda self, t, h: None
    plants[0].refresh = lambda self: None
res = run_scenario(load_scenario(f"scenarios/{name}.yaml", {("time", "stop"): stop, **BUILD}), log=False)
print(json.dumps({"wall": res.wall_time, "rmse": [e.rmse for e in res.errors], "plant": res.component_time["plant"]}))
'''


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def default_baseline() -> str:
    """The parent of the commit that removed delta/scalar_kinematics.py (HEAD if none did)."""
    removed = _git("log", "-1", "--format=%H", "--diff-filter=D", "--", "delta/scalar_kinematics.py")
    return f"{removed}^" if removed else "HEAD"


def run_in(tree: Path, code: str, *args: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", code, *args], cwd=tree, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"benchmark probe failed in {tree}:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="alternations; the best of each is kept (default 5)")
    ap.add_argument("--stop", type=float, default=10.0, help="simulated seconds of each scenario run (default 10)")
    ap.add_argument("--baseline", default=None, help="git revision to compare with (default: before the core)")
    ap.add_argument("--plant-baseline", action="store_true",
                    help="also time helix_ctc_analytic in the baseline tree (builds its FMUs)")
    record.add_options(ap)
    args = ap.parse_args(argv)
    return record.measured(args, "core", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    rev = args.baseline or default_baseline()
    sha = _git("rev-parse", "--short", rev)
    print(f"baseline {rev} = {sha}; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}", flush=True)
    with tempfile.TemporaryDirectory(prefix="cosim-bench-") as tmp:
        base = Path(tmp) / "baseline"
        _git("worktree", "add", "--detach", "--quiet", str(base), rev)
        try:
            best: dict[str, dict[str, dict[str, float]]] = {}
            for r in range(args.rounds):
                for label, tree in (("baseline", base), ("this tree", ROOT)):
                    res = run_in(tree, PROBE)
                    for kind, calls in res.items():
                        slot = best.setdefault(label, {}).setdefault(kind, {})
                        for k, us in calls.items():
                            slot[k] = min(slot.get(k, float("inf")), us)
                print(f"round {r + 1}/{args.rounds} done", flush=True)
            print(f"\nper call, best of {args.rounds} (us)        baseline {sha}   this tree   ratio")
            names = {"ik": "IK step (IK + limits + rates)", "ctc": "CTC law", "fwd": "forward dynamics",
                     "plant": "analytic plant, 1 ms step"}
            for kind in ("linear", "rotary"):
                for k, text in names.items():
                    old, new = best["baseline"][kind][k], best["this tree"][kind][k]
                    verdict = "not slower" if new <= old else "SLOWER"
                    print(f"  {kind:<6} {text:<30} {old:9.2f}   {new:9.2f}   {new / old:5.2f}  {verdict}")
            plants = {}
            labels = [("helix_ctc", ROOT, ()), ("helix_ctc_analytic", ROOT, ()), ("helix_ctc_analytic", ROOT, ("idle",))]
            if args.plant_baseline:
                labels.append(("helix_ctc_analytic", base, ()))
            for r in range(args.rounds):
                for name, tree, extra in labels:
                    res = run_in(tree, PLANT, name, str(args.stop), *extra)
                    key = (name, tree == base, bool(extra))
                    if key not in plants or res["wall"] < plants[key]["wall"]:
                        plants[key] = res
            print(f"\n{args.stop:g} s simulated, loop wall time, best of {args.rounds}, no log, "
                  "each scenario's own parallel setting")
            for (name, is_base, idle), res in plants.items():
                where = f"baseline {sha}" if is_base else "this tree, plant idle" if idle else "this tree"
                rmse = "" if idle else "   RMSE per axis " + ", ".join(f"{x:.3g}" for x in res["rmse"]) + " m"
                print(f"  {name:<20} {where:<21} {res['wall']:7.3f} s{rmse}")
            full, analytic = plants[("helix_ctc", False, False)], plants[("helix_ctc_analytic", False, False)]
            idle = plants[("helix_ctc_analytic", False, True)]
            speedup = full["wall"] / analytic["wall"]
            rmse_ok = max(analytic["rmse"]) < RMSE_TARGET
            print(f"  helix_ctc_analytic is {speedup:.2f}x faster than helix_ctc "
                  f"({'meets' if speedup >= SPEEDUP_TARGET else 'misses'} the {SPEEDUP_TARGET:g}x target); "
                  f"CTC RMSE on the analytic plant {'<' if rmse_ok else '>='} {RMSE_TARGET:g} m per axis")
            steps = round(args.stop / STEP)
            others = analytic["wall"] - analytic["plant"]  # everything but the plant, from the normal run
            exchange = idle["plant"]  # the plant FMU computing nothing: its FMI exchange
            budget = (full["wall"] / SPEEDUP_TARGET - others - exchange) / steps
            used = (analytic["plant"] - exchange) / steps
            print(f"  plant component {analytic['plant']:.3f} s, of which its FMI exchange {exchange:.3f} s (the "
                  f"plant computing nothing); the rest of the run {others:.3f} s")
            print(f"  ceiling (a plant of FMI exchange only): {others + exchange:.3f} s, "
                  f"{full['wall'] / (others + exchange):.2f}x. The {SPEEDUP_TARGET:g}x target leaves the plant "
                  f"{budget * 1e6:.1f} us per step for its computation; it takes {used * 1e6:.1f} us")
        finally:
            _git("worktree", "remove", "--force", str(base))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
